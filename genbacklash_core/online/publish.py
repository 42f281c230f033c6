"""What the online identifiers publish: an Estimate, its state and confidence, republished
only when something a reader sees has changed.

Between two fits (two of the recursive identifier's events) only the sample count and,
slowly, the aged confidence of the estimate change; both identifiers then reuse the last
:class:`~genbacklash_core.estimate.Estimate` with the new count
(:meth:`~genbacklash_core.estimate.Estimate.with_samples`) and build a new one only when the
state, the reason or the confidence moved (:func:`~.state.confidence_moved`). Before the
first estimate, the warming-up reason carries the excitation advice
(:class:`~.advice.AdviceCache`). The states follow :mod:`~genbacklash_core.online.state`.

:class:`WindowPublication` publishes the windowed identifier's fits: the confidence of the
last fit (:func:`~genbacklash_core.estimate.confidence_of`), aged by the samples since the
latest informative one; a fitted estimate that no new information confirmed for
``idle_samples`` is held (``no_excitation``). The bands are the fit's covariance plus how far
a drifting drivetrain has moved past the rows the fit remembers
(:func:`~genbacklash_core.online.tracking.with_tracking`).

:class:`MemoryPublication` publishes the recursive identifier's iterates: its state follows
its mode (``diverged`` while held or stopped), the confidence is computed from the published
state at each event and aged by the age of the branch whose newest row is oldest; the
covariance, carried from the separated vector by the delta method of eq. (34), is only
computed when read (:meth:`~genbacklash_core.estimate.Estimate.trusted`).

Examples
--------
>>> from genbacklash_core.online.feeds import RowFeed
>>> from genbacklash_core.online.fitter import WindowFitter
>>> from genbacklash_core.online.settings import WindowedSettings
>>> from genbacklash_core.online.status import IdentifierStatus
>>> from genbacklash_core.structure import Structure
>>> status = IdentifierStatus(Structure(3), sign_now=False)
>>> feed = RowFeed(window=1500, bins=16)
>>> publication = WindowPublication(status, WindowedSettings(), feed, WindowFitter(
...     status, WindowedSettings(), feed))
>>> est = publication.rebuild()
>>> est.state.value, est.available
('warming_up', False)
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from genbacklash_core.estimate import (
    Estimate,
    EstimatorState,
    aged_confidence,
    confidence_of,
    relative_std,
)

from .advice import AdviceCache
from .blocks import HELD, STOPPED, BlockMachine
from .covariance import natural_covariance
from .feeds import Feed, RowFeed
from .fitter import WindowFitter
from .settings import RecursiveSettings, WindowedSettings
from .state import FITTED_STATES, confidence_moved, held, settled_state
from .status import IdentifierStatus
from .tracking import with_tracking

__all__ = ["MemoryPublication", "WindowPublication"]


class WindowPublication:
    """The windowed identifier's estimate as published (see the module notes).

    Parameters
    ----------
    status : IdentifierStatus
    settings : WindowedSettings
    feed : Feed
        Its idle count ages the confidence and holds the estimate.
    fitter : WindowFitter
        The fits whose estimate is published.
    """

    def __init__(
        self,
        status: IdentifierStatus,
        settings: WindowedSettings,
        feed: Feed,
        fitter: WindowFitter,
    ) -> None:
        self._status = status
        self._settings = settings
        self._feed = feed
        self._fitter = fitter
        self._base_confidence = 0.0  # confidence of the last fit, before ageing

    def current(self, last: Estimate, advice: AdviceCache, advise: Callable[[], str]) -> Estimate:
        """The estimate to publish now, from the ``last`` one published: the warming-up
        reason with the excitation advice (``advise``, cached by ``advice``) of a memory of
        rows, a rebuilt estimate when the held state or the aged confidence moved, and the
        current sample count."""
        status = self._status
        fitter = self._fitter
        feed = self._feed
        est = last
        if isinstance(feed, RowFeed) and fitter.reported is None:
            key = (feed.rows, status.samples > 1, status.reason)  # the memory changes with rows
            reason = advice.reason(status.reason, key, advise)
            if reason != est.reason:
                est = Estimate.empty(
                    status.structure, status.samples, status.excitation, fitter.state, reason
                )
        if fitter.reported is not None:  # held and aged by the samples without information
            is_held = held(feed.idle, self._settings.idle_samples)
            was_held = est.state is EstimatorState.NO_EXCITATION and fitter.state in (
                EstimatorState.CONVERGED,
                EstimatorState.CONVERGING,
            )
            confidence = self._aged_confidence()
            if is_held != was_held or confidence_moved(confidence, est.confidence, floor=1e-12):
                est = self.rebuild()
        if est.samples != status.samples:
            est = est.with_samples(status.samples)
        return est

    def rebuild(self) -> Estimate:
        """The estimate from the fitter's current one (the confidence of a new fit)."""
        status = self._status
        fitter = self._fitter
        if fitter.reported is not None and fitter.covariance is not None:
            rel = relative_std(fitter.reported, fitter.covariance)
            self._base_confidence = confidence_of(fitter.state, rel, self._settings.converged_std)
        if fitter.reported is None or fitter.covariance is None:
            return Estimate.empty(
                status.structure, status.samples, status.excitation, fitter.state, status.reason
            )
        state, reason, confidence = self._published_state()
        p = fitter.reported.copy()
        p.flags.writeable = False
        # the bands: the fit's covariance plus how far a drifting drivetrain has moved past
        # the rows the fit remembers (genbacklash_core.online.tracking)
        # (the drift was fitted around this very estimate: its own correction is the distance)
        cov = with_tracking(fitter.covariance, status.drift)
        cov.flags.writeable = False
        return Estimate(
            status.structure,
            p,
            cov,
            fitter.residual,
            status.published_excitation,
            state,
            confidence,
            status.samples,
            reason,
        )

    def _aged_confidence(self) -> float:
        """The published confidence from the cached one of the last fit (cheap)."""
        s = self._settings
        return aged_confidence(
            self._base_confidence, float(self._feed.idle), s.confidence_half_life
        )

    def _published_state(self) -> tuple[EstimatorState, str, float]:
        """State, reason and confidence as published: a fitted estimate that no new
        information has confirmed for ``idle_samples`` is held (``no_excitation``), its
        confidence fading with the age of its information."""
        fitter = self._fitter
        state, reason = fitter.state, self._status.reason
        if fitter.reported is None or fitter.covariance is None:
            return state, reason, 0.0
        s = self._settings
        confidence = self._base_confidence
        if state not in FITTED_STATES:
            return state, reason, confidence
        idle = self._feed.idle
        if held(idle, s.idle_samples):
            state = EstimatorState.NO_EXCITATION
            reason = (
                f"estimate held: no information for {idle} samples (the input rests "
                f"or repeats); {self._status.reason}"
            )
        return state, reason, aged_confidence(confidence, float(idle), s.confidence_half_life)


