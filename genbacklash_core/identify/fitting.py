"""One identification run: the iteration from each start, refined by output error
(:mod:`genbacklash_core.refine`) and restarted at the holds the estimate falsifies; the best
candidate kept.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.data import (
    NonFinitePolicy,
    as_order,
    as_real,
    prepare_series,
    scale_limits,
)
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.refine import (
    RefinementResult,
    branch_support,
    falsified_holds,
    refine_parameters,
    simulate_parameters,
)
from genbacklash_core.samples import as_breaks, restart_points
from genbacklash_core.structure import Structure

from .iteration import IterationOutcome, run_iteration
from .regression import backlash_regression, detect_sign
from .results import (
    HOLD_ROUNDS,
    RESTART_DEAD_ZONES,
    USELESS_FIT,
    WARM_START_SAMPLES,
    Fit,
    IdentificationResult,
    IterationCallback,
    IterationHistory,
    nrmse,
)


@dataclass
class Candidate:
    """One start's outcome, refined when asked (internal)."""

    outcome: IterationOutcome
    history: list[FloatArray]
    p: FloatArray
    fit: float  # free-run NRMSE of p on the data
    refinement: RefinementResult | None
    converged: bool
    reason: str


def fit_candidate(
    structure: Structure,
    u: FloatArray,
    y: FloatArray,
    p_start: FloatArray,
    *,
    max_iterations: int,
    tol: float,
    refine: bool,
    callback: IterationCallback | None,
    breaks: BoolArray | None = None,
    restart_holds: bool = False,
    support: bool = True,
) -> Candidate:
    """Iterate from one start (warm-started on a prefix for long records), then refine.

    Without ``support`` a settled candidate is not checked for branches the data never
    reach (:func:`~genbacklash_core.refine.branch_support`, a free run of its own): its
    ``converged`` may then overstate, its ``p`` and ``fit`` are the same.
    """
    history: list[FloatArray] = []
    p = p_start
    if u.size > 4 * WARM_START_SAMPLES:
        # Long records: the early iterations only find the switching regime, which a prefix
        # shows as well; iterate there first and finish on all the data.
        head = run_iteration(
            structure,
            u[:WARM_START_SAMPLES],
            y[:WARM_START_SAMPLES],
            p,
            max_iterations,
            tol,
            callback,
            None if breaks is None else breaks[:WARM_START_SAMPLES],
        )
        if head.converged:
            p = head.p
            history = head.history[:-1]
    outcome = run_iteration(structure, u, y, p, max_iterations, tol, callback, breaks)
    prefix_iterations = len(history)
    history += outcome.history
    reason = outcome.reason
    if prefix_iterations:
        reason += f" on all data, after {prefix_iterations} on a prefix"
    # When the iteration did not settle - it wandered (typical at low SNR, where noise keeps
    # flipping switching decisions), stepped into crossing branches, or met a singular
    # regression - the output-error refinement from its last valid iterate decides.
    x0 = 0.0 if structure.cascade else float(y[0])
    p_final = outcome.last_valid
    refinement: RefinementResult | None = None
    converged = outcome.converged
    if refine:
        # The simulation error is piecewise smooth with local minima; refine from every point
        # the iteration cannot choose between and keep the lowest cost: each member of a limit
        # cycle, and after a failure also its first valid iterate and its start.
        starts = [p_final]
        if outcome.converged and outcome.period > 1:
            starts += outcome.history[-outcome.period : -1]
        elif not outcome.converged:
            starts += outcome.history[1:2] + outcome.history[:1]
        best, pinned = refine_described(
            structure, starts, p_final, u, y, x0, breaks, judge=restart_holds
        )
        if best is None:
            converged = False
            reason += "; no start valid on the input range to refine from (branches cross)"
        else:
            q, steps, ok, cost0, cost1, why = best
            p_final = q
            refinement = RefinementResult(structure.model(q), steps, ok, cost0, cost1, why)
            drop = 100.0 * (1.0 - cost1 / cost0) if cost0 > 0 else 0.0
            reason += (
                f"; output-error refinement: {steps} steps, simulation error -{drop:.1f}% ({why})"
            )
            if len(starts) > 1:
                reason += f", best of {len(starts)} starts"
            if pinned:
                reason += (
                    f"; restarted at {pinned} held readings the play operator does not "
                    "describe (the load moved inside the play)"
                )
            converged = ok
            if not outcome.converged and ok:
                # The failure may come from a structure that does not fit (a missing delay,
                # say). With the right structure the refined estimate sits near a fixed point
                # of the paper's iteration, so restarted there the iteration settles.
                check = run_iteration(structure, u, y, q, max_iterations, tol, None, breaks)
                converged = check.converged
                reason += (
                    "; restarted from the refined estimate, the iteration settled"
                    if converged
                    else "; restarted from the refined estimate, the iteration still did not "
                    f"settle ({check.reason}): the structure may not fit"
                )
    if refinement is not None and not pinned:  # its final cost: the free-run error of p_final
        spread = float(np.sum((y - np.mean(y)) ** 2))
        fit = float(np.sqrt(refinement.cost_end / spread)) if spread > 0 else float("inf")
    else:  # the free run restarts at lost readings only, not at falsified holds
        anchors = restart_points(breaks)
        fit = nrmse(y, simulate_parameters(structure, p_final, u, x0, anchors, y)[1])
    if (
        support
        and converged
        and (
            missing := branch_support(
                structure,
                p_final,
                u,
                y,
                x0,
                None if structure.cascade else restart_points(breaks),
            )
        )
    ):
        # Settled or not, an estimate whose branch the data never reach is no estimate of it.
        converged = False
        reason += f"; but the data do not determine the model (under-determined): {missing}"
    if converged and not fit < USELESS_FIT:
        converged = False
        reason += (
            f"; but the model explains almost none of the output (free-run NRMSE {fit:.3f}, "
            "no better than a constant): the structure does not fit the data (a dead time?)"
        )
    return Candidate(outcome, history, p_final, fit, refinement, converged, reason)


