"""Synthetic rosbag2 MCAP bags: the paper's examples and a drivetrain with a wearing gap.

Both write ``/command`` (``std_msgs/Float64MultiArray``, logged at the command's time) and
``/encoder`` (``sensor_msgs/JointState`` stamped at the sample time, logged 0.1-0.3 ms later,
as a recorder receives it), so that a replay with the default parameters
(``stamp_source = "header"``) sees the same samples the simulation used.

* :func:`write_example_bag`: one command and one encoder message per sample of the paper's
  Example 1-4 (its input range, model and SNR), at 1 kHz.
* :func:`write_drivetrain_bag`: the encoder at 1 kHz; the command at 100-1000 Hz (random
  intervals of 1-10 ms with 0-0.2 ms jitter), held between messages; Example 1's curved
  branches whose dead-zone widths ``c_L``, ``c_R`` grow linearly by ``wear`` over the record;
  white noise at SNR 25. The command carries a second joint's element and the encoder a
  second joint, so ``command_index`` and ``joint`` matter (the drivetrain is element 0 and
  joint ``drive_joint``, the defaults).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from genbacklash_core import Cascade, GeneralBacklash, paper_example, simulate_backlash

from .bagio import BagWriter
from .messages import (
    Float64MultiArray,
    Header,
    JointState,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)

__all__ = [
    "COMMAND_TOPIC",
    "ENCODER_TOPIC",
    "JOINT",
    "START_NS",
    "SimulatedBag",
    "write_drivetrain_bag",
    "write_example_bag",
]

COMMAND_TOPIC = "/command"
ENCODER_TOPIC = "/encoder"
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
    """

    path: Path
    description: str
    truth: GeneralBacklash | Cascade
    truth_end: GeneralBacklash | Cascade
    counts: dict[str, tuple[str, int]] = field(default_factory=dict)
    duration_s: float = 0.0


def _command(values: tuple[float, ...]) -> Float64MultiArray:
    size = len(values)
    layout = MultiArrayLayout((MultiArrayDimension("joints", size, size),), 0)
    return Float64MultiArray(layout, values)


def _encoder(stamp_ns: int, positions: tuple[float, ...]) -> JointState:
    names = (JOINT, OTHER_JOINT)[: len(positions)]
    return JointState(Header(Time.from_ns(stamp_ns), "encoder"), names, positions)


