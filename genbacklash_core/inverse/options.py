"""The compensator's options (limits, smoothing, confidence gating, the inversion range)
and the checks of its arguments.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from genbacklash_core.errors import GenBacklashError
from genbacklash_core.structure import as_order


def real_number(name: str, value: object) -> float:
    """``value`` as a float that is not NaN, else a one-line error that names ``name``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise GenBacklashError(f"{name} must be a real number, got {value!r}")
    result = float(value)
    if math.isnan(result):
        raise GenBacklashError(f"{name} must not be NaN")
    return result


@dataclass(frozen=True)
class CompensatorOptions:
    """Limits, smoothing, gating and the inversion range of the compensator.

    Parameters
    ----------
    u_min, u_max : float
        Output limits; every command lies in ``[u_min, u_max]``. Default unlimited.
    max_rate : float
        Largest ``|u(t) - u(t-1)|`` per sample, ``> 0``. Default unlimited.
    smoothing : int
        Number of samples over which the jump across the gap at a reversal is spread;
        ``0`` jumps at once. During the ramp the command still follows the path, then it is
        the exact inverse again.
    gate_low, gate_high : float
        Confidence thresholds in ``[0, 1]``, ``gate_low <= gate_high``. The correction weight
        is ``w = clip((confidence - gate_low) / (gate_high - gate_low), 0, 1)`` (``w = 1`` when
        ``confidence >= gate_high``) and the command ``u = x_d + w (u_inverse - x_d)``: at
        ``w = 0`` the compensator passes ``x_d`` through. A NaN confidence counts as ``0``.
        The defaults (0.2, 0.5) match :attr:`Estimate.confidence <genbacklash_core.Estimate>`:
        full correction once an online estimate has converged (confidence >= 0.5), a fade
        while it converges, pass-through while it warms up or diverged (confidence 0).
    valid_range : (float, float) or None
        Input interval on which the model is trusted and its branches are inverted; ``None``
        uses the output limits. It is intersected with ``[u_min, u_max]``.

    Examples
    --------
    >>> options = CompensatorOptions(u_min=-2.0, u_max=2.0, gate_low=0.5, gate_high=1.0)
    >>> options.inversion_range
    (-2.0, 2.0)
    >>> options.weight(0.75), options.weight(0.2), options.weight(float("nan"))
    (0.5, 0.0, 0.0)
    """

    u_min: float = -math.inf
    u_max: float = math.inf
    max_rate: float = math.inf
    smoothing: int = 0
    gate_low: float = 0.2
    gate_high: float = 0.5
    valid_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        u_min, u_max = real_number("u_min", self.u_min), real_number("u_max", self.u_max)
        if not u_min < u_max:
            raise GenBacklashError(f"need u_min < u_max, got u_min={u_min} and u_max={u_max}")
        max_rate = real_number("max_rate", self.max_rate)
        if not max_rate > 0:
            raise GenBacklashError(f"max_rate must be > 0, got {max_rate}")
        smoothing = as_order("smoothing", self.smoothing)
        if smoothing < 0:
            raise GenBacklashError(f"smoothing must be >= 0 samples, got {smoothing}")
        gate_low, gate_high = (
            real_number("gate_low", self.gate_low),
            real_number("gate_high", self.gate_high),
        )
        if not (0.0 <= gate_low <= 1.0 and 0.0 <= gate_high <= 1.0):
            raise GenBacklashError(
                f"gate_low and gate_high must lie in [0, 1], got {gate_low} and {gate_high}"
            )
        if gate_low > gate_high:
            raise GenBacklashError(
                f"need gate_low <= gate_high, got gate_low={gate_low} and gate_high={gate_high}"
            )
        valid_range = self.valid_range
        if valid_range is not None:
            try:
                low_raw, high_raw = valid_range
            except (TypeError, ValueError) as err:
                raise GenBacklashError(
                    f"valid_range must be a pair (low, high), got {valid_range!r}"
                ) from err
            low, high = (
                real_number("valid_range[0]", low_raw),
                real_number("valid_range[1]", high_raw),
            )
            if not low < high:
                raise GenBacklashError(f"valid_range needs low < high, got ({low}, {high})")
            if not (low < u_max and high > u_min):
                raise GenBacklashError(
                    f"valid_range ({low}, {high}) does not overlap the output limits "
                    f"[{u_min}, {u_max}]"
                )
            valid_range = (low, high)
        object.__setattr__(self, "u_min", u_min)
        object.__setattr__(self, "u_max", u_max)
        object.__setattr__(self, "max_rate", max_rate)
        object.__setattr__(self, "smoothing", smoothing)
        object.__setattr__(self, "gate_low", gate_low)
        object.__setattr__(self, "gate_high", gate_high)
        object.__setattr__(self, "valid_range", valid_range)

    @property
    def inversion_range(self) -> tuple[float, float]:
        """The input interval on which the branches are inverted (valid range within limits)."""
        if self.valid_range is None:
            return self.u_min, self.u_max
        return max(self.valid_range[0], self.u_min), min(self.valid_range[1], self.u_max)

    def weight(self, confidence: float) -> float:
        """Correction weight ``w`` in ``[0, 1]`` for a model confidence (NaN counts as 0)."""
        c = float(confidence)
        if not c == c:  # NaN: untrusted
            return 0.0
        if c >= self.gate_high:
            return 1.0
        if c <= self.gate_low:
            return 0.0
        return (c - self.gate_low) / (self.gate_high - self.gate_low)


DEFAULT_OPTIONS = CompensatorOptions()


def as_options(options: object) -> CompensatorOptions:
    if not isinstance(options, CompensatorOptions):
        raise GenBacklashError(f"options must be CompensatorOptions, got {options!r}")
    return options
