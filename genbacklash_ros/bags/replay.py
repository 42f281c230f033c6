"""Offline replay of a bag through the node's pipeline (replay *is* the node, fed from a file).

:func:`replay` reads the command and encoder topics of a rosbag2 directory or ``.mcap`` file
in log-time order, gives every message to one
:class:`~genbacklash_ros.node.pipeline.BacklashPipeline` with its log time as the receive time, and
writes an output bag with the input topics (copied byte for byte) plus what the node publishes:

* ``/backlash_identifier/estimate`` (``std_msgs/Float64MultiArray``),
* ``/compensated_command`` (the command's type, one per command message),
* ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``),

each logged at the log time of the input message that produced it. The returned
:class:`ReplayResult` holds the final estimate, the pipeline's counters and a
:class:`ReplayHistory` (estimates over time, raw and compensated commands, encoder samples)
and the input bag's metadata ``custom_data`` (a synthetic bag's truth) for
:mod:`genbacklash_ros.reports.replay`.

When the input turns out corrupt or truncated part-way, the replay stops there, flushes the
pipeline (:meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.finish`), closes the output bag
properly (it stays readable) and returns the reason in :attr:`ReplayResult.error`.
"""

from __future__ import annotations

import contextlib
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from genbacklash_core import Estimate
from genbacklash_ros.bags.bagio import (
    COMMAND_MSGTYPES,
    ENCODER_MSGTYPES,
    BagError,
    BagReader,
    BagWriter,
    RawMessage,
    RawRecord,
    check_motor,
    check_selection,
)
from genbacklash_ros.bags.prefetch import PrefetchedMessages, can_prefetch
from genbacklash_ros.bags.raw_values import RawValueReader, UndecodableMessage
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.gc_pauses import few_collections
from genbacklash_ros.node.compensate import CompensationStatus
from genbacklash_ros.node.messages import DiagnosticArray, Float64MultiArray, MessageError
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline, Output, PipelineStats

__all__ = ["OUTPUT_TOPICS", "ReplayHistory", "ReplayResult", "replay"]

OUTPUT_TOPICS: dict[str, str] = {
    "estimate": "/backlash_identifier/estimate",
    "compensated_command": "/compensated_command",
    "diagnostics": "/diagnostics",
}
"""Pipeline output key -> topic in the output bag (the node's names, GUIDE §4)."""

_PROGRESS_EVERY = 2048
_BLOCK = 8192  # input messages handed to the pipeline at once (BacklashPipeline.on_batch)


