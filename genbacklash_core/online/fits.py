"""The windowed identifier's fits: warm-started iterations of the batch method over a window.

:func:`fit_window` runs ``iterations`` warm-started iterations of the paper's method
(eqs. 22-29 for a backlash alone, eqs. 31-37 for the cascade) over the rows of a window
(:func:`~genbacklash_core.online.rows.window_rows`), each a least squares
(:func:`solve_normal`, with a seed's prior information when there is one), and says when the
window did not excite the parameters enough (:func:`block_conditioning`,
:func:`poorly_excited`). :func:`cold_fit` runs the batch iteration from the paper's start
(:func:`~genbacklash_core.identify.identify_backlash`,
:func:`~genbacklash_core.identify.identify_cascade`); the recursive identifier uses it too,
for its batch (re-)initialisations, on data that engaged both branches
(:func:`~genbacklash_core.online.engaged.unengaged_branch`). :func:`refine_window` adds a
few output-error steps; :func:`outlier_rows` says which remembered rows an accepted fit
cannot have produced.

Examples
--------
>>> from genbacklash_core import paper_example
>>> data = paper_example(1).generate(seed=0)
>>> found = cold_fit(Structure(3), False, data.u, data.y)
>>> structure, p = found
>>> bool(np.max(np.abs(p - paper_example(1).model.parameters())) < 0.05)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import identify_backlash, identify_cascade
from genbacklash_core.refine import refine_parameters
from genbacklash_core.simulate import play_bounds
from genbacklash_core.structure import Structure

from .covariance import natural_covariance
from .engaged import unengaged_branch
from .rows import WindowRows, settling_samples, window_rows
from .seed import SeedPrior

__all__ = [
    "FitFailure",
    "WindowFit",
    "block_conditioning",
    "cold_fit",
    "conditioning_floor",
    "fit_window",
    "outlier_rows",
    "parameter_blocks",
    "poorly_excited",
    "refine_window",
    "solve_normal",
]

OUTLIER_SIGMAS = 10.0  # rows this far off the accepted model are forgotten (memory mode)


@dataclass
class WindowFit:
    """A fit over a window (internal): the estimate and what the RLS needs to start from it."""

    p: FloatArray
    theta: FloatArray
    information: FloatArray  # Phi^T Phi of the final regression (theta space)
    covariance: FloatArray  # natural parameters
    sigma2: float  # residual variance, RSS / (m - P)
    residual: float  # RMS equation error
    settled: bool
    rows: WindowRows
    excitation: float
    reason: str


@dataclass
class FitFailure:
    """Why a window fit did not produce an estimate (internal)."""

    reason: str
    excitation: float
    no_information: bool  # True: the data lack information; False: the fit left the valid set
    rows: WindowRows | None = None  # the first regression (at the start estimate), when it ran


def parameter_blocks(structure: Structure) -> list[tuple[str, slice]]:
    """The separated vector's blocks: the left branch, the right branch, the linear block."""
    n1 = structure.degree + 1
    blocks = [("left branch", slice(0, n1)), ("right branch", slice(n1, 2 * n1))]
    if structure.cascade and structure.n_parameters > 2 * n1:
        blocks.append(("linear block", slice(2 * n1, structure.n_parameters)))
    return blocks


def block_conditioning(structure: Structure, information: FloatArray) -> FloatArray:
    """Smallest eigenvalue of each block's normalised (unit-diagonal) information matrix.

    1 for orthogonal regressors, 0 when they are collinear. Random input over the whole
    range gives ~0.02-0.2 (lower for higher degrees); an input that only sweeps a narrow part
    of a branch gives orders of magnitude less: the polynomial is then not identifiable.
    """
    out = np.zeros(len(parameter_blocks(structure)))
    for k, (_, block) in enumerate(parameter_blocks(structure)):
        sub = information[block, block]
        diag = np.diag(sub)
        if not np.all(diag > 0.0) or not np.all(np.isfinite(sub)):
            continue
        scale = np.sqrt(diag)
        out[k] = max(float(np.linalg.eigvalsh(sub / np.outer(scale, scale))[0]), 0.0)
    return out