class MemoryPublication:
    """The recursive identifier's estimate as published (see the module notes).

    Parameters
    ----------
    status : IdentifierStatus
    settings : RecursiveSettings
    machine : BlockMachine
        The blocks whose estimate is published.
    """

    def __init__(
        self, status: IdentifierStatus, settings: RecursiveSettings, machine: BlockMachine
    ) -> None:
        self._status, self._settings, self._machine = status, settings, machine
        self._published: tuple[tuple[object, ...], Estimate] | None = None

    def current(self, advice: AdviceCache, advise: Callable[[], str]) -> Estimate:
        """The estimate, its state and confidence, from the current internals; before the
        first estimate, the warming-up reason with the excitation advice (``advise``, cached
        by ``advice``) of a backlash.

        Between the schedule's events only the sample count and, slowly, the aged
        confidence change: the last estimate is then reused with the new count.
        """
        status = self._status
        machine = self._machine
        structure = status.structure
        s = self._settings
        excitation = status.published_excitation
        if not machine.ever_started:
            reason = status.reason
            if not structure.cascade:
                rows = sum(r.shape[0] for r, _ in machine.pending)
                advice_key = (machine.events, len(machine.memory), rows)  # rows at events
                reason = advice.reason(reason, advice_key, advise)
            return Estimate.empty(
                structure, status.samples, excitation, EstimatorState.WARMING_UP, reason
            )
        current = machine.current
        sigma2 = current.sigma2 if math.isfinite(current.sigma2) else machine.errors.long
        p_list, rel = current.summary(structure, sigma2)
        idle = machine.ages.idle(status.samples)  # since the newest informative row
        age = machine.ages.age(status.samples)  # of the branch whose newest row is oldest
        if machine.mode in (HELD, STOPPED):
            state = EstimatorState.DIVERGED
        elif held(idle, s.idle_samples):
            state = EstimatorState.NO_EXCITATION
        else:  # one iteration per block: the estimate is as settled as its memory
            state = settled_state(True, rel, s.converged_std)
        confidence = aged_confidence(
            confidence_of(state, rel, s.converged_std), float(age), s.confidence_half_life
        )
        key = (
            current.version,
            machine.events,
            state,
            status.reason,
            current.note,
            machine.restarts,
        )
        if self._published is not None and self._published[0] == key:
            last = self._published[1]
            if not confidence_moved(confidence, last.confidence, floor=0.0):
                return last.with_samples(status.samples)
        est = self._estimate(state, confidence, excitation, p_list, rel, sigma2)
        self._published = (key, est)
        return est

    def _estimate(
        self,
        state: EstimatorState,
        confidence: float,
        excitation: float,
        p_list: list[float],
        rel: float,
        sigma2: float,
    ) -> Estimate:
        """A new estimate: the current iterate in the natural parameters (eq. 34), its
        reason, and its covariance (computed when read)."""
        status = self._status
        machine = self._machine
        structure = status.structure
        current = machine.current
        remembered = len(machine.memory)
        if state is EstimatorState.DIVERGED:
            reason = f"diverged: {machine.why}"
            if status.reason:
                reason += f"; re-initialisation pending ({status.reason})"
        elif state is EstimatorState.NO_EXCITATION:
            reason = (
                f"estimate held: no new information for {self._settings.idle_samples} "
                f"samples or more (the input rests, repeats or moves too little); {remembered} "
                "rows remembered"
            )
        else:
            reason = f"{remembered} rows remembered; relative std {rel:.3g}"
            if machine.from_seed:
                reason = f"{status.reason}; {reason}"
            if machine.restarts:
                reason += f"; re-initialised {machine.restarts} time(s)"
        if current.note and state is not EstimatorState.DIVERGED:
            reason += f"; {current.note}"
        recent = machine.errors.recent
        residual = recent if math.isfinite(recent) else sigma2
        theta_copy = current.theta.copy()
        cov_theta = sigma2 * current.unit_cov  # sigma^2 (Phi^T Phi + R_0 + prior)^-1
        drift = status.drift
        p_now = np.array(p_list)
        # the drift goes on between its fits (one per DRIFT_EVERY samples): counted to the
        # last iterate's sample, not the publishing moment (chunking must not matter)
        ticks = machine.bands.ticks
        return Estimate.trusted(
            structure,
            p_now,
            lambda: with_tracking(
                natural_covariance(structure, theta_copy, cov_theta), drift, p_now, ticks
            ),
            math.sqrt(residual),
            excitation,
            state,
            confidence,
            status.samples,
            reason,
        )
