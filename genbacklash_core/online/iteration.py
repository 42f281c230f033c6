"""The recursive identifier's iteration: one warm-started pass of the paper's method over the
memory's rows.

Every ``block`` samples with new rows, the rows are re-evaluated at the current estimate
(eqs. 25-28) and the least squares of eq. (29) (backlash) or eq. (37) (cascade) is solved,
with a weak pull ``R_0`` towards the current estimate (no wind-up, never singular) and, after a
seed, the seed's information ``W`` weighted by what the memory has not refilled
(:func:`~genbacklash_core.online.seed.prior_weights`)::

    (Phi^T Phi + R_0 + W) theta_new = Phi^T z + R_0 theta + W theta_seed

:func:`solve_memory` is that one iteration; :func:`settle_memory` iterates it from a batch
fit until the estimate stops moving (a start or restart). :class:`Iterate` is the current
estimate the iterations update: an iterate that leaves the valid set is not taken, and the
last valid one stands. :func:`ewma` is the running average the identifier keeps its errors
and its excitation with.

Examples
--------
>>> from genbacklash_core import paper_example
>>> from genbacklash_core.online.memory import BinnedRows
>>> from genbacklash_core.online.rows import memory_regression
>>> truth = paper_example(1).model
>>> rng = np.random.default_rng(0)
>>> u0, u1 = rng.uniform(-2, 2, 400), rng.uniform(-2, 2, 400)
>>> x0 = truth.right(u0)  # every row starts engaged on the right branch, then moves
>>> x1 = np.where(u1 > u0, truth.right(u1), np.minimum(x0, truth.left(u1)))
>>> rows = np.column_stack([u0, u1, x0, x1, np.zeros(400), np.zeros(400)])
>>> found = settle_memory(Structure(3), truth.parameters() * 1.01, rows, 1e4, (-2.0, 2.0))
>>> solution, pull = found
>>> p = Structure(3).from_theta(solution.theta)
>>> bool(np.max(np.abs(p - truth.parameters())) < 1e-6)
True
>>> ewma(np.array([1.0, 1.0]), 0.5, 0.0)
0.75
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import relative_std_of
from genbacklash_core.structure import Structure

from .covariance import natural_from_theta, natural_variances, scaled_inverse
from .memory import BinnedRows
from .rows import memory_regression
from .seed import SeedPrior, prior_weights

__all__ = [
    "Iterate",
    "MemorySolution",
    "ewma",
    "settle_memory",
    "solve_memory",
    "theta_problem",
]

_INIT_ITERATIONS = 10  # warm iterations over the memory after a batch fit
_INIT_TOL = 1e-6  # they stop when no parameter moves more than this (relative)


@dataclass
class MemorySolution:
    """One iteration over the memory: the new separated vector and its information."""

    theta: FloatArray
    unit_covariance: FloatArray  # (Phi^T Phi + R_0 + prior)^-1
    sigma2: float  # residual variance of the memory's rows (NaN when too few)
    rows: int  # rows used


def solve_memory(
    structure: Structure,
    theta: FloatArray,
    rows: FloatArray,
    pull: FloatArray,
    prior: SeedPrior | None,
    weights: FloatArray | None,
    input_range: tuple[float, float],
) -> MemorySolution | str:
    """One iteration of the paper's method over the memory, from ``theta``.

    ``(Phi^T Phi + R_0 + W) theta_new = Phi^T z + R_0 theta + W theta_seed`` with the
    rows of eqs. (22)/(32) evaluated at ``theta`` (eqs. 25-28, 34) and ``W`` the seed's
    information weighted by what the memory has not refilled (``weights``, per parameter;
    needed with a ``prior``). The new iterate must be a valid model on ``input_range``, the
    input range seen; otherwise, why not.
    """
    try:
        p = structure.from_theta(theta)  # eq. (34)
    except GenBacklashError as err:
        return str(err)
    phi, target, _, _, _ = memory_regression(structure, p, rows)
    info = phi.T @ phi + pull
    rhs = phi.T @ target + pull @ theta
    weight = 0.0
    if prior is not None:
        assert weights is not None  # (the caller's contract)
        w = weights
        root = np.sqrt(w)
        seeded = prior.information * np.outer(root, root)
        info = info + seeded
        rhs = rhs + seeded @ prior.theta
        weight = float(np.mean(w))
    unit = scaled_inverse(info)
    if unit is None:
        return "the information matrix is singular"
    new = np.asarray(unit @ rhs, dtype=np.float64)  # eqs. (23)/(33) by least squares
    if not np.all(np.isfinite(new)):
        return "the estimate became non-finite"
    try:
        p_new = structure.from_theta(new)  # eq. (34)
    except GenBacklashError as err:
        return str(err)
    problem = structure.problem(p_new, input_range)
    if problem is not None:
        return problem
    error = target - phi @ new  # eqs. (29)/(37)
    rss = float(error @ error)
    count = float(target.size)
    if prior is not None and weight > 0.0:  # pooled with the rows the seed stands for
        # (as the windowed fits pool theirs, fits.fit_window; the weight here is the mean of
        # the per-branch ones, since this memory forgets by branch, not by window)
        rss += weight * prior.rows * prior.sigma2
        count += weight * prior.rows
    size = structure.n_parameters
    sigma2 = rss / (count - size) if count > size else math.nan
    return MemorySolution(new, unit, sigma2, int(target.size))


def settle_memory(
    structure: Structure,
    p: FloatArray,
    rows: FloatArray,
    covariance_bound: float,
    input_range: tuple[float, float],
) -> tuple[MemorySolution, FloatArray] | str:
    """Iterate from a batch fit over the memory until settled; the solution and its
    pull ``R_0`` (the information then over ``covariance_bound``). ``rows``: the memory's
    (:func:`~genbacklash_core.online.rows.memory_regression`); ``input_range``: the input
    range seen (the iterates must be valid models on it)."""
    if rows.shape[0] == 0:
        return "no rows in the memory"
    theta = structure.theta(p)  # eq. (34) inverted
    phi, _, _, _, _ = memory_regression(structure, p, rows)
    pull = (phi.T @ phi) / covariance_bound
    found: MemorySolution | None = None
    for _ in range(_INIT_ITERATIONS):
        step = solve_memory(structure, theta, rows, pull, None, None, input_range)
        if isinstance(step, str):
            if found is None:
                return step
            break
        change = np.max(np.abs(step.theta - theta))
        theta, found = step.theta, step
        if change <= _INIT_TOL * max(1.0, float(np.max(np.abs(theta)))):
            break
    assert found is not None
    if not math.isfinite(found.sigma2):
        return f"only {found.rows} informative rows for {structure.n_parameters} parameters"
    return found, pull


class Iterate:
    """The recursive identifier's current estimate and how it was reached.

    ``theta`` (eqs. 23/33), its unit covariance ``(Phi^T Phi + R_0 + W)^-1``, the residual
    variance ``sigma2`` (NaN until known), the pull ``R_0`` and a seed's prior ``W`` (until
    the memory has refilled), the last valid ``theta``, the iterations not taken in a row
    and why (``note``), and a ``version`` bumped whenever the estimate changes.

    Parameters
    ----------
    size : int
        Parameters of the separated vector.
    """

    def __init__(self, size: int) -> None:
        self.theta = np.zeros(size)
        self.last_valid = self.theta.copy()
        self.unit_cov = np.eye(size)
        self.sigma2 = math.nan
        self.pull = np.zeros((size, size))  # R_0, towards the current estimate
        self.prior: SeedPrior | None = None  # a seed's information, fading as rows come
        self.version = 0
        self.invalid = 0  # consecutive iterations not taken
        self.note = ""  # why the last iteration was not taken (the estimate held)
        self._summary: tuple[int, list[float], float] | None = None

    def seed(self, prior: SeedPrior, unit_cov: FloatArray, covariance_bound: float) -> None:
        """Start from a saved estimate's ``prior`` (``unit_cov``: its information's inverse)."""
        self.theta = prior.theta.copy()
        self.last_valid = prior.theta.copy()
        self.unit_cov = unit_cov
        self.sigma2 = prior.sigma2
        self.pull = prior.information / covariance_bound  # R_0: P <= bound * P_seed
        self.prior = prior
        self.version += 1

    def start(self, solution: MemorySolution, pull: FloatArray) -> None:
        """Start from a batch start's settled ``solution`` and its ``pull``."""
        self.prior = None
        self.pull = pull
        self.commit(solution)

    def commit(self, solution: MemorySolution) -> None:
        """Take an iterate as the current estimate."""
        self.theta = solution.theta
        self.unit_cov = solution.unit_covariance
        if math.isfinite(solution.sigma2):
            self.sigma2 = solution.sigma2
        self.last_valid = solution.theta.copy()
        self.invalid = 0
        self.note = ""
        self.version += 1

    def step(
        self, structure: Structure, memory: BinnedRows, input_range: tuple[float, float]
    ) -> str | None:
        """One iteration over ``memory`` (:func:`solve_memory`), the seed's prior weighted by
        what the memory has not refilled; taken, or why not (the estimate then holds)."""
        rows, _ = memory.rows()
        prior = self.prior
        weights = None if prior is None else prior_weights(structure, memory)
        if weights is not None and not np.any(weights > 0.0):
            self.prior = prior = weights = None  # the memory has refilled: the seed is gone
        step = solve_memory(structure, self.theta, rows, self.pull, prior, weights, input_range)
        if isinstance(step, str):
            self.invalid += 1
            self.note = f"the last iteration was not taken ({step})"
            return step
        self.commit(step)
        return None

    def restore(self, structure: Structure) -> None:
        """Go back to the last valid estimate if the current one was corrupted."""
        if theta_problem(structure, self.theta) is not None:
            self.theta = self.last_valid.copy()
        self.version += 1

    def summary(self, structure: Structure, sigma2: float) -> tuple[list[float], float]:
        """The natural parameters (eq. 34) and their largest relative standard deviation
        at residual variance ``sigma2``; computed once per version."""
        if self._summary is None or self._summary[0] != self.version:
            theta_list = self.theta.tolist()
            p_list = natural_from_theta(structure, theta_list)
            variances = natural_variances(structure, theta_list, sigma2 * self.unit_cov)
            self._summary = (self.version, p_list, relative_std_of(p_list, variances))
        return self._summary[1], self._summary[2]