def conditioning_floor(
    structure: Structure, reference: FloatArray, branches: float, linear: float
) -> FloatArray:
    """Per block, the conditioning below which it counts as not excited: ``branches`` (or
    ``linear`` for the linear block) times the reference."""
    fractions = [
        linear if name == "linear block" else branches for name, _ in parameter_blocks(structure)
    ]
    return np.asarray(reference * np.array(fractions), dtype=np.float64)


def poorly_excited(structure: Structure, conditioning: FloatArray, floor: FloatArray) -> str | None:
    """Which block the data excite too little (conditioning below its floor), as a
    sentence; None when every block is excited."""
    for k, (name, _) in enumerate(parameter_blocks(structure)):
        if conditioning[k] < floor[k]:
            return (
                f"the recent input covers too little of the {name} to identify it "
                f"(conditioning {conditioning[k]:.2g} < {floor[k]:.2g})"
            )
    return None


def solve_normal(
    phi: FloatArray, target: FloatArray, prior: SeedPrior | None = None
) -> tuple[FloatArray, FloatArray] | None:
    """Least squares by column-scaled normal equations: ``(theta, (Phi^T Phi)^-1)``.

    With a ``prior`` (information ``R_0`` about ``theta_0``) the regularised least squares
    ``(Phi^T Phi + R_0) theta = Phi^T z + R_0 theta_0``, and ``(Phi^T Phi + R_0)^-1``.
    None when the normalised information matrix is (numerically) singular, i.e. when its
    smallest eigenvalue is below ``1e-10`` times its largest.
    """
    gram = phi.T @ phi
    rhs = phi.T @ target
    if prior is not None:
        gram = gram + prior.information
        rhs = rhs + prior.information @ prior.theta
    scale = np.sqrt(np.diag(gram))
    if not np.all(scale > 0.0) or not np.all(np.isfinite(gram)):
        return None  # a regressor is identically zero, e.g. a branch never engaged
    outer = np.outer(scale, scale)
    values, vectors = np.linalg.eigh(gram / outer)
    if not values[0] > 1e-10 * values[-1]:
        return None
    inverse = (vectors / values) @ vectors.T / outer
    theta = inverse @ rhs
    return np.asarray(theta, dtype=np.float64), np.asarray(inverse, dtype=np.float64)


def _sign_problem(structure: Structure, p: FloatArray) -> str | None:
    """The cheap part of ``Structure.problem``: slope senses and dead-zone signs."""
    n = structure.degree
    s = structure.sign
    if p[0] * s <= 0.0 or p[n + 1] * s <= 0.0:
        return f"a branch slope changed sense (m_left_1={p[0]:.3g}, m_right_1={p[n + 1]:.3g})"
    if p[n] <= 0.0 or p[2 * n + 1] <= 0.0:
        return f"a dead-zone constant is not positive ({p[n]:.3g}, {p[2 * n + 1]:.3g})"
    return None