def refine_described(
    structure: Structure,
    starts: list[FloatArray],
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    x0: float,
    breaks: BoolArray | None,
    *,
    judge: bool,
) -> tuple[tuple[FloatArray, int, bool, float, float, str] | None, int]:
    """The output-error refinement from each of ``starts`` (the lowest cost kept), restarted
    where the play operator does not describe the samples (:func:`described_breaks`), and
    how many held readings were restarted at.

    Which holds a reading falsifies depends on the estimate the simulation runs with: they are
    taken at ``p`` (the iteration's estimate), then again at each refined estimate, until
    they repeat or :data:`HOLD_ROUNDS` refinements have run. A hold that only a wrong start
    seemed to break (the branches a little off) is simulated through again once the estimate
    is right; the refinement then ends where it would without the rule. Within a round every
    start is judged with the same restarts, so that their costs compare. Without ``judge``
    the refinement restarts at lost readings only (one round).
    """
    u_range = (float(u.min()), float(u.max()))
    restarts, pinned = described_breaks(structure, p, u, y, x0, breaks) if judge else (breaks, 0)
    best: tuple[FloatArray, int, bool, float, float, str] | None = None
    for round_ in range(HOLD_ROUNDS if judge else 1):
        best = None
        for start_p in starts:
            if structure.problem(start_p, u_range) is not None:
                continue
            trial = refine_parameters(structure, start_p, u, y, x0, breaks=restarts)
            if best is None or trial[4] < best[4]:
                best = trial
        if best is None or not judge or round_ == HOLD_ROUNDS - 1:
            break
        again, count = described_breaks(structure, best[0], u, y, x0, breaks)
        if same_breaks(again, restarts):
            break
        restarts, pinned, starts = again, count, [best[0]]
    return best, pinned


def same_breaks(a: BoolArray | None, b: BoolArray | None) -> bool:
    """Whether two sets of breaks (None: none) are the same."""
    if a is None or b is None:
        return a is b
    return bool(np.array_equal(a, b))


def described_breaks(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    x0: float,
    breaks: BoolArray | None,
) -> tuple[BoolArray | None, int]:
    """The output-error refinement's restarts for a backlash alone: the sample rule's breaks
    and the held samples whose reading falsifies the hold
    (:func:`~genbacklash_core.refine.falsified_holds`), and how many of the latter there are.
    Batch identification restarts there with ``restart_holds`` (``genbacklash identify``);
    the online identifiers' refinement does not.

    The output noise's standard deviation is taken from the rows of eq. (24) at ``p`` (the
    rows the iteration fitted: a branch engaged by the measured load), robustly (1.4826 times
    the median absolute residual), so that a misfit elsewhere does not raise it.
    """
    if structure.cascade:
        return breaks, 0
    phi, target = backlash_regression(structure, p, u, y, breaks)
    if target.size == 0:
        return breaks, 0
    residual = target - phi @ structure.theta(p)
    scale = 1.4826 * float(np.median(np.abs(residual - np.median(residual))))
    if not (math.isfinite(scale) and scale > 0.0):
        return breaks, 0
    held = falsified_holds(structure, p, u, y, x0, scale, restart_points(breaks))
    count = int(np.count_nonzero(held))
    if count == 0:
        return breaks, 0
    first = np.zeros(u.size, dtype=bool) if breaks is None else breaks
    return first | held, count


