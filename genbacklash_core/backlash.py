"""The general backlash: polynomial up and down branches around a dead zone (paper §3a).

A general backlash maps an input ``u(t)`` to an output ``x(t)`` (eq. 8): on the left branch
``L(u) = sum_i m_Li (u + c_L)^i`` (eq. 11), on the right branch
``R(u) = sum_i m_Ri (u - c_R)^i`` (eq. 12), and in between it holds its previous output.
Degree 1 is the ideal backlash of eqs. (1)/(7).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import Polynomial

from ._typing import ArrayLike, FloatArray
from .errors import GenBacklashError

__all__ = ["GeneralBacklash"]


def _as_coefficients(name: str, values: object) -> tuple[float, ...]:
    try:
        coefficients = tuple(float(v) for v in np.atleast_1d(np.asarray(values, dtype=float)))
    except (TypeError, ValueError) as err:
        raise GenBacklashError(f"{name} must be a sequence of numbers, got {values!r}") from err
    if not coefficients:
        raise GenBacklashError(f"{name} must hold at least one coefficient (degree >= 1)")
    if not all(math.isfinite(c) for c in coefficients):
        raise GenBacklashError(f"{name} must be finite, got {coefficients}")
    return coefficients


def evaluate_branch(m: FloatArray, shifted: FloatArray) -> FloatArray:
    """Evaluate ``sum_i m[i-1] * shifted**i`` by Horner's rule (eqs. 11-12).

    Parameters
    ----------
    m : ndarray
        Coefficients ``m_1 .. m_n``.
    shifted : ndarray
        ``u + c_L`` for the left branch (eq. 16) or ``u - c_R`` for the right (eq. 17).
    """
    coefficients = np.asarray(m, dtype=np.float64).tolist()  # Python floats: cheaper scalars
    acc = shifted * coefficients[-1]
    for coefficient in coefficients[-2::-1]:
        acc += coefficient
        acc *= shifted
    return np.asarray(acc, dtype=np.float64)


@dataclass(frozen=True)
class GeneralBacklash:
    """A general backlash with polynomial branches of degree ``n`` (eqs. 11-13).

    Parameters
    ----------
    m_left : sequence of float
        ``m_L1 .. m_Ln``, the left (upper for increasing branches) polynomial.
    c_left : float
        ``c_L > 0``, where the left branch crosses the u axis at ``u = -c_L``.
    m_right : sequence of float
        ``m_R1 .. m_Rn``, the right polynomial; same degree as the left.
    c_right : float
        ``c_R > 0``, where the right branch crosses the u axis at ``u = c_R``.

    Examples
    --------
    The paper's Example 1:

    >>> bl = GeneralBacklash((0.5, -0.3, 0.3), 0.7, (0.6, 0.4, 0.2), 0.8)
    >>> bl.degree, bl.increasing
    (3, True)
    >>> round(float(bl.left(np.array([0.0]))[0]), 6)  # L(0) = 0.5*0.7 - 0.3*0.7**2 + 0.3*0.7**3
    0.3059
    >>> bl.branches_separated(-2.0, 2.0)
    True
    """

    m_left: tuple[float, ...]
    c_left: float
    m_right: tuple[float, ...]
    c_right: float
    _m_left_array: FloatArray = field(init=False, repr=False, compare=False)
    _m_right_array: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        m_left = _as_coefficients("m_left", self.m_left)
        m_right = _as_coefficients("m_right", self.m_right)
        if len(m_left) != len(m_right):
            raise GenBacklashError(
                f"both branches need the same degree: m_left has {len(m_left)} "
                f"coefficients, m_right {len(m_right)}"
            )
        for name, value in (("c_left", self.c_left), ("c_right", self.c_right)):
            real = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
            if not (real and math.isfinite(value)):
                raise GenBacklashError(f"{name} must be a finite number, got {value!r}")
            if value <= 0:
                raise GenBacklashError(f"{name} must be > 0 (a dead-zone width), got {value}")
        if m_left[0] == 0.0 or m_right[0] == 0.0:
            raise GenBacklashError(
                f"m_left[0] and m_right[0] must be nonzero, got {m_left[0]} and {m_right[0]}"
            )
        if (m_left[0] > 0) != (m_right[0] > 0):
            raise GenBacklashError(
                "both branches must have the same monotonic sense: m_left[0]="
                f"{m_left[0]} and m_right[0]={m_right[0]} have different signs"
            )
        object.__setattr__(self, "m_left", m_left)
        object.__setattr__(self, "m_right", m_right)
        object.__setattr__(self, "c_left", float(self.c_left))
        object.__setattr__(self, "c_right", float(self.c_right))
        object.__setattr__(self, "_m_left_array", np.asarray(m_left, dtype=np.float64))
        object.__setattr__(self, "_m_right_array", np.asarray(m_right, dtype=np.float64))

    @classmethod
    def ideal(cls, slope: float, c_left: float, c_right: float) -> GeneralBacklash:
        """The ideal backlash of eq. (1): straight branches with one slope.

        >>> GeneralBacklash.ideal(1.0, 0.1, 0.2).degree
        1
        """
        return cls((slope,), c_left, (slope,), c_right)

    @property
    def degree(self) -> int:
        """Polynomial degree ``n`` of each branch."""
        return len(self.m_left)

    @property
    def increasing(self) -> bool:
        """True when the branches increase with ``u`` (``m_1 > 0``)."""
        return self.m_left[0] > 0

    @property
    def sign(self) -> float:
        """``+1.0`` for increasing branches, ``-1.0`` for decreasing ones."""
        return 1.0 if self.increasing else -1.0

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of :meth:`parameters` in order, as published on ``~/estimate``."""
        n = self.degree
        return (
            *(f"m_left_{i}" for i in range(1, n + 1)),
            "c_left",
            *(f"m_right_{i}" for i in range(1, n + 1)),
            "c_right",
        )

    def parameters(self) -> FloatArray:
        """Natural parameters ``[m_L1..m_Ln, c_L, m_R1..m_Rn, c_R]``."""
        return np.array([*self.m_left, self.c_left, *self.m_right, self.c_right])

    @classmethod
    def from_parameters(cls, values: ArrayLike, degree: int) -> GeneralBacklash:
        """Inverse of :meth:`parameters`."""
        p = np.asarray(values, dtype=float)
        n = degree
        if p.shape != (2 * n + 2,):
            raise GenBacklashError(f"expected {2 * n + 2} parameters for degree {n}, got {p.shape}")
        return cls(tuple(p[:n]), float(p[n]), tuple(p[n + 1 : 2 * n + 1]), float(p[2 * n + 1]))

    def theta(self) -> FloatArray:
        """The separated parameter vector of eq. (23).

        ``[m_L1, m_L1*c_L, m_L2..m_Ln, m_R1, m_R1*c_R, m_R2..m_Rn]``.
        """
        ml, mr = self.m_left, self.m_right
        return np.array(
            [ml[0], ml[0] * self.c_left, *ml[1:], mr[0], mr[0] * self.c_right, *mr[1:]]
        )  # eq. (23)

    def left(self, u: ArrayLike) -> FloatArray:
        """Left branch ``L(u)`` (eq. 11)."""
        uu = np.asarray(u, dtype=np.float64)
        return evaluate_branch(self._m_left_array, uu + self.c_left)  # eqs. (11), (16)

    def right(self, u: ArrayLike) -> FloatArray:
        """Right branch ``R(u)`` (eq. 12)."""
        uu = np.asarray(u, dtype=np.float64)
        return evaluate_branch(self._m_right_array, uu - self.c_right)  # eqs. (12), (17)

    def branch_difference(self) -> Polynomial:
        """``L(u) - R(u)`` as a polynomial in ``u``."""
        left = sum(
            (m * Polynomial([self.c_left, 1.0]) ** i for i, m in enumerate(self.m_left, 1)),
            Polynomial([0.0]),
        )
        right = sum(
            (m * Polynomial([-self.c_right, 1.0]) ** i for i, m in enumerate(self.m_right, 1)),
            Polynomial([0.0]),
        )
        return left - right

    def crossings(self, u_min: float, u_max: float) -> tuple[float, ...]:
        """Inputs in ``[u_min, u_max]`` where the two branches meet or cross.

        The model is only a backlash where the branches stay apart (the paper's condition
        below eq. 21); an empty tuple means the model is valid on the whole range.
        """
        if not u_min < u_max:
            raise GenBacklashError(f"need u_min < u_max, got {u_min} and {u_max}")
        difference = self.branch_difference()
        found: list[float] = []
        coef = difference.coef
        if np.allclose(coef, 0.0):
            return (float(u_min),)
        for root in difference.roots():
            real, imag = float(np.real(root)), float(np.imag(root))
            if abs(imag) <= 1e-9 * max(1.0, abs(real)) and u_min <= real <= u_max:
                found.append(real)
        for end in (u_min, u_max):
            if difference(end) * self.sign <= 0.0 and end not in found:
                found.append(float(end))
        return tuple(sorted(found))

    def branches_separated(self, u_min: float, u_max: float) -> bool:
        """True when the branches neither touch nor cross on ``[u_min, u_max]``."""
        return not self.crossings(u_min, u_max)

    def simulate(self, u: ArrayLike, x0: float = 0.0) -> FloatArray:
        """Simulate the backlash output (eqs. 8, 13, 20); see :func:`simulate_backlash`."""
        from .simulate import simulate_backlash

        return simulate_backlash(self, u, x0)
