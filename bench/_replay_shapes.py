"""The bag shapes `bench/replay.py` replays (issue 24: the floor ratio on bags of other shapes).

Each shape is a bag written from a simulation and the `genbacklash replay` arguments that
select its joint:

* ``operation``: the operation scenario (:func:`write_operation_bag`): Float64MultiArray
  commands at 100 Hz, a two-joint JointState at 1 kHz, 2 % lost, jittered stamps;
* ``float64``: the same motion on clean clocks: Float64 commands at 100 Hz, a one-joint
  JointState at 1 kHz stamped (and logged) 0.2 ms after each 1 ms tick, so one 0.2 ms
  after each command, none lost (the issue's 0.72x bag);
* ``arm6``: six drivetrains of one arm (:func:`write_arm_bag`): a six-element
  Float64MultiArray command, a six-joint JointState at 1 kHz (2 % lost), replayed for one
  joint (``joint_3``, command index 2);
* ``physics``: the operation scenario on the MuJoCo drivetrain ``near_ideal``
  (:func:`write_physics_bag`, what ``genbacklash simulate --physics near_ideal`` writes).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from genbacklash_core.scenarios import OPERATION_BACKLASH, arm_records, operation_record, worn
from genbacklash_ros.bags.bagio import BagWriter
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    START_NS,
    operation_settings,
    write_arm_bag,
    write_operation_bag,
)
from genbacklash_ros.node.messages import Float64, Header, JointState, Time

ARM_JOINT, ARM_INDEX = "joint_3", 2
SHAPE_NAMES = ("operation", "float64", "arm6", "physics")


@dataclass(frozen=True)
class Shape:
    """A bag shape: its name, what it holds, and the replay's selection arguments."""

    name: str
    description: str
    args: tuple[str, ...]
    write: Callable[[Path, float, int], None]


def write_float64_bag(path: Path, duration: float, seed: int) -> None:
    """Float64 commands at 100 Hz, a JointState at 1 kHz stamped and logged 0.2 ms after
    each 1 ms tick (so 0.2 ms after each command), none lost, no jitter."""
    cfg = dataclasses.replace(
        operation_settings((("operation", duration),), wear=0.2),
        loss=0.0,
        stamp_jitter=0.0,
        command_jitter=0.0,
    )
    rec = operation_record(cfg, seed)
    cmd_log = START_NS + rec.command_t_ns
    enc_log = START_NS + rec.sample_t_ns + 200_000
    log = np.concatenate([cmd_log, enc_log])
    kind = np.concatenate([np.zeros(cmd_log.size, np.int8), np.ones(enc_log.size, np.int8)])
    item = np.concatenate([np.arange(cmd_log.size), np.arange(enc_log.size)])
    with BagWriter(path) as writer:
        writer.add_topic(COMMAND_TOPIC, Float64.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        for j in np.lexsort((item, kind, log)).tolist():
            i = int(item[j])
            if kind[j] == 0:
                writer.write(COMMAND_TOPIC, int(log[j]), Float64(float(rec.command_u[i])))
            else:
                stamp = int(enc_log[i])
                reading = JointState(
                    Header(Time.from_ns(stamp), "encoder"), (JOINT,), (float(rec.y_all[i]),)
                )
                writer.write(ENCODER_TOPIC, stamp, reading)


def write_arm6_bag(path: Path, duration: float, seed: int) -> None:
    """Six drivetrains of one arm, each worn differently (:func:`write_arm_bag`)."""
    models = [worn(OPERATION_BACKLASH, 1.0 + 0.2 * k) for k in range(6)]
    settings = operation_settings((("operation", duration),))
    records = arm_records(models, settings, seed=seed)
    names = tuple(f"joint_{k + 1}" for k in range(6))
    write_arm_bag(path, records, names, tuple(range(6)), 6)


def write_operation(path: Path, duration: float, seed: int) -> None:
    write_operation_bag(path, operation_settings((("operation", duration),), wear=0.2), seed=seed)


def write_physics(path: Path, duration: float, seed: int) -> None:
    from genbacklash_core.scenarios import OperationSettings
    from genbacklash_ros.physics.bag import write_physics_bag
    from genbacklash_ros.physics.variants import variant

    write_physics_bag(path, variant("near_ideal"), OperationSettings(duration=duration), seed)


_TOPICS = ("--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC)
SHAPES: dict[str, Shape] = {
    "operation": Shape(
        "operation",
        "operation scenario: Float64MultiArray commands 100 Hz, two-joint JointState 1 kHz "
        "(2 % lost, jittered stamps)",
        (*_TOPICS, "--joint", JOINT),
        write_operation,
    ),
    "float64": Shape(
        "float64",
        "Float64 commands 100 Hz, one-joint JointState 1 kHz stamped 0.2 ms after each "
        "1 ms tick (0.2 ms after each command), none lost",
        (*_TOPICS, "--joint", JOINT),
        write_float64_bag,
    ),
    "arm6": Shape(
        "arm6",
        f"six-joint arm: six-element Float64MultiArray commands 100 Hz, six-joint JointState "
        f"1 kHz (2 % lost); replayed for {ARM_JOINT} (command index {ARM_INDEX})",
        (*_TOPICS, "--joint", ARM_JOINT, "--command-index", str(ARM_INDEX)),
        write_arm6_bag,
    ),
    "physics": Shape(
        "physics",
        "MuJoCo drivetrain near_ideal in the operation scenario (`--physics near_ideal`): "
        "the operation bag's topics and types",
        (*_TOPICS, "--joint", JOINT),
        write_physics,
    ),
}
