"""The drivetrain as a MuJoCo model (MJCF): rotor, pin, slot, coupling, load, servo.

Every joint is a hinge about ``z``. The rotor carries a spherical pin of radius ``rho`` on
the circle of radius ``r``; the slot hub carries two walls (boxes) whose inner faces are
radial planes at the angles ``slot_offset -+ (play/2 + asin(rho/r))``: a sphere on that
circle touches such a plane when its angle from it is ``asin(rho/r)``, so the pin moves
``play`` between the walls, exactly. The pin and the walls are the only colliding geoms
(frictionless contact, ``condim=1``; stiff: ``solref = (contact_time, 1)``). The hub is the
load itself (rigid) or a body of its own with a spring joint to the load (compliant). The
load's Coulomb and viscous friction are the joint's ``frictionloss`` and ``damping``; the
dry friction is made stiff (``solreffriction = (contact_time, 1)``) and the no-slip solver
runs after each step (:data:`NOSLIP_ITERATIONS`), so that it sticks: without both, MuJoCo's
soft friction acts like a viscous damper at low speed (a slow push at 0.01 rad/s met 0.08 of
0.4 N m, and a load under half its friction torque crept). With
gravity the axis is horizontal (gravity along ``-y``) and the load's centre of mass sits at
:data:`~genbacklash_ros.physics.variants.COM_RADIUS` on its ``x`` axis, so gravity pulls it
with ``-m g l cos(q)``; without, the axis is vertical and nothing but the servo and friction
acts. Integration is ``implicitfast`` (the servo's damping and the joints' damping are taken
implicitly).

>>> text = mjcf(DrivetrainParameters("test", ""), timestep=2.5e-4)
>>> "frictionloss" in text and 'name="servo"' in text
True
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from genbacklash_ros.physics.variants import COM_RADIUS, GRAVITY, DrivetrainParameters

if TYPE_CHECKING:
    import mujoco

__all__ = ["JOINTS", "NOSLIP_ITERATIONS", "build_model", "mjcf"]

JOINTS = ("motor", "slot", "load")
"""Joint names: the rotor, the slot hub (the load itself when rigid) and the load."""
NOSLIP_ITERATIONS = 5
"""MuJoCo's no-slip passes: without them its soft dry friction creeps (a load under a
torque below ``frictionloss`` slides, and a slow push meets a fraction of the friction)."""
_WALL = (0.01, 0.003, 0.01)  # half sizes of a wall: radial, tangential, axial (m)


def _wall(name: str, angle: float, side: float, p: DrivetrainParameters) -> str:
    """A wall whose inner face is the radial plane at ``angle``; the box lies on ``side``
    (+1: towards larger angles)."""
    half_r, half_t, half_z = _WALL
    x = p.pin_circle * math.cos(angle) - side * half_t * math.sin(angle)
    y = p.pin_circle * math.sin(angle) + side * half_t * math.cos(angle)
    return (
        f'<geom name="{name}" type="box" size="{half_r} {half_t} {half_z}" '
        f'pos="{x!r} {y!r} 0" euler="0 0 {angle!r}" contype="2" conaffinity="1" '
        f'condim="1" solref="{p.contact_time!r} 1" solimp="0.95 0.99 0.0001"/>'
    )


def mjcf(p: DrivetrainParameters, *, timestep: float) -> str:
    """The MJCF text of drivetrain ``p`` integrated every ``timestep`` seconds."""
    kp, kv = p.servo_gains()
    half = p.play / 2.0 + math.asin(p.pin_radius / p.pin_circle)  # eq. in the module notes
    gravity = f"0 {-GRAVITY!r} 0" if p.gravity_torque > 0.0 else f"0 0 {-GRAVITY!r}"
    walls = _wall("wall_low", p.slot_offset - half, -1.0, p) + _wall(
        "wall_high", p.slot_offset + half, 1.0, p
    )
    load_joint = (
        f'<joint name="{{name}}" type="hinge" axis="0 0 1" frictionloss="{p.load_friction!r}" '
        f'damping="{p.load_damping!r}" solreffriction="{p.contact_time!r} 1"/>'
    )
    if p.gravity_torque > 0.0:
        m = p.com_mass
        rest = p.load_inertia - m * COM_RADIUS**2  # about the centre of mass
        load_inertial = (
            f'<inertial pos="{COM_RADIUS!r} 0 0" mass="{m!r}" '
            f'diaginertia="{rest!r} {rest!r} {rest!r}"/>'
        )
    else:
        j = p.load_inertia
        load_inertial = f'<inertial pos="0 0 0" mass="1" diaginertia="{j!r} {j!r} {j!r}"/>'
    if p.rigid:
        hub = f'<body name="slot">{load_joint.format(name="slot")}{load_inertial}{walls}</body>'
    else:
        j = p.hub_inertia
        hub = (
            f'<body name="slot"><joint name="slot" type="hinge" axis="0 0 1"/>'
            f'<inertial pos="0 0 0" mass="0.1" diaginertia="{j!r} {j!r} {j!r}"/>{walls}'
            f'<body name="load"><joint name="load" type="hinge" axis="0 0 1" '
            f'stiffness="{p.coupling_stiffness!r}" damping="{p.coupling_damping!r}"/>'
            f"{load_inertial}</body></body>"
        )
    # the coupling's joint is relative to the hub; the load's friction acts on the load's
    # absolute angle, which a child joint cannot carry: a rigid load takes it on "slot", a
    # compliant one through the tendon below (slot + load angle)
    friction = ""
    if not p.rigid:
        friction = (
            f'<tendon><fixed name="load_angle" frictionloss="{p.load_friction!r}" '
            f'damping="{p.load_damping!r}" solreffriction="{p.contact_time!r} 1">'
            f'<joint joint="slot" coef="1"/>'
            f'<joint joint="load" coef="1"/></fixed></tendon>'
        )
    return f"""<mujoco model="genbacklash_{p.name}">
  <compiler angle="radian"/>
  <option timestep="{timestep!r}" integrator="implicitfast" gravity="{gravity}"
          noslip_iterations="{NOSLIP_ITERATIONS}"/>
  <worldbody>
    <body name="rotor">
      <joint name="motor" type="hinge" axis="0 0 1" armature="{p.motor_inertia!r}"
             damping="{p.motor_damping!r}"/>
      <inertial pos="0 0 0" mass="1e-6" diaginertia="1e-12 1e-12 1e-12"/>
      <geom name="pin" type="sphere" size="{p.pin_radius!r}" pos="{p.pin_circle!r} 0 0"
            contype="1" conaffinity="2" condim="1" solref="{p.contact_time!r} 1"
            solimp="0.95 0.99 0.0001"/>
    </body>
    {hub}
  </worldbody>
  {friction}
  <actuator>
    <position name="servo" joint="motor" kp="{kp!r}" kv="{kv!r}" forcelimited="true"
              forcerange="{-p.torque_limit!r} {p.torque_limit!r}"/>
  </actuator>
</mujoco>
"""


def build_model(p: DrivetrainParameters, *, timestep: float) -> mujoco.MjModel:
    """Compile :func:`mjcf` (needs ``mujoco``)."""
    import mujoco

    return mujoco.MjModel.from_xml_string(mjcf(p, timestep=timestep))
