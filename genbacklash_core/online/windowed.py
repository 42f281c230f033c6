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

This module holds the identifier itself, a composition of parts that stand in the sibling
modules of :mod:`genbacklash_core.online` (see there), one concept each: what it fits on
(the rows of a backlash alone, the samples of a cascade; :mod:`~.feeds`), when it fits
(:mod:`~.schedule`), the fits as they follow one another (cold start, warm fits, restarts;
:mod:`~.fitter`), what it publishes (:mod:`~.publish`), and the interface it shares with the
recursive identifier (:mod:`~.base`; the seed's start, :mod:`~.seed`).
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.estimate import Estimate, EstimatorState

from .advice import BranchCoverage
from .base import OnlineIdentifier
from .feeds import Feed, RowFeed, SampleFeed
from .fitter import WindowFitter
from .inputs import settings_or_default, template
from .publish import WindowPublication
from .schedule import FitSchedule
from .seed import SeedPrior, WindowSeed
from .settings import WindowedSettings
from .state import settled_state

__all__ = ["WindowedIdentifier", "WindowedSettings"]


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
        self._schedule = FitSchedule(self.min_samples)
        self._fitter = WindowFitter(self._status, s, self._feed)
        self._publication = WindowPublication(self._status, s, self._feed, self._fitter)
        self._estimate = Estimate.empty(self._status.structure)

    @property
    def coverage(self) -> BranchCoverage | None:
        """Rows per branch and input region in the memory (a backlash alone; None for the
        cascade, which remembers samples)."""
        return self._feed.coverage()

    def _continue_from(self, prior: SeedPrior, estimate: Estimate) -> None:
        """Continue from a seed (:meth:`seed`): its parameters as the current estimate and
        the start of the next warm-started iterations (no cold start runs), its information
        a prior standing for ``min(window, samples)`` samples of the window at first, fewer
        as the window fills, none once it is full. Output-error refinement (``refine``)
        resumes once the seed has left the window."""
        s = self.settings
        samples = min(s.window, estimate.samples) if estimate.samples else s.window
        seed = WindowSeed(prior, samples, self._feed.progress)
        covariance = np.array(estimate.covariance, dtype=np.float64)
        rel = self._fitter.plant(seed, covariance, estimate.residual)
        settled = estimate.state in (EstimatorState.CONVERGED, EstimatorState.NO_EXCITATION)
        self._fitter.state = settled_state(settled, rel, s.converged_std)
        self._status.reason = (
            f"seeded from a saved estimate ({estimate.state.value}); relative std {rel:.3g}"
        )
        self._schedule.restart(self._status.samples, self._feed.progress, self.min_samples)
        self._estimate = self._publication.rebuild()

    @property
    def from_seed(self) -> bool:
        """True while the window still leans on a seed (:meth:`seed`): it has not yet
        taken as many new samples as the seed stands for."""
        return self._fitter.seed_weight() > 0.0

    def _take_one(self, u: float, y: float, follows: bool) -> None:
        feed = self._feed
        if not isinstance(feed, RowFeed):
            self._intake(np.array([u]), np.array([y]), np.array([not follows]))
            return
        # one sample, without arrays (the per-sample path of a hand-written loop)
        feed.push(u, y, follows and not self._break_next)
        self._break_next = False
        self._status.samples += 1
        if self._schedule.due(feed.rows):
            self._fit()
        self._publish()

    def _take(self, uu: FloatArray, yy: FloatArray, bb: BoolArray) -> None:
        """Feed validated samples, fitting whenever the schedule says (see update_many)."""
        if uu.size:
            for count in self._feed.take(uu, yy, bb, lambda: self._schedule.next_fit):
                self._status.samples += count
                if self._schedule.due(self._feed.progress):
                    self._fit()
        self._publish()

    def refit(self) -> Estimate:
        """Fit the window now instead of at the next scheduled sample; the new estimate.

        For a final estimate at the end of a record (a replay, a benchmark): without it the
        estimate may be up to ``K`` samples old. The schedule restarts from here. Right
        after :meth:`seed`, until ``min_samples`` new samples arrived, the seed stands.
        """
        if len(self._feed) >= (1 if self._fitter.seed is None else self.min_samples):
            self._fit(early=True)
        return self._publish()

    def excitation_advice(self) -> str:
        """What the data have not shown yet, and what motion would show it ("" when the
        memory covers both branches over the input range seen). A backlash alone only."""
        need = self.min_samples - len(self._feed) if self._fitter.p is None else 0
        return self._feed.advice(self._status.samples, need)

    def _fit(self, early: bool = False) -> None:
        """One fit (:class:`~.fitter.WindowFitter`), the next one scheduled, the estimate
        rebuilt."""
        feed, schedule, status = self._feed, self._schedule, self._status
        recent = schedule.recent(feed.progress, len(feed), early)
        self._fitter.fit(recent, schedule.new_samples(status.samples))
        schedule.plan(
            self.settings,
            length=len(feed),
            progress=feed.progress,
            samples=status.samples,
            cold_failures=self._fitter.failing_cold_starts,
        )
        self._estimate = self._publication.rebuild()

    def _publish(self) -> Estimate:
        assert self._estimate is not None  # (reset made one)
        self._estimate = self._publication.current(
            self._estimate, self._advice, self.excitation_advice
        )
        return self._estimate