def _latencies(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.integers(100_000, 300_000, n)  # recorder receive delay, ns


def write_example_bag(
    path: str | Path,
    number: int,
    *,
    seed: int = 0,
    n_samples: int | None = None,
    snr: float | None = None,
) -> SimulatedBag:
    """Write the paper's Example ``number`` (1-4) as a bag: one command and one encoder
    message per sample, 1 kHz, the example's input range, model and SNR.

    Returns what was written (:class:`SimulatedBag`).
    """
    example = paper_example(number)
    data = example.generate(seed, n_samples=n_samples, snr=snr)
    n = data.u.size
    rng = np.random.default_rng([seed, 1])
    times = START_NS + np.arange(n, dtype=np.int64) * PERIOD_NS
    delay = _latencies(rng, n)
    with BagWriter(path) as writer:
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        for k in range(n):
            t = int(times[k])
            writer.write(COMMAND_TOPIC, t, _command((float(data.u[k]),)))
            writer.write(ENCODER_TOPIC, t + int(delay[k]), _encoder(t, (float(data.y[k]),)))
    kind = "cascade" if isinstance(example.model, Cascade) else "general backlash"
    return SimulatedBag(
        Path(path),
        f"paper Example {number} ({kind}), {n} samples at 1 kHz, |u| < {example.u_max}, "
        f"SNR {snr or example.snr}, seed {seed}",
        example.model,
        example.model,
        {
            COMMAND_TOPIC: (Float64MultiArray.ros_type, n),
            ENCODER_TOPIC: (JointState.ros_type, n),
        },
        n * PERIOD_NS / 1e9,
    )


def _worn(model: GeneralBacklash, factor: float) -> GeneralBacklash:
    return GeneralBacklash(
        model.m_left, model.c_left * factor, model.m_right, model.c_right * factor
    )


def write_drivetrain_bag(
    path: str | Path,
    *,
    seed: int = 0,
    duration: float = 12.0,
    wear: float = 0.2,
    snr: float = 25.0,
    u_max: float = 2.0,
) -> SimulatedBag:
    """Write the drivetrain scenario (see the module notes) as a bag.

    Parameters
    ----------
    path : str or Path
        The bag directory to create.
    seed : int
    duration : float
        Length of the record in seconds (1 kHz encoder: ``1000 * duration`` messages).
    wear : float
        Relative growth of both dead-zone widths over the record (0.2: 20 % wider at the end).
    snr : float
        std(clean encoder) / std(noise).
    u_max : float
        Commands are uniform in ``(-u_max, u_max)``.
    """
    base = paper_example(1).backlash
    rng = np.random.default_rng(seed)
    n = round(duration * 1e9 / PERIOD_NS)
    enc_t = START_NS + np.arange(n, dtype=np.int64) * PERIOD_NS
    # command messages at 100-1000 Hz with jitter
    gaps = rng.integers(1_000_000, 10_000_001, n)
    cmd_t = START_NS + np.cumsum(gaps) - gaps[0]
    cmd_t = cmd_t[cmd_t <= enc_t[-1]]
    cmd_t = cmd_t + rng.integers(0, 200_000, cmd_t.size)
    cmd_t = np.maximum.accumulate(cmd_t)
    cmd_t = cmd_t[np.concatenate(([True], np.diff(cmd_t) > 0))]
    cmd_u = rng.uniform(-u_max, u_max, cmd_t.size)
    # the input of each encoder sample: the command held since its time
    k = np.searchsorted(cmd_t, enc_t, side="right") - 1
    held = np.where(k >= 0, cmd_u[np.maximum(k, 0)], 0.0)
    # the play operator with a gap that grows linearly: blocks of 50 samples
    clean = np.empty(n)
    x_prev = 0.0
    block = 50
    for start in range(0, n, block):
        stop = min(start + block, n)
        factor = 1.0 + wear * (start + stop - 1) / 2 / max(n - 1, 1)
        clean[start:stop] = simulate_backlash(_worn(base, factor), held[start:stop], x_prev)
        x_prev = float(clean[stop - 1])
    y = clean + rng.normal(0.0, float(np.std(clean)) / snr, n)
    other = np.cumsum(rng.normal(0.0, 1e-3, n))  # a second joint, slowly drifting
    delay = _latencies(rng, n)
    with BagWriter(path) as writer:
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        events = [(int(t), 0, i) for i, t in enumerate(cmd_t)]
        events += [(int(t) + int(delay[i]), 1, i) for i, t in enumerate(enc_t)]
        events.sort()
        for log_time, kind, i in events:
            if kind == 0:
                writer.write(COMMAND_TOPIC, log_time, _command((float(cmd_u[i]), 0.0)))
            else:
                msg = _encoder(int(enc_t[i]), (float(y[i]), float(other[i])))
                writer.write(ENCODER_TOPIC, log_time, msg)
    span = (enc_t[-1] - START_NS) / 1e9
    return SimulatedBag(
        Path(path),
        f"drivetrain: encoder 1 kHz, command {cmd_t.size / span:.0f} Hz on average "
        f"(100-1000 Hz, jittered), Example 1 branches, gap +{wear:.0%} over {duration:g} s, "
        f"SNR {snr:g}, seed {seed}",
        base,
        _worn(base, 1.0 + wear),
        {
            COMMAND_TOPIC: (Float64MultiArray.ros_type, int(cmd_t.size)),
            ENCODER_TOPIC: (JointState.ros_type, n),
        },
        n * PERIOD_NS / 1e9,
    )