def ewma(values: FloatArray, alpha: float, start: float) -> float:
    """The last of ``m(t) = m(t-1) + alpha (v(t) - m(t-1))`` from ``m = start``.

    >>> ewma(np.array([1.0, 1.0, 1.0]), 0.5, 0.0)
    0.875
    """
    n = values.size
    if n == 1:
        return start + alpha * (float(values[0]) - start)
    decay = 1.0 - alpha
    if n > 4096:  # the weights below would underflow long before; filter instead
        from scipy import signal  # here, not at the top: 0.5 s of import a backlash never needs

        out, _ = signal.lfilter([alpha], [1.0, -decay], values, zi=[decay * start])
        return float(out[-1])
    weights = alpha * decay ** np.arange(n - 1, -1, -1, dtype=np.float64)
    return float(start * decay**n + weights @ values)


def theta_problem(structure: Structure, theta: FloatArray) -> str | None:
    """The cheap validity checks of a separated vector ``theta`` (finite, slopes, dead
    zones), run before each block so that the identifier never iterates from a corrupted
    state. (The windowed fits check the natural parameters of their final iterate instead,
    :func:`~genbacklash_core.online.fits.fit_window`, before the full
    ``Structure.problem``; the recursive identifier has only ``theta`` at hand here.)

    >>> from genbacklash_core.structure import Structure
    >>> theta_problem(Structure(1), np.array([1.0, 0.1, 1.0, 0.1])) is None
    True
    >>> theta_problem(Structure(1), np.array([1.0, -0.1, 1.0, 0.1]))
    'a dead-zone constant became negative'
    """
    n = structure.degree
    s = structure.sign
    if not math.isfinite(float(theta.sum())):
        return "the estimate became non-finite"
    m_l1, m_r1 = float(theta[0]), float(theta[n + 1])
    if m_l1 * s <= 0.0 or m_r1 * s <= 0.0:
        return f"a branch slope changed sign (m_left_1={m_l1:.3g}, m_right_1={m_r1:.3g})"
    if theta[1] / m_l1 <= 0.0 or theta[n + 2] / m_r1 <= 0.0:
        return "a dead-zone constant became negative"
    return None
