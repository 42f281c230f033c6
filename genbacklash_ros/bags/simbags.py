"""Synthetic rosbag2 MCAP bags: the paper's examples and drivetrains, with their truth.

All write ``/command`` (``std_msgs/Float64MultiArray``, logged at the command's time) and
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
  joint ``drive_joint``, the defaults). The paper-style random input: a new uniform value
  at every command.
* :func:`write_operation_bag`: a drivetrain in normal operation
  (:func:`genbacklash_core.scenarios.operation_record`): smooth point-to-point moves, dwells
  and jogs (or one-way traverses, pick-and-place cycles, sine sweeps, chained as phases),
  100 Hz position commands held by the servo, a 1 kHz encoder quantised to 4096 counts/rev
  whose readings are stamped at their (jittered) sampling instants and sometimes lost (a
  lost reading is absent from the bag), and optionally wearing dead zones.

Every bag stores its truth in the rosbag2 metadata (``custom_data``, key
:data:`TRUTH_KEY`, a JSON object; :class:`BagTruth`): the model at the start and at the end
of the record, the true dead zones over time, the scenario's settings and seed. A report
reads it back with :func:`read_truth` to draw the true gap and to judge compensation
against the true drivetrain.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from genbacklash_core import (
    Cascade,
    GeneralBacklash,
    paper_example,
)
from genbacklash_core.cascade import model_from_dict, model_to_dict
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    STRAIGHT_BACKLASH,
    OperationRecord,
    OperationSettings,
    operation_record,
    simulate_worn,
    worn,
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
from genbacklash_ros.node.pipeline import BacklashPipeline

__all__ = [
    "ARM_TRUTH_KEY",
    "COMMAND_TOPIC",
    "ENCODER_TOPIC",
    "JOINT",
    "MOTOR_TOPIC",
    "START_NS",
    "TRUTH_KEY",
    "BagTruth",
    "SimulatedBag",
    "arm_messages",
    "operation_settings",
    "phases_label",
    "read_truth",
    "write_arm_bag",
    "write_drivetrain_bag",
    "write_example_bag",
    "write_operation_bag",
    "write_record_bag",
]

COMMAND_TOPIC = "/command"
ENCODER_TOPIC = "/encoder"
MOTOR_TOPIC = "/motor_encoder"
"""A motor-side encoder (physics bags with a motor encoder)."""
JOINT = "drive_joint"
OTHER_JOINT = "wheel_joint"
START_NS = 1_700_000_000 * 1_000_000_000  # recordings start at a plausible wall-clock time
PERIOD_NS = 1_000_000  # encoder at 1 kHz
TRUTH_KEY = "genbacklash.truth"
"""``custom_data`` key of the truth JSON (:class:`BagTruth`)."""
TRUTH_FORMAT = 1
TRUTH_STEP_S = 0.25  # resolution of the stored dead zones over time


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


# --------------------------------------------------------------------------- truth


def _backlash(model: GeneralBacklash | Cascade) -> GeneralBacklash:
    return model.backlash if isinstance(model, Cascade) else model


@dataclass(frozen=True, eq=False)
class BagTruth:
    """The truth a synthetic bag carries in its metadata (``custom_data[TRUTH_KEY]``).

    Attributes
    ----------
    scenario : str
        ``"drivetrain"``, ``"example N"``, an operation phase kind, or the phases'
        ``kind:seconds,...`` list.
    description : str
        One line on what the bag holds.
    seed : int
    start_ns : int
        Bag time (ns since the epoch) of the record's time 0; times below count from it.
    model, model_end : GeneralBacklash or Cascade
        The drivetrain at the start and at the end of the record.
    t_s, c_left, c_right : ndarray
        The true dead zones at times ``t_s`` (seconds from ``start_ns``, every
        :data:`TRUTH_STEP_S`): they change when the gap wears.
    phases : tuple of (str, float)
        Each phase's kind and start time (s); empty for the random-input bags.
    settings : dict
        The scenario's settings as given (JSON values).
    """

    scenario: str
    description: str
    seed: int
    start_ns: int
    model: GeneralBacklash | Cascade
    model_end: GeneralBacklash | Cascade
    t_s: np.ndarray
    c_left: np.ndarray
    c_right: np.ndarray
    phases: tuple[tuple[str, float], ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)

    def dead_zones(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The true ``(c_left, c_right)`` at times ``t_s`` (s from :attr:`start_ns`),
        interpolated linearly and held beyond the ends."""
        t = np.asarray(t_s, dtype=np.float64)
        return np.interp(t, self.t_s, self.c_left), np.interp(t, self.t_s, self.c_right)

    def to_json(self) -> str:
        """The JSON stored under :data:`TRUTH_KEY` (compact, rounded to 1e-9)."""

        def r(values: np.ndarray) -> list[float]:
            return [round(float(v), 9) for v in values]

        return json.dumps(
            {
                "format": TRUTH_FORMAT,
                "scenario": self.scenario,
                "description": self.description,
                "seed": self.seed,
                "start_ns": self.start_ns,
                "model": model_to_dict(self.model),
                "model_end": model_to_dict(self.model_end),
                "dead_zones": {
                    "t": r(self.t_s),
                    "c_left": r(self.c_left),
                    "c_right": r(self.c_right),
                },
                "phases": [[kind, start] for kind, start in self.phases],
                "settings": self.settings,
            },
            separators=(",", ":"),
        )

    @classmethod
    def from_json(cls, text: str) -> BagTruth:
        """Parse :meth:`to_json`'s output; ``ValueError`` (or ``KeyError``/``TypeError``)
        when it is not one."""
        data = json.loads(text)
        if not isinstance(data, dict) or data.get("format") != TRUTH_FORMAT:
            raise ValueError("not a genbacklash truth record")
        zones = data["dead_zones"]
        t_s = np.asarray(zones["t"], dtype=np.float64)
        c_left = np.asarray(zones["c_left"], dtype=np.float64)
        c_right = np.asarray(zones["c_right"], dtype=np.float64)
        if not (t_s.ndim == 1 and t_s.size and t_s.shape == c_left.shape == c_right.shape):
            raise ValueError("dead_zones must hold equally long non-empty lists")
        if not (np.all(np.isfinite(t_s)) and np.all(np.diff(t_s) > 0)):
            raise ValueError("dead_zones.t must increase")
        settings = data.get("settings", {})
        return cls(
            scenario=str(data["scenario"]),
            description=str(data.get("description", "")),
            seed=int(data["seed"]),
            start_ns=int(data["start_ns"]),
            model=model_from_dict(data["model"]),
            model_end=model_from_dict(data["model_end"]),
            t_s=t_s,
            c_left=c_left,
            c_right=c_right,
            phases=tuple((str(k), float(t)) for k, t in data.get("phases", [])),
            settings=settings if isinstance(settings, dict) else {},
        )


