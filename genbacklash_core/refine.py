"""Output-error refinement: minimise the free-run simulation error (maximum likelihood).

The paper's equation-error iteration (eqs. 29, 37) puts the noisy output into its regressors
and so is biased by output noise. Minimising the simulation error instead is the maximum
likelihood estimate under white output noise. This module does that by Levenberg-Marquardt
with an analytic Jacobian:

* backlash: while a branch is engaged the output is the branch value, so its sensitivity is the
  branch's derivative; while the backlash holds, the sensitivity is the one at the last
  engagement. A running maximum over engagement indices gives that in one vectorised pass.
* linear block: ``y = (A(q)/B(q)) x``, so ``dy/d(backlash) = (A/B) dx``,
  ``dy/da_i = (1/B) x(t-i)`` and ``dy/db_j = -(1/B) y(t-j)`` (filters, no loops).

The normal equations are formed once per step (N x P times P x N is cheap for P ~ 10 even at
N = 1e6), column-scaled, damped and solved with ``numpy.linalg.lstsq``; damping retries cost a
simulation each but no new Jacobian. Steps that leave the valid set (c <= 0, flipped slope,
unstable linear block) are rejected like steps that raise the cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._typing import BoolArray, FloatArray
from .backlash import GeneralBacklash
from .cascade import Cascade
from .data import as_order, as_real, check_scale, prepare_series
from .errors import GenBacklashError, NotEnoughExcitationError
from .play import play_operator
from .samples import restart_points
from .simulate import play_bounds
from .structure import Structure

__all__ = [
    "RefinementResult",
    "branch_support",
    "refine_output_error",
    "simulate_parameters",
    "simulation_jacobian",
]


@dataclass(frozen=True)
class RefinementResult:
    """Outcome of :func:`refine_output_error`.

    Attributes
    ----------
    model : GeneralBacklash or Cascade
        The refined model (the start model when no step lowered the cost).
    iterations : int
        Accepted Levenberg-Marquardt steps.
    converged : bool
        True when the relative cost decrease fell below the tolerance.
    cost_start, cost_end : float
        Sum of squared free-run simulation errors before and after.
    reason : str
        Why it stopped.
    """

    model: GeneralBacklash | Cascade
    iterations: int
    converged: bool
    cost_start: float
    cost_end: float
    reason: str


def _shift(v: FloatArray, k: int) -> FloatArray:
    """``v(t - k)`` with zeros before the start (rest)."""
    out = np.zeros_like(v)
    if k < v.shape[0]:
        out[k:] = v[: v.shape[0] - k]
    return out


def simulate_parameters(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    x0: float,
    anchors: BoolArray | None = None,
    y: FloatArray | None = None,
    *,
    branches: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Free-run simulation ``(x, y)`` of the model with parameter vector ``p``.

    For a backlash alone ``y`` is ``x``; a linear block starts from rest. ``anchors`` (a
    backlash alone, with the measured ``y``) restarts the simulation at the measured output
    where the chain of consecutive samples breaks (a lost reading: the inputs in between
    are unknown), as ``x0`` starts it at the first sample. ``branches``: ``(L(u), R(u))`` at
    ``p`` where the caller has them (``structure.branches(p, u)``; the Jacobian at the same
    ``p`` takes them too, :func:`_engaged`).
    """
    left, right = structure.branches(p, u) if branches is None else branches
    lo, hi = play_bounds(left, right)
    if anchors is not None and y is not None and not structure.cascade and anchors.any():
        lo, hi = lo.copy(), hi.copy()
        lo[anchors] = hi[anchors] = y[anchors]  # the clamp pins x(t) to the reading there
    x = play_operator(lo, hi, x0)  # eqs. (20), (36)
    if not structure.cascade:
        return x, x
    from scipy import signal  # here, not at the top: 0.5 s of import a backlash never needs

    a, b = structure.linear_part(p)
    y = signal.lfilter(np.concatenate([[0.0], a]), np.concatenate([[1.0], b]), x)  # eq. (30)
    return x, np.asarray(y, dtype=np.float64)


