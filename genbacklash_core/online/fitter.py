"""The windowed identifier's fits as they follow one another: cold start, warm fits, restarts.

:class:`WindowFitter` holds what one fit hands the next: the equation-error estimate the
warm-started iterations start from, the estimate published (refined when asked), its
covariance and residual, the state, and the counters that decide a restart. Each call of
:meth:`WindowFitter.fit` runs one fit over the feed's data
(:class:`~genbacklash_core.online.feeds.Feed`):

* **Cold start.** Until a first fit succeeds (and after a divergence), the batch iteration
  from the paper's start (:func:`~genbacklash_core.online.fits.cold_fit`), then the warm
  iterations from its result. A failed cold start leaves the last valid estimate standing.
* **Warm fits.** ``iterations`` warm-started iterations of the paper's method
  (eqs. 22-29, 31-37; :func:`~genbacklash_core.online.fits.fit_window`) from the current
  estimate, with a seed's prior (:class:`~genbacklash_core.online.seed.WindowSeed`) while the
  window leans on one. A fit on data that excite a parameter block too little
  (:func:`~genbacklash_core.online.fits.poorly_excited`) carries no information: the estimate
  is frozen (``no_excitation``), or, for a memory of rows, restarted from the memory. A fit
  that leaves the valid set is rejected; ``max_failures`` in a row restart from the paper's
  start (``diverged``).
* **Acceptance.** An accepted fit is refined by output error when asked (not while a seed
  stands), purges the rows it cannot have produced, and is ``converged`` once it settled
  (the iteration settled, or the published estimate moved by less than one standard
  deviation since the last fit; three once converged) with a relative standard deviation
  within ``converged_std``.

The schedule of the fits is :class:`~genbacklash_core.online.schedule.FitSchedule`'s; what
is published, :class:`~genbacklash_core.online.publish.WindowPublication`'s.

Examples
--------
>>> from genbacklash_core import paper_example
>>> from genbacklash_core.online.feeds import RowFeed
>>> data = paper_example(1).generate(seed=0, n_samples=400)
>>> feed = RowFeed(window=1500, bins=16)
>>> for _ in feed.take(data.u, data.y, np.zeros(400, dtype=bool), lambda: 10**9):
...     pass
>>> status = IdentifierStatus(Structure(3), sign_now=False)
>>> fitter = WindowFitter(status, WindowedSettings(), feed)
>>> fitter.fit(recent=0, new_samples=400)
>>> fitter.state.value, status.reason.startswith("cold start")
('converged', True)
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.estimate import EstimatorState, relative_std
from genbacklash_core.structure import Structure

from .feeds import Feed
from .fits import (
    FitFailure,
    WindowFit,
    cold_fit,
    conditioning_floor,
    fit_window,
    parameter_blocks,
    poorly_excited,
)
from .inputs import deadband
from .seed import SeedPrior, WindowSeed
from .settings import WindowedSettings
from .state import settled_state
from .status import IdentifierStatus

__all__ = ["WindowFitter"]


class WindowFitter:
    """The windowed identifier's succession of fits (see the module notes).

    Parameters
    ----------
    status : IdentifierStatus
        The identifier's status: the fits move its structure, reason, excitation and drift.
    settings : WindowedSettings
    feed : Feed
        What the fits take their data from.
    """

    def __init__(self, status: IdentifierStatus, settings: WindowedSettings, feed: Feed) -> None:
        self._status = status
        self._settings = settings
        self._feed = feed
        self.p: FloatArray | None = None  # equation-error estimate (warm start)
        self.reported: FloatArray | None = None  # published (refined when asked)
        self.covariance: FloatArray | None = None
        self.residual = math.nan
        self.state = EstimatorState.WARMING_UP
        self.seed: WindowSeed | None = None  # a saved estimate the window still leans on
        self.needs_cold = True
        self.cold_failures = 0
        self._failures = 0
        self._restarted = True
        self._conditioning_ref = np.zeros(len(parameter_blocks(status.structure)))
        self._span_ref = 0.0  # widest input span of an accepted fit

    def plant(self, seed: WindowSeed, estimate_covariance: FloatArray, residual: float) -> float:
        """Take a seed's estimate as the current one and the start of the next warm fits
        (no cold start runs); its relative standard deviation."""
        self.seed = seed
        self._set_p(seed.prior.p.copy())
        self.reported = seed.prior.p.copy()
        self.covariance = estimate_covariance
        self.residual = residual
        self.needs_cold = False
        self._restarted = False  # the next fit continues from the seed (steadiness test)
        return relative_std(seed.prior.p, self.covariance)

    @property
    def failing_cold_starts(self) -> int:
        """Cold starts failed in a row while one is needed (the schedule backs off)."""
        return self.cold_failures if self.needs_cold else 0

    def seed_weight(self) -> float:
        """Share of the seed's samples still counted (those new samples did not replace)."""
        if self.seed is None:
            return 0.0
        return self.seed.weight(self._feed.seed_left(self.seed.samples, self.seed.progress))

    def fit(self, recent: int, new_samples: int) -> None:
        """One fit over the feed's data: a cold start when one is needed, else a warm fit
        judged on the ``recent`` progress of the feed since the last fit (``new_samples``
        samples)."""
        u, y, b = self._feed.data()
        if self.needs_cold:
            self._cold_start(u, y, b)
        else:
            self._warm_fit(u, y, b, recent, new_samples)

    # ---- internals

    def _set_p(self, p: FloatArray) -> None:
        """Take ``p`` as the equation-error estimate (and the cascade's settling horizon)."""
        self.p = p
        self._feed.settle(self._status.structure, p)

    def _deadband(self, u: FloatArray) -> float:
        """Input step below which the input counts as resting (of the widest span fitted)."""
        # the widest span of an accepted fit (before the first fit: this window's), so a
        # narrow window after wide motion does not take small jitter for moves
        span = max(self._span_ref, float(np.ptp(u)) * self.needs_cold)
        return deadband(self._settings.input_deadband, span)

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
            iterations=self._settings.iterations,
            tol=self._settings.tol,
            settle=self._settings.settle,
            deadband=self._deadband(u),
            breaks=b,
        )
        return outcome.reason if isinstance(outcome, FitFailure) else (structure, outcome)

    def _cold_start(self, u: FloatArray, y: FloatArray, b: BoolArray) -> None:
        status = self._status
        self.seed = None  # a restart after divergence: the seed is discredited
        started = self._start_fit(u, y, b)
        if isinstance(started, str):
            self._cold_failed(started)
            return
        status.structure, outcome = started
        status.sign_now = True
        self._restarted = True
        self.needs_cold = False
        self.cold_failures = 0
        self._failures = 0
        self._accept(outcome, u)
        status.reason = "cold start: " + status.reason

    def _retry_cold(self, u: FloatArray, y: FloatArray, b: BoolArray) -> bool:
        """A fresh batch start over the whole memory; True when it gave an estimate (the
        current one stands otherwise, without counting as a divergence)."""
        started = self._start_fit(u, y, b)
        if isinstance(started, str):
            return False
        self._status.structure, outcome = started
        self._restarted = True
        self._failures = 0
        self._accept(outcome, u)
        self._status.reason = "restarted from the memory: " + self._status.reason
        return True

    def _cold_failed(self, why: str) -> None:
        self.cold_failures += 1
        self._status.reason = f"cold start failed: {why}"
        if self.p is not None:  # a restart after divergence: keep the last valid estimate
            self.state = EstimatorState.DIVERGED
            self._status.reason = f"diverged; {self._status.reason}"

    def _seed_prior(self) -> SeedPrior | None:
        """The seed's prior, weighted by the share of its samples still counted (None once
        new samples replaced them all, and from then on)."""
        weight = self.seed_weight()
        if weight <= 0.0:
            self.seed = None
        return None if self.seed is None else self.seed.prior.scaled(weight)

    def _warm_fit(
        self, u: FloatArray, y: FloatArray, b: BoolArray, recent: int, new_samples: int
    ) -> None:
        assert self.p is not None
        s = self._settings
        status = self._status
        prior = self._seed_prior()
        memory = self._feed.by_rows
        if memory and recent <= 0:  # nothing new since the last fit: the estimate holds
            return
        outcome = fit_window(
            status.structure,
            u,
            y,
            self.p,
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
            share = recent / max(new_samples, 1)
            outcome.excitation = min(share, 1.0)
        floor = conditioning_floor(
            status.structure, self._conditioning_ref, s.min_conditioning, s.min_linear_conditioning
        )
        rows = outcome.rows
        conditioning = None
        if rows is not None and (isinstance(outcome, WindowFit) or not outcome.no_information):
            # a fit (or an invalid one) on data that excite a block too little: no information
            conditioning = self._feed.conditioning(status.structure, rows, s.excitation_window)
            poor = poorly_excited(status.structure, conditioning, floor)
            if poor is not None:
                outcome = FitFailure(poor, outcome.excitation, True)
        if isinstance(outcome, WindowFit):
            self._failures = 0
            self._accept(outcome, u, conditioning)
            return
        status.excitation = outcome.excitation
        if outcome.no_information and memory and self._retry_cold(u, y, b):
            # memory mode: the memory holds every region it has seen, so a regression that
            # is singular (or a block that looks unexcited) at the current estimate says the
            # estimate is off (an early cold start on few rows), not that data are missing
            return
        if outcome.no_information:
            self.state = EstimatorState.NO_EXCITATION
            status.reason = f"estimate frozen: {outcome.reason}"
            return
        self._failures += 1
        status.reason = f"fit rejected ({self._failures} in a row): {outcome.reason}"
        if self._failures >= s.max_failures:
            # the data stay (in memory mode: what the data taught, by region); a fresh start
            # from the paper's start over all of them
            self.state = EstimatorState.DIVERGED
            status.reason = f"diverged: {outcome.reason}; restarting from the paper's start"
            self.needs_cold = True
            self._cold_start(u, y, b)

    def _accept(
        self, fit: WindowFit, u: FloatArray, conditioning: FloatArray | None = None
    ) -> None:
        s = self._settings
        status = self._status
        structure = status.structure
        if conditioning is None:
            conditioning = self._feed.conditioning(structure, fit.rows, s.excitation_window)
        self._conditioning_ref = np.maximum(self._conditioning_ref, conditioning)
        self._span_ref = max(self._span_ref, float(np.ptp(u)))
        self._set_p(fit.p)
        reported = fit.p
        if s.refine and self.seed is None:
            previous = self.reported
            start = fit.p if self._restarted or previous is None else previous
            if structure.problem(start, (float(u.min()), float(u.max()))) is not None:
                start = fit.p
            refined = self._feed.refine(structure, start, fit, s.refine_iterations)
            if refined is not None:
                reported = refined
        # rows the accepted model cannot have produced are forgotten (the fit that follows
        # is scheduled as usual)
        self._feed.purge(structure, fit.p, fit.residual)
        previous = None if self._restarted else self.reported
        self._restarted = False
        self.reported = reported
        self.covariance = fit.covariance
        status.drift = self._feed.drift(structure, reported)
        self.residual = fit.residual
        status.excitation = fit.excitation
        rel = relative_std(reported, fit.covariance)
        # settled: the iteration settled on this window, or the published estimate moved by
        # less than one standard deviation since the last fit (new data move it by ~0.3-0.5);
        # once converged, by less than three (hysteresis: no flicker from noise)
        std = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
        allowed = 3.0 if self.state is EstimatorState.CONVERGED else 1.0
        steady = previous is not None and bool(np.all(np.abs(reported - previous) <= allowed * std))
        self.state = settled_state(fit.settled or steady, rel, s.converged_std)
        if self.state is EstimatorState.CONVERGED:
            status.reason = f"settled; relative std {rel:.3g}"
        else:
            why = "settled" if fit.settled or steady else "still moving"
            status.reason = f"{why}; relative std {rel:.3g}"
            if fit.reason:
                status.reason += f"; stopped early: {fit.reason}"
