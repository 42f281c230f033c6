"""What a drivetrain's physics does after the play: the load's own motion.

The paper's backlash (eqs. 8, 13, 20) is the limit of a stiff drivetrain whose load has so
much friction that it stops the moment the driving flank stops: the load position is the
play operator ``x(t) = clamp(x(t-1), lo(t), hi(t))`` on the branch values ``lo = min(L(v),
R(v))``, ``hi = max(L(v), R(v))`` (eqs. 11-12 on the gear's input ``v``). Three physical
effects break that limit, each a :class:`LoadPhysics` that replaces the play operator by a
recursion on the same bounds (all quantities per sample; the model has no clock):

``coasting_load``
    A load with little friction keeps moving when the flank that pushed it slows down: free
    of both flanks it moves on with velocity ``w``, which friction shrinks each sample,
    ``w <- sign(w) max(retention |w| - friction, 0)`` (viscous and Coulomb deceleration),
    until it stops or meets a flank (an inelastic contact: it then moves with that flank at the
    flank's mean velocity over ``window`` samples, so a held, stepwise command still gives a
    velocity). ``retention = 0`` is the play operator exactly. Where the simulation restarts
    at a reading (an *anchor*, after lost readings: the bounds are pinned to it) the load
    takes that position and keeps its velocity: a reading says where the load is, not how
    fast it moves. (Treated as a flank, the anchor gave the load the velocity of the jump
    onto the reading, the model's own error over ``window`` samples; on the coasting physics
    drivetrain behind a 100 Hz servo, with the motor's true position as the gear's input,
    that left a validation misfit of 0.028, the play operator's, and keeping the velocity
    0.020.)
``compliant_coupling``
    A spring after the play: the load ``z`` is pulled towards the interval ``[lo, hi]`` by
    ``stiffness^2 (clamp(z, lo, hi) - z)`` and the spring's damping ``2 damping stiffness``
    acts while it is deflected; free of both flanks it coasts as above. A stiff spring with
    ``retention = 0`` is the play operator. At an anchor the load likewise takes the reading
    as its position and keeps its velocity, slowed as a free load's (the pinned bounds are
    no flank to be deflected from: read as one, they pulled the load towards the reading and
    left it with the spring's reply to the model's own error, a ``coasting_load``-like jolt
    every restart that took compliant drivetrains' records to ``coasting_load`` once the
    coasting load kept its velocity).
``load_torque``
    A torque on the load (gravity, a process force) that beats the load's friction over part
    of the travel, ``region = (z_1, z_2)``: there the load rests on one flank (``side`` -1:
    the lower bound ``lo``, +1: ``hi``) whichever way the gear turns, falling towards it by at
    most ``fall`` per sample. Outside the region the play operator holds.

The recursions are sequential and nonlinear (a contact is a switch), so they run as plain
loops over Python floats (about 2-4 microseconds a sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError

__all__ = ["PHYSICS_NAMES", "LoadPhysics", "PhysicsKind"]

PhysicsKind = Literal["coasting_load", "compliant_coupling", "load_torque"]
PHYSICS_NAMES: tuple[PhysicsKind, ...] = ("coasting_load", "compliant_coupling", "load_torque")
MAX_STIFFNESS = 1.8  # rad per sample: the semi-implicit Euler step is stable below 2


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
        raise GenBacklashError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise GenBacklashError(f"{name} must be finite, got {value}")
    return float(value)


@dataclass(frozen=True)
class LoadPhysics:
    """The load's motion after the play (see the module notes).

    Parameters
    ----------
    kind : {"coasting_load", "compliant_coupling", "load_torque"}
        Which effect; also its catalog name.
    retention : float
        Share of its velocity the free load keeps each sample, in ``[0, 1]``.
    friction : float
        Coulomb deceleration of the free load, output units per sample squared, ``>= 0``.
    window : int
        Samples over which a flank's velocity is averaged (the command's hold length).
    stiffness : float
        ``compliant_coupling``: the spring's natural frequency, rad per sample, in ``(0, 1.8]``.
    damping : float
        ``compliant_coupling``: its damping ratio, ``>= 0``.
    side : int
        ``load_torque``: -1 when the torque holds the load on ``lo``, +1 on ``hi``.
    region : tuple of float
        ``load_torque``: the load positions ``(z_1, z_2)`` where it does.
    fall : float
        ``load_torque``: most the load moves towards that flank per sample, ``> 0``.

    Examples
    --------
    >>> lo, hi = np.array([0.0, 1.0, 1.0, 1.0]), np.array([0.5, 1.5, 1.5, 1.5])
    >>> LoadPhysics("coasting_load").simulate(lo, hi, 0.0).tolist()  # the play operator
    [0.0, 1.0, 1.0, 1.0]
    >>> LoadPhysics("coasting_load", retention=1.0, window=1).simulate(lo, hi, 0.0).tolist()
    [0.0, 1.0, 1.5, 1.5]
    >>> LoadPhysics("load_torque", side=1, region=(-5.0, 5.0), fall=1.0).simulate(lo, hi, 0.0)
    array([0.5, 1.5, 1.5, 1.5])
    """

    kind: PhysicsKind
    retention: float = 0.0
    friction: float = 0.0
    window: int = 1
    stiffness: float = MAX_STIFFNESS
    damping: float = 1.0
    side: int = -1
    region: tuple[float, float] = (0.0, 0.0)
    fall: float = math.inf

    def __post_init__(self) -> None:
        if self.kind not in PHYSICS_NAMES:
            raise GenBacklashError(
                f"unknown load physics {self.kind!r}; choose from {', '.join(PHYSICS_NAMES)}"
            )
        retention = _number("retention", self.retention)
        if not 0.0 <= retention <= 1.0:
            raise GenBacklashError(f"retention must be in [0, 1], got {retention}")
        object.__setattr__(self, "retention", retention)
        friction = _number("friction", self.friction)
        if friction < 0.0:
            raise GenBacklashError(f"friction must be >= 0, got {friction}")
        object.__setattr__(self, "friction", friction)
        if isinstance(self.window, bool) or not isinstance(self.window, (int, np.integer)):
            raise GenBacklashError(f"window must be a whole number, got {self.window!r}")
        if self.window < 1:
            raise GenBacklashError(f"window must be >= 1 sample, got {self.window}")
        object.__setattr__(self, "window", int(self.window))
        stiffness = _number("stiffness", self.stiffness)
        if not 0.0 < stiffness <= MAX_STIFFNESS:
            raise GenBacklashError(f"stiffness must be in (0, {MAX_STIFFNESS}], got {stiffness}")
        object.__setattr__(self, "stiffness", stiffness)
        damping = _number("damping", self.damping)
        if damping < 0.0:
            raise GenBacklashError(f"damping must be >= 0, got {damping}")
        object.__setattr__(self, "damping", damping)
        if self.side not in (-1, 1):
            raise GenBacklashError(f"side must be -1 or +1, got {self.side!r}")
        low, high = (_number("region", r) for r in self.region)
        if not low <= high:
            raise GenBacklashError(f"the region must be ordered, got ({low}, {high})")
        object.__setattr__(self, "region", (low, high))
        fall = self.fall
        if isinstance(fall, bool) or not isinstance(fall, (int, float, np.floating)):
            raise GenBacklashError(f"fall must be a number, got {fall!r}")
        if not float(fall) > 0.0 or math.isnan(fall):
            raise GenBacklashError(f"fall must be > 0, got {fall}")
        object.__setattr__(self, "fall", float(fall))

    @property
    def n_free(self) -> int:
        """Fitted parameters, for information criteria (the window is read off the data, the
        side is a choice of two: counted as one)."""
        return {"coasting_load": 2, "compliant_coupling": 4, "load_torque": 4}[self.kind]

    def simulate(
        self, lo: FloatArray, hi: FloatArray, x0: float, anchors: BoolArray | None = None
    ) -> FloatArray:
        """The load position for the flank bounds ``lo <= hi`` (eq. 20's interval), from
        ``x0`` at rest.

        ``anchors`` marks the samples where the simulation restarts at a reading, to which
        the caller has pinned ``lo == hi``: the coasting load and the spring's load take
        that position and keep their velocity (module notes). The torque's load has none to
        keep: eq. (20)'s clamp onto the pinned bounds is its restart.
        """
        pinned = None if anchors is None else np.asarray(anchors, dtype=bool).tolist()
        if self.kind == "coasting_load":
            return _coast(lo, hi, x0, (self.retention, self.friction, self.window), pinned)
        if self.kind == "compliant_coupling":
            return _spring(
                lo,
                hi,
                x0,
                (self.stiffness, self.damping, self.retention, self.friction),
                pinned,
            )
        return _torque(lo, hi, x0, self.side, self.region, self.fall)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (only the parameters of its kind)."""
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind in ("coasting_load", "compliant_coupling"):
            out.update(retention=self.retention, friction=self.friction, window=self.window)
        if self.kind == "compliant_coupling":
            out.update(stiffness=self.stiffness, damping=self.damping)
        if self.kind == "load_torque":
            out.update(side=self.side, region=list(self.region), fall=self.fall)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LoadPhysics:
        """The inverse of :meth:`to_dict`."""
        values = dict(data)
        if "region" in values:
            values["region"] = tuple(values["region"])
        return cls(**values)


def _coast(
    lo: FloatArray,
    hi: FloatArray,
    x0: float,
    parameters: tuple[float, float, int],
    anchors: list[bool] | None,
) -> FloatArray:
    """``coasting_load`` (module notes)."""
    retention, friction, window = parameters
    low, high = lo.tolist(), hi.tolist()
    n = len(low)
    out = [0.0] * n
    x, w = x0, 0.0
    for t in range(n):
        speed = retention * abs(w) - friction  # friction acts first: retention 0 is eq. (20)
        w = 0.0 if speed <= 0.0 else (speed if w > 0.0 else -speed)
        if anchors is not None and anchors[t]:
            x = out[t] = low[t]  # restarted at the reading; the velocity carries on
            continue
        free = x + w
        bottom, top = low[t], high[t]
        if free < bottom or free > top:
            x = bottom if free < bottom else top  # contact: move with the flank
            w = (x - (out[t - window] if t >= window else x0)) / window
        else:
            x = free
        out[t] = x
    return np.asarray(out, dtype=np.float64)


def _spring(
    lo: FloatArray,
    hi: FloatArray,
    x0: float,
    parameters: tuple[float, float, float, float],
    anchors: list[bool] | None,
) -> FloatArray:
    """``compliant_coupling`` (module notes), semi-implicit Euler."""
    stiffness, damping, retention, friction = parameters
    k = stiffness * stiffness
    c = 2.0 * damping * stiffness
    low, high = lo.tolist(), hi.tolist()
    n = len(low)
    out = [0.0] * n
    z, w = x0, 0.0
    for t in range(n):
        bottom, top = low[t], high[t]
        anchored = anchors is not None and anchors[t]  # then bottom == top: the reading
        if not anchored and (z < bottom or z > top):
            deflection = (bottom if z < bottom else top) - z
            w += k * deflection - c * w
        else:
            speed = retention * abs(w) - friction
            w = 0.0 if speed <= 0.0 else (speed if w > 0.0 else -speed)
        z = bottom if anchored else z + w  # restarted at the reading, the velocity kept
        out[t] = z
    return np.asarray(out, dtype=np.float64)


def _torque(
    lo: FloatArray,
    hi: FloatArray,
    x0: float,
    side: int,
    region: tuple[float, float],
    fall: float,
) -> FloatArray:
    """``load_torque`` (module notes)."""
    low, high = lo.tolist(), hi.tolist()
    z1, z2 = region
    n = len(low)
    out = [0.0] * n
    x = x0
    for t in range(n):
        bottom, top = low[t], high[t]
        x = bottom if x < bottom else top if x > top else x  # eq. (20)
        if z1 <= x <= z2:
            target = bottom if side < 0 else top
            step = target - x
            x = target if abs(step) <= fall else x + math.copysign(fall, step)
        out[t] = x
    return np.asarray(out, dtype=np.float64)
