"""The ``backlash_identifier`` node over plain DDS (cyclonedds), where ROS 2 is not installed.

The same :class:`~genbacklash_ros.node.pipeline.BacklashPipeline` and
:class:`~genbacklash_ros.node.parameters.NodeParameters` as the rclpy node, with what ROS 2 puts on
the wire: topic names ``rt/<name>``, type names ``pkg::msg::dds_::Type_``, ROS 2's CDR
(:mod:`genbacklash_ros.transports.dds_types`) and ROS 2's QoS. ROS 2 nodes on the same
``ROS_DOMAIN_ID`` exchange messages with it (``ros2 topic echo /compensated_command`` works).
It is a ROS 2 graph citizen (:mod:`genbacklash_ros.transports.ros_graph`): its endpoints carry
their REP-2016 type hashes, and it announces itself on ``ros_discovery_info``, so
``ros2 node list`` lists it and ``ros2 topic info -v`` names it. It has no parameter services
(parameters come from a params file at start). Where discovery shows a publisher of another
type on ``command`` or ``encoder``, ``/diagnostics`` says so (key ``wiring``) and names the
parameter that selects the type.

Interface (GUIDE §4; every name remappable, see :class:`Topics`)
-----------------------------------------------------------------
* subscribes ``command`` (default QoS: RELIABLE, VOLATILE) and ``encoder`` (sensor-data QoS:
  BEST_EFFORT, VOLATILE), each reader with a history of :data:`READER_DEPTH` samples rather than
  ROS 2's 10 and 5, so that a busy loop does not lose messages; with ``gear_input``
  motor_encoder also ``motor_encoder`` (the ``motor_encoder_type``, sensor-data QoS), the
  motor-side position that is the gear's input (dual encoders); the readers are created once
  discovery has settled (:func:`~genbacklash_ros.transports.ros_graph.await_discovery`, 1-3 s
  after the start), so that a publisher already running loses nothing after it matches them;
* publishes ``~/estimate`` (``/backlash_identifier/estimate``), ``compensated_command`` (the
  command's type) and ``/diagnostics``, all with the default QoS, ``compensated_command`` with
  a writer history of :data:`~genbacklash_ros.node.wiring.ANSWER_DEPTH` samples (a subscriber
  descheduled while the node answers a backlog gets every answer resent).
* with several joints (a :class:`~genbacklash_ros.node.joints.JointSet` with ``joints``) the
  same pipeline as the rclpy node's (:func:`~genbacklash_ros.node.multijoint.make_pipeline`):
  ``~/<joint>/estimate`` per joint instead of ``~/estimate``, one compensated array, one
  ``/diagnostics`` status per joint.

The loop
--------
One thread runs everything: it waits on a WaitSet holding a ReadCondition (not-read samples)
per reader and a GuardCondition for :meth:`DdsNode.stop`, at most until the next wall-clock
tick (and at most 0.1 s, so that a signal handler runs promptly). On a wake-up it takes every
available sample of every reader, orders them by source timestamp, converts them
(:mod:`genbacklash_ros.transports.dds_convert`) and calls the pipeline, then publishes the
pipeline's outputs. Once per wall-clock second it publishes ``/diagnostics`` with level STALE
when no message arrived during that second (while data flow, the pipeline reports every second of
data time). :meth:`DdsNode.stop` (e.g. from SIGINT/SIGTERM) ends the loop; the node then calls
``pipeline.finish()``, publishes the final estimate and diagnostics, and writes the final
checkpoint (checkpoints are written on a background thread, atomically).

Receive time
------------
Integer nanoseconds. ``receive_time="source"`` (default) takes the sample's DDS source
timestamp (when the writer wrote it; on one host or with synchronised clocks this is the
arrival time less the transport latency, and unlike the time the loop takes the sample it does
not grow late when the loop is busy), never later than the wall clock; ``"take"`` the wall
clock when the loop takes the sample. Either is made strictly increasing per stream (1 ns
steps), so that a burst taken at once is not dropped as duplicates. Messages with a header
stamp use the stamp (``stamp_source`` parameter).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal

from cyclonedds.core import GuardCondition, InstanceState, ReadCondition, SampleState, ViewState
from cyclonedds.core import WaitSet as _WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.checkpoint_writer import BackgroundCheckpointWriter
from genbacklash_ros.node.joints import JointSet
from genbacklash_ros.node.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    JointState,
    KeyValue,
    Message,
    MessageError,
)
from genbacklash_ros.node.multijoint import make_pipeline
from genbacklash_ros.node.parameters import NODE_NAME, NodeParameters
from genbacklash_ros.node.pipeline import Output
from genbacklash_ros.node.wiring import ANSWER_DEPTH, READER_DEPTH
from genbacklash_ros.transports.dds_convert import DDS_TYPES, from_dds, to_dds
from genbacklash_ros.transports.dds_types import dds_topic
from genbacklash_ros.transports.ros_graph import (
    PARTICIPANT_USER_DATA,
    GraphAnnouncer,
    PublicationWatch,
    Subscribed,
    WiringMismatch,
    await_discovery,
    endpoint_qos,
)
from genbacklash_ros.transports.thread_priority import apply_thread_priority, worker_for

__all__ = [
    "DEFAULT_QOS",
    "READER_DEPTH",
    "SENSOR_QOS",
    "DdsNode",
    "NodeStats",
    "Topics",
    "domain_id_from_env",
    "resolve_topic",
    "with_wiring",
]

_LOG = logging.getLogger("genbacklash.node")

MAX_DOMAIN_ID = 232  # ROS 2's limit for ROS_DOMAIN_ID
TICK_NS = 1_000_000_000  # wall-clock diagnostics period
MAX_WAIT_NS = 100_000_000  # longest WaitSet wait: a signal handler runs within this
TAKE_BATCH = 512  # samples taken per reader and call

DEFAULT_QOS = Qos(
    Policy.History.KeepLast(10),
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.Durability.Volatile,
)
"""ROS 2's default QoS (``rmw_qos_profile_default``): KEEP_LAST 10, RELIABLE, VOLATILE."""