@dataclass
class ReplayHistory:
    """What a replay saw and published, for reports (times in integer nanoseconds).

    Attributes
    ----------
    names : tuple of str
        Parameter names of the estimates.
    estimate_t, estimates : list
        Data time and :class:`~genbacklash_core.Estimate` of every ``estimate`` output.
    command_t, command_raw, command_sent : list
        Time, raw value and compensated value of every accepted command.
    encoder_t, encoder_y : list
        Time and value of every readable encoder message.
    compensation_t, compensation : list
        Data time of every ``diagnostics`` output and the compensation's status it reported
        (:class:`~genbacklash_ros.node.compensate.CompensationStatus`: on, faded or off, and
        why).
    """

    names: tuple[str, ...] = ()
    estimate_t: list[int] = field(default_factory=list)
    estimates: list[Estimate] = field(default_factory=list)
    command_t: list[int] = field(default_factory=list)
    command_raw: list[float] = field(default_factory=list)
    command_sent: list[float] = field(default_factory=list)
    encoder_t: list[int] = field(default_factory=list)
    encoder_y: list[float] = field(default_factory=list)
    compensation_t: list[int] = field(default_factory=list)
    compensation: list[CompensationStatus] = field(default_factory=list)

    def parameters(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(t_s, values, std)``: time in seconds from the first estimate, parameter
        values and standard deviations, shapes ``(K,)``, ``(K, P)``, ``(K, P)``."""
        if not self.estimates:
            empty = np.zeros((0, len(self.names)))
            return np.zeros(0), empty, empty
        t = np.asarray(self.estimate_t, dtype=np.int64)
        t_s = (t - t[0]) / 1e9
        values = np.array([e.parameters for e in self.estimates])
        std = np.array([e.std() for e in self.estimates])
        return t_s, values, std


@dataclass(frozen=True)
class ReplayResult:
    """The outcome of :func:`replay`.

    Attributes
    ----------
    output : Path
        The output bag directory.
    estimate : Estimate
        The final estimate (after :meth:`BacklashPipeline.finish`).
    stats : PipelineStats
    params : NodeParameters
        The parameters the pipeline ran with (types taken from the bag).
    messages_in, messages_out : int
        Messages read from the input, written to the output (inputs included).
    seconds : float
        Wall-clock time of the replay.
    history : ReplayHistory
    error : str
        Why the replay stopped early ("" when it read the whole input).
    custom_data : dict or None
        The input bag's metadata ``custom_data`` (a synthetic bag's truth lives there:
        :func:`genbacklash_ros.bags.simbags.read_truth`); None when it has none.
    servo : dict or None
        The servo model the identifier's input went through
        (:attr:`~genbacklash_ros.node.pipeline.BacklashPipeline.servo`); None with
        ``servo_model`` none.
    input_topics : tuple of str
        Every topic of the input bag (whether it holds a node's outputs:
        :func:`~genbacklash_ros.bags.bagio.node_outputs`).
    """

    output: Path
    estimate: Estimate
    stats: PipelineStats
    params: NodeParameters
    messages_in: int
    messages_out: int
    seconds: float
    history: ReplayHistory
    error: str = ""
    custom_data: dict[str, str] | None = None
    servo: dict[str, object] | None = None
    input_topics: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """JSON-ready summary: the final estimate (``Estimate.to_dict``) plus counters."""
        out: dict[str, object] = dict(self.estimate.to_dict())
        out["output"] = str(self.output)
        out["messages_in"] = self.messages_in
        out["messages_out"] = self.messages_out
        out["commands"] = self.stats.commands
        out["compensated"] = self.stats.compensated
        out["dropped"] = dict(self.stats.dropped)
        out["error"] = self.error or None
        if self.servo is not None:  # servo_model: the servo the input was modelled through
            out["servo"] = dict(self.servo)
        return out


def _compensation_of(message: Any) -> CompensationStatus:
    """The compensation's status a ``/diagnostics`` message reports (its key-value pairs)."""
    values = {kv.key: kv.value for kv in message.status[0].values}
    return CompensationStatus(
        float(values.get("compensation_weight", "nan")),
        values.get("compensation_state", "off"),
        values.get("compensation_reason", ""),
    )


class _Progress:
    """Progress over the input messages on stderr (updated in blocks: cheap): a bar on a
    terminal, a plain line every few seconds otherwise (:class:`~genbacklash_ros.progress.
    Progress`)."""

    def __init__(self, total: int, enabled: bool) -> None:
        from genbacklash_ros.progress import Progress

        self._bar = Progress(
            "genbacklash replay", total=total, unit="msg", enabled=enabled, unit_scale=True
        )
        self._pending = 0

    def step(self, count: int = 1) -> None:
        self._pending += count
        if self._pending >= _PROGRESS_EVERY:
            self._bar.update(self._pending)
            self._pending = 0

    def close(self) -> None:
        self._bar.update(self._pending)
        self._pending = 0
        self._bar.close()


class _CorruptMessages:
    """Messages whose bytes do not decode: skipped (the replay goes on, like the node),
    and reported at the end, since they mean the bag is damaged."""

    def __init__(self) -> None:
        self.count = 0
        self.first = ""

    def note(self, err: MessageError, topic: str, log_time: int) -> None:
        if isinstance(err, UndecodableMessage):
            self.count += 1
            if not self.first:
                self.first = f"{topic} at log time {log_time} ns: {err}"

    def summary(self, bag: Path) -> str:
        if not self.count:
            return ""
        which = "message was" if self.count == 1 else "messages were"
        return (
            f"{bag} is corrupt: {self.count} {which} not decodable and skipped "
            f"(first: {self.first})"
        )


