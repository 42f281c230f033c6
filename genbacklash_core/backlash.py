"""The general backlash: polynomial up and down branches around a dead zone (paper §3a).

A general backlash maps an input ``u(t)`` to an output ``x(t)`` (eq. 8): on the left branch
``L(u) = sum_i m_Li (u + c_L)^i`` (eq. 11), on the right branch
``R(u) = sum_i m_Ri (u - c_R)^i`` (eq. 12), and in between it holds its previous output.
Degree 1 is the ideal backlash of eqs. (1)/(7).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.polynomial import Polynomial

from ._typing import ArrayLike, FloatArray
from .data import as_float_array, as_order, as_real
from .errors import GenBacklashError, NonFiniteInputError

__all__ = ["GeneralBacklash"]


def _as_coefficients(name: str, values: object) -> tuple[float, ...]:
    try:
        array = as_float_array(name, values)
    except GenBacklashError as err:
        raise GenBacklashError(f"{name} must be a sequence of numbers, got {values!r}") from err
    if array.ndim > 1:
        raise GenBacklashError(f"{name} must be a sequence of numbers, got shape {array.shape}")
    coefficients = tuple(np.atleast_1d(array).tolist())
    if not coefficients:
        raise GenBacklashError(f"{name} must hold at least one coefficient (degree >= 1)")
    if not all(math.isfinite(c) for c in coefficients):
        raise GenBacklashError(f"{name} must be finite, got {coefficients}")
    return coefficients


def _dead_zone(name: str, value: object) -> float:
    try:
        return as_real(name, value)
    except GenBacklashError as err:
        raise GenBacklashError(f"{name} must be a finite number, got {value!r}") from err


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
    # Beyond the float range the value saturates to +-inf (finite input and coefficients give
    # no NaN); callers check what must be finite.
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(_horner(coefficients, shifted), dtype=np.float64)


def _horner(m: Sequence[float], shifted: Any) -> Any:
    """``sum_i m[i-1] * shifted**i`` by Horner's rule (eqs. 11-12), for a float or an array
    (every branch evaluation takes these operations, so that all give the same bits)."""
    acc = shifted * m[-1]
    for coefficient in m[-2::-1]:
        acc += coefficient
        acc *= shifted
    return acc


def branch_input(u: ArrayLike) -> FloatArray:
    """``u`` as a float array of finite samples, or a clear error."""
    uu = as_float_array("u", u)
    if not np.all(np.isfinite(uu)):
        bad = int(np.count_nonzero(~np.isfinite(uu)))
        raise NonFiniteInputError(
            f"{bad} of {uu.size} input samples are NaN or infinite; clean the input first"
        )
    return uu


def finite_branch(name: str, values: FloatArray, u: FloatArray) -> FloatArray:
    """``values`` of a branch at ``u``, or an error when they overflowed float64."""
    if not np.all(np.isfinite(values)):
        largest = float(np.max(np.abs(u))) if u.size else 0.0
        raise GenBacklashError(
            f"the {name} branch overflows float64 for inputs up to |u| = {largest:.3g}; the "
            "model cannot be evaluated there: rescale the input (e.g. to radians or metres)"
        )
    return values


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
        c_left, c_right = _dead_zone("c_left", self.c_left), _dead_zone("c_right", self.c_right)
        for name, value in (("c_left", c_left), ("c_right", c_right)):
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
        object.__setattr__(self, "c_left", c_left)
        object.__setattr__(self, "c_right", c_right)
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
        p = as_float_array("values", values)
        n = as_order("degree", degree)
        if n < 1:
            raise GenBacklashError(f"degree must be >= 1, got {n}")
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

    def branches_at(self, u: float) -> tuple[float, float]:
        """``(L(u), R(u))`` at one finite input, in Python floats (eqs. 11-12, 16-17): what
        :meth:`left` and :meth:`right` give for ``[u]``, without arrays for a single value.

        >>> GeneralBacklash.ideal(1.0, 0.1, 0.2).branches_at(1.0)
        (1.1, 0.8)
        """
        left = _horner(self.m_left, u + self.c_left)  # eqs. (11), (16)
        right = _horner(self.m_right, u - self.c_right)  # eqs. (12), (17)
        return float(left), float(right)

    def branches(self, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(L(u), R(u))`` of a float64 array in one step, exactly as :meth:`left` and
        :meth:`right` give them, without their input checks: for a caller whose inputs are
        finite already (NaN or inf in ``u`` give NaN or inf, not an error).

        >>> GeneralBacklash.ideal(1.0, 0.1, 0.2).branches(np.array([1.0, 2.0]))
        (array([1.1, 2.1]), array([0.8, 1.8]))
        """
        with np.errstate(over="ignore", invalid="ignore"):
            left = _horner(self.m_left, u + self.c_left)  # eqs. (11), (16)
            right = _horner(self.m_right, u - self.c_right)  # eqs. (12), (17)
        return left, right

    def left(self, u: ArrayLike) -> FloatArray:
        """Left branch ``L(u)`` (eq. 11); ``+-inf`` where it exceeds the float range.

        Raises :class:`~genbacklash_core.errors.NonFiniteInputError` for NaN/inf input.
        """
        uu = branch_input(u)
        with np.errstate(over="ignore"):  # a huge |u + c_L| saturates to +-inf below
            return evaluate_branch(self._m_left_array, uu + self.c_left)  # eqs. (11), (16)

    def right(self, u: ArrayLike) -> FloatArray:
        """Right branch ``R(u)`` (eq. 12); ``+-inf`` where it exceeds the float range.

        Raises :class:`~genbacklash_core.errors.NonFiniteInputError` for NaN/inf input.
        """
        uu = branch_input(u)
        with np.errstate(over="ignore"):
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
        u_min, u_max = as_real("u_min", u_min), as_real("u_max", u_max)
        if not u_min < u_max:
            raise GenBacklashError(f"need u_min < u_max, got {u_min} and {u_max}")
        with np.errstate(all="ignore"):  # overflow is checked below
            difference = self.branch_difference()
            coef = difference.coef
            at_ends = [float(difference(end)) for end in (u_min, u_max)]
            # coefficients too small to divide by (the companion matrix) cannot place a root
            # where the polynomial is still finite: leave them out of the root search
            trimmed = difference.trim(1e-290 * float(np.max(np.abs(coef))))
            try:
                roots = trimmed.roots() if trimmed.degree() > 0 else np.zeros(0)
            except np.linalg.LinAlgError:
                roots = np.full(1, np.nan)
        if not (np.all(np.isfinite(coef)) and np.all(np.isfinite(roots))):
            raise GenBacklashError(
                "cannot locate where the branches cross: L(u) - R(u) overflows float64 "
                "(the coefficients are too large or span too many orders of magnitude)"
            )
        if not all(math.isfinite(v) for v in at_ends):
            raise GenBacklashError(
                f"the branches overflow float64 on [{u_min:.3g}, {u_max:.3g}]; cannot compare "
                "them there: use a narrower range"
            )
        found: list[float] = []
        if np.allclose(coef, 0.0):
            return (u_min,)
        for root in roots:
            real, imag = float(np.real(root)), float(np.imag(root))
            if abs(imag) <= 1e-9 * max(1.0, abs(real)) and u_min <= real <= u_max:
                found.append(real)
        for end, value in zip((u_min, u_max), at_ends, strict=True):
            if value * self.sign <= 0.0 and end not in found:
                found.append(end)
        return tuple(sorted(found))

    def branches_separated(self, u_min: float, u_max: float) -> bool:
        """True when the branches neither touch nor cross on ``[u_min, u_max]``."""
        return not self.crossings(u_min, u_max)

    def simulate(self, u: ArrayLike, x0: float = 0.0) -> FloatArray:
        """Simulate the backlash output (eqs. 8, 13, 20); see :func:`simulate_backlash`."""
        from .simulate import simulate_backlash

        return simulate_backlash(self, u, x0)