SENSOR_QOS = Qos(
    Policy.History.KeepLast(5),
    Policy.Reliability.BestEffort,
    Policy.Durability.Volatile,
)
"""ROS 2's sensor-data QoS (``qos_profile_sensor_data``): KEEP_LAST 5, BEST_EFFORT."""


def _deep(qos: Qos, depth: int = READER_DEPTH) -> Qos:
    return Qos(*(p for p in qos if not isinstance(p, Policy.History.KeepLast))) + Qos(
        Policy.History.KeepLast(depth)
    )


ReceiveTime = Literal["source", "take"]
_Kind = Literal["command", "encoder", "motor_encoder"]

_COMMAND_ROS_TYPES = {
    "float64": Float64.ros_type,
    "float64_multi_array": Float64MultiArray.ros_type,
    "joint_state": JointState.ros_type,
}
_ENCODER_ROS_TYPES = {"joint_state": JointState.ros_type, "float64": Float64.ros_type}


def with_wiring(
    diagnostics: DiagnosticArray, mismatches: tuple[WiringMismatch, ...]
) -> DiagnosticArray:
    """``diagnostics`` with the wiring mismatches added to its first status: at least WARN,
    each mismatch's line appended to the message and under the key ``wiring``."""
    if not mismatches or not diagnostics.status:
        return diagnostics
    first, *rest = diagnostics.status
    lines = [m.text() for m in mismatches]
    status = replace(
        first,
        level=max(first.level, DiagnosticStatus.WARN),
        message="; ".join([first.message, *lines]) if first.message else "; ".join(lines),
        values=(*first.values, KeyValue("wiring", "; ".join(lines))),
    )
    return replace(diagnostics, status=(status, *rest))