def fit_window(
    structure: Structure,
    u: FloatArray,
    y: FloatArray,
    p_start: FloatArray,
    *,
    iterations: int,
    tol: float,
    settle: float,
    deadband: float,
    recent: int | None = None,
    min_excitation: float = 0.0,
    prior: SeedPrior | None = None,
    breaks: BoolArray | None = None,
) -> WindowFit | FitFailure:
    """Up to ``iterations`` warm-started iterations of the paper's method on one window.

    Steps (a)-(b) of §3b / §4b from ``p_start``: regression at the current estimate, least
    squares for the separated vector (eqs. 23/33), natural parameters by eq. (34). The
    iteration has settled when no parameter moved more than ``tol * max(1, max|p|)`` or more
    than ``settle`` of its standard deviation; it stops there. An iterate with a slope or
    dead zone of the wrong sign ends the iteration at the previous one; the final estimate
    must be valid on the window's input range (branches apart, stable linear block). The
    excitation is the informative share of the ``recent`` latest samples at ``p_start``;
    below ``min_excitation`` nothing is fitted. A ``prior`` (a saved estimate's information,
    :func:`seed_prior`) joins each regression as ``prior.rows`` earlier rows would: the
    least squares are regularised towards it and the residual variance is pooled with its.
    """
    size = structure.n_parameters
    u_range = (float(u.min()), float(u.max()))
    p = p_start
    accepted: WindowFit | None = None
    excitation = 0.0
    reason = ""
    first: WindowRows | None = None
    settling = settling_samples(structure, p) if structure.cascade else None
    for k in range(iterations):
        rows = window_rows(structure, p, u, y, deadband, settling, breaks)
        if k == 0:
            first = rows
            flags = rows.informative if recent is None else rows.informative[-recent:]
            excitation = float(flags.mean()) if flags.size else 0.0
            if excitation < min_excitation:
                return FitFailure(
                    f"the recent input carried no information (informative share "
                    f"{excitation:.3f} < {min_excitation:g})",
                    excitation,
                    True,
                )
        m = rows.target.size
        if m < (2 * size if prior is None else 1):
            if accepted is not None:
                break
            return FitFailure(
                f"only {m} informative samples in the window for {size} parameters",
                excitation,
                True,
            )
        solved = solve_normal(rows.phi, rows.target, prior)
        if solved is None:
            if accepted is not None:
                break
            return FitFailure(
                "the regression is singular (a branch is not engaged in the window, or the "
                "input does not cover enough of its range)",
                excitation,
                True,
            )
        theta, inverse = solved
        try:
            p_new = structure.from_theta(theta)
        except GenBacklashError as err:
            reason = str(err)
            break
        problem = _sign_problem(structure, p_new)  # the full check on the final estimate
        if problem is not None:
            reason = problem
            break
        error = rows.target - rows.phi @ theta
        rss = float(error @ error)
        count: float = m
        if prior is not None:  # pooled with the rows the prior stands for
            # (the recursive identifier pools the same way, with a per-branch weight and its
            # own rounding order: iteration.solve_memory; kept apart to stay bit-identical)
            rss += prior.sigma2 * prior.rows
            count = m + prior.rows
        sigma2 = rss / max(count - size, 1)
        covariance = natural_covariance(structure, theta, sigma2 * inverse)
        change = np.abs(p_new - p)
        std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
        settled = bool(
            np.all(change <= np.maximum(tol * max(1.0, float(np.max(np.abs(p_new)))), settle * std))
        )
        accepted = WindowFit(
            p=p_new,
            theta=theta,
            information=rows.phi.T @ rows.phi,
            covariance=covariance,
            sigma2=sigma2,
            residual=math.sqrt(rss / count),
            settled=settled,
            rows=rows,
            excitation=excitation,
            reason="",
        )
        p = p_new
        if settled:
            break
    if accepted is None:
        return FitFailure(reason or "no valid iterate", excitation, False, first)
    problem = structure.problem(accepted.p, u_range)
    if problem is not None:
        return FitFailure(problem, excitation, False, first)
    accepted.reason = reason
    return accepted


