"""Bags of an arm: several drivetrains on one clock, one command array and one
``JointState`` (:func:`write_arm_bag`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from genbacklash_core.scenarios import (
    OperationRecord,
)
from genbacklash_ros.bags.bagio import BagWriter
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    Header,
    JointState,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)

from .layout import COMMAND_TOPIC, ENCODER_TOPIC, START_NS

ARM_TRUTH_KEY = "genbacklash.arm_truth"
"""``custom_data`` key of an arm bag's truth: joint -> the model's parameters (JSON)."""


def arm_messages(
    records: list[OperationRecord],
    names: tuple[str, ...],
    command_indices: tuple[int, ...],
    size: int,
    *,
    delay_ns: int = 200_000,
) -> list[tuple[int, str, Float64MultiArray | JointState]]:
    """The messages an arm of several drivetrains sends, in arrival order: ``(receive ns,
    topic, message)``.

    One :data:`COMMAND_TOPIC` Float64MultiArray of ``size`` elements per command tick, joint
    ``k``'s command at ``command_indices[k]`` and the elements no joint uses counting the
    commands (``0, 1, 2, ...``: they must pass through a node unchanged); one
    :data:`ENCODER_TOPIC` JointState per reading that arrived, holding every joint's
    position, received ``delay_ns`` after its stamp. ``records`` share their clocks
    (:func:`~genbacklash_core.scenarios.arm_records`). Times from :data:`START_NS`.
    """
    if not (len(records) == len(names) == len(command_indices)) or not records:
        raise ValueError("one record, one name and one command index per joint")
    if len(set(command_indices)) != len(command_indices) or max(command_indices) >= size:
        raise ValueError(f"command_indices {command_indices} do not fit {size} elements")
    first = records[0]
    cmd_t = START_NS + first.command_t_ns
    enc_t = START_NS + first.encoder_t_ns
    free = [i for i in range(size) if i not in command_indices]
    layout = MultiArrayLayout((MultiArrayDimension("joints", size, size),), 0)
    cmd_u = np.stack([r.command_u for r in records])
    enc_y = np.stack([r.encoder_y for r in records])
    out: list[tuple[int, str, Float64MultiArray | JointState]] = []
    for i in range(cmd_t.size):
        data = [0.0] * size
        for k, index in enumerate(command_indices):
            data[index] = float(cmd_u[k, i])
        for index in free:
            data[index] = float(i)
        out.append((int(cmd_t[i]), COMMAND_TOPIC, Float64MultiArray(layout, tuple(data))))
    for i in range(enc_t.size):
        stamp = int(enc_t[i])
        reading = JointState(
            Header(Time.from_ns(stamp), "encoder"), names, tuple(enc_y[:, i].tolist())
        )
        out.append((stamp + delay_ns, ENCODER_TOPIC, reading))
    out.sort(key=lambda item: (item[0], item[1] != COMMAND_TOPIC))
    return out


def write_arm_bag(
    path: str | Path,
    records: list[OperationRecord],
    names: tuple[str, ...],
    command_indices: tuple[int, ...],
    size: int,
) -> dict[str, int]:
    """Write :func:`arm_messages` as a bag (log time = receive time), with each joint's
    true model under :data:`ARM_TRUTH_KEY`; returns topic -> message count."""
    messages = arm_messages(records, names, command_indices, size)
    truth = {
        name: {
            "m_left": list(r.truth.m_left),
            "c_left": r.truth.c_left,
            "m_right": list(r.truth.m_right),
            "c_right": r.truth.c_right,
            "parameters": r.truth.parameters().tolist(),
        }
        for name, r in zip(names, records, strict=True)
    }
    counts = {COMMAND_TOPIC: 0, ENCODER_TOPIC: 0}
    with BagWriter(path) as writer:
        writer.set_custom_data(ARM_TRUTH_KEY, json.dumps(truth))
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        for log_ns, topic, msg in messages:
            writer.write(topic, log_ns, msg)
            counts[topic] += 1
    return counts
