"""The physics drivetrains' parameters: one frozen dataclass, four named variants.

A drivetrain (all angles in radians at the load; the gear ratio is folded into the motor
side, so the motor position is in load radians):

    command (held) -> position servo (PD, bandwidth, torque limit) -> motor rotor
    -> pin in a slot (the play, as contact) -> slot hub [-> spring coupling] -> load
    (inertia, Coulomb + viscous friction [, gravity])

The servo is MuJoCo's position actuator, ``tau = clip(kp (command - q_m) - kv dq_m,
+-torque_limit)``, tuned critically damped on the engaged inertia ``J = J_m + J_hub + J_L``:
``omega_n = 2 pi bandwidth / 0.6436`` (the -3 dB frequency of ``omega_n^2 / (s +
omega_n)^2`` is ``0.6436 omega_n``), ``kp = J omega_n^2``, ``kv = 2 J omega_n``.

The variants (:data:`VARIANTS`; 4 deg of play, ``c_L`` 32.4 mrad, ``c_R`` 37.4 mrad, servo
60 Hz and 10 N m unless changed):

========== ====== ====== ======= ======== ======== ======= ==========================
variant    J_m    J_L    Coulomb viscous  coupling gravity what it shows
           kg m2  kg m2  N m     N m s/r  N m/rad  N m
========== ====== ====== ======= ======== ======== ======= ==========================
near_ideal 2e-3   2e-4   0.4     0.02     rigid    0       friction stops the load at
                                                           once: the play operator on
                                                           the motor position
coasting   2e-3   2e-3   0.01    0.001    rigid    0       the load coasts across the
                                                           play when the motor slows
compliant  2e-3   1e-3   0.02    0.005    20       0       a 22 Hz ring after the play
           (hub 1e-4, coupling damping 0.01 N m s/rad)
gravity    2e-3   1e-3   0.1     0.01     rigid    0.12    gravity holds the load on
                                                           one flank where |q| < 0.59
========== ====== ====== ======= ======== ======== ======= ==========================

Examples
--------
>>> p = variant("near_ideal")
>>> round(p.play, 5), round(p.c_left, 5), round(p.c_right, 5)
(0.06981, 0.03241, 0.03741)
>>> kp, kv = variant("coasting", bandwidth=20.0).servo_gains()
>>> round(kp, 1), round(kv, 4)
(152.5, 1.562)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from genbacklash_core import GenBacklashError

__all__ = [
    "BANDWIDTH_RANGE",
    "DEFAULT_BANDWIDTH",
    "VARIANTS",
    "DrivetrainParameters",
    "variant",
]

DEFAULT_BANDWIDTH = 60.0
BANDWIDTH_RANGE = (5.0, 200.0)
"""Accepted servo bandwidths, Hz (the issue's drivetrains run 20-100 Hz)."""
GRAVITY = 9.81
COM_RADIUS = 0.05  # m: where the load's centre of mass sits off the axis (gravity variant)
_CRITICAL_3DB = 0.6436  # -3 dB frequency of a critically damped 2nd-order loop / omega_n


@dataclass(frozen=True)
class DrivetrainParameters:
    """One physics drivetrain (see the module notes). SI units, angles in load radians.

    Attributes
    ----------
    name, description : str
    play : float
        Geometric play at the load: the slot's angular width minus the pin's, rad.
    slot_offset : float
        Angle of the slot's centre from the pin with motor and load both at 0, rad; the
        geometric dead zones are ``c_left = play/2 - slot_offset``, ``c_right = play/2 +
        slot_offset`` (the project's :class:`~genbacklash_core.GeneralBacklash` convention:
        going up the load trails the motor by ``c_right``).
    motor_inertia : float
        Rotor inertia (reflected to the load side), kg m^2.
    motor_damping : float
        Viscous friction at the rotor, N m s/rad.
    load_inertia : float
        Load inertia about the axis, kg m^2 (its centre of mass included).
    load_friction : float
        Coulomb friction torque on the load, N m (MuJoCo's joint ``frictionloss``).
    load_damping : float
        Viscous friction on the load, N m s/rad.
    coupling_stiffness : float
        Torsional spring between the slot hub and the load, N m/rad; 0: the slot is cut in
        the load itself (rigid).
    coupling_damping : float
        Damping of that spring, N m s/rad.
    hub_inertia : float
        Inertia of the slot hub when there is a coupling, kg m^2.
    gravity_torque : float
        ``m g l`` of the load: gravity pulls it with ``-m g l cos(q)`` (axis horizontal),
        N m; 0: the axis is vertical.
    bandwidth : float
        Servo bandwidth (-3 dB, load engaged), Hz.
    torque_limit : float
        Servo torque limit, N m.
    pin_radius, pin_circle : float
        The pin (a sphere) and the circle it rides on, m.
    contact_time : float
        MuJoCo contact time constant (``solref[0]``), s: >= 2 simulation steps.
    """

    name: str
    description: str
    play: float = math.radians(4.0)
    slot_offset: float = 0.0025
    motor_inertia: float = 2e-3
    motor_damping: float = 1e-3
    load_inertia: float = 2e-4
    load_friction: float = 0.4
    load_damping: float = 0.02
    coupling_stiffness: float = 0.0
    coupling_damping: float = 0.0
    hub_inertia: float = 1e-4
    gravity_torque: float = 0.0
    bandwidth: float = DEFAULT_BANDWIDTH
    torque_limit: float = 10.0
    pin_radius: float = 0.004
    pin_circle: float = 0.03
    contact_time: float = 5e-4

    def __post_init__(self) -> None:
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if item.type == "str":
                continue
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise GenBacklashError(f"{item.name} must be a finite number, got {value!r}")
        positive = ("play", "motor_inertia", "load_inertia", "hub_inertia", "torque_limit")
        for name in (*positive, "pin_radius", "pin_circle", "contact_time"):
            if not getattr(self, name) > 0.0:
                raise GenBacklashError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in (
            "motor_damping",
            "load_friction",
            "load_damping",
            "coupling_stiffness",
            "coupling_damping",
            "gravity_torque",
        ):
            if not getattr(self, name) >= 0.0:
                raise GenBacklashError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        low, high = BANDWIDTH_RANGE
        if not low <= self.bandwidth <= high:
            raise GenBacklashError(
                f"bandwidth must lie in [{low:g}, {high:g}] Hz, got {self.bandwidth:g}"
            )
        if not abs(self.slot_offset) < self.play / 2.0:
            raise GenBacklashError("slot_offset must leave both dead zones > 0")
        if not self.pin_radius < 0.2 * self.pin_circle:
            raise GenBacklashError("pin_radius must be < 0.2 pin_circle")
        if self.play / 2.0 + math.asin(self.pin_radius / self.pin_circle) > 0.5:
            raise GenBacklashError(f"play {self.play:g} rad is too wide for this slot")
        if self.gravity_torque > 0.0 and not self.load_inertia > self.com_mass * COM_RADIUS**2:
            raise GenBacklashError(
                f"load_inertia {self.load_inertia:g} is below the centre of mass's own "
                f"m l^2 = {self.com_mass * COM_RADIUS**2:g} for gravity_torque "
                f"{self.gravity_torque:g}"
            )

    @property
    def c_left(self) -> float:
        """Geometric dead zone of the left (downward) branch, rad."""
        return self.play / 2.0 - self.slot_offset

    @property
    def c_right(self) -> float:
        """Geometric dead zone of the right (upward) branch, rad."""
        return self.play / 2.0 + self.slot_offset

    @property
    def rigid(self) -> bool:
        """No spring between the slot and the load."""
        return self.coupling_stiffness == 0.0

    @property
    def engaged_inertia(self) -> float:
        """What the servo moves with the play closed, kg m^2."""
        hub = 0.0 if self.rigid else self.hub_inertia
        return self.motor_inertia + hub + self.load_inertia

    @property
    def com_mass(self) -> float:
        """Mass at :data:`COM_RADIUS` that gives :attr:`gravity_torque`, kg."""
        return self.gravity_torque / (GRAVITY * COM_RADIUS)

    def servo_gains(self) -> tuple[float, float]:
        """``(kp, kv)`` of the position actuator (N m/rad, N m s/rad): critically damped on
        the engaged inertia, -3 dB at :attr:`bandwidth`."""
        omega = 2.0 * math.pi * self.bandwidth / _CRITICAL_3DB
        j = self.engaged_inertia
        return j * omega * omega, 2.0 * j * omega

    def with_bandwidth(self, bandwidth: float) -> DrivetrainParameters:
        """The same drivetrain with another servo bandwidth, Hz."""
        return dataclasses.replace(self, bandwidth=float(bandwidth))

    def to_dict(self) -> dict[str, Any]:
        """Every parameter, the geometric dead zones and the servo gains (JSON values)."""
        out: dict[str, Any] = dataclasses.asdict(self)
        kp, kv = self.servo_gains()
        out.update(c_left=self.c_left, c_right=self.c_right, servo_kp=kp, servo_kv=kv)
        return out


VARIANTS: dict[str, DrivetrainParameters] = {
    "near_ideal": DrivetrainParameters(
        "near_ideal",
        "stiff, frictional load (Coulomb 0.4 N m on 2e-4 kg m^2): the load stops with the motor",
    ),
    "coasting": DrivetrainParameters(
        "coasting",
        "a load with little friction (0.01 N m on 2e-3 kg m^2) that coasts into the play when "
        "the motor slows or stops",
        load_inertia=2e-3,
        load_friction=0.01,
        load_damping=1e-3,
    ),
    "compliant": DrivetrainParameters(
        "compliant",
        "a compliant coupling after the play (20 N m/rad to 1e-3 kg m^2: rings at ~22 Hz)",
        load_inertia=1e-3,
        load_friction=0.02,
        load_damping=0.005,
        coupling_stiffness=20.0,
        coupling_damping=0.01,
    ),
    "gravity": DrivetrainParameters(
        "gravity",
        "gravity on the load (m g l 0.12 N m against 0.1 N m of friction): the load rests on "
        "the lower flank where |q| < 0.59 rad",
        load_inertia=1e-3,
        load_friction=0.1,
        load_damping=0.01,
        gravity_torque=0.12,
    ),
}
"""The named drivetrains (see the module notes)."""


def variant(name: str, *, bandwidth: float | None = None) -> DrivetrainParameters:
    """The variant ``name`` of :data:`VARIANTS`, with another servo ``bandwidth`` (Hz) if
    given; :class:`~genbacklash_core.GenBacklashError` for an unknown name."""
    try:
        params = VARIANTS[name]
    except KeyError:
        raise GenBacklashError(
            f"unknown physics variant {name!r}; choose from {', '.join(VARIANTS)}"
        ) from None
    return params if bandwidth is None else params.with_bandwidth(bandwidth)