def _engaged(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    x: FloatArray,
    x0: float,
    anchors: BoolArray | None = None,
    branches: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[BoolArray, BoolArray]:
    """Where the free-run simulation ``x`` follows the left and the right branch.

    Samples pinned to the measurement (``anchors``) follow neither. ``branches``: ``(L(u),
    R(u))`` at ``p`` where the caller has them (those the simulation ran on).
    """
    left, right = structure.branches(p, u) if branches is None else branches
    x_prev = np.concatenate([[x0], x[:-1]])
    f1 = (left - x_prev) * structure.sign <= 0.0  # eq. (18): left branch engaged
    f2 = ((x_prev - right) * structure.sign <= 0.0) & ~f1  # eq. (19)
    if anchors is not None:
        f1 &= ~anchors
        f2 &= ~anchors
    return f1, f2


def branch_support(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    x0: float,
    anchors: BoolArray | None = None,
) -> str | None:
    """Why the data do not determine a branch of the model ``p``, or None when they do.

    A branch's ``n + 1`` parameters (eq. 23) enter the free-run simulation only where it is
    engaged (eqs. 18-19), and there only through its values at those inputs: they are
    determined when the simulation follows the branch at ``n + 1`` distinct inputs at least.

    >>> s = Structure(1)
    >>> u = np.array([0.0, 1.0, 2.0, 1.0, 0.5, 0.0])
    >>> branch_support(s, np.array([1.0, 0.1, 1.0, 0.1]), u, u, 0.0) is None
    True
    >>> print(branch_support(s, np.array([1.0, 0.1, 1.0, 0.1]), u[:4], u[:4], 0.0))
    ... # doctest: +NORMALIZE_WHITESPACE
    the left branch is followed at 1 distinct inputs by the free-run simulation;
    its 2 parameters need 2
    """
    branches = structure.branches(p, u)
    x = simulate_parameters(structure, p, u, x0, anchors, y, branches=branches)[0]
    f1, f2 = _engaged(structure, p, u, x, x0, anchors, branches)
    needed = structure.degree + 1
    said = []
    for name, engaged in (("left", f1), ("right", f2)):
        inputs = np.unique(u[engaged]).size
        if inputs < needed:
            said.append(
                f"the {name} branch is followed at {inputs} distinct inputs by the free-run "
                f"simulation; its {needed} parameters need {needed}"
            )
    return "; ".join(said) or None


HOLD_SIGMAS = 4.0
"""How many noise standard deviations a reading may lie off the play operator's hold before
the hold counts as falsified (:func:`falsified_holds`); white noise crosses it on 6e-5 of the
held samples."""


def falsified_holds(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    x0: float,
    scale: float,
    anchors: BoolArray | None = None,
) -> BoolArray:
    """The held samples whose reading says the load was not held: ``True`` where the free-run
    simulation of the backlash ``p`` holds its state (the clamp of eq. 20 leaves it; eqs.
    18-19 engage no branch, or the input is still) and the reading lies more than
    :data:`HOLD_SIGMAS` ``scale`` (the output noise's standard deviation) off it.

    The play operator moves its output only where the input pushes it through a branch; a
    load that moves on by itself inside the play -- one that coasts when the motor stops,
    one that a load torque keeps on one flank while the input leaves it, one that rings on a
    spring -- is not described by it there. At each such sample the simulation restarts at
    the reading (as after a lost one, ``anchors``), so that the samples after it are
    simulated from where the load is, and the output-error fit
    (:func:`refine_parameters`) does not bend the branches to reach a load the play operator
    cannot place. White noise alone crosses the threshold on a few held samples in 1e5.

    Examples
    --------
    >>> s = Structure(1)
    >>> p = np.array([1.0, 0.1, 1.0, 0.1])  # x = u + 0.1 (left) / u - 0.1 (right)
    >>> u = np.array([0.0, 0.5, 0.5, 0.5, 0.5])
    >>> y = np.array([-0.1, 0.4, 0.4, 0.45, 0.45])  # the load coasts on at rest of u
    >>> falsified_holds(s, p, u, y, -0.1, 0.005).tolist()
    [False, False, False, True, False]
    """
    lo, hi = play_bounds(*structure.branches(p, u))
    limit = HOLD_SIGMAS * scale
    pinned = np.zeros(u.size, dtype=bool) if anchors is None else anchors
    out = np.zeros(u.size, dtype=bool)
    # sequential: a restart moves the state every later hold is judged against
    x = x0
    for t, (low, high, reading, pin) in enumerate(
        zip(lo.tolist(), hi.tolist(), y.tolist(), pinned.tolist(), strict=True)
    ):
        if pin:
            x = reading
            continue
        held = min(max(x, low), high)  # eq. (20)
        if held == x and abs(reading - x) > limit:
            out[t] = True
            x = reading
        else:
            x = held
    return out


def _backlash_sensitivity(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    x: FloatArray,
    x0: float,
    anchors: BoolArray | None = None,
    branches: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """``dx/dp`` for the backlash parameters, shape (N, 2n+2), column-major.

    At ``anchors`` the simulation is pinned to the measurement: no sensitivity there, nor
    after it until a branch engages again. ``branches``: as :func:`_engaged` takes them.
    """
    n = structure.degree
    m_left, c_left, m_right, c_right = structure.split(p)
    f1, f2 = _engaged(structure, p, u, x, x0, anchors, branches)
    pinned = np.zeros(u.size, dtype=bool) if anchors is None else anchors
    last = np.where(f1 | f2 | pinned, np.arange(u.size), -1)
    np.maximum.accumulate(last, out=last)  # index of the last engagement at or before t
    never = last < 0  # before the first engagement the output is x0: no sensitivity
    source = np.where(never, 0, last)
    # ``last`` never decreases, so ``never`` is a prefix: zeroed by a slice, not a mask
    # (a mask's assignment is ~40x the slice's on the bands' 10,000-sample free run)
    unset = int(np.count_nonzero(never))

    xi1 = u + c_left  # eq. (16)
    xi2 = u - c_right  # eq. (17)
    jac = np.empty((u.size, structure.n_backlash), order="F")
    power1 = np.ones_like(xi1)
    power2 = np.ones_like(xi2)
    dleft_dc = np.zeros_like(xi1)
    dright_dc = np.zeros_like(xi2)

    def held(engaged_value: FloatArray, column: int) -> None:
        # The output holds the value of the last engaged branch: gather its sensitivity.
        np.take(engaged_value, source, out=jac[:, column])
        jac[:unset, column] = 0.0

    for i in range(1, n + 1):
        dleft_dc += i * m_left[i - 1] * power1  # d/dc_L sum m_Li xi1^i
        dright_dc -= i * m_right[i - 1] * power2  # d/dc_R sum m_Ri (u - c_R)^i
        power1 = power1 * xi1
        power2 = power2 * xi2
        held(np.where(f1, power1, 0.0), i - 1)  # dL/dm_Li = xi1^i
        held(np.where(f2, power2, 0.0), n + i)  # dR/dm_Ri = xi2^i
    held(np.where(f1, dleft_dc, 0.0), n)
    held(np.where(f2, dright_dc, 0.0), 2 * n + 1)
    return jac


def _jacobian(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    x: FloatArray,
    y: FloatArray,
    x0: float,
    anchors: BoolArray | None = None,
    branches: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """``dy/dp`` of the free-run simulation, shape (N, P), column-major (``branches``: as
    :func:`_engaged` takes them)."""
    jx = _backlash_sensitivity(structure, p, u, x, x0, anchors, branches)
    if not structure.cascade:
        return jx
    from scipy import signal  # here, not at the top: 0.5 s of import a backlash never needs

    a, b = structure.linear_part(p)
    num = np.concatenate([[0.0], a])
    den = np.concatenate([[1.0], b])
    jac = np.empty((u.size, structure.n_parameters), order="F")
    for col in range(structure.n_backlash):
        jac[:, col] = signal.lfilter(num, den, jx[:, col])  # (A/B) dx/dp
    col = structure.n_backlash
    for i in range(2, structure.na + 1):
        jac[:, col] = signal.lfilter([1.0], den, _shift(x, i))  # dy/da_i
        col += 1
    for j in range(1, structure.nb + 1):
        jac[:, col] = -signal.lfilter([1.0], den, _shift(y, j))  # dy/db_j
        col += 1
    return jac


def simulation_jacobian(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    x0: float,
    breaks: BoolArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """The free-run simulation ``y_sim`` of ``p`` and its Jacobian ``dy_sim/dp``, shape (N, P).

    The refinement's own (analytic) sensitivities, at ``p``; with ``breaks`` a backlash alone
    restarts at the reading after each break (:func:`simulate_parameters`), and holds no
    sensitivity there until a branch engages again.

    >>> s = Structure(1)
    >>> u = np.array([0.0, 1.0, 2.0, 1.0])
    >>> y_sim, jac = simulation_jacobian(s, np.array([1.0, 0.1, 1.0, 0.1]), u, u, 0.0)
    >>> y_sim.tolist(), jac[:, 3].tolist()  # dy/dc_R = -m_R1 while the right branch leads
    ([0.0, 0.9, 1.9, 1.1], [0.0, -1.0, -1.0, 0.0])
    """
    anchors = None if structure.cascade else restart_points(breaks)
    branches = structure.branches(p, u)
    x, y_sim = simulate_parameters(structure, p, u, x0, anchors, y, branches=branches)
    return y_sim, _jacobian(structure, p, u, x, y_sim, x0, anchors, branches)


_OVERFLOW = "the simulation error or its Jacobian overflows float64: the model is far out of scale"


# Far out of scale with the data a model overflows float64: checked where it matters.
@np.errstate(over="ignore", invalid="ignore")
def refine_parameters(
    structure: Structure,
    p_start: FloatArray,
    u: FloatArray,
    y: FloatArray,
    x0: float,
    *,
    max_iterations: int = 50,
    tol: float = 1e-10,
    breaks: BoolArray | None = None,
) -> tuple[FloatArray, int, bool, float, float, str]:
    """Levenberg-Marquardt on the simulation error from ``p_start`` (flat-vector form).

    ``breaks`` (the sample rule, :mod:`genbacklash_core.samples`): for a backlash alone the
    simulation restarts at the reading after each break, since the inputs of the lost
    readings are unknown; a cascade simulates on through.

    Returns ``(p, accepted_steps, converged, cost_start, cost_end, reason)``.
    """
    p = np.array(p_start, dtype=np.float64)
    u_range = (float(u.min()), float(u.max()))
    if (problem := structure.problem(p, u_range)) is not None:
        raise GenBacklashError(f"cannot refine from an invalid model: {problem}")
    anchors = None if structure.cascade else restart_points(breaks)  # the first: from x0

    def simulate(q: FloatArray) -> tuple[FloatArray, FloatArray, tuple[FloatArray, FloatArray]]:
        # the branches too: the Jacobian at an accepted q takes them (not evaluated again)
        branches = structure.branches(q, u)
        x, y_sim = simulate_parameters(structure, q, u, x0, anchors, y, branches=branches)
        return x, y_sim, branches

    x, yhat, branches = simulate(p)
    residual = y - yhat
    cost = float(residual @ residual)
    cost_start = cost
    if not math.isfinite(cost):
        return p, 0, False, cost, cost, _OVERFLOW
    damping = 1e-3
    accepted = 0
    for _ in range(max_iterations):
        jac = _jacobian(structure, p, u, x, yhat, x0, anchors, branches)
        gram = jac.T @ jac
        grad = jac.T @ residual
        if not (np.all(np.isfinite(gram)) and np.all(np.isfinite(grad))):
            return p, accepted, accepted > 0, cost_start, cost, _OVERFLOW
        scale = np.sqrt(np.diag(gram))
        scale[scale == 0.0] = 1.0
        scaled = gram / np.outer(scale, scale)
        rhs = grad / scale
        improved = False
        while damping <= 1e10:
            system = scaled + damping * np.eye(scaled.shape[0])
            step = np.linalg.lstsq(system, rhs, rcond=None)[0] / scale
            candidate = p + step
            if structure.problem(candidate, u_range) is None:
                x_new, y_new, branches_new = simulate(candidate)
                res_new = y - y_new
                cost_new = float(res_new @ res_new)
                if cost_new < cost:
                    improved = True
                    break
            damping *= 4.0
        if not improved:
            # Stuck before any step means a kink of the piecewise-smooth cost, not a minimum.
            stalled = "no step lowers the simulation error"
            return p, accepted, accepted > 0, cost_start, cost, stalled
        decrease = (cost - cost_new) / max(cost, 1e-300)
        p, x, yhat, residual, cost = candidate, x_new, y_new, res_new, cost_new
        branches = branches_new
        accepted += 1
        damping = max(damping / 5.0, 1e-12)
        if decrease < tol:
            return p, accepted, True, cost_start, cost, "relative cost decrease below tolerance"
    return p, accepted, False, cost_start, cost, f"stopped after {max_iterations} steps"


def refine_output_error(
    model: GeneralBacklash | Cascade,
    u: FloatArray,
    y: FloatArray,
    *,
    x0: float | None = None,
    max_iterations: int = 50,
    tol: float = 1e-10,
) -> RefinementResult:
    """Refine ``model`` by minimising the free-run simulation error on ``(u, y)``.

    Parameters
    ----------
    model : GeneralBacklash or Cascade
        Start, usually the result of the equation-error iteration.
    u, y : ndarray
        Input and measured output.
    x0 : float, optional
        Backlash state before the first sample; default ``y[0]`` for a backlash alone and 0
        for a cascade (which starts from rest).
    max_iterations, tol : int, float
        Step limit and relative cost-decrease tolerance.

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(1); data = ex.generate(seed=1)
    >>> rough = GeneralBacklash((0.45, -0.25, 0.3), 0.6, (0.55, 0.4, 0.2), 0.7)
    >>> out = refine_output_error(rough, data.u, data.y)
    >>> bool(np.max(np.abs(out.model.parameters() - ex.model.parameters())) < 0.05)
    True
    """
    if not isinstance(model, (GeneralBacklash, Cascade)):
        raise GenBacklashError(f"model must be a GeneralBacklash or a Cascade, got {model!r}")
    structure = Structure.of(model)
    uu, yy = prepare_series(u, y)
    if uu.size == 0:
        raise NotEnoughExcitationError("no samples to refine on")
    check_scale(uu, yy, structure.degree)
    max_iterations = as_order("max_iterations", max_iterations)
    if max_iterations < 0:
        raise GenBacklashError(f"max_iterations must be >= 0, got {max_iterations}")
    tol = as_real("tol", tol)
    start_state = (float(yy[0]) if not structure.cascade else 0.0) if x0 is None else x0
    start_state = as_real("x0", start_state)
    p, steps, converged, cost0, cost1, reason = refine_parameters(
        structure, model.parameters(), uu, yy, start_state, max_iterations=max_iterations, tol=tol
    )
    if not math.isfinite(cost0):
        raise GenBacklashError(f"cannot refine this model on these data: {reason}")
    return RefinementResult(structure.model(p), steps, converged, cost0, cost1, reason)