def cold_fit(
    structure: Structure,
    sign_known: bool,
    u: FloatArray,
    y: FloatArray,
    breaks: BoolArray | None = None,
) -> tuple[Structure, FloatArray] | str:
    """The batch iteration (with its restarts) from the paper's start; or why it failed.

    Detects the branch sense when it is not known yet. ``breaks``: the sample rule. Data
    that never engaged a branch of a backlash alone
    (:func:`~genbacklash_core.online.engaged.unengaged_branch`) are not fitted: no start or
    refinement can determine that branch.
    """
    if (unengaged := unengaged_branch(structure, u, y, breaks)) is not None:
        return unengaged
    sign = structure.sign if sign_known else None
    try:
        for refine in (False, True):
            # Without refinement first (cheaper); when the iteration does not settle (it can
            # creep on for more than its 30 iterations), the default identify decides: its
            # refined estimate counts only when the iteration restarted there settles.
            if structure.cascade:
                result = identify_cascade(
                    u,
                    y,
                    structure.degree,
                    structure.na,
                    structure.nb,
                    sign=sign,
                    refine=refine,
                    breaks=breaks,
                )
            else:
                result = identify_backlash(
                    u, y, structure.degree, sign=sign, refine=refine, breaks=breaks
                )
            if result.converged:
                break
    except GenBacklashError as err:
        return str(err)
    if not result.converged:
        return result.reason
    found = Structure.of(result.model)
    return found, result.model.parameters()


def refine_window(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    fit: WindowFit,
    steps: int,
    breaks: BoolArray | None = None,
) -> FloatArray | None:
    """A few output-error steps on the window from ``p``; None when they cannot run.

    For the cascade the window starts mid-stream: the simulation starts at the first sample
    whose internal state is known, from that state, and the free response of the linear
    block to the measured past is taken off the output so that simulating from rest fits.
    """
    if structure.cascade:
        rows = fit.rows
        if rows.x is None:
            return None
        na, nb = structure.na, structure.nb
        start = rows.first + max(na, nb) + 1
        if u.size - start < 4 * structure.n_parameters:
            return None
        a, b = structure.linear_part(p)
        num = np.concatenate([[0.0], a])
        den = np.concatenate([[1.0], b])
        past_y = y[start - nb : start][::-1] if nb else np.zeros(0)
        past_x = rows.x[start - na : start][::-1]
        from scipy import signal  # here, not at the top: 0.5 s of import a backlash never needs

        zi = signal.lfiltic(num, den, past_y, past_x)
        free = signal.lfilter(num, den, np.zeros(u.size - start), zi=zi)[0]
        u_fit, y_fit, x0 = u[start:], y[start:] - free, float(rows.x[start - 1])
    else:
        u_fit, y_fit, x0 = u, y, float(y[0])
    brk = None if structure.cascade else breaks
    try:
        q = refine_parameters(structure, p, u_fit, y_fit, x0, max_iterations=steps, breaks=brk)[0]
    except GenBacklashError:
        return None
    return q


def outlier_rows(
    structure: Structure,
    p: FloatArray,
    u1: FloatArray,
    y0: FloatArray,
    y1: FloatArray,
    residual: float,
) -> BoolArray | None:
    """Which rows ``(u(t), x(t-1), x(t))`` the accepted model ``p`` cannot have produced:
    one-step prediction errors (eq. 20, one step of the play operator from ``x(t-1)``)
    beyond :data:`OUTLIER_SIGMAS` robust standard deviations (at least ``residual``). None
    when there are too few rows (four per parameter) to judge.

    >>> from genbacklash_core import paper_example
    >>> truth = paper_example(1).model
    >>> u1 = np.linspace(-1.5, 1.5, 40); y0 = truth.right(u1 - 0.1)
    >>> y1 = truth.right(u1); y1[7] += 5.0  # one garbage reading
    >>> np.flatnonzero(outlier_rows(Structure(3), truth.parameters(), u1, y0, y1, 0.01)).tolist()
    [7]
    """
    if u1.size < 4 * structure.n_parameters:
        return None
    left, right = structure.branches(p, u1)
    lo, hi = play_bounds(left, right)
    error = y1 - np.minimum(np.maximum(y0, lo), hi)  # eq. (20): one step from x(t-1)
    scale = 1.4826 * float(np.median(np.abs(error)))
    limit = OUTLIER_SIGMAS * max(scale, residual, 1e-12)
    return np.asarray(np.abs(error) > limit)
