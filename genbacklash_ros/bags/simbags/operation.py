"""Bags of a drivetrain in normal operation (:func:`write_operation_bag`) and of any simulated
record (:func:`write_record_bag`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    STRAIGHT_BACKLASH,
    OperationSettings,
    operation_record,
)
from genbacklash_ros.bags.bagio import BagWriter
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    JointState,
)

from .layout import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    MOTOR_TOPIC,
    START_NS,
    SimulatedBag,
    command_message,
    encoder_message,
    recorder_latencies,
)
from .truth import TRUTH_KEY, TRUTH_STEP_S, BagTruth, settings_dict


def phases_label(settings: OperationSettings) -> str:
    """The scenario's name: the phase kind for one phase, else ``kind:seconds,...``."""
    schedule = settings.schedule
    if len(schedule) == 1:
        return schedule[0][0]
    return ",".join(f"{kind}:{seconds:g}" for kind, seconds in schedule)


def operation_settings(
    phases: tuple[tuple[str, float], ...],
    *,
    wear: float = 0.0,
    loss: float = 0.02,
    noise: float = 0.0,
    straight: bool = False,
) -> OperationSettings:
    """The settings ``genbacklash simulate`` uses: the default drivetrain
    (:data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`, or its straight-branch twin
    :data:`~genbacklash_core.scenarios.STRAIGHT_BACKLASH`) running ``phases``."""
    return OperationSettings(
        phases=tuple(phases),
        model=STRAIGHT_BACKLASH if straight else OPERATION_BACKLASH,
        loss=loss,
        noise=noise,
        wear=wear,
    )


def write_operation_bag(
    path: str | Path, settings: OperationSettings | None = None, seed: int = 0
) -> SimulatedBag:
    """Write a drivetrain in normal operation (see the module notes) as a bag.

    Parameters
    ----------
    path : str or Path
        The bag directory to create.
    settings : OperationSettings, optional
        The scenario (phases, model, rates, jitter, loss, wear...); default 60 s of
        ``"operation"`` with :data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`.
    seed : int

    Notes
    -----
    ``/command`` (``std_msgs/Float64MultiArray``, element 0 the drivetrain, element 1 a
    second joint's command) is logged at each command's time. ``/encoder``
    (``sensor_msgs/JointState``: ``drive_joint`` and ``wheel_joint``) carries one message per
    reading that arrived, its header stamp the reading's (jittered) sampling instant, logged
    0.1-0.3 ms later; lost readings are absent. The truth (:class:`BagTruth`) goes into the
    metadata's ``custom_data``.
    """
    cfg = OperationSettings() if settings is None else settings
    rec = operation_record(cfg, seed)
    rng = np.random.default_rng([int(seed), 21])
    label = phases_label(cfg)
    total = cfg.total_seconds
    # the truth: dead zones every TRUTH_STEP_S (the simulation's wear steps are that long)
    sample_t = rec.sample_t_ns
    grid = np.arange(0.0, sample_t[-1] / 1e9, TRUTH_STEP_S)
    grid = np.append(grid, sample_t[-1] / 1e9) if sample_t[-1] / 1e9 > grid[-1] else grid
    index = np.clip(np.searchsorted(sample_t, np.round(grid * 1e9)), 0, sample_t.size - 1)
    branches = "straight" if cfg.model.degree == 1 else f"curved (degree {cfg.model.degree})"
    end = rec.truth_end
    description = (
        f"{label}: {total:g} s of a drivetrain in operation, commands {cfg.command_rate:g} Hz "
        f"held, encoder {cfg.encoder_rate:g} Hz ({cfg.counts_per_rev} counts/rev, stamp "
        f"jitter {cfg.stamp_jitter * 1e6:g} us, {cfg.loss:.0%} lost), {branches} branches, "
        f"c_L {cfg.model.c_left:.4f} -> {end.c_left:.4f}, c_R {cfg.model.c_right:.4f} -> "
        f"{end.c_right:.4f} rad (wear {cfg.wear:g}), seed {seed}"
    )
    truth = BagTruth(
        label,
        description,
        int(seed),
        START_NS,
        cfg.model,
        end,
        grid,
        rec.c_left[index],
        rec.c_right[index],
        rec.phase_starts,
        settings_dict(cfg),
    )
    custom = {TRUTH_KEY: truth.to_json()}
    counts = write_record_bag(
        path,
        custom,
        rng,
        rec.command_t_ns,
        rec.command_u,
        sample_t,
        rec.received,
        rec.y_all,
    )
    return SimulatedBag(Path(path), description, cfg.model, end, counts, total, custom)


