"""A planned motion (:class:`Trajectory`): its commands at a rate, checked against the joint's
limits by finite differences.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.data import as_float_array, count_reversals
from genbacklash_core.errors import GenBacklashError

from .limits import MotionLimits, as_positive

_TOLERANCE = 1e-9  # relative tolerance of the limit checks (finite differences)


def _differences(u: FloatArray, rate: float) -> tuple[FloatArray, FloatArray]:
    """Velocity and acceleration by finite differences, the motion at rest before and after
    (the first and last command repeated)."""
    padded = np.concatenate([u[:1], u, u[-1:]])
    velocity = np.diff(padded) * rate
    acceleration = np.diff(padded, 2) * (rate * rate)
    return np.asarray(velocity, dtype=np.float64), np.asarray(acceleration, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Position commands at a fixed rate, checked against motion limits.

    Attributes
    ----------
    limits : MotionLimits
    command_rate : float
        Commands per second; command ``k`` is due at ``t = k / command_rate``.
    u : ndarray
        The commands (read-only), at least two. The motion starts and ends at rest: the
        finite differences are taken with the first and last command repeated.

    Raises
    ------
    GenBacklashError
        A command outside ``[low, high]``, or a finite-difference velocity or acceleration
        beyond ``v_max`` or ``a_max`` by more than ``1e-9`` of the limit.

    Examples
    --------
    >>> limits = MotionLimits(0.0, 1.0, v_max=1.0, a_max=100.0)
    >>> Trajectory(limits, 10.0, np.array([0.0, 0.05, 0.1, 0.1])).duration
    0.3
    >>> Trajectory(limits, 10.0, np.array([0.0, 0.5, 0.5]))
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: command 1 moves at 5 units/s; v_max is 1
    """

    limits: MotionLimits
    command_rate: float
    u: FloatArray = field(repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.limits, MotionLimits):
            raise GenBacklashError(f"limits must be MotionLimits, got {self.limits!r}")
        rate = as_positive("command_rate", self.command_rate)
        object.__setattr__(self, "command_rate", rate)
        u = np.array(as_float_array("u", self.u), dtype=np.float64)
        if u.ndim != 1 or u.size < 2:
            raise GenBacklashError(f"u must be one-dimensional with >= 2 commands, got {u.shape}")
        if not np.all(np.isfinite(u)):
            raise GenBacklashError("u holds NaN or infinite commands")
        lim = self.limits
        outside = np.flatnonzero((u < lim.low) | (u > lim.high))
        if outside.size:
            k = int(outside[0])
            raise GenBacklashError(
                f"command {k} ({u[k]:.6g}) lies outside the range [{lim.low:g}, {lim.high:g}]"
            )
        velocity, acceleration = _differences(u, rate)
        for name, values, limit, unit in (
            ("moves at", velocity, lim.v_max, "units/s"),
            ("accelerates at", acceleration, lim.a_max, "units/s^2"),
        ):
            k = int(np.argmax(np.abs(values)))
            if abs(values[k]) > limit * (1.0 + _TOLERANCE):
                limit_name = "v_max" if unit == "units/s" else "a_max"
                raise GenBacklashError(
                    f"command {k} {name} {abs(values[k]):.6g} {unit}; {limit_name} is {limit:g}"
                )
        u.flags.writeable = False
        object.__setattr__(self, "u", u)

    @property
    def t(self) -> FloatArray:
        """Times of the commands, seconds from the first."""
        return np.arange(self.u.size) / self.command_rate

    @property
    def duration(self) -> float:
        """Seconds from the first command to the last."""
        return (self.u.size - 1) / self.command_rate

    @property
    def reversals(self) -> int:
        """How often the motion changes direction."""
        return count_reversals(self.u)

    @property
    def velocity(self) -> FloatArray:
        """Finite-difference velocity between consecutive commands (and from/to rest)."""
        return _differences(self.u, self.command_rate)[0]

    @property
    def acceleration(self) -> FloatArray:
        """Finite-difference acceleration at each command (at rest before and after)."""
        return _differences(self.u, self.command_rate)[1]

    @property
    def peak_velocity(self) -> float:
        """Largest finite-difference speed."""
        return float(np.max(np.abs(self.velocity)))

    @property
    def peak_acceleration(self) -> float:
        """Largest finite-difference acceleration."""
        return float(np.max(np.abs(self.acceleration)))