@dataclass(frozen=True)
class Topics:
    """The node's topic names as ROS 2 writes them (relative, ``~/`` private, or absolute).

    Remap one with :meth:`remapped` (``{"command": "/arm/command"}``).

    >>> Topics().resolved(NODE_NAME)["estimate"]
    '/backlash_identifier/estimate'
    >>> Topics().remapped({"command": "/arm/cmd"}).resolved(NODE_NAME, "/robot")["command"]
    '/arm/cmd'
    """

    command: str = "command"
    encoder: str = "encoder"
    motor_encoder: str = "motor_encoder"
    estimate: str = "~/estimate"
    compensated_command: str = "compensated_command"
    diagnostics: str = "/diagnostics"

    def remapped(self, changes: Mapping[str, str]) -> Topics:
        """A copy with the topics in ``changes`` (keyed by the names above) replaced."""
        known = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise GenBacklashError(
                f"cannot remap {', '.join(unknown)}: the node's topics are {', '.join(known)}"
            )
        return replace(self, **changes)

    def resolved(self, node_name: str = NODE_NAME, namespace: str = "") -> dict[str, str]:
        """Fully qualified ROS names (``/ns/topic``) by key."""
        return {
            f.name: resolve_topic(getattr(self, f.name), node_name, namespace) for f in fields(self)
        }


def resolve_topic(name: str, node_name: str = NODE_NAME, namespace: str = "") -> str:
    """ROS 2 name resolution: ``~/x`` -> ``/ns/node/x``, ``x`` -> ``/ns/x``, ``/x`` stays.

    >>> resolve_topic("~/estimate", "backlash_identifier", "/arm")
    '/arm/backlash_identifier/estimate'
    >>> resolve_topic("command", namespace="arm"), resolve_topic("/diagnostics", namespace="/arm")
    ('/arm/command', '/diagnostics')
    """
    text = name.strip()
    if not text or any(c.isspace() for c in text) or "//" in text:
        raise GenBacklashError(f"invalid topic name {name!r}")
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    if text.startswith("/"):
        return text.rstrip("/") or text
    if text == "~" or text.startswith("~/"):
        return f"{ns}/{node_name}{text[1:]}".rstrip("/")
    return f"{ns}/{text}".rstrip("/")


def domain_id_from_env(environ: Mapping[str, str] | None = None) -> int:
    """``ROS_DOMAIN_ID`` (0 when unset or empty), validated to ``[0, 232]``.

    >>> domain_id_from_env({"ROS_DOMAIN_ID": "42"}), domain_id_from_env({})
    (42, 0)
    """
    env = os.environ if environ is None else environ
    text = env.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError as err:
        raise GenBacklashError(f"ROS_DOMAIN_ID must be a whole number, got {text!r}") from err
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise GenBacklashError(f"ROS_DOMAIN_ID must lie in [0, {MAX_DOMAIN_ID}], got {value}")
    return value


@dataclass
class NodeStats:
    """Counters of a :class:`DdsNode` (messages taken and published, by topic key)."""

    received: dict[str, int] = field(
        default_factory=lambda: {"command": 0, "encoder": 0, "motor_encoder": 0}
    )
    published: dict[str, int] = field(
        default_factory=lambda: {"compensated_command": 0, "estimate": 0, "diagnostics": 0}
    )
    undecodable: int = 0
    stale_reports: int = 0


@dataclass(frozen=True, slots=True)
class _Event:
    order_ns: int
    seq: int
    kind: _Kind
    message: Message


