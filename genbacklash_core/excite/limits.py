"""What the joint may do (:class:`MotionLimits`), and the checks of the numbers the
commissioning functions take.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core.errors import GenBacklashError


def as_finite(name: str, value: object) -> float:
    """``value`` as a float; :class:`GenBacklashError` naming ``name`` unless it is a finite
    number (a bool is not one).

    >>> as_finite("rate", 100)
    100.0
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GenBacklashError(f"{name} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise GenBacklashError(f"{name} must be finite, got {value!r}")
    return out


def as_positive(name: str, value: object) -> float:
    """:func:`as_finite`, and above 0."""
    out = as_finite(name, value)
    if not out > 0.0:
        raise GenBacklashError(f"{name} must be > 0, got {value!r}")
    return out


def as_whole(name: str, value: object, low: int) -> int:
    """``value`` as an int; :class:`GenBacklashError` naming ``name`` unless it is a whole
    number (a bool is not one) of at least ``low``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise GenBacklashError(f"{name} must be a whole number >= {low}, got {value!r}")
    if int(value) < low:
        raise GenBacklashError(f"{name} must be a whole number >= {low}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class MotionLimits:
    """What the joint may do: its position range and its velocity and acceleration limits.

    Attributes
    ----------
    low, high : float
        Position range (the command's units, e.g. rad), ``low < high``.
    v_max : float
        Largest speed, units per second (> 0).
    a_max : float
        Largest acceleration, units per second squared (> 0).

    Examples
    --------
    >>> MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0).span
    2.4
    >>> MotionLimits(-1.2, 1.2, v_max=-3.0, a_max=30.0)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: v_max must be > 0, got -3.0
    """

    low: float
    high: float
    v_max: float
    a_max: float

    def __post_init__(self) -> None:
        low, high = as_finite("low", self.low), as_finite("high", self.high)
        if not low < high:
            raise GenBacklashError(
                f"the position range needs low < high, got low={low!r}, high={high!r}"
            )
        if not math.isfinite(high - low):
            raise GenBacklashError(f"the position range [{low:g}, {high:g}] is too wide")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)
        object.__setattr__(self, "v_max", as_positive("v_max", self.v_max))
        object.__setattr__(self, "a_max", as_positive("a_max", self.a_max))

    @property
    def span(self) -> float:
        """``high - low``."""
        return self.high - self.low