def run_identification(
    structure: Structure,
    u: FloatArray,
    y: FloatArray,
    *,
    start: FloatArray | None,
    max_iterations: int,
    tol: float,
    refine: bool,
    callback: IterationCallback | None,
    breaks: BoolArray | None = None,
    restart_holds: bool = False,
    support: bool = True,
) -> IdentificationResult:
    p = structure.start() if start is None else np.asarray(start, dtype=np.float64).copy()
    if p.shape != (structure.n_parameters,):
        raise GenBacklashError(
            f"start must have {structure.n_parameters} parameters, got {p.shape}"
        )
    if (problem := structure.problem(p)) is not None:
        raise GenBacklashError(f"invalid start: {problem}")
    reach = float(np.max(np.abs(u))) + max(p[structure.degree], p[2 * structure.degree + 1])
    if reach > (limit := scale_limits(structure.degree, u.size)[0]):
        raise GenBacklashError(
            f"invalid start: its dead zones put |u + c| up to {reach:.3g}, beyond the "
            f"{limit:.3g} a degree-{structure.degree} regression on {u.size} samples takes"
        )
    max_iterations = as_order("max_iterations", max_iterations)
    if max_iterations < 1:
        raise GenBacklashError(f"max_iterations must be >= 1, got {max_iterations}")
    tol = as_real("tol", tol)
    if tol < 0.0:
        raise GenBacklashError(f"tol must be >= 0, got {tol}")
    if not isinstance(refine, (bool, np.bool_)):
        raise GenBacklashError(f"refine must be True or False, got {refine!r}")
    if callback is not None and not callable(callback):
        raise GenBacklashError(f"callback must be callable or None, got {callback!r}")

    def attempt(start_p: FloatArray) -> Candidate:
        return fit_candidate(
            structure,
            u,
            y,
            start_p,
            max_iterations=max_iterations,
            tol=tol,
            refine=refine,
            callback=callback,
            breaks=breaks,
            restart_holds=restart_holds,
            support=support,
        )

    best = attempt(p)
    if not best.outcome.converged and start is None:
        # The paper's start did not settle: the iteration can stall on a spurious fixed point.
        # Try wider dead zones and keep the candidate that simulates the data best.
        span = float(np.ptp(u))
        for fraction in RESTART_DEAD_ZONES:
            alternative = attempt(structure.start(c=fraction * span))
            # For the same data NRMSE orders candidates as the simulation error does.
            if alternative.fit < best.fit and (alternative.converged or not best.converged):
                best = alternative
                best.reason += f" (restarted from dead zones {fraction:g} x the input span)"
            if best.outcome.converged:
                break
    return IdentificationResult(
        model=structure.model(best.p),
        iterations=len(best.history) - 1,
        converged=best.converged,
        reason=best.reason,
        fit=Fit(best.fit),
        history=IterationHistory(structure.names(), np.array(best.history)),
        equation_error_model=structure.model(best.outcome.last_valid),
        refinement=best.refinement,
    )


def prepare_inputs(
    u: ArrayLike, y: ArrayLike, nonfinite: NonFinitePolicy, breaks: ArrayLike | None
) -> tuple[FloatArray, FloatArray, BoolArray | None]:
    """:func:`prepare_series` plus the sample rule: a dropped non-finite sample breaks the
    chain of consecutive samples just as a lost reading does."""
    uu, yy = prepare_series(u, y, nonfinite)
    if breaks is None:
        return uu, yy, None
    raw_u = np.asarray(u, dtype=np.float64)
    b = as_breaks(breaks, raw_u.size)
    if uu.size == raw_u.size:
        return uu, yy, b
    keep = np.isfinite(raw_u) & np.isfinite(np.asarray(y, dtype=np.float64))
    after_drop = np.concatenate([[True], ~keep[:-1]])  # the sample before was dropped
    return uu, yy, (b | after_drop)[keep]


def sign_option(sign: float | None, u: FloatArray, y: FloatArray, max_lag: int) -> float:
    if sign is None:
        return detect_sign(u, y, max_lag)
    if not isinstance(sign, numbers.Real) or sign not in (1, -1):
        raise GenBacklashError(f"sign must be +1, -1 or None (detect), got {sign!r}")
    return float(sign)
