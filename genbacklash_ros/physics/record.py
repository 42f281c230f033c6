"""A physics drivetrain in operation: the operation scenario's motion and clocks, MuJoCo's
mechanics.

:func:`physics_record` draws exactly what :func:`~genbacklash_core.scenarios.operation_record`
draws for the same seed and settings (the motion of
:func:`~genbacklash_core.scenarios.operation_commands`, the clocks of
:func:`~genbacklash_core.scenarios.timeline`, the encoder of
:func:`~genbacklash_core.scenarios.readings`: 100 Hz held commands with jitter, trapezoidal
moves, dwells and jogs; a 1 kHz load encoder quantised to ``counts_per_rev`` with stamp
jitter and losses), but the load is what the simulator makes of the commands
(:mod:`genbacklash_ros.physics.engine`) instead of the play operator on the held command. The
encoder reads the load at its (jittered) sampling instants, interpolated between the
simulator's steps. A motor encoder reads the rotor at the same instants with its own losses
(the same quantisation; its random draws come from a stream of their own, so the load
encoder's readings do not change with it).

Examples
--------
>>> from genbacklash_core.scenarios import OperationSettings
>>> from genbacklash_ros.physics.variants import variant
>>> rec = physics_record(variant("near_ideal"), OperationSettings(duration=1.0), seed=1)
>>> rec.command_t_ns.size, rec.sample_t_ns.size
(100, 1000)
>>> bool(rec.trajectory.t_ns[-1] >= rec.sample_t_ns[-1])  # 4 kHz steps past the last reading
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_core.scenarios import (
    OperationSettings,
    operation_commands,
    readings,
    timeline,
)
from genbacklash_ros.physics.engine import DEFAULT_RATE, Drivetrain, Trajectory
from genbacklash_ros.physics.variants import DrivetrainParameters

__all__ = ["PhysicsRecord", "physics_record"]


@dataclass(frozen=True, eq=False)
class PhysicsRecord:
    """A simulated record (see the module notes).

    Attributes
    ----------
    params : DrivetrainParameters
    settings : OperationSettings
        The motion, clocks and encoder (its ``model`` is not used: the physics is the model).
    seed : int
    command_t_ns, command_u : ndarray
        Command stamps (ns from the start) and values, rad.
    sample_t_ns : ndarray of int
        Every encoder sampling instant, lost readings included.
    u_all : ndarray
        The held command at each sampling instant.
    motor_all, x_all : ndarray
        The rotor and the load angles at each instant.
    y_all, received : ndarray
        The load encoder's readings and which of them arrive.
    motor_y, motor_received : ndarray
        The motor encoder's readings and which of them arrive.
    trajectory : Trajectory
        Every simulator step.
    phase_starts : tuple of (str, float)
    """

    params: DrivetrainParameters
    settings: OperationSettings
    seed: int
    command_t_ns: np.ndarray
    command_u: np.ndarray
    sample_t_ns: np.ndarray
    u_all: np.ndarray
    motor_all: np.ndarray
    x_all: np.ndarray
    y_all: np.ndarray
    received: np.ndarray
    motor_y: np.ndarray
    motor_received: np.ndarray
    trajectory: Trajectory
    phase_starts: tuple[tuple[str, float], ...] = ()

    @property
    def encoder_t_ns(self) -> np.ndarray:
        """Stamps of the load readings that arrive."""
        return np.asarray(self.sample_t_ns[self.received], dtype=np.int64)

    @property
    def encoder_y(self) -> np.ndarray:
        """The load readings that arrive."""
        return np.asarray(self.y_all[self.received], dtype=np.float64)


def physics_record(
    params: DrivetrainParameters,
    settings: OperationSettings | None = None,
    seed: int = 0,
    *,
    rate: float = DEFAULT_RATE,
) -> PhysicsRecord:
    """Simulate ``params`` running the operation scenario ``settings`` (default: 40 s of
    ``"operation"``) with ``seed`` (see the module notes)."""
    cfg = OperationSettings(duration=40.0) if settings is None else settings
    if not isinstance(cfg, OperationSettings):
        raise GenBacklashError(f"settings must be OperationSettings, got {cfg!r}")
    rng = np.random.default_rng([int(seed), 12])  # operation_record's stream, draw for draw
    values, phase_starts = operation_commands(rng, cfg)
    cmd_t, t = timeline(
        rng,
        values.size,
        command_rate=cfg.command_rate,
        encoder_rate=cfg.encoder_rate,
        command_jitter_ns=round(cfg.command_jitter * 1e9),
        stamp_jitter_ns=cfg.stamp_jitter * 1e9,
    )
    sim = Drivetrain(params, rate=rate, position=float(values[0]))
    until = max(int(t[-1]), int(cmd_t[-1])) + sim.step_ns
    trajectory = sim.follow(cmd_t, values, until)
    x = trajectory.load_at(t)
    motor = trajectory.motor_at(t)
    y, received = readings(rng, x, noise=cfg.noise, quantum=cfg.quantum, loss=cfg.loss)
    motor_rng = np.random.default_rng([int(seed), 23])
    motor_y, motor_received = readings(
        motor_rng, motor, noise=cfg.noise, quantum=cfg.quantum, loss=cfg.loss
    )
    k = np.maximum(np.searchsorted(cmd_t, t, side="right") - 1, 0)
    if not (np.all(np.isfinite(x)) and math.isfinite(float(np.max(np.abs(motor))))):
        raise GenBacklashError("the simulation diverged (non-finite positions)")
    return PhysicsRecord(
        params=params,
        settings=cfg,
        seed=int(seed),
        command_t_ns=cmd_t,
        command_u=values,
        sample_t_ns=t,
        u_all=values[k],
        motor_all=motor,
        x_all=x,
        y_all=y,
        received=received,
        motor_y=motor_y,
        motor_received=motor_received,
        trajectory=trajectory,
        phase_starts=phase_starts,
    )