class _Feed:
    """Blocks of input messages through the pipeline, and what it publishes into the output.

    Each block's values are read at once (:meth:`RawValueReader.read_many`) and given to
    :meth:`BacklashPipeline.on_batch`; a message whose bytes the fast reader does not take is
    read (or rejected) by itself, in its place, through the per-message path
    (:meth:`BacklashPipeline.on_command_value`, :meth:`~BacklashPipeline.on_encoder_value`),
    as every message is when not ``batched``. The input messages are copied as raw records,
    each followed by what it made the node publish.
    """

    def __init__(
        self,
        pipeline: BacklashPipeline,
        read_cmd: RawValueReader,
        read_enc: RawValueReader,
        writer: BagWriter,
        command_topic: str,
        command_type: str,
        history: ReplayHistory,
        corrupt: _CorruptMessages,
        publish: Callable[[list[Output], int], list[RawMessage]],
        use_header: bool,
        batched: bool,
        motor: tuple[str, RawValueReader] | None = None,
    ) -> None:
        self.pipeline = pipeline
        self.read_cmd, self.read_enc = read_cmd, read_enc
        self.writer = writer
        self.command_topic, self.command_type = command_topic, command_type
        self.history = history
        self.corrupt = corrupt
        self.publish = publish
        self.use_header = use_header
        self.batched = batched
        # a motor encoder (the gear's input): its messages go the per-message way
        self.motor_topic = motor[0] if motor is not None else ""
        self.read_motor: RawValueReader | None = motor[1] if motor is not None else None

    def block(self, items: list[RawRecord]) -> None:
        """Feed ``items`` (in log-time order; :class:`RawMessage`\\ s or their fields as
        tuples) and write the output they make."""
        n = len(items)
        topics, times, _types, raws = zip(*items, strict=True)  # the fields, each in order
        names = np.array(topics, dtype=object)
        is_cmd = names == self.command_topic
        is_mot = names == self.motor_topic if self.read_motor is not None else None
        heads = np.zeros(n, dtype=np.int64)
        values = np.full(n, np.nan)
        ok = np.zeros(n, dtype=bool)
        fits = True
        try:
            log = np.fromiter(times, dtype=np.int64, count=n)
        except OverflowError:  # a damaged record's time: this block goes message by message
            log = np.zeros(n, dtype=np.int64)
            fits = batched = False
        else:
            batched = self.batched
        if batched:
            enc_mask = ~is_cmd if is_mot is None else ~is_cmd & ~is_mot
            for reader, mine in ((self.read_cmd, is_cmd), (self.read_enc, enc_mask)):
                where = np.flatnonzero(mine)
                h, v, good = reader.read_many([raws[k] for k in where.tolist()])
                heads[where], values[where], ok[where] = h, v, good
        pipe = self.pipeline
        history = self.history
        sent = np.full(n, np.nan)
        accepted = np.zeros(n, dtype=bool)
        stamps = np.zeros(n, dtype=np.int64)
        outputs: dict[int, list[Output]] = {}
        start = 0
        odd_ones = ~ok if is_mot is None else ~ok | is_mot
        for odd in [*np.flatnonzero(odd_ones).tolist(), n]:  # not batched: every message
            if odd > start:  # the messages read at once: one batch
                part = pipe.on_batch(
                    is_cmd[start:odd], heads[start:odd], values[start:odd], log[start:odd]
                )
                accepted[start:odd], stamps[start:odd], sent[start:odd] = (
                    part.accepted,
                    part.stamps,
                    part.sent,
                )
                for k, out in part.outputs:
                    outputs.setdefault(start + k, []).append(out)
            if odd == n:
                break
            if is_mot is not None and is_mot[odd]:
                more = self._motor(RawMessage(*items[odd]))
                if more:
                    outputs[odd] = more
                start = odd + 1
                continue
            outs = self._one(RawMessage(*items[odd]), bool(is_cmd[odd]), heads, values, ok, odd)
            if outs is not None:
                taken, more = outs
                if taken is not None:
                    stamps[odd], sent[odd] = taken
                    accepted[odd] = True
                if more:
                    outputs[odd] = more
            start = odd + 1
        enc = np.flatnonzero(~is_cmd & ok if is_mot is None else ~is_cmd & ~is_mot & ok)
        if fits:  # the log times as int64
            stamped = heads[enc] if self.use_header else np.zeros(enc.size, dtype=np.int64)
            history.encoder_t.extend(np.where(stamped != 0, stamped, log[enc]).tolist())
        else:
            history.encoder_t.extend(
                head if self.use_header and head else times[k]
                for k, head in zip(enc.tolist(), heads[enc].tolist(), strict=True)
            )
        history.encoder_y.extend(values[enc].tolist())
        cmd = np.flatnonzero(accepted)
        history.command_t.extend(stamps[cmd].tolist())
        history.command_raw.extend(values[cmd].tolist())
        history.command_sent.extend(sent[cmd].tolist())
        # the input copied as read, each accepted command followed by its compensated
        # command and each message by what it made the node publish: whole runs of input
        # records go into the list at once, between the messages that add something
        comp_topic = OUTPUT_TOPICS["compensated_command"]
        comp_type = self.command_type
        events = cmd.tolist()
        patched = self.read_cmd.patch_many([raws[k] for k in events], sent[cmd])
        compensated = dict(zip(events, patched, strict=True))
        writer = self.writer
        if outputs:
            events = sorted({*events, *outputs})
        accepted_list = accepted.tolist()
        records: list[RawRecord] = []
        done = 0
        for k in events:
            records += items[done : k + 1]
            done = k + 1
            log_time = times[k]
            if accepted_list[k]:
                records.append(RawMessage(comp_topic, log_time, comp_type, compensated[k]))
            due = outputs.get(k)
            if due:
                records += self.publish(due, log_time)
        records += items[done:]
        writer.write_messages(records)

    def _motor(self, item: RawMessage) -> list[Output]:
        """A motor encoder message through the per-message path (rejected when its bytes
        do not decode)."""
        assert self.read_motor is not None
        try:
            header_ns, value = self.read_motor.read(item.raw)
        except MessageError as err:
            self.pipeline.reject("motor", str(err))
            self.corrupt.note(err, item.topic, item.log_time_ns)
            return []
        return self.pipeline.on_motor_value(header_ns, value, item.log_time_ns)

    def _one(
        self,
        item: RawMessage,
        is_cmd: bool,
        heads: np.ndarray,
        values: np.ndarray,
        ok: np.ndarray,
        k: int,
    ) -> tuple[tuple[int, float] | None, list[Output]] | None:
        """A message by itself through the per-message path (rejected when its bytes do
        not decode); records its stamp and value in ``heads``, ``values`` and ``ok[k]``."""
        pipe = self.pipeline
        stream: Literal["command", "encoder"] = "command" if is_cmd else "encoder"
        reader = self.read_cmd if is_cmd else self.read_enc
        try:
            header_ns, value = reader.read(item.raw)
        except MessageError as err:
            pipe.reject(stream, str(err))
            self.corrupt.note(err, item.topic, item.log_time_ns)
            return None
        heads[k], values[k], ok[k] = header_ns, value, True
        if is_cmd:
            taken = pipe.on_command_value(header_ns, value, item.log_time_ns)
            if taken is None:
                return None
            stamp, sent, outs = taken
            return (stamp, sent), outs
        return None, pipe.on_encoder_value(header_ns, value, item.log_time_ns)


