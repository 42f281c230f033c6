"""Bags of the paper's examples (:func:`write_example_bag`) and of a paper-style drivetrain
with a new random command at every command message (:func:`write_drivetrain_bag`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from genbacklash_core import (
    Cascade,
    paper_example,
)
from genbacklash_core.scenarios import (
    simulate_worn,
    worn,
)
from genbacklash_ros.bags.bagio import BagWriter
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    JointState,
)

from .layout import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    PERIOD_NS,
    START_NS,
    SimulatedBag,
    command_message,
    encoder_message,
    recorder_latencies,
)
from .truth import TRUTH_KEY, BagTruth, constant_zones


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
    delay = recorder_latencies(rng, n)
    kind = "cascade" if isinstance(example.model, Cascade) else "general backlash"
    description = (
        f"paper Example {number} ({kind}), {n} samples at 1 kHz, |u| < {example.u_max}, "
        f"SNR {snr or example.snr}, seed {seed}"
    )
    duration_s = n * PERIOD_NS / 1e9
    t_s, c_left, c_right = constant_zones(example.model, duration_s)
    truth = BagTruth(
        f"example {number}",
        description,
        seed,
        START_NS,
        example.model,
        example.model,
        t_s,
        c_left,
        c_right,
        settings={"example": number, "samples": n, "snr": snr or example.snr},
    )
    custom = {TRUTH_KEY: truth.to_json()}
    with BagWriter(path) as writer:
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        for k in range(n):
            t = int(times[k])
            writer.write(COMMAND_TOPIC, t, command_message((float(data.u[k]),)))
            writer.write(ENCODER_TOPIC, t + int(delay[k]), encoder_message(t, (float(data.y[k]),)))
        writer.set_custom_data(TRUTH_KEY, custom[TRUTH_KEY])
    return SimulatedBag(
        Path(path),
        description,
        example.model,
        example.model,
        {
            COMMAND_TOPIC: (Float64MultiArray.ros_type, n),
            ENCODER_TOPIC: (JointState.ros_type, n),
        },
        duration_s,
        custom,
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
    block = 50
    starts = np.arange(0, n, block)
    factor = np.repeat(
        1.0 + wear * (starts + np.minimum(starts + block, n) - 1) / 2 / max(n - 1, 1), block
    )[:n]
    clean = simulate_worn(base, held, 0.0, base.c_left * factor, base.c_right * factor)
    y = clean + rng.normal(0.0, float(np.std(clean)) / snr, n)
    other = np.cumsum(rng.normal(0.0, 1e-3, n))  # a second joint, slowly drifting
    delay = recorder_latencies(rng, n)
    span = (enc_t[-1] - START_NS) / 1e9
    description = (
        f"drivetrain (paper-style random input): encoder 1 kHz, command "
        f"{cmd_t.size / span:.0f} Hz on average (100-1000 Hz, jittered), Example 1 branches, "
        f"gap +{wear:.0%} over {duration:g} s, SNR {snr:g}, seed {seed}"
    )
    t_s, c_left, c_right = constant_zones(base, n * PERIOD_NS / 1e9, wear)
    truth = BagTruth(
        "drivetrain",
        description,
        seed,
        START_NS,
        base,
        worn(base, 1.0 + wear),
        t_s,
        c_left,
        c_right,
        settings={"duration": duration, "wear": wear, "snr": snr, "u_max": u_max},
    )
    custom = {TRUTH_KEY: truth.to_json()}
    with BagWriter(path) as writer:
        writer.set_custom_data(TRUTH_KEY, custom[TRUTH_KEY])
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        events = [(int(t), 0, i) for i, t in enumerate(cmd_t)]
        events += [(int(t) + int(delay[i]), 1, i) for i, t in enumerate(enc_t)]
        events.sort()
        for log_time, kind, i in events:
            if kind == 0:
                writer.write(COMMAND_TOPIC, log_time, command_message((float(cmd_u[i]), 0.0)))
            else:
                msg = encoder_message(int(enc_t[i]), (float(y[i]), float(other[i])))
                writer.write(ENCODER_TOPIC, log_time, msg)
    return SimulatedBag(
        Path(path),
        description,
        base,
        worn(base, 1.0 + wear),
        {
            COMMAND_TOPIC: (Float64MultiArray.ros_type, int(cmd_t.size)),
            ENCODER_TOPIC: (JointState.ros_type, n),
        },
        n * PERIOD_NS / 1e9,
        custom,
    )