class DdsNode:
    """The ``backlash_identifier`` node on a cyclonedds DomainParticipant.

    Parameters
    ----------
    params : NodeParameters or JointSet
        One joint's parameters, or several joints' (``joints``: one estimate topic each,
        ``~/<joint>/estimate``; :mod:`~genbacklash_ros.node.multijoint`).
    domain_id : int, optional
        DDS domain; default ``ROS_DOMAIN_ID`` (0 when unset).
    topics : Topics
        Topic names (remapped as wanted).
    namespace : str
        ROS namespace of the node (prefixes relative and private names).
    receive_time : {"source", "take"}
        Receive time of a sample (see the module notes).
    clock : callable
        Wall clock in integer nanoseconds (``time.time_ns``).

    Examples
    --------
    ``node = DdsNode(load_params_file("config/params.yaml")); node.spin()``; call
    :meth:`stop` from a signal handler or another thread.
    """

    def __init__(
        self,
        params: NodeParameters | JointSet,
        *,
        domain_id: int | None = None,
        topics: Topics | None = None,
        namespace: str = "",
        receive_time: ReceiveTime = "source",
        clock: Callable[[], int] = time.time_ns,
    ) -> None:
        if receive_time not in ("source", "take"):
            raise GenBacklashError(f"receive_time must be 'source' or 'take', got {receive_time!r}")
        joints = params if isinstance(params, JointSet) else JointSet.single(params)
        params = joints.base
        self.params = params
        self.joints = joints
        self.domain_id = domain_id_from_env() if domain_id is None else int(domain_id)
        if not 0 <= self.domain_id <= MAX_DOMAIN_ID:
            raise GenBacklashError(f"domain id must lie in [0, {MAX_DOMAIN_ID}]")
        self.topics = (topics or Topics()).resolved(NODE_NAME, namespace)
        self.stats = NodeStats()
        self._receive_time = receive_time
        self._clock = clock
        self._stop = threading.Event()
        self._checkpoints = BackgroundCheckpointWriter()
        self.pipeline = make_pipeline(
            joints,
            checkpoint_writer=self._checkpoints,
            worker=worker_for(params.thread_priority),
        )
        self._last_receive: dict[_Kind, int] = {"command": -1, "encoder": -1, "motor_encoder": -1}
        self._seq = 0

        qos_participant = Qos(Policy.EntityName(NODE_NAME), Policy.Userdata(PARTICIPANT_USER_DATA))
        self._participant = DomainParticipant(self.domain_id, qos=qos_participant)
        dp = self._participant
        command_ros = _COMMAND_ROS_TYPES[params.command_type]
        encoder_ros = _ENCODER_ROS_TYPES[params.encoder_type]
        command_type = DDS_TYPES[command_ros]
        estimate_ros, diagnostics_ros = Float64MultiArray.ros_type, DiagnosticArray.ros_type
        t = self.topics
        # the readers only once this participant knows the endpoints of those running already:
        # else a Fast DDS publisher matches them first and its first second of samples is lost
        self.discovered = await_discovery(dp)
        if self.discovered.incomplete:
            _LOG.warning(
                "discovery: %d of %d participants had not announced both a writer and a reader "
                "in %.1f s; a publisher among them may lose its first messages to this node",
                self.discovered.incomplete,
                self.discovered.participants,
                self.discovered.waited_s,
            )
        # one reader per input; a motor encoder (gear_input motor_encoder, dual encoders) is
        # the gear's input
        # (kind, ROS type, QoS, the parameter that chose the type, the types it may name)
        inputs: list[tuple[_Kind, str, Any, str, dict[str, str]]] = [
            ("command", command_ros, DEFAULT_QOS, "command_type", _COMMAND_ROS_TYPES),
            ("encoder", encoder_ros, SENSOR_QOS, "encoder_type", _ENCODER_ROS_TYPES),
        ]
        if params.motor_input:
            motor_ros = _ENCODER_ROS_TYPES[params.motor_encoder_type]
            inputs.append(
                ("motor_encoder", motor_ros, SENSOR_QOS, "motor_encoder_type", _ENCODER_ROS_TYPES)
            )
        self._readers: dict[_Kind, DataReader[Any]] = {
            kind: DataReader(
                dp,
                Topic(dp, dds_topic(t[kind]), DDS_TYPES[ros_type]),
                qos=endpoint_qos(_deep(qos), ros_type),
            )
            for kind, ros_type, qos, _, _ in inputs
        }
        self._writers: dict[str, DataWriter[Any]] = {
            "compensated_command": DataWriter(
                dp,
                Topic(dp, dds_topic(t["compensated_command"]), command_type),
                endpoint_qos(_deep(DEFAULT_QOS, ANSWER_DEPTH), command_ros),
            ),
            "diagnostics": DataWriter(
                dp,
                Topic(dp, dds_topic(t["diagnostics"]), DDS_TYPES[diagnostics_ros]),
                endpoint_qos(DEFAULT_QOS, diagnostics_ros),
            ),
        }
        # one estimate writer per joint with `joints` (~/<joint>/estimate), else ~/estimate
        estimate_topic = Topic(dp, dds_topic(t["estimate"]), DDS_TYPES[estimate_ros])
        self._estimate_writers: dict[str, DataWriter[Any]] = {}
        for joint in joints.joints or ("",):
            topic = estimate_topic
            if joint:
                name = resolve_topic(f"~/{joint}/estimate", NODE_NAME, namespace)
                topic = Topic(dp, dds_topic(name), DDS_TYPES[estimate_ros])
            self._estimate_writers[joint] = DataWriter(
                dp, topic, endpoint_qos(DEFAULT_QOS, estimate_ros)
            )
        self._graph = GraphAnnouncer(dp, NODE_NAME, namespace)
        self._graph.announce(
            self._readers.values(),
            [*self._writers.values(), *self._estimate_writers.values()],
        )
        self._watch = PublicationWatch(
            dp,
            {
                dds_topic(t[kind]): Subscribed(
                    DDS_TYPES[ros_type].__idl_typename__, parameter, tuple(choices.items())
                )
                for kind, ros_type, _, parameter, choices in inputs
            },
        )
        mask = SampleState.NotRead | ViewState.Any | InstanceState.Any
        self._ready = {kind: ReadCondition(r, mask) for kind, r in self._readers.items()}
        self._guard = GuardCondition(dp)
        self._waitset = _WaitSet(dp)
        for condition in (*self._ready.values(), self._guard):
            self._waitset.attach(condition)
        if self.pipeline.warm_start_note:
            _LOG.info("%s", self.pipeline.warm_start_note)

    # ------------------------------------------------------------------ control

    def stop(self) -> None:
        """Ask the loop to end (safe from a signal handler or another thread)."""
        self._stop.set()
        try:
            self._guard.set(True)
        except Exception:  # never raise out of a signal handler
            pass

    @property
    def stopping(self) -> bool:
        """True once :meth:`stop` was called."""
        return self._stop.is_set()

    def spin(self, duration_s: float | None = None) -> NodeStats:
        """Run the loop until :meth:`stop` (or for ``duration_s`` seconds), then shut down:
        ``pipeline.finish()``, the final outputs, the final checkpoint.
        """
        start = self._clock()
        end = None if duration_s is None else start + int(duration_s * 1e9)
        next_tick = start + TICK_NS
        data_since_tick = False
        _LOG.info(
            "backlash_identifier on DDS domain %d: command %s, encoder %s -> %s, %s, %s",
            self.domain_id,
            self.topics["command"],
            self.topics["encoder"],
            self.topics["compensated_command"],
            self.topics["estimate"],
            self.topics["diagnostics"],
        )
        problem = apply_thread_priority(self.params.thread_priority)  # this thread takes them
        if problem:
            _LOG.warning(problem)
        try:
            while not self._stop.is_set():
                now = self._clock()
                if end is not None and now >= end:
                    break
                wait = min(max(next_tick - now, 0), MAX_WAIT_NS)
                self._waitset.wait(wait)
                if self._process_available():
                    data_since_tick = True
                now = self._clock()
                if now >= next_tick:
                    self.check_wiring()
                    if not data_since_tick:
                        self._publish([self.pipeline.diagnostics(now, stale=True)])
                        self.stats.stale_reports += 1
                    data_since_tick = False
                    next_tick = max(next_tick + TICK_NS, now + 1)
            # drain what arrived before the stop, then finish
            self._process_available()
            self._publish(self.pipeline.finish())
            self._graph.withdraw()
        finally:
            self.pipeline.close()
            self._checkpoints.close()
            self.pipeline_stats_log()
        return self.stats

    @property
    def wiring_mismatches(self) -> tuple[WiringMismatch, ...]:
        """Publishers of another type on a subscribed topic, as last checked."""
        return self._watch.mismatches

    def check_wiring(self) -> tuple[WiringMismatch, ...]:
        """Read what discovery reported about publications (once per wall-clock second in
        :meth:`spin`); log each new mismatch once. Returns the current mismatches."""
        for mismatch in self._watch.poll():
            _LOG.warning("%s", mismatch.text())
        return self._watch.mismatches

    def pipeline_stats_log(self) -> None:
        """Log the counters (at shutdown)."""
        s = self.pipeline.stats
        dropped = {k: n for k, n in s.dropped.items() if n}
        _LOG.info(
            "stopped: %d commands, %d encoder messages, %d samples identified, %d published "
            "(%s), %d checkpoints written; dropped %s",
            s.commands,
            s.encoder_messages,
            s.samples,
            sum(self.stats.published.values()),
            ", ".join(f"{k} {n}" for k, n in self.stats.published.items()),
            self._checkpoints.written,
            dropped or "none",
        )

    # ------------------------------------------------------------------ the loop body

    def _receive_ns(self, kind: _Kind, source_ns: int, now: int) -> int:
        base = now if self._receive_time == "take" or source_ns <= 0 else min(source_ns, now)
        stamp = max(base, self._last_receive[kind] + 1)
        self._last_receive[kind] = stamp
        return stamp

    def _take(self, kind: _Kind, events: list[_Event]) -> None:
        reader, condition = self._readers[kind], self._ready[kind]
        while True:
            samples = reader.take(TAKE_BATCH, condition=condition)
            for sample in samples:
                info = sample.sample_info
                if not info.valid_data:
                    continue
                try:
                    message = from_dds(sample)
                except MessageError as err:
                    self.stats.undecodable += 1
                    _LOG.debug("undecodable %s sample: %s", kind, err)
                    continue
                self._seq += 1
                events.append(_Event(int(info.source_timestamp), self._seq, kind, message))
            if len(samples) < TAKE_BATCH:
                return

    def _process_available(self) -> bool:
        """Take, order and process every available sample; True when there were any."""
        events: list[_Event] = []
        for kind in self._readers:
            self._take(kind, events)
        if not events:
            return False
        events.sort(key=lambda e: (e.order_ns, e.seq))
        now = self._clock()
        pipe = self.pipeline
        for event in events:
            receive_ns = self._receive_ns(event.kind, event.order_ns, now)
            self.stats.received[event.kind] += 1
            if event.kind == "command":
                answer = pipe.answer(event.message, receive_ns)  # type: ignore[arg-type]
                if answer is not None:  # published before the estimate and diagnostics
                    self._publish([answer])
                outputs = pipe.periodic()
            elif event.kind == "encoder":
                outputs = pipe.on_encoder(event.message, receive_ns)
            else:
                outputs = pipe.on_motor(event.message, receive_ns)
            if outputs:
                self._publish(outputs)
        return True

    def _publish(self, outputs: list[Output]) -> None:
        for output in outputs:
            writer = (
                self._estimate_writers[output.joint]
                if output.topic == "estimate"
                else self._writers[output.topic]
            )
            message = output.message
            if output.topic == "diagnostics" and isinstance(message, DiagnosticArray):
                message = with_wiring(message, self._watch.mismatches)
            try:
                writer.write(to_dds(message))
            except MessageError as err:  # never stop the loop for one message
                _LOG.warning("not published on %s: %s", output.topic, err)
                continue
            self.stats.published[output.topic] += 1
