"""The regression of the paper's iteration: the switching functions (eqs. 27-28), the rows of
eqs. (24)/(29) for a backlash and eqs. (33)/(36) for the cascade, and their least-squares
solve (damped where a branch is undetermined).
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.play import play_operator
from genbacklash_core.samples import breaks_to_rows
from genbacklash_core.simulate import play_bounds
from genbacklash_core.structure import Structure


def detect_sign(u: FloatArray, y: FloatArray, max_lag: int) -> float:
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


def solve_least_squares(phi: FloatArray, target: FloatArray) -> FloatArray | None:
    """Least-squares solution of ``phi @ theta = target``, or None when it is singular.

    The column-scaled normal equations are formed once (cheap for the few columns here even
    at N = 1e6) and solved by ``numpy.linalg.lstsq``, whose rank decides singularity.
    """
    gram = phi.T @ phi  # (called under run_iteration's errstate: overflow is checked here)
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


def solve_damped(phi: FloatArray, target: FloatArray, theta_prev: FloatArray) -> FloatArray | None:
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


def backlash_columns(
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


def switching_functions(
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
    f1, f2 = switching_functions(structure, p, u_t, x_prev)
    informative = (f1 + f2) > 0.0  # rows with neither branch engaged carry no information
    if breaks is not None:
        informative &= ~breaks[1:]  # eq. (24) needs x(t-1): never across a lost reading
    if deadband is not None:
        informative &= np.abs(np.diff(u)) > deadband
    rows = np.flatnonzero(informative)  # gathered once: the same values as masking each array
    f1, f2 = f1[rows], f2[rows]
    phi = backlash_columns(structure, p, u_t[rows], f1, f2)
    target = x_t[rows] - x_prev[rows] * (1.0 - f1) * (1.0 - f2)  # eq. (29)
    return phi, target, informative


def backlash_regression(
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


def cascade_regression(
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
    f1, f2 = switching_functions(structure, p, u, x_prev)
    na, nb = structure.na, structure.nb
    t0 = max(1, na, nb)
    m = u.size - t0  # rows t = t0 .. N-1
    n_bl = structure.n_backlash
    phi = np.empty((m, structure.n_parameters), order="F")
    prev = slice(t0 - 1, u.size - 1)  # index t-1 for every row
    phi[:, :n_bl] = backlash_columns(structure, p, u[prev], f1[prev], f2[prev])
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


def undetermined_branch(structure: Structure, phi: FloatArray) -> str:
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