def read_truth(custom_data: Mapping[str, str] | None) -> BagTruth | None:
    """The :class:`BagTruth` in a bag's ``custom_data`` (e.g.
    :attr:`~genbacklash_ros.bags.bagio.BagReader.custom_data`); None when there is none or it
    does not parse (tolerant: a report just goes without the truth)."""
    if not custom_data or TRUTH_KEY not in custom_data:
        return None
    try:
        return BagTruth.from_json(custom_data[TRUTH_KEY])
    except (ValueError, KeyError, TypeError, IndexError, AttributeError):
        return None


def _constant_zones(
    model: GeneralBacklash | Cascade, duration_s: float, wear: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dead zones every :data:`TRUTH_STEP_S` for a gap growing linearly by ``wear``."""
    t = np.arange(0.0, duration_s, TRUTH_STEP_S)
    t = np.append(t, duration_s) if duration_s > t[-1] else t
    factor = 1.0 + wear * t / max(duration_s, 1e-12)
    bl = _backlash(model)
    return t, bl.c_left * factor, bl.c_right * factor


def command_message(values: tuple[float, ...]) -> Float64MultiArray:
    """A ``/command`` message: one element per joint, the drivetrain first."""
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
    kind = "cascade" if isinstance(example.model, Cascade) else "general backlash"
    description = (
        f"paper Example {number} ({kind}), {n} samples at 1 kHz, |u| < {example.u_max}, "
        f"SNR {snr or example.snr}, seed {seed}"
    )
    duration_s = n * PERIOD_NS / 1e9
    t_s, c_left, c_right = _constant_zones(example.model, duration_s)
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
            writer.write(ENCODER_TOPIC, t + int(delay[k]), _encoder(t, (float(data.y[k]),)))
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
    delay = _latencies(rng, n)
    span = (enc_t[-1] - START_NS) / 1e9
    description = (
        f"drivetrain (paper-style random input): encoder 1 kHz, command "
        f"{cmd_t.size / span:.0f} Hz on average (100-1000 Hz, jittered), Example 1 branches, "
        f"gap +{wear:.0%} over {duration:g} s, SNR {snr:g}, seed {seed}"
    )
    t_s, c_left, c_right = _constant_zones(base, n * PERIOD_NS / 1e9, wear)
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
                msg = _encoder(int(enc_t[i]), (float(y[i]), float(other[i])))
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


# --------------------------------------------------------------------------- operation


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


def _settings_dict(settings: OperationSettings) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in fields(settings):
        value = getattr(settings, item.name)
        if item.name == "model":
            out["model"] = model_to_dict(value)
        elif item.name == "phases":
            out["phases"] = [[kind, seconds] for kind, seconds in settings.schedule]
        else:
            out[item.name] = value
    return out


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
        _settings_dict(cfg),
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
    enc_log = enc_stamp + _latencies(rng, enc_stamp.size)
    cmd_log = START_NS + command_t_ns
    logs, kinds, items = [cmd_log, enc_log], [0, 1], [cmd_n, enc_log.size]
    mot_stamp = mot_y = np.empty(0)
    if motor is not None:
        mot_stamp = START_NS + sample_t_ns[motor[1]]
        mot_y = motor[0][motor[1]]
        logs.append(mot_stamp + _latencies(rng, mot_stamp.size))
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
                msg = _encoder(int(enc_stamp[i]), (float(enc_y[i]), float(enc_wheel[i])))
                writer.write(ENCODER_TOPIC, int(log[j]), msg)
            else:
                msg = _encoder(int(mot_stamp[i]), (float(mot_y[i]),))
                writer.write(MOTOR_TOPIC, int(log[j]), msg)
    counts = {
        COMMAND_TOPIC: (Float64MultiArray.ros_type, cmd_n),
        ENCODER_TOPIC: (JointState.ros_type, int(enc_stamp.size)),
    }
    if motor is not None:
        counts[MOTOR_TOPIC] = (JointState.ros_type, int(mot_stamp.size))
    return counts


class FedRecord(NamedTuple):
    """What :func:`feed_record` saw: the compensated value sent per command (the command
    itself where the pipeline dropped it), which commands were accepted, and the data time
    (s after the first command) of the first published estimate (None: none)."""

    sent: np.ndarray
    accepted: np.ndarray
    first_estimate_s: float | None


def feed_record(pipe: BacklashPipeline, rec: OperationRecord, delay_ns: int = 200_000) -> FedRecord:
    """Feed a simulated record to ``pipe`` message by message, in the order a node receives
    them: each command at its time, each reading ``delay_ns`` after its stamp (a reading and
    a command at the same time: the command first). The caller calls ``pipe.finish()``."""
    cmd_t, cmd_u = rec.command_t_ns, rec.command_u
    enc_t, enc_y = rec.encoder_t_ns, rec.encoder_y
    events = np.concatenate([cmd_t, enc_t + delay_ns])
    kinds = np.concatenate([np.zeros(cmd_t.size, dtype=int), np.ones(enc_t.size, dtype=int)])
    index = np.concatenate([np.arange(cmd_t.size), np.arange(enc_t.size)])
    sent = cmd_u.astype(np.float64, copy=True)
    accepted = np.zeros(cmd_t.size, dtype=bool)
    first: float | None = None
    for j in np.lexsort((kinds, events)).tolist():
        i = int(index[j])
        if kinds[j] == 0:
            result = pipe.on_command_value(None, float(cmd_u[i]), int(cmd_t[i]))
            if result is None:
                continue
            accepted[i] = True
            _, sent[i], outputs = result
        else:
            outputs = pipe.on_encoder_value(int(enc_t[i]), float(enc_y[i]), int(events[j]))
        if first is None and any(o.topic == "estimate" for o in outputs):
            first = (int(events[j]) - int(cmd_t[0])) / 1e9
    return FedRecord(sent, accepted, first)


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
