"""Exact simulation of the general backlash and of the cascade (eqs. 8, 13, 20-21, 30).

Two forms of each: the fast vectorised one built on :func:`~genbacklash_core.play.play_operator`,
and the per-sample reference loop written straight from the paper's difference equations, which
the tests and benchmarks hold the fast form against.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._typing import ArrayLike, FloatArray
from .backlash import GeneralBacklash, branch_input, finite_branch
from .cascade import Cascade
from .data import as_real
from .errors import GenBacklashError
from .linear import simulate_linear
from .play import play_operator

__all__ = [
    "CascadeOutput",
    "simulate_backlash",
    "simulate_backlash_loop",
    "simulate_cascade",
    "simulate_cascade_loop",
    "switching_functions",
]


class CascadeOutput(NamedTuple):
    """Internal backlash output ``x`` and cascade output ``y``."""

    x: FloatArray
    y: FloatArray


def _as_input(u: ArrayLike) -> FloatArray:
    uu = branch_input(u)
    if uu.ndim != 1:
        raise GenBacklashError(f"the input must be one-dimensional, got shape {uu.shape}")
    return uu


def _check_model(model: object, kind: type[GeneralBacklash] | type[Cascade]) -> None:
    if not isinstance(model, kind):
        raise GenBacklashError(f"model must be a {kind.__name__}, got {type(model).__name__}")


def _finite_output(values: FloatArray, what: str) -> FloatArray:
    if not np.all(np.isfinite(values)):
        raise GenBacklashError(
            f"the {what} overflows float64: the model cannot be simulated on this input "
            "(rescale the input, or check the model)"
        )
    return values


def play_bounds(left: FloatArray, right: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Clamp bounds of the play operator from the branch values at each sample.

    Increasing branches have ``R <= L`` (``lo = R``, ``hi = L``), decreasing ones the reverse;
    taking the pointwise min/max covers both senses with one rule.
    """
    return np.minimum(left, right), np.maximum(left, right)


def simulate_backlash(model: GeneralBacklash, u: ArrayLike, x0: float = 0.0) -> FloatArray:
    """Output of the general backlash (eqs. 8, 13, 20) for input ``u``.

    Parameters
    ----------
    model : GeneralBacklash
    u : array_like, shape (N,)
    x0 : float
        Output before the first sample, ``x(-1)``.

    Examples
    --------
    >>> bl = GeneralBacklash.ideal(1.0, 0.5, 0.5)
    >>> simulate_backlash(bl, [0.0, 1.0, 0.8, 0.0, -1.0]).tolist()
    [0.0, 0.5, 0.5, 0.5, -0.5]
    """
    _check_model(model, GeneralBacklash)
    uu = _as_input(u)
    start = as_real("x0", x0)
    left, right = model.left(uu), model.right(uu)
    for name, values in (("left", left), ("right", right)):
        finite_branch(name, values, uu)
    return play_operator(*play_bounds(left, right), start)


def switching_functions(
    model: GeneralBacklash, u: FloatArray, x_prev: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Switching functions ``f1, f2`` (eqs. 18-19, 27-28) as 0/1 floats.

    The test is taken relative to the branch slope sign so that it holds for decreasing
    branches too, as eqs. (5)-(6) do by dividing by the slope (GUIDE §2):
    ``f1 = h((L(u) - x(t-1)) * sign(m_1))``, ``f2 = h((x(t-1) - R(u)) * sign(m_1))``.
    """
    s = model.sign
    f1 = (model.left(u) - x_prev) * s <= 0.0  # eq. (18) with h of eq. (4)
    f2 = (x_prev - model.right(u)) * s <= 0.0  # eq. (19)
    return f1.astype(np.float64), f2.astype(np.float64)


def simulate_backlash_loop(model: GeneralBacklash, u: ArrayLike, x0: float = 0.0) -> FloatArray:
    """Per-sample reference loop of eqs. (16)-(20), written as a user would write it."""
    _check_model(model, GeneralBacklash)
    uu = _as_input(u)
    m_left, m_right = model.m_left, model.m_right
    c_left, c_right, s = model.c_left, model.c_right, model.sign
    out = np.empty(uu.size)
    x_prev = as_real("x0", x0)
    # numpy scalars as a user would index them (the benchmarks' reference speed); an
    # overflow gives inf (no warning) and is reported below
    with np.errstate(over="ignore", invalid="ignore"):
        for t in range(uu.size):
            xi1 = uu[t] + c_left  # eq. (16)
            xi2 = uu[t] - c_right  # eq. (17)
            left = sum(m * xi1**i for i, m in enumerate(m_left, 1))  # eq. (11)
            right = sum(m * xi2**i for i, m in enumerate(m_right, 1))  # eq. (12)
            f1 = 1.0 if (left - x_prev) * s <= 0.0 else 0.0  # eq. (18)
            f2 = 1.0 if (x_prev - right) * s <= 0.0 else 0.0  # eq. (19)
            x_prev = left * f1 + right * f2 + x_prev * (1.0 - f1) * (1.0 - f2)  # eq. (20)
            out[t] = x_prev
    return _finite_output(out, "backlash output")


def simulate_cascade(model: Cascade, u: ArrayLike, x0: float = 0.0) -> CascadeOutput:
    """Cascade output (eqs. 20, 30); the linear block starts from rest.

    Examples
    --------
    >>> from genbacklash_core import LinearBlock
    >>> model = Cascade(GeneralBacklash.ideal(1.0, 0.5, 0.5), LinearBlock(a=(1.0,)))
    >>> simulate_cascade(model, [1.0, 1.0, 0.0]).y.tolist()
    [0.0, 0.5, 0.5]
    """
    _check_model(model, Cascade)
    x = simulate_backlash(model.backlash, u, x0)
    return CascadeOutput(x, simulate_linear(model.linear, x))


def simulate_cascade_loop(model: Cascade, u: ArrayLike, x0: float = 0.0) -> CascadeOutput:
    """Per-sample reference loop of eqs. (20) and (30)."""
    _check_model(model, Cascade)
    x = simulate_backlash_loop(model.backlash, u, x0)
    a, b = model.linear.a, model.linear.b
    y = np.zeros(x.size)
    with np.errstate(over="ignore", invalid="ignore"):  # checked below
        for t in range(x.size):
            acc = 0.0
            for i, ai in enumerate(a, 1):
                if t - i >= 0:
                    acc += ai * x[t - i]  # eq. (30), input terms
            for j, bj in enumerate(b, 1):
                if t - j >= 0:
                    acc -= bj * y[t - j]  # eq. (30), output terms
            y[t] = acc
    return CascadeOutput(x, _finite_output(y, "linear block's output"))