def _replay_params(
    base: NodeParameters | None,
    command_msgtype: str,
    encoder_msgtype: str,
    overrides: dict[str, object],
) -> NodeParameters:
    params = NodeParameters() if base is None else base
    changes: dict[str, object] = {
        "command_type": COMMAND_MSGTYPES[command_msgtype],
        "encoder_type": ENCODER_MSGTYPES[encoder_msgtype],
        # replay: the recorded command is what the drivetrain got (issue 4, item 1)
        "compensation_in_loop": False,
        # a replay runs once: a checkpoint file of a live node must not be overwritten
        "checkpoint_file": "",
    }
    changes.update({k: v for k, v in overrides.items() if v is not None})
    return params.replace(**changes)


def replay(
    bag: str | Path,
    output: str | Path,
    *,
    command_topic: str,
    encoder_topic: str,
    params: NodeParameters | None = None,
    joint: str | None = None,
    command_index: int | None = None,
    model: str | None = None,
    degree: int | None = None,
    na: int | None = None,
    nb: int | None = None,
    method: str | None = None,
    progress: bool = False,
    batched: bool = True,
    motor_topic: str | None = None,
    motor_joint: str | None = None,
    prefetch: bool = True,
) -> ReplayResult:
    """Replay ``bag`` through one :class:`BacklashPipeline` and write ``output``.

    Parameters
    ----------
    bag : str or Path
        rosbag2 directory or ``.mcap`` file.
    output : str or Path
        Output bag directory (must not exist).
    command_topic, encoder_topic : str
        Topics of the command (Float64, Float64MultiArray, JointState) and of the encoder
        (JointState, Float64); their types set ``command_type`` and ``encoder_type``.
    params : NodeParameters, optional
        Node parameters (e.g. from a params file); the keyword arguments below override them.
    joint, command_index, model, degree, na, nb, method : optional
        Overrides of the parameters of the same name (None: keep).
    progress : bool
        Show a tqdm progress bar on stderr.
    batched : bool
        Feed the pipeline blocks of messages (:meth:`BacklashPipeline.on_batch`, the fast
        path); False: one message at a time (:meth:`~BacklashPipeline.on_command_value`,
        :meth:`~BacklashPipeline.on_encoder_value`). The outputs are the same.
    motor_topic : str, optional
        A motor encoder's topic (JointState or Float64; dual encoders): the gear's input
        (``gear_input = "motor_encoder"``, ``motor_encoder_type`` from its type), copied to
        the output like the others. The pipeline then takes every message by itself (its
        per-message path), a few times slower than the block path.
    motor_joint : str, optional
        The motor encoder JointState's joint (None: the parameter ``motor_joint``, else
        ``joint``).
    prefetch : bool
        Read the bag one block ahead in a child process, on a second core
        (:mod:`genbacklash_ros.bags.prefetch`), where one can be forked safely and pays:
        from a process of one thread, not daemonic, on more than one CPU, with a CPU free
        (the load average below the CPUs), without ``GENBACKLASH_PREFETCH=0``
        (:func:`~genbacklash_ros.bags.prefetch.can_prefetch`); else, and with False or
        ``batched`` False, read in this process. The outputs are the same.

    Returns
    -------
    ReplayResult

    Raises
    ------
    BagError
        The input cannot be opened, a topic is missing or of an unsupported type, the
        joint or command index matches nothing in the bag
        (:func:`~genbacklash_ros.bags.bagio.check_selection`), or the output cannot be
        created. Damage found part-way does not raise: see
        :attr:`ReplayResult.error`.
    """
    if command_topic == encoder_topic:
        raise BagError(f"the command and encoder topics must differ, both are {command_topic!r}")
    started = time.perf_counter()
    with (
        few_collections(),
        one_blas_thread(),
        BagReader(bag) as reader,
        contextlib.ExitStack() as stop,
    ):
        cmd_info = reader.topic(command_topic, COMMAND_MSGTYPES)
        enc_info = reader.topic(encoder_topic, ENCODER_MSGTYPES)
        custom_data = reader.custom_data
        input_topics = tuple(reader.topics)
        overrides: dict[str, object] = {
            "joint": joint,
            "command_index": command_index,
            "model": model,
            "degree": degree,
            "na": na,
            "nb": nb,
            "method": method,
        }
        mot_type = ""
        if motor_topic is not None:
            try:
                mot_type = reader.topic(motor_topic, ENCODER_MSGTYPES).msgtype
            except BagError as err:
                raise BagError(f"motor encoder: {err}") from err
            overrides["gear_input"] = "motor_encoder"
            overrides["motor_encoder_type"] = ENCODER_MSGTYPES[mot_type]
            overrides["motor_joint"] = motor_joint
        run_params = _replay_params(params, cmd_info.msgtype, enc_info.msgtype, overrides)
        # a joint, an index or a topic that matches nothing stops here, before any output
        check_selection(
            reader,
            command_topic,
            encoder_topic,
            joint=run_params.joint,
            command_index=run_params.command_index,
        )
        topics = [command_topic, encoder_topic]
        motor: tuple[str, RawValueReader] | None = None
        if motor_topic is not None:
            check_motor(reader, motor_topic, topics, joint=run_params.motor_joint_name)
            motor = (
                motor_topic,
                RawValueReader(mot_type, "encoder", joint=run_params.motor_joint_name),
            )
            topics.append(motor_topic)
        elif run_params.motor_input:
            raise BagError(
                "the parameters say gear_input motor_encoder: name the motor encoder's topic "
                "with --motor-encoder TOPIC"
            )
        # the reading child is forked now, before this replay starts threads (a progress
        # bar's, the writer's): a fork copies only the calling thread (can_prefetch)
        source: PrefetchedMessages | None = None
        if prefetch and batched and can_prefetch():  # closed (the child waited for) on exit
            source = stop.enter_context(PrefetchedMessages(reader.path, topics, _BLOCK))
        pipeline = BacklashPipeline(run_params)
        history = ReplayHistory(names=run_params.structure().names())
        index, joint_name = run_params.command_index, run_params.joint
        use_header = run_params.stamp_source == "header"
        error = ""
        count = 0
        last_log = 0
        bar = _Progress(reader.count(topics), progress)
        with BagWriter(output) as writer:
            writer.add_topic(command_topic, cmd_info.msgtype)
            writer.add_topic(encoder_topic, enc_info.msgtype)
            if motor_topic is not None:
                writer.add_topic(motor_topic, mot_type)
            writer.add_topic(OUTPUT_TOPICS["estimate"], Float64MultiArray.ros_type)
            writer.add_topic(OUTPUT_TOPICS["compensated_command"], cmd_info.msgtype)
            writer.add_topic(OUTPUT_TOPICS["diagnostics"], DiagnosticArray.ros_type)

            last_estimate: list[Any] = [None, b""]  # the estimate message encoded last

            def publish(outputs: list[Output], log_time: int) -> list[RawMessage]:
                """The records of what the node published at ``log_time``."""
                records = []
                for out in outputs:
                    message = out.message
                    if out.topic != "estimate":
                        raw = writer.encode(message)
                    elif message == last_estimate[0]:  # unchanged since: its bytes again
                        raw = last_estimate[1]
                    else:
                        raw = writer.encode(message)
                        last_estimate[:] = [message, raw]
                    records.append(
                        RawMessage(OUTPUT_TOPICS[out.topic], log_time, message.ros_type, raw)
                    )
                    if out.topic == "estimate" and out.estimate is not None:
                        history.estimate_t.append(out.stamp_ns)
                        history.estimates.append(out.estimate)
                    elif out.topic == "diagnostics":
                        history.compensation_t.append(out.stamp_ns)
                        history.compensation.append(_compensation_of(message))
                return records

            # Values come straight from the CDR bytes (RawValueReader: a layout learnt from
            # rosbags, the adapters' rules) and the compensated command is the command's
            # bytes with its value replaced: no message objects on the way.
            read_cmd = RawValueReader(cmd_info.msgtype, "command", index=index, joint=joint_name)
            read_enc = RawValueReader(enc_info.msgtype, "encoder", joint=joint_name)
            corrupt = _CorruptMessages()
            feed = _Feed(
                pipeline,
                read_cmd,
                read_enc,
                writer,
                command_topic,
                cmd_info.msgtype,
                history,
                corrupt,
                publish,
                use_header,
                batched,
                motor,
            )
            block: list[RawRecord] = []
            stream = iter(source) if source is not None else reader.raw_messages(topics)
            size = _BLOCK if batched else 1
            try:
                while True:
                    # extend keeps what it took when the reader raises part-way
                    block.extend(itertools.islice(stream, size))
                    if not block:
                        break
                    # taken out first: if feeding raises (Ctrl-C), the block is not fed again
                    taken, block = block, []
                    feed.block(taken)
                    count += len(taken)
                    last_log = taken[-1][1]
                    bar.step(len(taken))
            except BagError as err:
                error = str(err)
            finally:
                if block:  # what was read before the damage (or the last block)
                    feed.block(block)
                    count += len(block)
                    last_log = block[-1][1]
                    bar.step(len(block))
                bar.close()
            error = error or corrupt.summary(Path(bag))
            writer.write_messages(publish(pipeline.finish(), last_log))
            messages_out = writer.count
    return ReplayResult(
        Path(output),
        pipeline.estimate,
        pipeline.stats,
        run_params,
        count,
        messages_out,
        time.perf_counter() - started,
        history,
        error,
        custom_data,
        pipeline.servo,
        input_topics,
    )
