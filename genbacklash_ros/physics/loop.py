"""The physics drivetrains in closed loop with the node's pipeline (benchmarks and tests).

:class:`Clocks` is one seed of the operation scenario's motion and clocks (moves, dwells,
jogs; 100 Hz held commands with jitter; a 1 kHz load encoder at 4096 counts/rev with stamp
jitter and 2 % loss). :func:`open_loop` drives a drivetrain with given commands;
:func:`node_loop` puts the node's :class:`~genbacklash_ros.node.pipeline.BacklashPipeline` in
the loop: each command goes through it and its compensated command is what the servo takes
(after ``delay_ns``: a transport and a drive's loop between them), and each encoder reading
is fed to it as it happens.
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

__all__ = ["Clocks", "node_loop", "open_loop"]


class Clocks:
    """The motion and the clocks of one seed (the operation scenario's)."""

    def __init__(self, seed: int, duration: float) -> None:
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
    values, cmd_t, t = clocks.values, clocks.cmd_t, clocks.t
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
                pipe.on_motor_value(None, r, int(t[i]))
            if clocks.received[i]:
                y = float(np.round(x[i - j] / q) * q) if q else float(x[i - j])
                pipe.on_encoder_value(None, y, int(t[i]))
        j = stop
    pipe.finish(refit=False)
    return loads, pipe.estimate, pipe.guard, pipe.measured
