"""Model structure and the flat natural-parameter vector shared by the estimators.

The estimators work on a flat vector ``p`` of natural parameters,
``[m_L1..m_Ln, c_L, m_R1..m_Rn, c_R]`` followed for a cascade by ``[a_2..a_r, b_1..b_p]``,
and turn it into a validated model object only at the end.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ._typing import FloatArray
from .backlash import GeneralBacklash, evaluate_branch
from .cascade import Cascade
from .data import as_order
from .errors import GenBacklashError
from .linear import LinearBlock, denominator_is_stable

__all__ = ["Structure", "as_order"]

_CROSSING_GRID = 257  # input points at which branch separation is checked


@functools.lru_cache(maxsize=64)
def _crossing_grid(u_min: float, u_max: float) -> FloatArray:
    """Read-only input grid for the crossing check (cached: the estimators ask repeatedly)."""
    grid = np.linspace(u_min, u_max, _CROSSING_GRID)
    grid.flags.writeable = False
    return grid


@dataclass(frozen=True)
class Structure:
    """Degree ``n``, linear orders ``na`` (``r``) and ``nb`` (``p``), and the branch sense.

    ``na = 0`` means a backlash alone (no linear block).
    """

    degree: int
    na: int = 0
    nb: int = 0
    sign: float = 1.0

    def __post_init__(self) -> None:
        for name in ("degree", "na", "nb"):
            object.__setattr__(self, name, as_order(name, getattr(self, name)))
        if self.degree < 1:
            raise GenBacklashError(f"degree must be >= 1, got {self.degree}")
        if self.na < 0 or self.nb < 0:
            raise GenBacklashError(f"na and nb must be >= 0, got {self.na} and {self.nb}")
        if self.na == 0 and self.nb > 0:
            raise GenBacklashError("a linear block needs na >= 1 (a_1 = 1)")
        if self.sign not in (1.0, -1.0):
            raise GenBacklashError(f"sign must be +1 or -1, got {self.sign}")

    @classmethod
    def of(cls, model: GeneralBacklash | Cascade) -> Structure:
        """The structure of an existing model."""
        if isinstance(model, Cascade):
            bl = model.backlash
            return cls(bl.degree, model.linear.na, model.linear.nb, bl.sign)
        return cls(model.degree, 0, 0, model.sign)

    @property
    def cascade(self) -> bool:
        """True when a linear block follows the backlash."""
        return self.na > 0

    @property
    def n_backlash(self) -> int:
        """Number of backlash parameters, ``2n + 2``."""
        return 2 * self.degree + 2

    @property
    def n_parameters(self) -> int:
        """Length of the natural parameter vector."""
        return self.n_backlash + (self.na - 1 + self.nb if self.cascade else 0)

    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order."""
        n = self.degree
        names = [f"m_left_{i}" for i in range(1, n + 1)] + ["c_left"]
        names += [f"m_right_{i}" for i in range(1, n + 1)] + ["c_right"]
        if self.cascade:
            names += [f"a_{i}" for i in range(2, self.na + 1)]
            names += [f"b_{j}" for j in range(1, self.nb + 1)]
        return tuple(names)

    def start(self, c: float = 0.001) -> FloatArray:
        """The paper's start: ``m_1 = +/-1``, ``c = 0.001``, everything else zero (§3b, §4b)."""
        p = np.zeros(self.n_parameters)
        n = self.degree
        p[0] = self.sign
        p[n] = c
        p[n + 1] = self.sign
        p[2 * n + 1] = c
        return p

    def split(self, p: FloatArray) -> tuple[FloatArray, float, FloatArray, float]:
        """``(m_left, c_left, m_right, c_right)`` from a parameter vector."""
        n = self.degree
        return p[:n], float(p[n]), p[n + 1 : 2 * n + 1], float(p[2 * n + 1])

    def linear_part(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(a, b)`` with ``a_1 = 1`` from a parameter vector (cascade only)."""
        start = self.n_backlash
        a = np.concatenate([[1.0], p[start : start + self.na - 1]])
        b = p[start + self.na - 1 :]
        return a, b

    def branches(self, p: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Branch values ``L(u)``, ``R(u)`` (eqs. 11-12, 16-17)."""
        m_left, c_left, m_right, c_right = self.split(p)
        return evaluate_branch(m_left, u + c_left), evaluate_branch(m_right, u - c_right)

    def from_theta(self, theta: FloatArray) -> FloatArray:
        """Natural parameters from the separated vector of eqs. (23)/(33).

        ``c_L = theta_2 / theta_1`` and ``c_R`` likewise (eq. 34); raises when ``m_1`` vanishes.
        """
        n = self.degree
        m_l1, m_r1 = theta[0], theta[n + 1]
        if abs(m_l1) < 1e-12 or abs(m_r1) < 1e-12:
            raise GenBacklashError(
                f"the estimated slope m_1 vanished (m_left_1={m_l1:.3g}, m_right_1={m_r1:.3g})"
            )
        p = np.empty(self.n_parameters)
        p[0] = m_l1
        p[1:n] = theta[2 : n + 1]
        p[n] = theta[1] / m_l1  # eq. (34): c_L = c_1 / m_L1
        p[n + 1] = m_r1
        p[n + 2 : 2 * n + 1] = theta[n + 3 : 2 * n + 2]
        p[2 * n + 1] = theta[n + 2] / m_r1  # eq. (34): c_R = c_2 / m_R1
        p[2 * n + 2 :] = theta[2 * n + 2 :]
        return p

    def theta(self, p: FloatArray) -> FloatArray:
        """The separated vector of eqs. (23)/(33) from natural parameters (eq. 34 inverted)."""
        n = self.degree
        theta = np.empty(self.n_parameters)
        theta[0] = p[0]
        theta[1] = p[0] * p[n]  # eq. (23): m_L1 c_L
        theta[2 : n + 1] = p[1:n]
        theta[n + 1] = p[n + 1]
        theta[n + 2] = p[n + 1] * p[2 * n + 1]  # eq. (23): m_R1 c_R
        theta[n + 3 : 2 * n + 2] = p[n + 2 : 2 * n + 1]
        theta[2 * n + 2 :] = p[2 * n + 2 :]
        return theta

    def problem(self, p: FloatArray, u_range: tuple[float, float] | None = None) -> str | None:
        """Why ``p`` is not a valid model, or None when it is.

        With ``u_range`` the branches must also stay apart on that input range (the paper's
        condition below eq. 21): where they cross the model is no backlash.
        """
        if not np.isfinite(p).all():
            return "a parameter became non-finite"
        m_left, c_left, m_right, c_right = self.split(p)
        if m_left[0] * self.sign <= 0 or m_right[0] * self.sign <= 0:
            sense = "increasing" if self.sign > 0 else "decreasing"
            return (
                f"the branch slopes (m_left_1={m_left[0]:.3g}, m_right_1={m_right[0]:.3g}) "
                f"are not {sense} as the start assumed"
            )
        if c_left <= 0 or c_right <= 0:
            return (
                f"a dead-zone constant is not positive (c_left={c_left:.3g}, c_right={c_right:.3g})"
            )
        if u_range is not None:
            grid = _crossing_grid(float(u_range[0]), float(u_range[1]))
            left, right = self.branches(p, grid)
            if not (np.all(np.isfinite(left)) and np.all(np.isfinite(right))):
                return "the branches overflow float64 on the input range"
            with np.errstate(over="ignore"):  # an infinite difference still has its sign
                crossed = (left - right) * self.sign <= 0.0
            if crossed.any():
                where = grid[crossed]
                return (
                    f"the branches cross on the input range (u in [{where.min():.3g}, "
                    f"{where.max():.3g}])"
                )
        if self.cascade:
            _, b = self.linear_part(p)
            if not denominator_is_stable(np.concatenate([[1.0], b])):
                return f"the linear block is unstable (b={np.round(b, 4).tolist()})"
        return None

    def model(self, p: FloatArray) -> GeneralBacklash | Cascade:
        """The validated model object for ``p``."""
        m_left, c_left, m_right, c_right = self.split(p)
        backlash = GeneralBacklash(tuple(m_left), c_left, tuple(m_right), c_right)
        if not self.cascade:
            return backlash
        a, b = self.linear_part(p)
        return Cascade(backlash, LinearBlock(a=tuple(a), b=tuple(b)))
