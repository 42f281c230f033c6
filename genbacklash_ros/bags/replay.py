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

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from genbacklash_core import Estimate
from genbacklash_ros.bags.bagio import (
    COMMAND_MSGTYPES,
    ENCODER_MSGTYPES,
    BagError,
    BagReader,
    BagWriter,
)
from genbacklash_ros.bags.raw_values import RawValueReader, UndecodableMessage
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
    """

    names: tuple[str, ...] = ()
    estimate_t: list[int] = field(default_factory=list)
    estimates: list[Estimate] = field(default_factory=list)
    command_t: list[int] = field(default_factory=list)
    command_raw: list[float] = field(default_factory=list)
    command_sent: list[float] = field(default_factory=list)
    encoder_t: list[int] = field(default_factory=list)
    encoder_y: list[float] = field(default_factory=list)

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
        return out


class _Progress:
    """A tqdm bar on stderr over the input messages (updated in blocks: cheap)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self._bar = None
        self._pending = 0
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc="replay", unit="msg", unit_scale=True, leave=False)

    def step(self) -> None:
        self._pending += 1
        if self._pending >= _PROGRESS_EVERY and self._bar is not None:
            self._bar.update(self._pending)
            self._pending = 0

    def close(self) -> None:
        if self._bar is not None:
            self._bar.update(self._pending)
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

    Returns
    -------
    ReplayResult

    Raises
    ------
    BagError
        The input cannot be opened, a topic is missing or of an unsupported type, or the
        output cannot be created. Damage found part-way does not raise: see
        :attr:`ReplayResult.error`.
    """
    if command_topic == encoder_topic:
        raise BagError(f"the command and encoder topics must differ, both are {command_topic!r}")
    started = time.perf_counter()
    with BagReader(bag) as reader:
        cmd_info = reader.topic(command_topic, COMMAND_MSGTYPES)
        enc_info = reader.topic(encoder_topic, ENCODER_MSGTYPES)
        custom_data = reader.custom_data
        overrides: dict[str, object] = {
            "joint": joint,
            "command_index": command_index,
            "model": model,
            "degree": degree,
            "na": na,
            "nb": nb,
            "method": method,
        }
        run_params = _replay_params(params, cmd_info.msgtype, enc_info.msgtype, overrides)
        pipeline = BacklashPipeline(run_params)
        history = ReplayHistory(names=run_params.structure().names())
        index, joint_name = run_params.command_index, run_params.joint
        use_header = run_params.stamp_source == "header"
        error = ""
        count = 0
        last_log = 0
        bar = _Progress(reader.count([command_topic, encoder_topic]), progress)
        with BagWriter(output) as writer:
            writer.add_topic(command_topic, cmd_info.msgtype)
            writer.add_topic(encoder_topic, enc_info.msgtype)
            writer.add_topic(OUTPUT_TOPICS["estimate"], Float64MultiArray.ros_type)
            writer.add_topic(OUTPUT_TOPICS["compensated_command"], cmd_info.msgtype)
            writer.add_topic(OUTPUT_TOPICS["diagnostics"], DiagnosticArray.ros_type)

            def publish(outputs: list[Output], log_time: int) -> None:
                for out in outputs:
                    writer.write(OUTPUT_TOPICS[out.topic], log_time, out.message)
                    if out.topic == "estimate" and out.estimate is not None:
                        history.estimate_t.append(out.stamp_ns)
                        history.estimates.append(out.estimate)

            # Values come straight from the CDR bytes (RawValueReader: a layout learnt from
            # rosbags, the adapters' rules) and the compensated command is the command's
            # bytes with its value replaced: no message objects on the way.
            read_cmd = RawValueReader(cmd_info.msgtype, "command", index=index, joint=joint_name)
            read_enc = RawValueReader(enc_info.msgtype, "encoder", joint=joint_name)
            corrupt = _CorruptMessages()
            comp_topic = OUTPUT_TOPICS["compensated_command"]
            cmd_type = cmd_info.msgtype
            write_raw = writer.write_raw
            enc_t, enc_y = history.encoder_t, history.encoder_y
            try:
                for topic, log_time, msgtype, raw in reader.raw_messages(
                    [command_topic, encoder_topic]
                ):
                    count += 1
                    bar.step()
                    last_log = log_time
                    write_raw(topic, log_time, raw, msgtype)
                    if topic == command_topic:
                        try:
                            header_ns, value = read_cmd.read(raw)
                        except MessageError as err:
                            pipeline.reject("command", str(err))
                            corrupt.note(err, topic, log_time)
                            continue
                        accepted = pipeline.on_command_value(header_ns, value, log_time)
                        if accepted is None:
                            continue
                        stamp, sent, outs = accepted
                        write_raw(comp_topic, log_time, read_cmd.patch(raw, sent), cmd_type)
                        history.command_t.append(stamp)
                        history.command_raw.append(value)
                        history.command_sent.append(sent)
                    else:
                        try:
                            header_ns, value = read_enc.read(raw)
                        except MessageError as err:
                            pipeline.reject("encoder", str(err))
                            corrupt.note(err, topic, log_time)
                            continue
                        enc_t.append(header_ns if use_header and header_ns else log_time)
                        enc_y.append(value)
                        outs = pipeline.on_encoder_value(header_ns, value, log_time)
                    if outs:
                        publish(outs, log_time)
            except BagError as err:
                error = str(err)
            finally:
                bar.close()
            error = error or corrupt.summary(Path(bag))
            publish(pipeline.finish(), last_log)
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
    )
