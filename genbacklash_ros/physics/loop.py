"""The physics drivetrains in closed loop with the node's pipeline (benchmarks and tests).

:class:`Clocks` is one seed of the operation scenario's motion and clocks (moves, dwells,
jogs; 100 Hz held commands with jitter; a 1 kHz load encoder at 4096 counts/rev with stamp
jitter and 2 % loss). :func:`open_loop` drives a drivetrain with given commands;
:func:`node_loop` puts the node's :class:`~genbacklash_ros.node.pipeline.BacklashPipeline` in
the loop: each command goes through it and its compensated command is what the servo takes
(after ``delay_ns``: a transport and a drive's loop between them), and each encoder reading
is fed to it as it happens.

With ``late_ms`` the readings reach the node stamped as a driver stamps them that publishes
them from a busy loop (the live demo's arm, :mod:`genbacklash_ros.demo.live`): after each
command the loop is busy for a random time (exponential, ``late_ms`` on average, at most
8 ms), and the readings taken meanwhile are stamped when it is done, 20 us apart. The
physics is sampled at the readings' true instants (:attr:`Clocks.t`); the node sees
:attr:`Clocks.stamps`. At 1.5 ms on average, about 8 % of the 1 kHz readings are stamped less
than half a period after the one before, as the live arm's are at 500 Hz (7 %).
"""

from __future__ import annotations

import numpy as np

from genbacklash_core import Estimate, GuardVerdict
from genbacklash_core.measured import TrackingVerdict
from genbacklash_core.scenarios import OperationSettings, operation_commands, timeline
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.physics.engine import Drivetrain, Trajectory
from genbacklash_ros.physics.variants import DrivetrainParameters

__all__ = [
    "BUSY_MAX_NS",
    "BUSY_START_NS",
    "PUBLISH_NS",
    "Clocks",
    "late_stamps",
    "node_loop",
    "open_loop",
]


BUSY_START_NS = 1_000_000
"""The late publisher is busy from this long after each command (the live arm's first look
for the node's answer, :data:`genbacklash_ros.demo.live.ANSWER_NS`)."""
BUSY_MAX_NS = 8_000_000
"""The late publisher's busy time at most (before the next command)."""
PUBLISH_NS = 20_000
"""The late publisher publishes the readings it caught up on this far apart (the live arm:
tens of microseconds per JointState)."""


def late_stamps(
    rng: np.random.Generator, cmd_t: np.ndarray, t: np.ndarray, late_ms: float
) -> np.ndarray:
    """The stamps of readings taken at ``t`` (ns) by a publisher busy after every command
    stamped ``cmd_t`` for an exponential time of mean ``late_ms`` (at most
    :data:`BUSY_MAX_NS`): a reading taken while it is busy is stamped when it is done.

    >>> cmd_t = np.array([0, 10_000_000])
    >>> t = np.arange(1, 20) * 1_000_000
    >>> stamps = late_stamps(np.random.default_rng(0), cmd_t, t, 2.0)
    >>> bool(np.all(stamps >= t)) and bool(np.all(np.diff(stamps) > 0))
    True
    """
    busy = np.minimum(rng.exponential(late_ms * 1e6, cmd_t.size), BUSY_MAX_NS).astype(np.int64)
    start = cmd_t + BUSY_START_NS
    k = np.searchsorted(cmd_t, t, side="right") - 1
    valid = k >= 0
    kk = np.maximum(k, 0)
    done = start[kk] + busy[kk]
    inside = valid & (t >= start[kk]) & (t < done)
    stamps = np.where(inside, done, t)
    # published one after the other, PUBLISH_NS apart: stamps increase strictly
    spacing = np.arange(t.size, dtype=np.int64) * PUBLISH_NS
    return np.maximum.accumulate(stamps - spacing) + spacing


