"""Batch identification of a general backlash (eqs. 22-29) and of the cascade (eqs. 31-37).

Both run the paper's iteration with internal-variable estimation: from the current parameter
estimate, compute the switching functions ``f1, f2`` and the internal variables ``xi1, xi2``
(and for the cascade the internal output ``x`` of eq. 36), solve one linear least-squares
problem for the separated parameter vector (eqs. 23/33), and repeat. By default the result is
then refined by output-error minimisation (:mod:`genbacklash_core.refine`), which removes the
iteration's noise bias.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._typing import ArrayLike, BoolArray, FloatArray
from .backlash import GeneralBacklash
from .cascade import Cascade, model_to_dict
from .data import (
    NonFinitePolicy,
    as_float_array,
    as_order,
    as_real,
    check_excitation,
    check_scale,
    prepare_series,
    scale_limits,
)
from .errors import GenBacklashError, NonFiniteInputError
from .play import play_operator
from .refine import (
    RefinementResult,
    branch_support,
    falsified_holds,
    refine_parameters,
    simulate_parameters,
)
from .samples import as_breaks, breaks_to_rows, restart_points
from .simulate import play_bounds
from .structure import Structure

__all__ = [
    "MAX_ITERATIONS",
    "TOL",
    "IdentificationResult",
    "IterationHistory",
    "backlash_misfit",
    "backlash_rows",
    "described_breaks",
    "identify_backlash",
    "identify_cascade",
    "nrmse",
]

IterationCallback = Callable[[int, FloatArray], None]

_CYCLE_LOOKBACK = 4  # how many earlier iterates a limit cycle may span
MAX_ITERATIONS = 30
"""The paper's iteration's default iteration limit (every identification function's)."""
TOL = 1e-4
"""The default convergence tolerance: the iteration stops when no parameter moves more than
``TOL * max(1, max|p|)``."""
_WARM_START_SAMPLES = 20_000  # prefix length for the warm start on long records
_RESTART_DEAD_ZONES = (0.05, 0.2)  # restart dead zones, as fractions of the input span
_HOLD_ROUNDS = 3  # refinements at most, each with the falsified holds of the estimate before it
_USELESS_FIT = 0.95  # free-run NRMSE from which a model explains nothing (SNR 1 gives ~0.71)


@dataclass(frozen=True, eq=False)
class IterationHistory:
    """Parameter estimates per iteration (row 0 is the start), for the paper's Figs. 4-12."""

    names: tuple[str, ...]
    values: FloatArray

    def __post_init__(self) -> None:
        if self.values.ndim != 2 or self.values.shape[1] != len(self.names):
            raise GenBacklashError(
                f"history values must be (iterations+1, {len(self.names)}), got {self.values.shape}"
            )

    def series(self, name: str) -> FloatArray:
        """Estimates of one parameter over the iterations."""
        return self.values[:, self.names.index(name)]


@dataclass(frozen=True)
class Fit:
    """Quality of fit: free-run simulation NRMSE, ``||y - y_sim|| / ||y - mean(y)||``."""

    nrmse: float


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Outcome of :func:`identify_backlash` or :func:`identify_cascade`.

    Attributes
    ----------
    model : GeneralBacklash or Cascade
        The estimate (after refinement when it ran). When ``converged`` is False this is the
        last valid estimate, or the start model when there was none.
    iterations : int
        Iterations of the paper's method that were run.
    converged : bool
        True when the iteration met its criterion (and the refinement, when run, too).
    reason : str
        A sentence saying why it stopped.
    fit : Fit
        Free-run NRMSE of ``model`` on the data.
    history : IterationHistory
        The iteration's parameter estimates, start included.
    equation_error_model : GeneralBacklash or Cascade
        The iteration's estimate before refinement.
    refinement : RefinementResult or None
        The output-error refinement, when it ran.
    """

    model: GeneralBacklash | Cascade
    iterations: int
    converged: bool
    reason: str
    fit: Fit
    history: IterationHistory
    equation_error_model: GeneralBacklash | Cascade
    refinement: RefinementResult | None

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of the CLI contract (GUIDE §4), plus ``play`` (``c_L + c_R``, rad)
        and ``fit.misfit`` (the free-run NRMSE, also under its old key ``fit.nrmse``)."""
        out = model_to_dict(self.model)
        out["iterations"] = self.iterations
        out["converged"] = self.converged
        out["reason"] = self.reason
        backlash = self.model.backlash if isinstance(self.model, Cascade) else self.model
        out["play"] = float(backlash.c_left + backlash.c_right)  # rad, the whole dead band
        # the misfit: the free-run NRMSE ("nrmse" kept for the contract)
        out["fit"] = {"nrmse": self.fit.nrmse, "misfit": self.fit.nrmse}
        return out


def nrmse(y: FloatArray, y_sim: FloatArray) -> float:
    """Normalised root-mean-square error ``||y - y_sim|| / ||y - mean(y)||``.

    ``inf`` when ``y_sim`` holds NaN or inf (a simulation that blew up); NaN/inf in the
    measured ``y`` raise :class:`~genbacklash_core.errors.NonFiniteInputError`.

    >>> nrmse(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    0.0
    """
    yy, ys = as_float_array("y", y), as_float_array("y_sim", y_sim)
    if yy.ndim != 1 or yy.shape != ys.shape or yy.size == 0:
        raise GenBacklashError(
            f"y and y_sim must be non-empty, one-dimensional and of one length, got shapes "
            f"{yy.shape} and {ys.shape}"
        )
    if not np.all(np.isfinite(yy)):
        raise NonFiniteInputError("y holds NaN or infinite samples; clean the data first")
    if not np.all(np.isfinite(ys)):
        return math.inf  # a simulation that blew up fits infinitely badly
    scale = max(float(np.max(np.abs(yy))), float(np.max(np.abs(ys))))
    if scale > 0.0:  # the ratio does not change with the scale; this keeps squares finite
        yy, ys = yy / scale, ys / scale
    spread = float(np.sum((yy - np.mean(yy)) ** 2))
    if spread == 0.0:
        return 0.0 if np.array_equal(yy, ys) else math.inf
    with np.errstate(over="ignore"):  # a nearly constant y: the ratio may overflow to inf
        return float(np.sqrt(np.sum((yy - ys) ** 2) / spread))


def _detect_sign(u: FloatArray, y: FloatArray, max_lag: int) -> float:
    """Sense of the branches from the data: the sign of the lagged input-output covariance."""
    uc = u - u.mean()
    yc = y - y.mean()
    total = sum(float(uc[: uc.size - k] @ yc[k:]) for k in range(max_lag + 1))
    if total == 0.0:
        raise GenBacklashError(
            "cannot tell whether the branches increase or decrease (zero input-output "
            "covariance); pass sign=+1 or sign=-1"
        )
    return 1.0 if total > 0 else -1.0


def _solve_least_squares(phi: FloatArray, target: FloatArray) -> FloatArray | None:
    """Least-squares solution of ``phi @ theta = target``, or None when it is singular.

    The column-scaled normal equations are formed once (cheap for the few columns here even
    at N = 1e6) and solved by ``numpy.linalg.lstsq``, whose rank decides singularity.
    """
    gram = phi.T @ phi  # (called under _iterate's errstate: overflow is checked here)
    rhs = phi.T @ target
    if not (np.all(np.isfinite(gram)) and np.all(np.isfinite(rhs))):
        return None  # the regressors overflow: an iterate far out of scale with the data
    scale = np.sqrt(np.diag(gram))
    if np.any(scale == 0.0):
        return None  # a regressor is identically zero, e.g. a branch never engaged
    scaled = gram / np.outer(scale, scale)
    if not np.all(np.isfinite(scaled)):
        return None
    theta_scaled, _, rank, _ = np.linalg.lstsq(scaled, rhs / scale, rcond=1e-10)
    if rank < phi.shape[1] or not np.all(np.isfinite(theta_scaled)):
        return None
    return np.asarray(theta_scaled / scale, dtype=np.float64)


def _solve_damped(phi: FloatArray, target: FloatArray, theta_prev: FloatArray) -> FloatArray | None:
    """Least squares with a small pull towards ``theta_prev``, for a singular regression.

    Minimises ``||phi theta - target||^2 + lam ||D (theta - theta_prev)||^2`` with ``D`` the
    column norms (so the pull is scale-free) and ``lam`` a millionth of the largest of them:
    directions the data determine move to their least-squares values, the others (a branch
    not engaged under the current switching estimate, polynomial columns that collapse on
    held inputs) keep their previous values instead of ending the iteration.
    """
    gram = phi.T @ phi
    rhs = phi.T @ target
    if not (np.all(np.isfinite(gram)) and np.all(np.isfinite(rhs))):
        return None
    if not np.all(np.isfinite(theta_prev)):
        return None
    diag = np.diag(gram).copy()
    top = float(np.max(diag)) if diag.size else 0.0
    if not top > 0.0:
        return None
    weight = np.maximum(diag, 1e-6 * top)  # never-engaged columns still get a pull
    lam = 1e-6
    scale = np.sqrt(weight)
    scaled = gram / np.outer(scale, scale) + lam * np.eye(diag.size)
    scaled_rhs = rhs / scale + lam * theta_prev * scale
    try:
        theta_scaled = np.linalg.solve(scaled, scaled_rhs)
    except np.linalg.LinAlgError:
        return None
    theta = theta_scaled / scale
    return np.asarray(theta, dtype=np.float64) if np.all(np.isfinite(theta)) else None


def _backlash_columns(
    structure: Structure, p: FloatArray, u: FloatArray, f1: FloatArray, f2: FloatArray
) -> FloatArray:
    """Data vector of eq. (22): ``[u f1, f1, xi1^2 f1 .. xi1^n f1, u f2, -f2, xi2^2 f2 ..]``."""
    n = structure.degree
    cols = np.empty((u.size, 2 * n + 2), order="F")  # column-major: contiguous column writes
    cols[:, 0] = u * f1
    cols[:, 1] = f1
    cols[:, n + 1] = u * f2
    cols[:, n + 2] = -f2
    if n == 1:  # the ideal backlash: no powers of xi (the servo's score runs this often)
        return cols
    _, c_left, _, c_right = structure.split(p)
    xi1 = u + c_left  # eq. (25)
    xi2 = u - c_right  # eq. (26)
    power1, power2 = xi1.copy(), xi2.copy()
    for i in range(2, n + 1):
        power1 *= xi1
        power2 *= xi2
        cols[:, i] = power1 * f1
        cols[:, n + 1 + i] = power2 * f2
    return cols


def _switching(
    structure: Structure, p: FloatArray, u: FloatArray, x_prev: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Estimated switching functions (eqs. 27-28), sign-corrected for decreasing branches."""
    left, right = structure.branches(p, u)
    f1 = ((left - x_prev) * structure.sign <= 0.0).astype(np.float64)  # eq. (27)
    f2 = ((x_prev - right) * structure.sign <= 0.0).astype(np.float64)  # eq. (28)
    return f1, f2


def backlash_rows(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    x: FloatArray,
    breaks: BoolArray | None = None,
    deadband: float | None = None,
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """The rows of eqs. (24)/(29) for a measured backlash output ``x``: the row rule of the
    batch iteration and of the online identifiers' windows, in one place.

    Row ``t`` pairs ``x(t)`` with ``x(t-1)``. It carries information when

    * a branch is engaged at ``x(t-1)``, the measured load (eqs. 27-28; a row with neither
      engaged holds the state and tells nothing, eq. 29);
    * sample ``t`` follows sample ``t-1`` on the encoder's clock (``breaks``,
      :mod:`genbacklash_core.samples`): eq. (24) needs ``x(t-1)``;
    * with ``deadband``, the input moved by more than ``deadband`` (the online identifiers,
      whose memory files the rows of moves; ``input_deadband`` of the input span). Batch
      identification passes None and keeps the engaged rows of a held input too: on the
      physics drivetrains with the command as the input, the moved rows alone read the
      play 0.45-0.81 of the geometric on coasting and gravity at 60 and 100 Hz where all
      engaged rows read 0.74-0.98 (BENCHMARKS.md, "Rerun 2026-11-28, branch batch-1").

    Parameters
    ----------
    structure : Structure
    p : ndarray
        The parameters the switching functions are evaluated at.
    u, x : ndarray, shape (N,)
        Input and measured output.
    breaks : ndarray of bool, shape (N,), optional
        The sample rule's breaks (None: every sample follows the one before).
    deadband : float, optional
        The least input move a row needs (None: none needed).

    Returns
    -------
    phi, target : ndarray
        The regressors (eq. 22) and targets (eq. 29) of the informative rows.
    informative : ndarray of bool, shape (N - 1,)
        Which rows those are (row ``t - 1`` of it pairs samples ``t - 1`` and ``t``).
    """
    u_t, x_prev, x_t = u[1:], x[:-1], x[1:]
    f1, f2 = _switching(structure, p, u_t, x_prev)
    informative = (f1 + f2) > 0.0  # rows with neither branch engaged carry no information
    if breaks is not None:
        informative &= ~breaks[1:]  # eq. (24) needs x(t-1): never across a lost reading
    if deadband is not None:
        informative &= np.abs(np.diff(u)) > deadband
    rows = np.flatnonzero(informative)  # gathered once: the same values as masking each array
    f1, f2 = f1[rows], f2[rows]
    phi = _backlash_columns(structure, p, u_t[rows], f1, f2)
    target = x_t[rows] - x_prev[rows] * (1.0 - f1) * (1.0 - f2)  # eq. (29)
    return phi, target, informative


def _backlash_regression(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    x: FloatArray,
    breaks: BoolArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Regressors and target of the batch iteration's rows (:func:`backlash_rows`, every
    engaged row whether the input moved or not)."""
    phi, target, _ = backlash_rows(structure, p, u, x, breaks)
    return phi, target


def _cascade_regression(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    breaks: BoolArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Regressors (eq. 32) and target (eq. 37) with the internal ``x`` estimated by eq. (36).

    With ``breaks``, rows whose measured lags ``y(t-1) .. y(t-p)`` reach across a lost
    reading are left out; the internal ``x`` runs on through (the held input is known).
    """
    left, right = structure.branches(p, u)
    x = play_operator(*play_bounds(left, right), 0.0)  # eq. (36), from rest
    x_prev = np.concatenate([[0.0], x[:-1]])
    f1, f2 = _switching(structure, p, u, x_prev)
    na, nb = structure.na, structure.nb
    t0 = max(1, na, nb)
    m = u.size - t0  # rows t = t0 .. N-1
    n_bl = structure.n_backlash
    phi = np.empty((m, structure.n_parameters), order="F")
    prev = slice(t0 - 1, u.size - 1)  # index t-1 for every row
    phi[:, :n_bl] = _backlash_columns(structure, p, u[prev], f1[prev], f2[prev])
    x_lagged = np.concatenate([[0.0, 0.0], x])  # x_lagged[t + 2 - i] = x(t - i), rest before 0
    col = n_bl
    for i in range(2, na + 1):
        phi[:, col] = x_lagged[t0 + 2 - i : u.size + 2 - i]  # x(t-i), eq. (32)
        col += 1
    for j in range(1, nb + 1):
        phi[:, col] = -y[t0 - j : u.size - j]  # -y(t-j), eq. (32)
        col += 1
    hold = x_lagged[t0 : u.size] * (1.0 - f1[prev]) * (1.0 - f2[prev])  # x(t-2)[1-f1][1-f2]
    target = y[t0:] - hold  # eq. (37)
    if breaks is not None and nb > 0:
        ok = breaks_to_rows(breaks, nb)[t0 - nb :]  # y(t-1) .. y(t-nb) all consecutive
        return phi[ok], target[ok]
    return phi, target


def _undetermined(structure: Structure, phi: FloatArray) -> str:
    """Which branch a singular backlash regression (eq. 22) leaves undetermined, in words.

    A branch's ``n + 1`` parameters need rows engaging it (``f1`` or ``f2`` = 1, eqs. 27-28)
    at ``n + 1`` distinct inputs at least; a branch that has them and still makes the
    regression singular is named as collinear.
    """
    n = structure.degree
    said = []
    for name, first in (("left", 0), ("right", n + 1)):
        engaged = phi[:, first + 1] != 0.0  # the f1 (or -f2) column of eq. (22)
        inputs = np.unique(phi[engaged, first]).size  # u f1 (u f2) on those rows
        if not engaged.any():
            said.append(f"the {name} branch never engaged (eq. {27 if first == 0 else 28})")
        elif inputs <= n:
            said.append(
                f"the {name} branch engaged at only {inputs} distinct input(s) for its "
                f"{n + 1} parameters"
            )
    return " and ".join(said) or "collinear regressors (eq. 22)"


@dataclass
class _IterationOutcome:
    """Working state of :func:`_iterate` (internal, mutable)."""

    p: FloatArray
    last_valid: FloatArray
    valid: bool  # whether p itself is a valid model on the data's input range
    history: list[FloatArray]
    iterations: int
    converged: bool
    reason: str
    period: int = 1  # length of the limit cycle the iteration settled in (1: a fixed point)
    damped: int = 0  # iterations whose regression was singular and took a damped step


# Far-off iterates overflow float64: their non-finite parameters and regressors are caught by
# the validity check and the solver (a singular regression).
@np.errstate(over="ignore", invalid="ignore")
def _iterate(
    structure: Structure,
    u: FloatArray,
    y: FloatArray,
    p_start: FloatArray,
    max_iterations: int,
    tol: float,
    callback: IterationCallback | None,
    breaks: BoolArray | None = None,
) -> _IterationOutcome:
    """The paper's iteration, steps (a)-(c) of §3b / §4b, from ``p_start``.

    For a backlash alone a singular regression (a branch not engaged under the current
    switching estimate, or polynomial columns that collapse on held inputs) takes a damped
    step that keeps the undetermined directions where they were (:func:`_solve_damped`);
    only when even that fails does the iteration stop. A cascade stops there.
    """
    regression = _cascade_regression if structure.cascade else _backlash_regression
    u_range = (float(u.min()), float(u.max()))
    p = p_start.copy()
    out = _IterationOutcome(p, p.copy(), True, [p.copy()], 0, False, "")
    change = float("nan")
    for iteration in range(1, max_iterations + 1):
        out.iterations = iteration
        phi, target = regression(structure, p, u, y, breaks)  # step (b): internal variables
        theta = _solve_least_squares(phi, target) if target.size >= phi.shape[1] else None
        damped = False  # whether eq. (29) left some parameters undetermined this step
        if theta is None and target.size > 0 and not structure.cascade:
            # (a cascade's singular regression means a structure that does not fit, e.g. a
            # dead time it lacks: GUIDE §2; it ends there with that reason)
            theta = _solve_damped(phi, target, structure.theta(p))
            out.damped += 1
            damped = True
        if theta is None:  # step (a) impossible
            out.reason = (
                f"iteration {iteration}: the regression became singular (a branch is never "
                "engaged or regressors are collinear): the model structure may not fit the data, "
                "e.g. a delay or order the model lacks, or the data do not excite both branches"
            )
            return out
        try:
            p_new = structure.from_theta(theta)
        except GenBacklashError as err:
            out.reason = f"iteration {iteration}: {err}"
            return out
        change = float(np.max(np.abs(p_new - p)))
        # The switching patterns can flip back and forth between iterations: a limit cycle.
        # Revisiting one of the last few iterates within tol is as settled as it gets.
        recent = np.array(out.history[-_CYCLE_LOOKBACK:])
        distances = np.max(np.abs(recent - p_new), axis=1)[::-1]  # [1 back, 2 back, ...]
        period = int(np.argmin(distances)) + 1
        settled = float(distances[period - 1])
        p = out.p = p_new
        out.history.append(p.copy())
        if callback is not None:
            callback(iteration, p.copy())
        problem = structure.problem(p, u_range)
        out.valid = problem is None
        if out.valid:
            out.last_valid = p.copy()
        if settled <= tol * max(1.0, float(np.max(np.abs(p)))):  # step (c)
            if damped:
                # A damped step carries what eq. (29) does not determine: an iterate whose
                # branch no row engages is its own fixed point without being an estimate.
                out.reason = (
                    f"iteration {iteration}: the iteration settled with "
                    f"{_undetermined(structure, phi)}: eq. (29) does not determine that "
                    "branch (its parameters were carried over, not estimated)"
                )
                return out
            if problem is None:
                out.converged = True
                out.period = period
                out.reason = (
                    f"converged: parameter change {change:.2g} after {iteration} iterations"
                )
                if period > 1:
                    out.reason += f" (a period-{period} cycle of switching patterns)"
            else:
                out.reason = f"the iteration settled on an invalid model: {problem}"
            return out
    out.reason = (
        f"no convergence in {max_iterations} iterations (last parameter change {change:.2g})"
    )
    if (problem := structure.problem(p, u_range)) is not None:
        out.reason += f"; {problem}"  # the last iterate's problem, for the reason only
    return out


@dataclass
class _Candidate:
    """One start's outcome, refined when asked (internal)."""

    outcome: _IterationOutcome
    history: list[FloatArray]
    p: FloatArray
    fit: float  # free-run NRMSE of p on the data
    refinement: RefinementResult | None
    converged: bool
    reason: str


def _candidate(
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
) -> _Candidate:
    """Iterate from one start (warm-started on a prefix for long records), then refine.

    Without ``support`` a settled candidate is not checked for branches the data never
    reach (:func:`~genbacklash_core.refine.branch_support`, a free run of its own): its
    ``converged`` may then overstate, its ``p`` and ``fit`` are the same.
    """
    history: list[FloatArray] = []
    p = p_start
    if u.size > 4 * _WARM_START_SAMPLES:
        # Long records: the early iterations only find the switching regime, which a prefix
        # shows as well; iterate there first and finish on all the data.
        head = _iterate(
            structure,
            u[:_WARM_START_SAMPLES],
            y[:_WARM_START_SAMPLES],
            p,
            max_iterations,
            tol,
            callback,
            None if breaks is None else breaks[:_WARM_START_SAMPLES],
        )
        if head.converged:
            p = head.p
            history = head.history[:-1]
    outcome = _iterate(structure, u, y, p, max_iterations, tol, callback, breaks)
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
        best, pinned = _refine_described(
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
                check = _iterate(structure, u, y, q, max_iterations, tol, None, breaks)
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
    if converged and not fit < _USELESS_FIT:
        converged = False
        reason += (
            f"; but the model explains almost none of the output (free-run NRMSE {fit:.3f}, "
            "no better than a constant): the structure does not fit the data (a dead time?)"
        )
    return _Candidate(outcome, history, p_final, fit, refinement, converged, reason)


def _refine_described(
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
    they repeat or :data:`_HOLD_ROUNDS` refinements have run. A hold that only a wrong start
    seemed to break (the branches a little off) is simulated through again once the estimate
    is right; the refinement then ends where it would without the rule. Within a round every
    start is judged with the same restarts, so that their costs compare. Without ``judge``
    the refinement restarts at lost readings only (one round).
    """
    u_range = (float(u.min()), float(u.max()))
    restarts, pinned = described_breaks(structure, p, u, y, x0, breaks) if judge else (breaks, 0)
    best: tuple[FloatArray, int, bool, float, float, str] | None = None
    for round_ in range(_HOLD_ROUNDS if judge else 1):
        best = None
        for start_p in starts:
            if structure.problem(start_p, u_range) is not None:
                continue
            trial = refine_parameters(structure, start_p, u, y, x0, breaks=restarts)
            if best is None or trial[4] < best[4]:
                best = trial
        if best is None or not judge or round_ == _HOLD_ROUNDS - 1:
            break
        again, count = described_breaks(structure, best[0], u, y, x0, breaks)
        if _same(again, restarts):
            break
        restarts, pinned, starts = again, count, [best[0]]
    return best, pinned


def _same(a: BoolArray | None, b: BoolArray | None) -> bool:
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
    phi, target = _backlash_regression(structure, p, u, y, breaks)
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


def _run(
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

    def attempt(start_p: FloatArray) -> _Candidate:
        return _candidate(
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
        for fraction in _RESTART_DEAD_ZONES:
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


def _prepare(
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


def _sign_option(sign: float | None, u: FloatArray, y: FloatArray, max_lag: int) -> float:
    if sign is None:
        return _detect_sign(u, y, max_lag)
    if not isinstance(sign, numbers.Real) or sign not in (1, -1):
        raise GenBacklashError(f"sign must be +1, -1 or None (detect), got {sign!r}")
    return float(sign)


def identify_backlash(
    u: ArrayLike,
    x: ArrayLike,
    degree: int = 3,
    *,
    sign: float | None = None,
    start: GeneralBacklash | None = None,
    refine: bool = True,
    max_iterations: int = MAX_ITERATIONS,
    tol: float = TOL,
    nonfinite: NonFinitePolicy = "raise",
    callback: IterationCallback | None = None,
    breaks: ArrayLike | None = None,
    restart_holds: bool = False,
) -> IdentificationResult:
    """Identify a general backlash from input ``u`` and measured output ``x`` (eqs. 22-29).

    Parameters
    ----------
    u, x : array_like, shape (N,)
        Actuator command and measured (load-side) position.
    degree : int
        Polynomial degree ``n >= 1`` of each branch; 1 is the ideal backlash.
    sign : {+1, -1, None}
        Whether the branches increase or decrease; None detects it from the data.
    start : GeneralBacklash, optional
        Initial estimate; default the paper's ``m_1 = sign``, ``c = 0.001``.
    refine : bool
        Run the output-error refinement after the iteration (default True).
    max_iterations, tol : int, float
        The iteration stops when no parameter moves more than ``tol * max(1, max|p|)``.
    nonfinite : {"raise", "drop"}
        Policy for NaN/inf samples.
    callback : callable, optional
        Called as ``callback(iteration, parameters)`` after each iteration.
    breaks : array_like of bool, shape (N,), optional
        The sample rule (:func:`~genbacklash_core.samples.sample_breaks`): True where a
        sample does not follow the one before on the encoder's clock (a lost reading, a
        gap). Rows of eq. (24) are never formed across a break. Default: all consecutive.
    restart_holds : bool
        The refinement restarts its simulation at held readings the play operator does not
        describe (:func:`described_breaks`: a load that moves on inside the play), judged
        again at each refined estimate. ``genbacklash identify`` sets it. Off by default:
        on a smooth input lagged 5 samples (a servo the model lacks) it read the play worse.

    Returns
    -------
    IdentificationResult

    Raises
    ------
    NonFiniteInputError, NotEnoughExcitationError, GenBacklashError

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(1)
    >>> data = ex.generate(seed=0)
    >>> result = identify_backlash(data.u, data.y, degree=3)
    >>> result.converged
    True
    >>> bool(np.max(np.abs(result.model.parameters() - ex.model.parameters())) < 0.03)
    True
    """
    structure, uu, xx, bb, p0 = _backlash_problem(u, x, degree, sign, start, nonfinite, breaks)
    return _run(
        structure,
        uu,
        xx,
        start=p0,
        max_iterations=max_iterations,
        tol=tol,
        refine=refine,
        callback=callback,
        breaks=bb,
        restart_holds=restart_holds,
    )


def backlash_misfit(
    u: ArrayLike, x: ArrayLike, degree: int = 1, *, breaks: ArrayLike | None = None
) -> float:
    """The free-run NRMSE of the backlash the paper's iteration finds (no refinement).

    The number ``identify_backlash(u, x, degree, refine=False, breaks=breaks).fit.nrmse``
    reads, to the bit, at less cost: without the refinement a candidate's ``converged``
    never chooses between starts (the restarts follow the iteration's own convergence and
    the lower misfit), so the check that the data reach every branch of a settled candidate
    (a free run of its own, which decides ``converged`` alone) is skipped. What
    :func:`~genbacklash_core.servo.estimate_servo` scores each candidate servo by.

    Raises
    ------
    GenBacklashError
        As :func:`identify_backlash` (too few samples, no excitation, bad input).

    >>> from genbacklash_core import paper_example
    >>> data = paper_example(1).generate(seed=0)
    >>> misfit = backlash_misfit(data.u, data.y, 3)
    >>> misfit == identify_backlash(data.u, data.y, 3, refine=False).fit.nrmse
    True
    """
    structure, uu, xx, bb, _ = _backlash_problem(u, x, degree, None, None, "raise", breaks)
    result = _run(
        structure,
        uu,
        xx,
        start=None,
        max_iterations=MAX_ITERATIONS,
        tol=TOL,
        refine=False,
        callback=None,
        breaks=bb,
        support=False,
    )
    return result.fit.nrmse


def _backlash_problem(
    u: ArrayLike,
    x: ArrayLike,
    degree: int,
    sign: float | None,
    start: GeneralBacklash | None,
    nonfinite: NonFinitePolicy,
    breaks: ArrayLike | None,
) -> tuple[Structure, FloatArray, FloatArray, BoolArray | None, FloatArray | None]:
    """:func:`identify_backlash`'s input checked: the structure (its sign detected unless
    given), the prepared samples and breaks, the start's parameters (None: the paper's)."""
    degree = as_order("degree", degree)
    if degree < 1:
        raise GenBacklashError(f"degree must be >= 1, got {degree}")
    uu, xx, bb = _prepare(u, x, nonfinite, breaks)
    structure = Structure(degree, 0, 0, 1.0)
    check_excitation(uu, xx, structure.n_parameters)
    check_scale(uu, xx, degree)
    if start is not None and not isinstance(start, GeneralBacklash):
        raise GenBacklashError(f"start must be a GeneralBacklash or None, got {start!r}")
    s = start.sign if start is not None else _sign_option(sign, uu, xx, 0)
    structure = Structure(degree, 0, 0, s)
    p0 = None
    if start is not None:
        if start.degree != degree:
            raise GenBacklashError(f"start has degree {start.degree}, expected {degree}")
        p0 = start.parameters()
    return structure, uu, xx, bb, p0


def identify_cascade(
    u: ArrayLike,
    y: ArrayLike,
    degree: int = 3,
    na: int = 2,
    nb: int = 2,
    *,
    sign: float | None = None,
    start: Cascade | None = None,
    refine: bool = True,
    max_iterations: int = MAX_ITERATIONS,
    tol: float = TOL,
    nonfinite: NonFinitePolicy = "raise",
    callback: IterationCallback | None = None,
    breaks: ArrayLike | None = None,
) -> IdentificationResult:
    """Identify a general backlash followed by linear dynamics (eqs. 31-37).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input of the backlash and output of the linear block.
    degree : int
        Polynomial degree of each branch.
    na, nb : int
        ``r >= 1`` input terms (``a_1 = 1`` included) and ``p >= 0`` output terms of eq. (30).
    sign, start, refine, max_iterations, tol, nonfinite, callback, breaks
        As in :func:`identify_backlash`; the linear block starts at zero. Rows whose
        measured lags reach across a break are left out.

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(3)
    >>> data = ex.generate(seed=0)
    >>> result = identify_cascade(data.u, data.y, degree=3, na=2, nb=2)
    >>> result.converged, result.model.linear.na
    (True, 2)
    >>> bool(np.max(np.abs(result.model.parameters() - ex.model.parameters())) < 0.03)
    True
    """
    degree, na, nb = as_order("degree", degree), as_order("na", na), as_order("nb", nb)
    if degree < 1:
        raise GenBacklashError(f"degree must be >= 1, got {degree}")
    if na < 1 or nb < 0:
        raise GenBacklashError(f"need na >= 1 and nb >= 0, got na={na}, nb={nb}")
    uu, yy, bb = _prepare(u, y, nonfinite, breaks)
    structure = Structure(degree, na, nb, 1.0)
    check_excitation(uu, yy, structure.n_parameters)
    check_scale(uu, yy, degree)
    if start is not None and not isinstance(start, Cascade):
        raise GenBacklashError(f"start must be a Cascade or None, got {start!r}")
    s = start.backlash.sign if start is not None else _sign_option(sign, uu, yy, na + 3)
    structure = Structure(degree, na, nb, s)
    p0 = None
    if start is not None:
        if Structure.of(start) != structure:
            raise GenBacklashError(
                f"start has structure {Structure.of(start)}, expected {structure}"
            )
        p0 = start.parameters()
    return _run(
        structure,
        uu,
        yy,
        start=p0,
        max_iterations=max_iterations,
        tol=tol,
        refine=refine,
        callback=callback,
        breaks=bb,
    )
