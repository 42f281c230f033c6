"""The linear dynamic block that follows the backlash in a cascade (paper §4, eq. 30).

``y(t) = sum_{i=1}^{r} a_i x(t-i) - sum_{j=1}^{p} b_j y(t-j)`` with ``a_1 = 1``: the key-term
normalisation that makes the cascade identifiable (the gain belongs to the backlash).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._typing import ArrayLike, FloatArray
from .data import as_float_array
from .errors import GenBacklashError, NonFiniteInputError

__all__ = ["LinearBlock", "simulate_linear"]


@dataclass(frozen=True)
class LinearBlock:
    """Difference equation (30) with ``a = (1, a_2, .., a_r)`` and ``b = (b_1, .., b_p)``.

    Examples
    --------
    The block of the paper's Examples 3 and 4,
    ``y(t) = x(t-1) + 0.15 x(t-2) + 0.2 y(t-1) - 0.35 y(t-2)``:

    >>> block = LinearBlock(a=(1.0, 0.15), b=(-0.2, 0.35))
    >>> block.na, block.nb, block.stable
    (2, 2, True)
    >>> round(block.dc_gain, 6)
    1.0
    """

    a: tuple[float, ...]
    b: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        a, b = _coefficients("a", self.a), _coefficients("b", self.b)
        if not a:
            raise GenBacklashError("a needs at least a_1 (na >= 1)")
        if a[0] != 1.0:
            raise GenBacklashError(
                f"a_1 must be 1 (key-term normalisation, eq. 31), got {a[0]}; "
                "scale the backlash by a_1 instead"
            )
        if not all(math.isfinite(v) for v in (*a, *b)):
            raise GenBacklashError(f"coefficients must be finite, got a={a}, b={b}")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)

    @property
    def na(self) -> int:
        """``r``: number of ``a`` coefficients, ``a_1`` included."""
        return len(self.a)

    @property
    def nb(self) -> int:
        """``p``: number of ``b`` coefficients."""
        return len(self.b)

    @property
    def numerator(self) -> FloatArray:
        """Transfer-function numerator in powers of ``q^-1``: ``[0, a_1, .., a_r]``."""
        return np.array([0.0, *self.a])

    @property
    def denominator(self) -> FloatArray:
        """Transfer-function denominator in powers of ``q^-1``: ``[1, b_1, .., b_p]``."""
        return np.array([1.0, *self.b])

    @property
    def stable(self) -> bool:
        """True when every pole lies strictly inside the unit circle."""
        return denominator_is_stable(self.denominator)

    @property
    def dc_gain(self) -> float:
        """Steady-state gain ``sum a / (1 + sum b)`` (inf for a pole at 1)."""
        den = 1.0 + sum(self.b)
        return math.inf if den == 0.0 else sum(self.a) / den

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the free parameters ``a_2..a_r, b_1..b_p``."""
        return (
            *(f"a_{i}" for i in range(2, self.na + 1)),
            *(f"b_{j}" for j in range(1, self.nb + 1)),
        )

    def parameters(self) -> FloatArray:
        """Free parameters ``[a_2..a_r, b_1..b_p]`` (``a_1 = 1`` is fixed)."""
        return np.array([*self.a[1:], *self.b])

    def simulate(self, x: ArrayLike) -> FloatArray:
        """Output of eq. (30) from rest; see :func:`simulate_linear`."""
        return simulate_linear(self, x)


def _coefficients(name: str, values: object) -> tuple[float, ...]:
    array = as_float_array(name, values)
    if array.ndim != 1:
        raise GenBacklashError(f"{name} must be a sequence of numbers, got {values!r}")
    return tuple(array.tolist())


def denominator_is_stable(denominator: FloatArray) -> bool:
    """True when the polynomial ``[1, b_1..b_p]`` in ``q^-1`` has all roots inside |z| < 1."""
    if len(denominator) <= 1:
        return True
    poles = np.roots(denominator)
    return bool(np.all(np.abs(poles) < 1.0 - 1e-9))


def simulate_linear(block: LinearBlock, x: ArrayLike) -> FloatArray:
    """Simulate eq. (30) from rest (``x(t) = y(t) = 0`` for ``t < 0``).

    >>> simulate_linear(LinearBlock(a=(1.0,), b=(-0.5,)), [1.0, 0.0, 0.0]).tolist()
    [0.0, 1.0, 0.5]
    """
    if not isinstance(block, LinearBlock):
        raise GenBacklashError(f"block must be a LinearBlock, got {type(block).__name__}")
    xx = as_float_array("x", x)
    if xx.ndim != 1:
        raise GenBacklashError(f"x must be one-dimensional, got shape {xx.shape}")
    if not np.all(np.isfinite(xx)):
        raise NonFiniteInputError("the input of the linear block holds NaN or infinite samples")
    if xx.size == 0:
        return np.zeros(0)
    from scipy import signal  # here, not at the top: 0.5 s of import a backlash never needs

    y = np.asarray(signal.lfilter(block.numerator, block.denominator, xx), dtype=np.float64)
    if not np.all(np.isfinite(y)):
        raise GenBacklashError(
            "the linear block's output overflows float64"
            + (" (the block is unstable)" if not block.stable else "")
            + ": rescale the input, or check the block"
        )
    return y
