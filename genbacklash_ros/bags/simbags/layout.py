"""What every synthetic bag holds: its topics and joints, the clock it starts at, the
messages written to them and what a writer returns (:class:`SimulatedBag`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from genbacklash_core import (
    Cascade,
    GeneralBacklash,
)
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    Header,
    JointState,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)

COMMAND_TOPIC = "/command"
ENCODER_TOPIC = "/encoder"
MOTOR_TOPIC = "/motor_encoder"
"""A motor-side encoder (physics bags with a motor encoder)."""
JOINT = "drive_joint"
OTHER_JOINT = "wheel_joint"
START_NS = 1_700_000_000 * 1_000_000_000  # recordings start at a plausible wall-clock time
PERIOD_NS = 1_000_000  # encoder at 1 kHz


@dataclass(frozen=True)
class SimulatedBag:
    """What a synthetic bag holds.

    Attributes
    ----------
    path : Path
    description : str
    truth : GeneralBacklash or Cascade
        The model at the start of the record.
    truth_end : GeneralBacklash or Cascade
        The model at the end (differs from ``truth`` when the gap wears).
    counts : dict
        Topic -> (message type, message count).
    duration_s : float
    custom_data : dict
        What was stored in the bag's metadata ``custom_data`` (:data:`TRUTH_KEY` -> JSON).
    """

    path: Path
    description: str
    truth: GeneralBacklash | Cascade
    truth_end: GeneralBacklash | Cascade
    counts: dict[str, tuple[str, int]] = field(default_factory=dict)
    duration_s: float = 0.0
    custom_data: dict[str, str] = field(default_factory=dict)


def command_message(values: tuple[float, ...]) -> Float64MultiArray:
    """A ``/command`` message: one element per joint, the drivetrain first."""
    size = len(values)
    layout = MultiArrayLayout((MultiArrayDimension("joints", size, size),), 0)
    return Float64MultiArray(layout, values)


def encoder_message(stamp_ns: int, positions: tuple[float, ...]) -> JointState:
    """An ``/encoder`` message stamped ``stamp_ns``: the drivetrain's joint, then the other."""
    names = (JOINT, OTHER_JOINT)[: len(positions)]
    return JointState(Header(Time.from_ns(stamp_ns), "encoder"), names, positions)


def recorder_latencies(rng: np.random.Generator, n: int) -> np.ndarray:
    """How long after its stamp a recorder logs each of ``n`` encoder messages (ns)."""
    return rng.integers(100_000, 300_000, n)  # recorder receive delay, ns
