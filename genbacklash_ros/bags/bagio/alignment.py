"""The batch form of the pipeline's alignment: one sample per encoder message with the command
held (:func:`align`, :func:`read_aligned`), and which topics are the node's outputs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from genbacklash_core.measured import OfflineBaseline
from genbacklash_core.servo import ServoFit, ServoModel
from genbacklash_ros.bags.raw_values import RawValueReader
from genbacklash_ros.node.sample_rule import ServoChoice, select_rows

from .messages import BagError, RawMessage
from .reader import BagReader
from .selection import check_motor, check_selection

# --------------------------------------------------------------------------- alignment


@dataclass(frozen=True, eq=False)
class AlignedSeries:
    """Identification samples: one per encoder message, the command held.

    ``t`` (int64 ns), ``u`` (the latest command at or before ``t``), ``y`` (the encoder);
    ``skipped`` counts encoder samples before the first command; ``breaks`` (bool) the
    sample rule: True where a sample does not follow the one before it on the encoder's
    clock (:mod:`genbacklash_ros.node.sample_rule`; pass it to the identifiers' ``breaks``).
    ``damage``: why the bag's reading stopped early ("" when it was read to its end; see
    :func:`read_aligned`'s ``keep_readable``). ``servo``, ``servo_fit``: the servo model
    whose output ``u`` is, and its estimate (:func:`~genbacklash_ros.node.sample_rule.select_rows`).
    ``baseline``: the record's tracking without compensation as the node's judge measures
    it (:func:`read_aligned`'s ``baseline``; None when not asked for, or when the bag may
    hold compensation: :func:`node_outputs`).
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    skipped: int
    breaks: np.ndarray
    damage: str = ""
    servo: ServoModel | None = None
    servo_fit: ServoFit | None = None
    baseline: OfflineBaseline | None = None


def node_outputs(topics: Iterable[str]) -> list[str]:
    """The topics of ``topics`` the node publishes (a compensated command, its estimate): a
    record that holds one may have had compensation in the loop, so its tracking is not
    counted as tracking without compensation (``/diagnostics`` is every node's, not counted).

    >>> node_outputs(["/command", "/encoder", "/compensated_command", "/diagnostics"])
    ['/compensated_command']
    """
    marks = ("compensated_command", "backlash_identifier/estimate")
    return [t for t in topics if t.endswith(marks)]


def align(
    cmd_t: np.ndarray,
    cmd_u: np.ndarray,
    enc_t: np.ndarray,
    enc_y: np.ndarray,
    *,
    marks: np.ndarray | None = None,
    bridge: bool = False,
    settle_ns: int = 0,
    servo: ServoChoice = None,
    motor: bool = False,
) -> AlignedSeries:
    """Zero-order-hold alignment of a command stream to encoder times (batch form); the rows
    and their breaks are :func:`~genbacklash_ros.node.sample_rule.select_rows`'s (shared with
    a CSV of the same readings).

    The pipeline's rule (:mod:`genbacklash_ros.node.pipeline`, ``sample_period = 0``): the input
    of the sample at encoder time ``t`` is the latest command with time ``<= t``; samples
    before the first command are skipped. Both streams must be sorted by time. With
    ``motor`` the "commands" are a motor encoder's readings (the gear's input): a reading
    whose motor reading is not its own is taken out
    (:func:`~genbacklash_ros.node.sample_rule.paired_keep`) and ``settle_ns`` is not applied.

    The breaks follow the pipeline's sample rule too: the encoder's nominal period is the
    median difference of ``enc_t`` (:func:`~genbacklash_core.samples.nominal_period`), a
    sample breaks where its stamp is not one period, rounded, after the one before, and
    where ``marks`` (one per encoder reading) says a reading was taken out before it (a
    message the adapters rejected); the first sample kept always breaks. With ``bridge`` (for
    a backlash alone: :func:`~genbacklash_core.samples.bridge_lost`), a break that only lost
    readings made -- at most :data:`~genbacklash_core.samples.MAX_BRIDGED` of them, none
    rejected -- is lifted where the commands in force over the gap were monotone.

    >>> s = align(np.array([10, 20]), np.array([1.0, 2.0]), np.array([5, 10, 15, 25]),
    ...           np.array([0.1, 0.2, 0.3, 0.4]))
    >>> s.u.tolist(), s.y.tolist(), s.skipped
    ([1.0, 1.0, 2.0], [0.2, 0.3, 0.4], 1)
    >>> s.breaks.tolist()  # 20 ns lost between 15 and 25
    [True, False, True]
    """
    ct = np.asarray(cmd_t, dtype=np.int64)
    et = np.asarray(enc_t, dtype=np.int64)
    k = np.searchsorted(ct, et, side="right") - 1
    rows = select_rows(
        et,
        k,
        cmd_u,
        enc_y,
        marks=marks,
        bridge=bridge,
        settle_ns=0 if motor else settle_ns,
        servo=None if motor else servo,
        input_stamps=ct if motor else None,
    )
    return AlignedSeries(
        rows.t,
        rows.u,
        rows.y,
        rows.skipped,
        rows.breaks,
        servo=rows.servo,
        servo_fit=rows.servo_fit,
    )


def _increasing(times: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop samples whose time is not after the previous accepted one (as the pipeline)."""
    t = np.asarray(times, dtype=np.int64)
    keep = _increasing_mask(t)
    return t[keep], np.asarray(values, dtype=np.float64)[keep]


def _increasing_mask(t: np.ndarray) -> np.ndarray:
    """Which of the times ``t`` are after every one before them."""
    if t.size < 2:
        return np.ones(t.size, dtype=bool)
    return t > np.maximum.accumulate(np.concatenate(([np.iinfo(np.int64).min], t[:-1])))


def read_aligned(
    path: str | Path,
    command_topic: str,
    encoder_topic: str,
    *,
    joint: str = "",
    command_index: int = 0,
    bridge: bool = False,
    settle_ns: int = 0,
    keep_readable: bool = False,
    servo: ServoChoice = None,
    motor_topic: str | None = None,
    motor_joint: str = "",
    baseline: bool = False,
) -> AlignedSeries:
    """Read a command and an encoder topic from a bag and align them (see :func:`align`;
    ``bridge`` for a backlash alone; ``settle_ns`` the servo's settling rule, as the node;
    ``servo`` the servo model, or ``"auto"``).

    With ``baseline`` the record's tracking without compensation is measured as the node's
    judge measures it (:func:`~genbacklash_ros.node.tracking_stage.record_baseline`, the
    encoder readings against the commands) into :attr:`AlignedSeries.baseline`, unless
    the bag holds a node's outputs (:func:`node_outputs`: compensation may have been in the
    loop).

    With ``motor_topic`` (a motor encoder, dual encoders: the node's ``gear_input =
    "motor_encoder"``) the input of each row is the motor reading of the encoder reading's
    stamp (``motor_joint``: its joint, default ``joint``), as the node pairs them; the
    command topic is still checked and read (the rows start at the first command).

    A bag that turns out truncated or corrupt part-way raises :class:`BagError`; with
    ``keep_readable`` the messages before the damage are aligned instead, as a replay keeps
    them, and :attr:`AlignedSeries.damage` says where the reading stopped.

    Times are header stamps when the message has a non-zero one, else the log time (the
    pipeline's default ``stamp_source = "header"``). Messages the adapters reject (joint
    missing, index out of range, non-finite values) are skipped; a rejected encoder message
    breaks the chain of consecutive samples at the next encoder reading in log order, as in
    the pipeline (``breaks``, see :func:`align`).
    """
    with BagReader(path) as reader:
        cmd_info, enc_info = check_selection(
            reader, command_topic, encoder_topic, joint=joint, command_index=command_index
        )
        plain = not node_outputs(reader.topics)
        cmd_type, enc_type = cmd_info.msgtype, enc_info.msgtype
        motor_joint = motor_joint or joint
        mot_type = ""
        if motor_topic is not None:
            mot_type = check_motor(
                reader, motor_topic, (command_topic, encoder_topic), joint=motor_joint
            ).msgtype
        # values straight from the CDR bytes, in numpy steps per block; a message the fast
        # path cannot vouch for is read (or rejected) by the adapters, one by one
        readers = {
            command_topic: RawValueReader(cmd_type, "command", index=command_index, joint=joint),
            encoder_topic: RawValueReader(enc_type, "encoder", joint=joint),
        }
        parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {
            command_topic: [],
            encoder_topic: [],
        }
        if motor_topic is not None:
            readers[motor_topic] = RawValueReader(mot_type, "encoder", joint=motor_joint)
            parts[motor_topic] = []

        def take(block: list[RawMessage]) -> None:
            for topic, read in readers.items():
                mine = [m for m in block if m.topic == topic]
                head, value, ok = read.read_all([m.raw for m in mine])
                log = np.fromiter((m.log_time_ns for m in mine), dtype=np.int64, count=len(mine))
                parts[topic].append((np.where(head != 0, head, log), value, ok))

        block: list[RawMessage] = []
        damage = ""
        try:
            for item in reader.raw_messages(list(parts)):
                block.append(item)
                if len(block) >= 8192:
                    take(block)
                    block = []
        except BagError as err:  # damaged part-way: the messages before it were yielded
            if not keep_readable:
                raise
            damage = str(err)
        take(block)

    c_t, c_u, c_ok = (np.concatenate(a) for a in zip(*parts[command_topic], strict=True))
    e_t, e_y, e_ok = (np.concatenate(a) for a in zip(*parts[encoder_topic], strict=True))
    # a reading taken out (rejected) breaks the chain at the next one kept (log order)
    e_m = np.diff(np.cumsum(~e_ok)[e_ok], prepend=0) > 0
    c_t, c_u, e_t, e_y = c_t[c_ok], c_u[c_ok], e_t[e_ok], e_y[e_ok]
    before = f" before the damage ({damage})" if damage else ""
    if not c_t.size:
        raise BagError(f"no readable command on {command_topic!r} in {path}{before}")
    if not e_t.size:
        raise BagError(f"no readable encoder reading on {encoder_topic!r} in {path}{before}")
    order_c = np.argsort(c_t, kind="stable")
    order_e = np.argsort(e_t, kind="stable")
    c_t, c_u = _increasing(c_t[order_c], c_u[order_c])
    e_t, e_y, e_m = e_t[order_e], e_y[order_e], e_m[order_e]
    unique = _increasing_mask(e_t)
    if not unique.all():  # a duplicate's mark passes to the next reading kept
        seen = np.cumsum(e_m)[unique]
        e_m = np.diff(seen, prepend=0) > 0
        e_t, e_y = e_t[unique], e_y[unique]
    if motor_topic is not None:  # the gear's input: the motor readings after the first command
        m_t, m_y, m_ok = (np.concatenate(a) for a in zip(*parts[motor_topic], strict=True))
        m_t, m_y = m_t[m_ok], m_y[m_ok]
        if not m_t.size:
            raise BagError(f"no readable motor reading on {motor_topic!r} in {path}{before}")
        order_m = np.argsort(m_t, kind="stable")
        m_t, m_y = _increasing(m_t[order_m], m_y[order_m])
        after = m_t >= c_t[0]
        m_t, m_y = m_t[after], m_y[after]
        if not m_t.size:
            raise BagError(f"no motor reading on {motor_topic!r} follows the first command")
        series = align(m_t, m_y, e_t, e_y, marks=e_m, bridge=bridge, motor=True)
    else:
        series = align(
            c_t, c_u, e_t, e_y, marks=e_m, bridge=bridge, settle_ns=settle_ns, servo=servo
        )
    if series.t.size == 0:
        raise BagError(f"no encoder reading on {encoder_topic!r} follows the first command{before}")
    if baseline and plain:
        from genbacklash_ros.node.tracking_stage import record_baseline

        series = dataclasses.replace(series, baseline=record_baseline(c_t, c_u, e_t, e_y))
    return dataclasses.replace(series, damage=damage) if damage else series
