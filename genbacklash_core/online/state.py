"""The state and confidence both online identifiers publish.

An identifier's estimate is in one of the states of
:class:`~genbacklash_core.estimate.EstimatorState`. The rules below are the same for both:

* **Converged or converging.** A fitted estimate is ``converged`` once it has settled and the
  largest relative standard deviation of its parameters
  (:func:`~genbacklash_core.estimate.relative_std`) is within ``converged_std``
  (:func:`settled_state`); otherwise ``converging``.
* **No excitation is not divergence.** A fitted estimate that no new information confirmed
  for ``idle_samples`` samples is held: ``no_excitation`` (:func:`held`). Its parameters
  stand; its confidence fades with the age of its information
  (:func:`~genbacklash_core.estimate.aged_confidence`, half-life ``confidence_half_life``).
* **Republishing.** Between fits only the sample count and, slowly, the aged confidence
  change; an identifier rebuilds its estimate only when the confidence moved by more than
  :data:`CONFIDENCE_STEP` of itself (:func:`confidence_moved`).

What differs between the identifiers is on purpose and stays in each: which age the
confidence fades with (the windowed identifier: samples since the last informative row;
the recursive one: the age of the branch whose newest row is oldest, since it forgets per
branch), and the state the confidence is computed from (the windowed identifier keeps the
confidence of its last fit, capped while converging; the recursive one computes it from the
published state at each event).

Examples
--------
>>> settled_state(True, 0.01, 0.02).value, settled_state(False, 0.01, 0.02).value
('converged', 'converging')
>>> held(1500, idle_samples=1000), confidence_moved(0.5, 0.5004, floor=1e-12)
(True, False)
"""

from __future__ import annotations

from genbacklash_core.estimate import EstimatorState

__all__ = ["CONFIDENCE_STEP", "FITTED_STATES", "confidence_moved", "held", "settled_state"]

CONFIDENCE_STEP = 1e-3  # relative change of the aged confidence that is published again

FITTED_STATES = (
    EstimatorState.CONVERGED,
    EstimatorState.CONVERGING,
    EstimatorState.NO_EXCITATION,
)  # the states of a fitted estimate (not warming up, not diverged)


def settled_state(settled: bool, rel_std: float, converged_std: float) -> EstimatorState:
    """``converged`` when the estimate ``settled`` and its relative standard deviation is
    within ``converged_std``; else ``converging``."""
    if settled and rel_std <= converged_std:
        return EstimatorState.CONVERGED
    return EstimatorState.CONVERGING


def held(idle: int, idle_samples: int) -> bool:
    """Whether a fitted estimate is held (``no_excitation``): ``idle`` samples without new
    information, ``idle_samples`` or more."""
    return idle >= idle_samples


def confidence_moved(new: float, old: float, *, floor: float) -> bool:
    """Whether the published confidence moved from ``old`` to ``new`` by more than
    :data:`CONFIDENCE_STEP` of ``max(old, floor)``. (The windowed identifier passes a tiny
    positive ``floor`` so that a vanishing confidence is not republished at every sample;
    the recursive one 0, which republishes any change from 0: it always did.)"""
    return abs(new - old) > CONFIDENCE_STEP * max(old, floor)