def write_record_bag(
    path: str | Path,
    custom: Mapping[str, str],
    rng: np.random.Generator,
    command_t_ns: np.ndarray,
    command_u: np.ndarray,
    sample_t_ns: np.ndarray,
    received: np.ndarray,
    y_all: np.ndarray,
    motor: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict[str, tuple[str, int]]:
    """Write a simulated record's messages (see :func:`write_operation_bag`'s notes) with
    ``custom`` as the metadata's ``custom_data``; returns topic -> (type, count).

    ``sample_t_ns``, ``received`` and ``y_all`` hold every encoder sampling instant (ns from
    the start), whether it arrived, and its reading. ``motor`` adds :data:`MOTOR_TOPIC`:
    ``(readings, received)`` of a motor encoder sampled at the same instants, one
    ``sensor_msgs/JointState`` (``drive_joint``) per reading that arrived, logged 0.1-0.3 ms
    after its stamp. Draws from ``rng``: the second joint's commands and positions, the
    encoder's latencies, then the motor encoder's latencies.
    """
    # a second joint: the wheel turning slowly (the distractor element / joint)
    cmd_n = command_t_ns.size
    wheel_cmd = np.cumsum(rng.normal(0.0, 2e-3, cmd_n))
    k = np.clip(np.searchsorted(command_t_ns, sample_t_ns, side="right") - 1, 0, cmd_n - 1)
    wheel_pos = wheel_cmd[k] + rng.normal(0.0, 1e-4, sample_t_ns.size)
    enc_stamp = START_NS + sample_t_ns[received]
    enc_y, enc_wheel = y_all[received], wheel_pos[received]
    enc_log = enc_stamp + recorder_latencies(rng, enc_stamp.size)
    cmd_log = START_NS + command_t_ns
    logs, kinds, items = [cmd_log, enc_log], [0, 1], [cmd_n, enc_log.size]
    mot_stamp = mot_y = np.empty(0)
    if motor is not None:
        mot_stamp = START_NS + sample_t_ns[motor[1]]
        mot_y = motor[0][motor[1]]
        logs.append(mot_stamp + recorder_latencies(rng, mot_stamp.size))
        kinds.append(2)
        items.append(mot_stamp.size)
    # log-time order (a command first when both arrive at the same nanosecond)
    log = np.concatenate(logs)
    kind = np.concatenate([np.full(n, k_, np.int8) for k_, n in zip(kinds, items, strict=True)])
    item = np.concatenate([np.arange(n) for n in items])
    order = np.lexsort((item, kind, log))
    with BagWriter(path) as writer:
        for key, value in custom.items():
            writer.set_custom_data(key, value)
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        if motor is not None:
            writer.add_topic(MOTOR_TOPIC, JointState.ros_type)
        for j in order:
            i = int(item[j])
            if kind[j] == 0:
                values = (float(command_u[i]), float(wheel_cmd[i]))
                writer.write(COMMAND_TOPIC, int(log[j]), command_message(values))
            elif kind[j] == 1:
                msg = encoder_message(int(enc_stamp[i]), (float(enc_y[i]), float(enc_wheel[i])))
                writer.write(ENCODER_TOPIC, int(log[j]), msg)
            else:
                msg = encoder_message(int(mot_stamp[i]), (float(mot_y[i]),))
                writer.write(MOTOR_TOPIC, int(log[j]), msg)
    counts = {
        COMMAND_TOPIC: (Float64MultiArray.ros_type, cmd_n),
        ENCODER_TOPIC: (JointState.ros_type, int(enc_stamp.size)),
    }
    if motor is not None:
        counts[MOTOR_TOPIC] = (JointState.ros_type, int(mot_stamp.size))
    return counts
