"""Physics drivetrains for tests and benchmarks (issue 23): MuJoCo's rigid-body mechanics.

A position servo drives a rotor whose pin sits in a slot of the load (the play, as
contact); the load has inertia, Coulomb and viscous friction, optionally a compliant
coupling after the play or gravity. Needs ``mujoco`` (``pip install 'genbacklash[physics]'``);
this package imports it only where a model is built or stepped.

* :mod:`~genbacklash_ros.physics.variants`: the parameters, :data:`VARIANTS` by name;
* :mod:`~genbacklash_ros.physics.model`: the MJCF model;
* :mod:`~genbacklash_ros.physics.engine`: stepping it with held commands (the closed-loop API);
* :mod:`~genbacklash_ros.physics.truth`: the geometric play and the quasi-static sweep;
* :mod:`~genbacklash_ros.physics.record`: the operation scenario's motion, clocks and encoder
  on the physics;
* :mod:`~genbacklash_ros.physics.bag`: a record as a bag, with its truth.
"""

from __future__ import annotations

from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.engine import (
    DEFAULT_RATE,
    Drivetrain,
    Trajectory,
    simulate_commands,
)
from genbacklash_ros.physics.record import PhysicsRecord, physics_record
from genbacklash_ros.physics.truth import QuasiStatic, quasi_static
from genbacklash_ros.physics.variants import (
    VARIANTS,
    DrivetrainParameters,
    variant,
)

__all__ = [
    "DEFAULT_RATE",
    "VARIANTS",
    "Drivetrain",
    "DrivetrainParameters",
    "PhysicsRecord",
    "QuasiStatic",
    "Trajectory",
    "physics_record",
    "quasi_static",
    "simulate_commands",
    "variant",
    "write_physics_bag",
]

MISSING = "the physics drivetrains need mujoco: pip install 'genbacklash[physics]'"
"""The one-line reason the command line gives when ``mujoco`` does not import."""


def require_mujoco() -> None:
    """Raise :class:`~genbacklash_core.GenBacklashError` with :data:`MISSING` when
    ``mujoco`` does not import."""
    from genbacklash_core import GenBacklashError

    try:
        import mujoco  # noqa: F401
    except ImportError as err:
        raise GenBacklashError(MISSING) from err