class Clocks:
    """The motion and the clocks of one seed (the operation scenario's); with ``late_ms``,
    the stamps a late publisher gives the readings (module notes)."""

    def __init__(self, seed: int, duration: float, *, late_ms: float = 0.0) -> None:
        cfg = OperationSettings(duration=duration)
        rng = np.random.default_rng([int(seed), 12])
        self.values, _ = operation_commands(rng, cfg)
        self.cmd_t, self.t = timeline(
            rng,
            self.values.size,
            command_rate=cfg.command_rate,
            encoder_rate=cfg.encoder_rate,
            command_jitter_ns=round(cfg.command_jitter * 1e9),
            stamp_jitter_ns=cfg.stamp_jitter * 1e9,
        )
        self.received = np.random.default_rng([int(seed), 31]).random(self.t.size) >= cfg.loss
        # a motor encoder's readings, lost on their own draw
        self.motor_received = np.random.default_rng([int(seed), 32]).random(self.t.size) >= cfg.loss
        self.quantum = float(cfg.quantum)
        k = np.maximum(np.searchsorted(self.cmd_t, self.t, side="right") - 1, 0)
        self.desired = self.values[k]
        self.stamps = (
            late_stamps(np.random.default_rng([int(seed), 33]), self.cmd_t, self.t, late_ms)
            if late_ms > 0.0
            else self.t
        )


def open_loop(
    params: DrivetrainParameters, clocks: Clocks, commands: np.ndarray, delay_ns: int = 0
) -> np.ndarray:
    """The load at every encoder instant for ``commands`` taken ``delay_ns`` after the
    command stamps (the same delay the node's answers have)."""
    sim = Drivetrain(params, position=float(commands[0]))
    end = int(max(clocks.t[-1], clocks.cmd_t[-1] + delay_ns)) + sim.step_ns
    return sim.follow(clocks.cmd_t + delay_ns, commands, end).load_at(clocks.t)


def node_loop(
    params: DrivetrainParameters,
    clocks: Clocks,
    *,
    guard: bool,
    delay_ns: int = 0,
    extra: dict[str, object] | None = None,
    motor: bool = False,
) -> tuple[np.ndarray, Estimate, GuardVerdict, TrackingVerdict]:
    """The node's pipeline in the loop: its compensated command drives the servo,
    ``delay_ns`` after the command (a transport and a drive's loop between them);
    ``extra``: more node parameters (e.g. ``servo_model``); ``motor``: the node's input is
    a motor encoder (``gear_input`` motor_encoder: the rotor read at each encoder instant,
    quantised alike, lost on its own draw, fed just before the load's reading of the same
    stamp)."""
    node = NodeParameters.from_mapping(
        {
            "command_type": "float64",
            "encoder_type": "float64",
            "compensation_in_loop": True,  # the compensated command drives the servo
            "compensation_guard": guard,
            **({"gear_input": "motor_encoder", "motor_encoder_type": "float64"} if motor else {}),
            **(extra or {}),
        }
    )
    pipe = BacklashPipeline(node)
    values, cmd_t, t, stamps = clocks.values, clocks.cmd_t, clocks.t, clocks.stamps
    sim = Drivetrain(params, position=float(values[0]))
    loads = np.empty(t.size)
    j, prev = 0, None
    before = float(values[0])  # the command the servo holds until the answer comes
    for k in range(values.size):
        got = pipe.on_command_value(None, float(values[k]), int(cmd_t[k]))
        sent = float(values[k]) if got is None else got[1]
        end = int(cmd_t[k + 1]) if k + 1 < values.size else int(t[-1]) + sim.step_ns
        if delay_ns:
            late = sim.hold(before, min(int(cmd_t[k]) + delay_ns, end))
            piece = Trajectory.concatenate([late, sim.hold(sent, end)])
        else:
            piece = sim.hold(sent, end)
        before = sent
        traj = piece if prev is None else Trajectory.concatenate([prev, piece])
        prev = piece
        stop = int(np.searchsorted(t, min(end, int(traj.t_ns[-1])), side="right"))
        if stop <= j:
            continue
        x = traj.load_at(t[j:stop])
        m = traj.motor_at(t[j:stop]) if motor else x
        loads[j:stop] = x
        q = clocks.quantum
        for i in range(j, stop):
            if motor and clocks.motor_received[i]:
                r = float(np.round(m[i - j] / q) * q) if q else float(m[i - j])
                pipe.on_motor_value(None, r, int(stamps[i]))
            if clocks.received[i]:
                y = float(np.round(x[i - j] / q) * q) if q else float(x[i - j])
                pipe.on_encoder_value(None, y, int(stamps[i]))
        j = stop
    pipe.finish(refit=False)
    return loads, pipe.estimate, pipe.guard, pipe.measured
