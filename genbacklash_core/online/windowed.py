"""Online identification over a sliding window: warm-started iterations of the batch method.

A plain recursive least-squares over the paper's regressors converges slowly from a cold start
(GUIDE §2): early wrong switching decisions stay in the estimate. Re-running a few iterations of
the paper's method (eqs. 22-29, 31-37) over the most recent ``W`` samples, warm-started from the
previous estimate, converges in a few hundred samples and keeps doing so when the plant drifts.

:class:`WindowedIdentifier` keeps the last ``W`` samples in a preallocated ring buffer. The window
grows from empty to ``W`` (so the early fits use all the data). Once the buffer holds enough
samples with two input reversals, a cold start runs the batch iteration from the paper's start;
after that, every ``K`` samples it re-runs ``iterations`` warm-started iterations on the window,
optionally followed by a few output-error (Levenberg-Marquardt) steps. ``K`` grows with the
window length (``K = max(refit_every, refit_fraction * len)``), which bounds the amortised cost
per sample however large ``W`` is.

The window length trades accuracy against tracking: the estimate is a least-squares fit over
``W`` samples, so its standard deviation falls like ``1/sqrt(W)``, while a parameter that drifts
linearly is tracked with a lag of about ``W/2 + K/2`` samples.

This module holds the identifier itself: the schedule, the cold and warm fits, and what it
publishes. What it fits on (the rows of a backlash alone, the samples of a cascade) stands in
:mod:`~genbacklash_core.online.feeds`; the interface it shares with the recursive identifier
in :mod:`~genbacklash_core.online.base`, and the other parts in the sibling modules of
:mod:`genbacklash_core.online` (see there), one concept each.
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.estimate import (
    Estimate,
    EstimatorState,
    aged_confidence,
    confidence_of,
    relative_std,
)
from genbacklash_core.structure import Structure

from .advice import BranchCoverage
from .base import OnlineIdentifier
from .feeds import Feed, RowFeed, SampleFeed
from .fits import (
    FitFailure,
    WindowFit,
    cold_fit,
    conditioning_floor,
    fit_window,
    parameter_blocks,
    poorly_excited,
)
from .inputs import (
    deadband,
    settings_or_default,
    template,
)
from .seed import SeedPrior
from .settings import WindowedSettings
from .state import FITTED_STATES, confidence_moved, held, settled_state
from .tracking import with_tracking

__all__ = ["WindowedIdentifier", "WindowedSettings"]


# --------------------------------------------------------------------------- the identifier


class WindowedIdentifier(OnlineIdentifier[WindowedSettings]):
    """Online identification by warm-started batch iterations over a sliding window.

    Parameters
    ----------
    degree : int
        Polynomial degree of each branch.
    na, nb : int
        Linear block orders (eq. 30); ``na = 0`` (default) identifies a backlash alone.
    sign : {+1, -1, None}
        Branch sense; None detects it at the first fit.
    settings : WindowedSettings, optional

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(1)
    >>> data = ex.generate(seed=0, n_samples=300)
    >>> ident = WindowedIdentifier(degree=3)
    >>> est = ident.update_many(data.u, data.y)
    >>> est.state.value, est.samples
    ('converged', 300)
    >>> bool(np.max(np.abs(est.parameters - ex.model.parameters())) < 0.05)
    True
    >>> ident.update(0.5, 0.1).samples
    301

    After a restart, continue from a saved estimate instead of a cold start:

    >>> again = WindowedIdentifier(degree=3)
    >>> seeded = again.seed(est)
    >>> seeded.state.value, bool(np.array_equal(seeded.parameters, est.parameters))
    ('converged', True)
    """

    def __init__(
        self,
        degree: int = 3,
        na: int = 0,
        nb: int = 0,
        *,
        sign: float | None = None,
        settings: WindowedSettings | None = None,
    ) -> None:
        shape = template(degree, na, nb, sign)
        settings = settings_or_default(settings, WindowedSettings)
        super().__init__(shape, settings, settings.window)  # the longest regression: the window

    @property
    def min_samples(self) -> int:
        """Samples before the first fit is tried."""
        s = self.settings.min_samples
        return max(40, 6 * self._template.n_parameters) if s is None else s

    def reset(self) -> None:
        """Forget all samples and the estimate."""
        self._forget()
        s = self.settings
        # a backlash alone remembers rows by branch and input region; a cascade, samples
        self._feed: Feed = (
            SampleFeed(s.window) if self._template.cascade else RowFeed(s.window, s.bins)
        )
        self._base_confidence = 0.0  # confidence of the last fit, before ageing
        self._p: FloatArray | None = None  # equation-error estimate (warm start)
        self._reported: FloatArray | None = None  # published (refined when asked)
        self._covariance: FloatArray | None = None
        self._residual = math.nan
        self._state = EstimatorState.WARMING_UP
        self._fit_samples = 0  # samples at the last fit
        self._fit_progress = 0  # the feed's progress at the last fit
        self._next_fit = self.min_samples
        self._failures = 0
        self._restarted = True
        self._needs_cold = True
        self._cold_failures = 0
        self._conditioning_ref = np.zeros(len(parameter_blocks(self._template)))
        self._span_ref = 0.0  # widest input span of an accepted fit
        self._seed: SeedPrior | None = None  # a saved estimate the window still leans on
        self._seed_samples = 0  # samples of the window the seed stands for
        self._seed_progress = 0  # the feed's progress when the seed was planted
        self._estimate = Estimate.empty(self._status.structure)

    @property
    def coverage(self) -> BranchCoverage | None:
        """Rows per branch and input region in the memory (a backlash alone; None for the
        cascade, which remembers samples)."""
        return self._feed.coverage()

    def _set_p(self, p: FloatArray) -> None:
        """Take ``p`` as the equation-error estimate (and the cascade's settling horizon)."""
        self._p = p
        self._feed.settle(self._status.structure, p)

    def _continue_from(self, prior: SeedPrior, estimate: Estimate) -> None:
        """Continue from a seed (:meth:`seed`): its parameters as the current estimate and
        the start of the next warm-started iterations (no cold start runs), its information
        a prior standing for ``min(window, samples)`` samples of the window at first, fewer
        as the window fills, none once it is full. Output-error refinement (``refine``)
        resumes once the seed has left the window."""
        s = self.settings
        self._seed = prior
        self._seed_samples = min(s.window, estimate.samples) if estimate.samples else s.window
        self._set_p(prior.p.copy())
        self._reported = prior.p.copy()
        self._covariance = np.array(estimate.covariance, dtype=np.float64)
        self._residual = estimate.residual
        rel = relative_std(prior.p, self._covariance)
        settled = estimate.state in (EstimatorState.CONVERGED, EstimatorState.NO_EXCITATION)
        self._state = settled_state(settled, rel, s.converged_std)
        self._status.reason = (
            f"seeded from a saved estimate ({estimate.state.value}); relative std {rel:.3g}"
        )
        self._needs_cold = False
        self._restarted = False  # the next fit continues from the seed (steadiness test)
        self._fit_samples = self._status.samples
        self._fit_progress = self._seed_progress = self._feed.progress
        self._next_fit = self._feed.progress + self.min_samples
        self._rebuild()

    @property
    def from_seed(self) -> bool:
        """True while the window still leans on a seed (:meth:`seed`): it has not yet
        taken as many new samples as the seed stands for."""
        return self._seed_weight() > 0.0

    def _seed_weight(self) -> float:
        """Share of the seed's samples still counted (those new samples did not replace)."""
        if self._seed is None:
            return 0.0
        kept = self._feed.seed_left(self._seed_samples, self._seed_progress)
        return max(kept, 0) / self._seed_samples

    def _take_one(self, u: float, y: float, follows: bool) -> None:
        feed = self._feed
        if not isinstance(feed, RowFeed):
            self._intake(np.array([u]), np.array([y]), np.array([not follows]))
            return
        # one sample, without arrays (the per-sample path of a hand-written loop)
        feed.push(u, y, follows and not self._break_next)
        self._break_next = False
        self._status.samples += 1
        if feed.rows >= self._next_fit:
            self._fit()
        self._publish()

    def _take(self, uu: FloatArray, yy: FloatArray, bb: BoolArray) -> None:
        """Feed validated samples, fitting whenever the schedule says (see update_many)."""
        if uu.size:
            for count in self._feed.take(uu, yy, bb, lambda: self._next_fit):
                self._status.samples += count
                if self._feed.progress >= self._next_fit:
                    self._fit()
        self._publish()

    def refit(self) -> Estimate:
        """Fit the window now instead of at the next scheduled sample; the new estimate.

        For a final estimate at the end of a record (a replay, a benchmark): without it the
        estimate may be up to ``K`` samples old. The schedule restarts from here. Right
        after :meth:`seed`, until ``min_samples`` new samples arrived, the seed stands.
        """
        if len(self._feed) >= (1 if self._seed is None else self.min_samples):
            self._fit(early=True)
        return self._publish()

    # ---- internals

    def _published_state(self) -> tuple[EstimatorState, str, float]:
        """State, reason and confidence as published: a fitted estimate that no new
        information has confirmed for ``idle_samples`` is held (``no_excitation``), its
        confidence fading with the age of its information."""
        state, reason = self._state, self._status.reason
        if self._reported is None or self._covariance is None:
            return state, reason, 0.0
        s = self.settings
        confidence = self._base_confidence
        if state not in FITTED_STATES:
            return state, reason, confidence
        if held(self._feed.idle, s.idle_samples):
            state = EstimatorState.NO_EXCITATION
            reason = (
                f"estimate held: no information for {self._feed.idle} samples (the input rests "
                f"or repeats); {self._status.reason}"
            )
        return (
            state,
            reason,
            aged_confidence(confidence, float(self._feed.idle), s.confidence_half_life),
        )

    def excitation_advice(self) -> str:
        """What the data have not shown yet, and what motion would show it ("" when the
        memory covers both branches over the input range seen). A backlash alone only."""
        need = self.min_samples - len(self._feed) if self._p is None else 0
        return self._feed.advice(self._status.samples, need)

    def _quick_confidence(self) -> float:
        """The published confidence from the cached one of the last fit (cheap)."""
        s = self.settings
        return aged_confidence(
            self._base_confidence, float(self._feed.idle), s.confidence_half_life
        )

    def _publish(self) -> Estimate:
        est = self._estimate
        assert est is not None  # (reset made one)
        feed = self._feed
        if isinstance(feed, RowFeed) and self._reported is None:
            key = (
                feed.rows,
                self._status.samples > 1,
                self._status.reason,
            )  # the memory changes with rows
            reason = self._advice.reason(self._status.reason, key, self.excitation_advice)
            if reason != est.reason:
                self._estimate = est = Estimate.empty(
                    self._status.structure,
                    self._status.samples,
                    self._status.excitation,
                    self._state,
                    reason,
                )
        if self._reported is not None:  # held and aged by the samples without information
            is_held = held(self._feed.idle, self.settings.idle_samples)
            was_held = est.state is EstimatorState.NO_EXCITATION and self._state in (
                EstimatorState.CONVERGED,
                EstimatorState.CONVERGING,
            )
            confidence = self._quick_confidence()
            if is_held != was_held or confidence_moved(confidence, est.confidence, floor=1e-12):
                self._rebuild()
                est = self.estimate
        if est.samples != self._status.samples:
            self._estimate = est = est.with_samples(self._status.samples)
        return est

    def _schedule(self) -> None:
        s = self.settings
        k = max(s.refit_every, math.ceil(s.refit_fraction * len(self._feed)))
        if self._needs_cold and self._cold_failures:  # back off while cold starts fail,
            # but retry at least every W/8 samples: slow references excite the system slowly
            k = min(s.refit_every * 2 ** min(self._cold_failures, 10), max(s.window // 8, 1))
        self._fit_samples = self._status.samples
        self._fit_progress = self._feed.progress
        self._next_fit = self._feed.progress + k

    def _fit(self, early: bool = False) -> None:
        u, y, b = self._feed.data()
        if self._needs_cold:
            self._cold_start(u, y, b)
        else:
            recent = self._feed.progress - self._fit_progress
            if early:  # refit(): judge the excitation on as many samples as the scheduled fit
                # would have, not on the few since the last fit (a record ending at rest
                # would otherwise freeze a converged estimate as `no_excitation`)
                span = self._next_fit - self._fit_progress
                recent = max(recent, min(span, len(self._feed)))
            self._warm_fit(u, y, b, recent)
        self._schedule()
        self._rebuild()

    def _deadband(self, u: FloatArray) -> float:
        """Input step below which the input counts as resting (of the widest span fitted)."""
        # the widest span of an accepted fit (before the first fit: this window's), so a
        # narrow window after wide motion does not take small jitter for moves
        span = max(self._span_ref, float(np.ptp(u)) * self._needs_cold)
        return deadband(self.settings.input_deadband, span)

    def _start_fit(
        self, u: FloatArray, y: FloatArray, b: BoolArray
    ) -> tuple[Structure, WindowFit] | str:
        """The batch iteration from the paper's start, then the warm iterations from its
        result: the structure and the fit, or why it failed."""
        found = cold_fit(self._status.structure, self._status.sign_now, u, y, b)
        if isinstance(found, str):
            return found
        structure, p = found
        outcome = fit_window(
            structure,
            u,
            y,
            p,
            iterations=self.settings.iterations,
            tol=self.settings.tol,
            settle=self.settings.settle,
            deadband=self._deadband(u),
            breaks=b,
        )
        return outcome.reason if isinstance(outcome, FitFailure) else (structure, outcome)

    def _cold_start(self, u: FloatArray, y: FloatArray, b: BoolArray) -> None:
        self._seed = None  # a restart after divergence: the seed is discredited
        started = self._start_fit(u, y, b)
        if isinstance(started, str):
            self._cold_failed(started)
            return
        self._status.structure, outcome = started
        self._status.sign_now = True
        self._restarted = True
        self._needs_cold = False
        self._cold_failures = 0
        self._failures = 0
        self._accept(outcome, u, y, b)
        self._status.reason = "cold start: " + self._status.reason

    def _retry_cold(self, u: FloatArray, y: FloatArray, b: BoolArray) -> bool:
        """A fresh batch start over the whole memory; True when it gave an estimate (the
        current one stands otherwise, without counting as a divergence)."""
        started = self._start_fit(u, y, b)
        if isinstance(started, str):
            return False
        self._status.structure, outcome = started
        self._restarted = True
        self._failures = 0
        self._accept(outcome, u, y, b)
        self._status.reason = "restarted from the memory: " + self._status.reason
        return True

    def _cold_failed(self, why: str) -> None:
        self._cold_failures += 1
        self._status.reason = f"cold start failed: {why}"
        if self._p is not None:  # a restart after divergence: keep the last valid estimate
            self._state = EstimatorState.DIVERGED
            self._status.reason = f"diverged; {self._status.reason}"

    def _warm_fit(self, u: FloatArray, y: FloatArray, b: BoolArray, recent: int) -> None:
        assert self._p is not None
        s = self.settings
        weight = self._seed_weight()
        if weight <= 0.0:
            self._seed = None
        prior = None if self._seed is None else self._seed.scaled(weight)
        memory = self._feed.by_rows
        if memory and recent <= 0:  # nothing new since the last fit: the estimate holds
            return
        outcome = fit_window(
            self._status.structure,
            u,
            y,
            self._p,
            iterations=s.iterations,
            tol=s.tol,
            settle=s.settle,
            deadband=self._deadband(u),
            recent=None if memory else recent,
            min_excitation=0.0 if memory else s.min_excitation,
            prior=prior,
            breaks=b,
        )
        if memory:  # the share of the samples since the last fit that added a row
            share = recent / max(self._status.samples - self._fit_samples, 1)
            outcome.excitation = min(share, 1.0)
        floor = conditioning_floor(
            self._status.structure,
            self._conditioning_ref,
            s.min_conditioning,
            s.min_linear_conditioning,
        )
        rows = outcome.rows
        conditioning = None
        if rows is not None and (isinstance(outcome, WindowFit) or not outcome.no_information):
            # a fit (or an invalid one) on data that excite a block too little: no information
            conditioning = self._feed.conditioning(
                self._status.structure, rows, s.excitation_window
            )
            poor = poorly_excited(self._status.structure, conditioning, floor)
            if poor is not None:
                outcome = FitFailure(poor, outcome.excitation, True)
        if isinstance(outcome, WindowFit):
            self._failures = 0
            self._accept(outcome, u, y, b, conditioning)
            return
        self._status.excitation = outcome.excitation
        if outcome.no_information and memory and self._retry_cold(u, y, b):
            # memory mode: the memory holds every region it has seen, so a regression that
            # is singular (or a block that looks unexcited) at the current estimate says the
            # estimate is off (an early cold start on few rows), not that data are missing
            return
        if outcome.no_information:
            self._state = EstimatorState.NO_EXCITATION
            self._status.reason = f"estimate frozen: {outcome.reason}"
            return
        self._failures += 1
        self._status.reason = f"fit rejected ({self._failures} in a row): {outcome.reason}"
        if self._failures >= s.max_failures:
            # the data stay (in memory mode: what the data taught, by region); a fresh start
            # from the paper's start over all of them
            self._state = EstimatorState.DIVERGED
            self._status.reason = f"diverged: {outcome.reason}; restarting from the paper's start"
            self._needs_cold = True
            self._cold_start(u, y, b)

    def _accept(
        self,
        fit: WindowFit,
        u: FloatArray,
        y: FloatArray,
        b: BoolArray,
        conditioning: FloatArray | None = None,
    ) -> None:
        s = self.settings
        if conditioning is None:
            conditioning = self._feed.conditioning(
                self._status.structure, fit.rows, s.excitation_window
            )
        self._conditioning_ref = np.maximum(self._conditioning_ref, conditioning)
        self._span_ref = max(self._span_ref, float(np.ptp(u)))
        self._set_p(fit.p)
        reported = fit.p
        if s.refine and self._seed is None:
            previous = self._reported
            start = fit.p if self._restarted or previous is None else previous
            if self._status.structure.problem(start, (float(u.min()), float(u.max()))) is not None:
                start = fit.p
            refined = self._feed.refine(self._status.structure, start, fit, s.refine_iterations)
            if refined is not None:
                reported = refined
        if self._feed.purge(
            self._status.structure, fit.p, fit.residual
        ):  # rows forgotten: refit soon
            self._next_fit = min(self._next_fit, self._feed.progress + s.refit_every)
        previous = None if self._restarted else self._reported
        self._restarted = False
        self._reported = reported
        self._covariance = fit.covariance
        self._status.drift = self._feed.drift(self._status.structure, reported)
        self._residual = fit.residual
        self._status.excitation = fit.excitation
        rel = relative_std(reported, fit.covariance)
        # settled: the iteration settled on this window, or the published estimate moved by
        # less than one standard deviation since the last fit (new data move it by ~0.3-0.5);
        # once converged, by less than three (hysteresis: no flicker from noise)
        std = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
        allowed = 3.0 if self._state is EstimatorState.CONVERGED else 1.0
        steady = previous is not None and bool(np.all(np.abs(reported - previous) <= allowed * std))
        self._state = settled_state(fit.settled or steady, rel, s.converged_std)
        if self._state is EstimatorState.CONVERGED:
            self._status.reason = f"settled; relative std {rel:.3g}"
        else:
            why = "settled" if fit.settled or steady else "still moving"
            self._status.reason = f"{why}; relative std {rel:.3g}"
            if fit.reason:
                self._status.reason += f"; stopped early: {fit.reason}"

    def _rebuild(self) -> None:
        if self._reported is not None and self._covariance is not None:
            rel = relative_std(self._reported, self._covariance)
            self._base_confidence = confidence_of(self._state, rel, self.settings.converged_std)
        if self._reported is None or self._covariance is None:
            self._estimate = Estimate.empty(
                self._status.structure,
                self._status.samples,
                self._status.excitation,
                self._state,
                self._status.reason,
            )
            return
        state, reason, confidence = self._published_state()
        p = self._reported.copy()
        p.flags.writeable = False
        # the bands: the fit's covariance plus how far a drifting drivetrain has moved past
        # the rows the fit remembers (genbacklash_core.online.tracking)
        # (the drift was fitted around this very estimate: its own correction is the distance)
        cov = with_tracking(self._covariance, self._status.drift)
        cov.flags.writeable = False
        self._estimate = Estimate(
            self._status.structure,
            p,
            cov,
            self._residual,
            min(max(self._status.excitation, 0.0), 1.0),
            state,
            confidence,
            self._status.samples,
            reason,
        )
