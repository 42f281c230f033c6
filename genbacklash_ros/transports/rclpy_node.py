"""The ``backlash_identifier`` ROS 2 node (rclpy, ROS 2 Jazzy).

A thin node in the style of ros2/examples: it declares the parameters of
:data:`~genbacklash_ros.node.parameters.PARAMETER_SPECS` with descriptors (description, ranges),
converts incoming messages to :mod:`genbacklash_ros.node.messages` and hands them with their
receive time to the one :class:`~genbacklash_ros.node.pipeline.BacklashPipeline`, and publishes
what it returns. All logic is in the pipeline.

* subscribes ``command`` (default QoS; the type is the ``command_type`` parameter) and
  ``encoder`` (``qos_profile_sensor_data``), each with a history of
  :data:`~genbacklash_ros.node.wiring.READER_DEPTH` samples rather than 10 (5): at 1 kHz on a
  loaded machine a depth of 10 lost 2 % of the commands while the process was descheduled;
  with ``gear_input`` motor_encoder also ``motor_encoder`` (the ``motor_encoder_type``,
  sensor-data QoS), the motor-side position that is the gear's input (dual encoders);
* publishes ``~/estimate``, ``compensated_command`` (the command's type; a writer history of
  :data:`~genbacklash_ros.node.wiring.ANSWER_DEPTH`, so that a subscriber descheduled while
  the node answers a backlog gets every answer resent) and ``/diagnostics`` (also on a 1 Hz
  timer with level STALE while no message arrives);
* several joints (``joints``, ``command_indices``, ``<joint>.<name>``;
  :mod:`~genbacklash_ros.node.joints`): still one subscription each, one compensated array,
  ``~/<joint>/estimate`` per joint and one ``/diagnostics`` status per joint, all from one
  :class:`~genbacklash_ros.node.multijoint.MultiJointPipeline` (:func:`make_pipeline`);
* parameters: the params files in ``--ros-args`` are read first by the reader the DDS
  transport uses (:func:`~genbacklash_ros.node.parameters.load_params_file`, the same
  sections under the same namespace), so both transports accept and refuse a file alike, with
  the same one-line reason and exit status 2; a whole number is taken for a double
  (``publish_rate: 10`` in a file, ``ros2 param set ... publish_rate 5``). At run time each
  value is checked on its own and refused with the reason; the pairs ``u_min``/``u_max`` and
  ``gate_low``/``gate_high`` follow the rule of
  :func:`~genbacklash_ros.node.parameters.resolve_requested` (a pair left inconsistent by one
  set keeps running on its last consistent values until the other set comes, and the
  diagnostics say so under ``parameters_pending``). ``command_type``, ``encoder_type``,
  ``gear_input`` and ``motor_encoder_type`` are read-only (they fix the subscriptions: set
  them in the params file), and so is ``thread_priority`` (the message thread's scheduler and
  the identify stage are chosen at start: :mod:`~genbacklash_ros.transports.thread_priority`);
* wiring: once a second the node asks discovery which types are published on its
  ``command`` and ``encoder`` topics; a publisher of another type is named in
  ``/diagnostics`` (WARN, key ``wiring``) with the parameter that selects the type;
* shutdown: SIGINT and SIGTERM only set a flag (:mod:`~genbacklash_ros.transports.stop_signals`;
  rclpy's own handlers are not installed, so nothing is raised inside rclpy); the spin loop
  leaves at its next wake-up, and any further signals (a terminal's Ctrl-C reaches ``ros2
  launch`` and the node, and launch forwards another) are ignored while the node feeds what
  is pending, refits, writes its final checkpoint and shuts rclpy down, and, when run as a
  program, until the process has exited;
* checkpoints are written on a background thread (atomic file writes);
* the ``command``, ``encoder`` and ``motor_encoder`` subscriptions take raw CDR bytes
  (``raw=True``), which a :class:`~genbacklash_ros.bags.raw_messages.RawMessageCodec` per
  topic decodes by the byte layout learnt from the first message of each length (rclpy's
  deserializer for any other), and the compensated command is published as the command's
  bytes with its floats replaced: rclpy's conversions to and from Python objects cost more than
  the pipeline's answer at 1 kHz;
* the loop (:class:`WaitLoop`): one thread waits on an rcl wait set of its own holding the
  ``command`` subscription, the parameter services and the 1 Hz timer (not the ``encoder``:
  a reading needs no answer, so readings are taken at the next wake-up, at most
  :data:`WAKE_S` later); at each wake-up it takes every message pending on the two
  subscriptions straight from their handles
  (no executor, no task per message), orders them by source timestamp (as the DDS
  transport does) and hands them to the pipeline. A ``SingleThreadedExecutor`` still serves
  everything else (parameter services, the timer, QoS events, a ``/clock`` subscription with
  ``use_sim_time``), run without waiting only when one of those is ready and at least every
  :data:`WAKE_S`. rclpy's executor cost 0.9 of a core at 1 kHz for what the loop does in
  less (BENCHMARKS.md, "Six joints through one node"). A node added to any other executor
  (a test, a component container) is served by it as usual: the two subscriptions are only
  withheld from executors while a :class:`WaitLoop` runs.

rclpy is imported here only, and this module only when the rclpy transport is chosen.
Run it with ``ros2 run genbacklash_ros backlash_identifier --ros-args --params-file
config/params.yaml``, ``ros2 launch genbacklash_ros backlash_identifier.launch.py`` or
``genbacklash node --transport rclpy``.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from contextlib import ExitStack
from typing import Any

import rclpy
from diagnostic_msgs.msg import (
    DiagnosticArray as RosDiagnosticArray,
)
from diagnostic_msgs.msg import DiagnosticStatus as RosDiagnosticStatus
from diagnostic_msgs.msg import KeyValue as RosKeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    ShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState as RosJointState
from std_msgs.msg import Float64 as RosFloat64
from std_msgs.msg import Float64MultiArray as RosFloat64MultiArray
from std_msgs.msg import MultiArrayDimension as RosMultiArrayDimension

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.raw_messages import RawMessageCodec
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.gc_pauses import few_collections
from genbacklash_ros.node.checkpoint_writer import BackgroundCheckpointWriter
from genbacklash_ros.node.joints import JointSet, is_joint_parameter, load_joint_set
from genbacklash_ros.node.messages import (
    DiagnosticArray,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    Message,
    MessageError,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)
from genbacklash_ros.node.multijoint import MultiJointPipeline, make_pipeline
from genbacklash_ros.node.parameters import (
    NODE_NAME,
    PARAMETER_SPECS,
    NodeParameters,
    ParameterSpec,
    parse_ros_arguments,
    resolve_requested,
)
from genbacklash_ros.node.pipeline import Output
from genbacklash_ros.node.wiring import (
    ANSWER_DEPTH,
    READER_DEPTH,
    annotate,
    selected_type,
    type_mismatches,
)
from genbacklash_ros.transports.stop_signals import StopSignals
from genbacklash_ros.transports.thread_priority import apply_thread_priority, worker_for

__all__ = ["BacklashIdentifierNode", "WaitLoop", "descriptor", "from_ros", "main", "to_ros"]

DEFAULT_DEPTH = 10  # ROS 2 default QoS: KEEP_LAST 10, RELIABLE, VOLATILE
READ_ONLY = frozenset(
    {
        "command_type",
        "encoder_type",
        "gear_input",  # a motor encoder's subscription is made at start
        "motor_encoder_type",
        "joints",
        "command_indices",
        "thread_priority",  # the message thread's scheduler and the identify process: at start
    }
)
_ROS_COMMAND = {
    "float64": RosFloat64,
    "float64_multi_array": RosFloat64MultiArray,
    "joint_state": RosJointState,
}
_ROS_ENCODER = {"joint_state": RosJointState, "float64": RosFloat64}
_SPECS = {spec.name: spec for spec in PARAMETER_SPECS}
WAKE_S = 0.1  # longest wait: a stop request is seen within this, the executor run this often
# messages taken per subscription and wake-up at most: a reader's whole history, so that a
# node behind takes both streams whole and orders them (a smaller cap took 512 commands
# and readings that a lost stretch had left far apart); the rest at the next wake-up
TAKE_BATCH = READER_DEPTH
# take rounds after a wake-up's messages, before waiting again (WaitLoop._drain): at 1 kHz a
# command and the reading published right after it then take one wake-up, not two. A wait
# cost 25-35 us of CPU with Fast DDS (wait set filled, rcl_wait with nothing ready) where a
# take that finds nothing costs about 1 us: 2,000 wake-ups a second were 0.07 of a core
DRAIN_ROUNDS = 4
PENDING_KEY = "parameters_pending"  # diagnostics key: pairs held at their last consistent values


# --------------------------------------------------------------------------- descriptors


def descriptor(spec: ParameterSpec, name: str | None = None) -> Any:
    """The ``ParameterDescriptor`` of one parameter (description, range, read-only);
    ``name`` for a joint's own (``<joint>.<name>``)."""
    text = spec.description
    if spec.unit:
        text += f" [{spec.unit}]"
    if spec.restarts:
        text += " Changing it restarts identification."
    if name is not None:
        text = f"Joint {name.rpartition('.')[0]!r} only: {text}"
    desc = ParameterDescriptor(
        name=name or spec.name,
        description=text,
        read_only=spec.name in READ_ONLY,
    )
    if spec.choices:
        desc.additional_constraints = "one of: " + ", ".join(spec.choices)
    if spec.min is not None or spec.max is not None:
        if spec.type == "integer":
            low = int(spec.min) if spec.min is not None else -(2**63)
            high = int(spec.max) if spec.max is not None else 2**63 - 1
            desc.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
        elif spec.type == "double":
            low_f = spec.min if spec.min is not None else -math.inf
            high_f = spec.max if spec.max is not None else math.inf
            desc.floating_point_range = [
                FloatingPointRange(from_value=low_f, to_value=high_f, step=0.0)
            ]
    return desc


# --------------------------------------------------------------------------- conversion


def _header_from(h: Any) -> Header:
    return Header(Time(int(h.stamp.sec), int(h.stamp.nanosec)), str(h.frame_id))


def from_ros(msg: Any) -> Message:
    """Our message for an rclpy ``Float64``, ``Float64MultiArray`` or ``JointState``."""
    if isinstance(msg, RosFloat64):
        return Float64(float(msg.data))
    if isinstance(msg, RosFloat64MultiArray):
        dims = tuple(
            MultiArrayDimension(str(d.label), int(d.size), int(d.stride)) for d in msg.layout.dim
        )
        layout = MultiArrayLayout(dims, int(msg.layout.data_offset))
        return Float64MultiArray(layout, tuple(msg.data))
    if isinstance(msg, RosJointState):
        return JointState(
            _header_from(msg.header),
            tuple(msg.name),
            tuple(msg.position),
            tuple(msg.velocity),
            tuple(msg.effort),
        )
    raise MessageError(f"no conversion from {type(msg).__name__}")


def raw_codec(ros_class: Any) -> RawMessageCodec:
    """The codec of a raw subscription of ``ros_class``: our message from its CDR bytes
    (rclpy's deserializer and :func:`from_ros` for a layout it has not learnt)."""

    def slow(raw: bytes) -> Message:
        try:
            msg = deserialize_message(raw, ros_class)
        except Exception as err:  # rclpy's C deserializer: corrupt or cut bytes
            text = " ".join(str(err).split()) or type(err).__name__
            raise MessageError(f"a {ros_class.__name__} message does not decode: {text}") from err
        return from_ros(msg)

    ros_type = "/".join((*ros_class.__module__.split(".")[:2], ros_class.__name__))
    return RawMessageCodec(ros_type, slow)


def _decoded(codec: RawMessageCodec, msg: Any) -> Message:
    """Our message for what a subscription gave: raw bytes, or an rclpy message (a node
    whose subscriptions someone else drives with objects)."""
    return codec.decode(msg) if isinstance(msg, bytes) else from_ros(msg)


def _header_to(ros: Any, header: Header) -> None:
    ros.stamp.sec = header.stamp.sec
    ros.stamp.nanosec = header.stamp.nanosec
    ros.frame_id = header.frame_id


def to_ros(msg: Message) -> Any:
    """The rclpy message for one of our outgoing messages."""
    if isinstance(msg, Float64):
        return RosFloat64(data=float(msg.data))
    if isinstance(msg, Float64MultiArray):
        out = RosFloat64MultiArray()
        out.layout.dim = [
            RosMultiArrayDimension(label=d.label, size=d.size, stride=d.stride)
            for d in msg.layout.dim
        ]
        out.layout.data_offset = msg.layout.data_offset
        out.data = [float(v) for v in msg.data]
        return out
    if isinstance(msg, JointState):
        js = RosJointState()
        _header_to(js.header, msg.header)
        js.name = list(msg.name)
        js.position = [float(v) for v in msg.position]
        js.velocity = [float(v) for v in msg.velocity]
        js.effort = [float(v) for v in msg.effort]
        return js
    if isinstance(msg, DiagnosticArray):
        arr = RosDiagnosticArray()
        _header_to(arr.header, msg.header)
        arr.status = [
            RosDiagnosticStatus(
                level=bytes([s.level]),  # rclpy carries the `byte` field as bytes
                name=s.name,
                message=s.message,
                hardware_id=s.hardware_id,
                values=[RosKeyValue(key=kv.key, value=kv.value) for kv in s.values],
            )
            for s in msg.status
        ]
        return arr
    raise MessageError(f"no rclpy message for {type(msg).__name__}")


# --------------------------------------------------------------------------- the node


class BacklashIdentifierNode(Node):  # type: ignore[misc]
    """The ``backlash_identifier`` node: parameters, subscriptions, publishers, a timer."""

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        # The values from the params files and `-p` (rcl's overrides), checked and typed by
        # NodeParameters before rclpy sees them: rclpy would raise on an integer for a double
        # and on a value out of range, with a traceback. Raises: the node does not start.
        overrides = {
            name: param.value
            for name, param in self._parameter_overrides.items()
            if name in _SPECS or is_joint_parameter(name)
        }
        self._joints = JointSet.from_mapping(overrides)
        self._params = self._joints.base
        for spec in PARAMETER_SPECS:
            value = getattr(self._params, spec.name)
            self.declare_parameter(spec.name, value, descriptor(spec), ignore_override=True)
        self._declare_joint_parameters()
        self._requested: dict[str, object] = dict(self._joints.to_mapping())  # `ros2 param get`
        self._pending: tuple[str, ...] = ()
        self._wiring: tuple[str, ...] = ()
        self._checkpoints = BackgroundCheckpointWriter(
            on_error=lambda reason: self.get_logger().warning(reason)
        )
        self._pipeline = make_pipeline(
            self._joints,
            checkpoint_writer=self._checkpoints,
            worker=worker_for(self._params.thread_priority),
        )
        if self._pipeline.warm_start_note:
            self.get_logger().info(self._pipeline.warm_start_note)
        self.add_pre_set_parameters_callback(self._coerce_parameters)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        command_type = _ROS_COMMAND[self._params.command_type]
        encoder_type = _ROS_ENCODER[self._params.encoder_type]
        # not `_publishers`: rclpy's Node keeps its own list under that name and
        # destroy_node() walks it (a dict there ends every shutdown in a KeyError)
        self._outputs = {
            "compensated_command": self.create_publisher(
                command_type, "compensated_command", ANSWER_DEPTH
            ),
            "diagnostics": self.create_publisher(RosDiagnosticArray, "/diagnostics", DEFAULT_DEPTH),
        }
        # one estimate topic per joint with `joints` (~/<joint>/estimate), else ~/estimate
        self._estimates = {
            joint: self.create_publisher(
                RosFloat64MultiArray,
                f"~/{joint}/estimate" if joint else "~/estimate",
                DEFAULT_DEPTH,
            )
            for joint in (self._joints.joints or ("",))
        }
        # deep histories: the same QoS as ROS 2's defaults for matching, more room while busy
        # the two hot subscriptions: taken by a WaitLoop while one runs (any executor otherwise)
        self._hot_group = _LoopGroup()
        # raw: the messages as CDR bytes, decoded (and the answer encoded) by these codecs
        self._command_codec = raw_codec(command_type)
        self._encoder_codec = raw_codec(encoder_type)
        self._motor_codec = raw_codec(_ROS_ENCODER[self._params.motor_encoder_type])
        self._command_sub = self.create_subscription(
            command_type,
            "command",
            self._on_command,
            QoSProfile(depth=READER_DEPTH),
            callback_group=self._hot_group,
            raw=True,
        )
        sensor_qos = QoSProfile(
            history=qos_profile_sensor_data.history,
            depth=READER_DEPTH,
            reliability=qos_profile_sensor_data.reliability,
            durability=qos_profile_sensor_data.durability,
        )
        self._encoder_sub = self.create_subscription(
            encoder_type,
            "encoder",
            self._on_encoder,
            sensor_qos,
            callback_group=self._hot_group,
            raw=True,
        )
        # a motor encoder (gear_input motor_encoder, dual encoders): the gear's input
        self._motor_sub = (
            self.create_subscription(
                _ROS_ENCODER[self._params.motor_encoder_type],
                "motor_encoder",
                self._on_motor,
                sensor_qos,
                raw=True,
            )
            if self._params.motor_input
            else None
        )
        self._sim_time = bool(self.get_parameter("use_sim_time").value)
        self._data_since_tick = False
        self._timer = self.create_timer(1.0, self._on_tick)
        self._finished = False

    # ------------------------------------------------------------------ parameters

    @property
    def params(self) -> NodeParameters:
        """The parameters in use (the base set with several joints)."""
        return self._params

    def _declare_joint_parameters(self) -> None:
        """With ``joints``: ``joints``, ``command_indices`` (read-only) and each
        ``<joint>.<name>`` the params file or ``-p`` set (settable at run time)."""
        joints = self._joints
        if not joints.multi:
            return
        self.declare_parameter(
            "joints",
            list(joints.joints),
            ParameterDescriptor(
                name="joints",
                description="Joints served (names in the encoder's JointState).",
                read_only=True,
            ),
            ignore_override=True,
        )
        if joints.command_indices:
            self.declare_parameter(
                "command_indices",
                list(joints.command_indices),
                ParameterDescriptor(
                    name="command_indices",
                    description="Float64MultiArray command: each joint's element, in order.",
                    read_only=True,
                ),
                ignore_override=True,
            )
        for joint, name, _ in joints.overrides:
            params = joints.per_joint[joints.joints.index(joint)]
            self.declare_parameter(
                f"{joint}.{name}",
                getattr(params, name),
                descriptor(_SPECS[name], f"{joint}.{name}"),
                ignore_override=True,
            )

    def _coerce_parameters(self, parameters: Sequence[Any]) -> list[Any]:
        """A whole number for a double parameter becomes the double (``ros2 param set``
        sends ``5`` as an integer); everything else passes unchanged."""
        out = []
        for param in parameters:
            spec = _spec_of(param.name)
            value = param.value
            if (
                spec is not None
                and spec.type == "double"
                and isinstance(value, int)
                and not isinstance(value, bool)
            ):
                param = Parameter(param.name, value=float(value))
            out.append(param)
        return out

    def _validate_parameters(self, parameters: Sequence[Any]) -> Any:
        """Refuse a value that is invalid on its own, with the reason; pairs are resolved
        after the request (:func:`resolve_requested`), so a pair moves in either order."""
        for param in parameters:
            spec = _spec_of(param.name)
            if spec is None:
                continue
            try:
                spec.check(param.value)
            except GenBacklashError as err:
                return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: Sequence[Any]) -> None:
        changes = {p.name: p.value for p in parameters if _spec_of(p.name) is not None}
        if not changes:
            return
        self._requested.update(changes)
        if isinstance(self._pipeline, MultiJointPipeline):
            self._apply_joint_parameters()
            return
        params, pending = resolve_requested(self._params, self._requested)
        for line in pending:
            if line not in self._pending:
                self.get_logger().warning(line)
        self._pending = pending
        if params != self._params:
            applied = {
                k: v for k, v in params.to_mapping().items() if v != getattr(self._params, k)
            }
            self._params = params
            assert not isinstance(self._pipeline, MultiJointPipeline)
            self._pipeline.set_params(params)
            self.get_logger().info(f"parameters changed: {applied}")

    def _apply_joint_parameters(self) -> None:
        """Several joints: the values held, as a whole, applied when they are consistent;
        otherwise the node keeps running on its last consistent set and says so under
        ``parameters_pending`` until a later set makes them consistent."""
        assert isinstance(self._pipeline, MultiJointPipeline)
        try:
            joints = JointSet.from_mapping(self._requested)
        except GenBacklashError as err:
            line = f"{err}: running on the last consistent parameters until it is resolved"
            if (line,) != self._pending:
                self.get_logger().warning(line)
            self._pending = (line,)
            return
        self._pending = ()
        if joints != self._joints:
            self._pipeline.set_joint_set(joints)
            self._joints = joints
            self._params = joints.base
            self.get_logger().info("parameters changed")

    # ------------------------------------------------------------------ callbacks

    def _now_ns(self) -> int:
        return int(self.get_clock().now().nanoseconds)

    def _receive_ns(self, info: Any) -> int:
        """The time of a message without a header stamp: the publisher's source timestamp
        (as the DDS transport's default ``--receive-time source``), so that a reading stamped
        after its command is after it here too however late the callback runs; the node's
        clock with ``use_sim_time`` or without a source timestamp."""
        source = int(info.get("source_timestamp") or 0) if isinstance(info, dict) else 0
        if source > 0 and not self._sim_time:
            return source
        return self._now_ns()

    def _on_command(self, msg: Any, info: Any) -> None:
        # (two arguments: rclpy then passes the message info with the source timestamp)
        self._data_since_tick = True
        try:
            ours = _decoded(self._command_codec, msg)
        except MessageError as err:  # bytes that do not decode: counted, as replay counts them
            self.get_logger().warning(f"command: {err}", throttle_duration_sec=5.0)
            self._pipeline.reject("command", str(err))
            return
        pipeline = self._pipeline
        answer = pipeline.answer(ours, self._receive_ns(info))  # type: ignore[arg-type]
        if answer is not None:  # published before the estimate and diagnostics are made
            raw = None
            if isinstance(msg, bytes):  # the command's own bytes with the compensated floats
                raw = self._command_codec.encode(msg, ours, answer.message)
            if raw is None:
                self._publish([answer])
            else:
                self._outputs["compensated_command"].publish(raw)
        self._publish(pipeline.periodic())

    def _on_encoder(self, msg: Any, info: Any) -> None:
        self._data_since_tick = True
        try:
            ours = _decoded(self._encoder_codec, msg)
        except MessageError as err:  # bytes that do not decode: counted, as replay counts them
            self.get_logger().warning(f"encoder: {err}", throttle_duration_sec=5.0)
            self._pipeline.reject("encoder", str(err))
            return
        self._publish(self._pipeline.on_encoder(ours, self._receive_ns(info)))

    def _on_motor(self, msg: Any, info: Any) -> None:
        self._data_since_tick = True
        try:
            ours = _decoded(self._motor_codec, msg)
        except MessageError as err:  # bytes that do not decode: counted, as replay counts them
            self.get_logger().warning(f"motor encoder: {err}", throttle_duration_sec=5.0)
            self._pipeline.reject("motor", str(err))
            return
        self._publish(self._pipeline.on_motor(ours, self._receive_ns(info)))

    def _on_tick(self) -> None:
        """1 Hz: the wiring check, and diagnostics with level STALE when no message arrived
        during the second."""
        self.check_wiring()
        if not self._data_since_tick:
            self._publish([self._pipeline.diagnostics(self._now_ns(), stale=True)])
        self._data_since_tick = False

    def check_wiring(self) -> tuple[str, ...]:
        """Publishers of another type on the subscribed topics, as discovery shows them: one
        line each (:func:`~genbacklash_ros.node.wiring.type_mismatches`), kept for the
        diagnostics and logged when new."""
        problems: list[str] = []
        subscriptions = [(self._command_sub, "command_type"), (self._encoder_sub, "encoder_type")]
        if self._motor_sub is not None:
            subscriptions.append((self._motor_sub, "motor_encoder_type"))
        for subscription, parameter in subscriptions:
            topic = subscription.topic_name
            seen = [info.topic_type for info in self.get_publishers_info_by_topic(topic)]
            expected = selected_type(parameter, getattr(self._params, parameter))
            problems.extend(type_mismatches(topic, expected, parameter, seen))
        for line in problems:
            if line not in self._wiring:
                self.get_logger().warning(line)
        self._wiring = tuple(problems)
        return self._wiring

    def _publish(self, outputs: list[Output]) -> None:
        for output in outputs:
            message = output.message
            if isinstance(message, DiagnosticArray):
                message = annotate(message, self._wiring)
                message = annotate(message, self._pending, key=PENDING_KEY)
            if output.topic == "estimate":
                self._estimates[output.joint].publish(to_ros(message))
            else:
                self._outputs[output.topic].publish(to_ros(message))

    # ------------------------------------------------------------------ shutdown

    def finish(self) -> None:
        """Feed what is pending, publish the final estimate (when the context is still up)
        and write the final checkpoint."""
        if self._finished:
            return
        self._finished = True
        outputs = self._pipeline.finish()
        self._pipeline.close()
        try:
            if rclpy.ok():
                self._publish(outputs)
        except Exception as err:  # the middleware may be shutting down: keep the checkpoint
            self.get_logger().warning(f"final outputs not published: {err}")
        self._checkpoints.close()


# --------------------------------------------------------------------------- the loop


class _LoopGroup(ReentrantCallbackGroup):  # type: ignore[misc]
    """The callback group of the two hot subscriptions: executors take them as any other
    until a :class:`WaitLoop` claims them (their QoS event handlers, in the same group, stay
    the executors')."""

    def __init__(self) -> None:
        super().__init__()
        self.claimed: set[int] = set()  # id() of the entities a WaitLoop takes itself

    def can_execute(self, entity: Any) -> bool:
        return id(entity) not in self.claimed

    def beginning_execution(self, entity: Any) -> bool:
        return id(entity) not in self.claimed


class WaitLoop:
    """The node's own wait loop: the hot subscriptions taken without an executor.

    On construction it claims the node's ``command`` and ``encoder`` subscriptions (executors
    no longer wait on them) and builds one rcl wait set holding the command's, the node's
    other subscriptions, its timers, clients and services. Not the encoder's: a reading needs
    no answer, and waking for each of 1,000 a second cost the message thread a wake-up each
    (2,000 to 4,800 a second with the commands; a real-time thread, ``thread_priority``, wakes
    for every one). Its readings are taken at every wake-up (a command, a service, the timer,
    or :data:`WAKE_S` at most: its reader holds ``READER_DEPTH`` of them, 2 s at 1 kHz), in
    source order with the commands taken then, so a command is still handled after every
    reading that came before it. :meth:`run_once` waits on it (at most ``timeout_s``), then

    1. takes every message pending on the two subscriptions (``take_message`` on their
       handles, at most :data:`TAKE_BATCH` each: their whole histories, as the DDS
       transport takes everything available), orders them by source timestamp (a reading
       after the command it follows, however the two topics were delivered) and calls each
       subscription's callback (the node's ``_on_command``/``_on_encoder``) with the message
       and its info, as the executor did; then takes again what came meanwhile, up to
       :data:`DRAIN_ROUNDS` times, before it waits again (a take costs far less than a
       wake-up);
    2. when anything else in the wait set is ready, or :data:`WAKE_S` has passed since it
       last did, runs the ``executor`` without waiting until it has nothing ready (parameter
       services, the timer, QoS events, guard conditions and waitables, which are not in the
       wait set: their readiness is taken by the wait that sees it).

    The wait set is rebuilt when the node's entities change (a ``/clock`` subscription made
    when ``use_sim_time`` is set at run time). :meth:`close` gives the two subscriptions back
    to executors. rclpy's executor makes a new wait set, a task and a coroutine per message;
    this does one wait per wake-up and nothing per message but the take.

    Raises ``ExternalShutdownException`` when the context is shut down from elsewhere.
    """

    def __init__(self, node: BacklashIdentifierNode, executor: Any) -> None:
        self._node = node
        self._executor = executor
        # each with the callback an executor would call (the node's, taking the message info)
        self._hot = tuple((sub, sub.callback) for sub in (node._command_sub, node._encoder_sub))
        self._hot_ids = {id(sub) for sub, _ in self._hot}
        node._hot_group.claimed.update(self._hot_ids)
        self._context = node.context
        self._stack = ExitStack()
        self._wait_set: Any = None
        self._signature: tuple[int, ...] = ()
        self._subs: list[Any] = []
        self._waited: list[Any] = []  # the subscriptions in the wait set
        self._timers: list[Any] = []
        self._clients: list[Any] = []
        self._services: list[Any] = []
        self._last_executor = time.monotonic()
        self._seq = 0
        self.taken = 0  # messages taken from the hot subscriptions
        self.executor_runs = 0  # times the executor was run
        self._build()

    def _entity_signature(self) -> tuple[int, ...]:
        node = self._node
        return tuple(
            len(list(entities))
            for entities in (node.subscriptions, node.timers, node.clients, node.services)
        )

    def _build(self) -> None:
        """(Re)make the wait set from the node's entities, holding their handles (an entity
        is not destroyed under a wait)."""
        self._stack.close()
        self._stack = ExitStack()
        node = self._node
        hot = [sub for sub, _ in self._hot]
        self._subs = hot + [s for s in node.subscriptions if id(s) not in self._hot_ids]
        # waited on: the command's and the other subscriptions, not the encoder's (class notes)
        self._waited = [hot[0], *self._subs[len(hot) :]]
        self._timers = list(node.timers)
        self._clients = list(node.clients)
        self._services = list(node.services)
        for entity in (*self._subs, *self._timers, *self._clients, *self._services):
            self._stack.enter_context(entity.handle)
        self._stack.enter_context(self._context.handle)
        self._wait_set = _rclpy.WaitSet(
            len(self._waited),
            0,
            len(self._timers),
            len(self._clients),
            len(self._services),
            0,
            self._context.handle,
        )
        self._signature = self._entity_signature()

    def close(self) -> None:
        """Release the handles; executors take the two subscriptions again."""
        self._stack.close()
        self._wait_set = None
        self._node._hot_group.claimed.difference_update(self._hot_ids)

    def run_once(self, timeout_s: float = WAKE_S) -> int:
        """One wait (at most ``timeout_s``) and what it found; the messages taken."""
        ws = self._wait_set
        ws.clear_entities()
        for sub in self._waited:
            ws.add_subscription(sub.handle)
        for tmr in self._timers:
            ws.add_timer(tmr.handle)
        for cli in self._clients:
            ws.add_client(cli.handle)
        for srv in self._services:
            ws.add_service(srv.handle)
        ws.wait(int(timeout_s * 1e9))
        woke = time.monotonic()
        if not self._context.ok():
            raise ExternalShutdownException()
        # the command's if it is ready, and the encoder's whatever woke the wait (class notes)
        taken = self.take_pending((ws.is_ready("subscription", 0), True))
        if taken:
            taken += self._drain(woke)
        others = (
            any(ws.is_ready("subscription", i) for i in range(1, len(self._waited)))
            or ws.get_ready_entities("timer")
            or ws.get_ready_entities("service")
            or ws.get_ready_entities("client")
        )
        if others or time.monotonic() - self._last_executor >= WAKE_S:
            self.run_executor()
        return taken

    def _drain(self, woke: float) -> int:
        """Take again what came while the last messages were handled, before waiting: the
        encoder reading published just after a command is usually there by the time the
        command is answered, and a take that finds nothing (about 1 us a subscription) costs
        far less than the wait that would otherwise wake for it (25-35 us of CPU with Fast
        DDS). At most :data:`DRAIN_ROUNDS` rounds, and none once :data:`WAKE_S` has passed
        since ``woke``, so that a node behind (whole histories a round) still serves its
        services and sees a stop request as often as before."""
        taken = 0
        for _ in range(DRAIN_ROUNDS):
            if time.monotonic() - woke >= WAKE_S:
                break
            got = self.take_pending()
            if not got:
                break
            taken += got
        return taken

    def take_pending(self, ready: Sequence[bool] = (True, True)) -> int:
        """Take what is pending on the two subscriptions (those ``ready`` says have
        something), in source-timestamp order, into the node; the number taken."""
        events: list[tuple[int, int, Any, Any, Any]] = []
        for (sub, callback), pending in zip(self._hot, ready, strict=True):
            if not pending:
                continue
            handle, msg_type, raw = sub.handle, sub.msg_type, sub.raw
            for _ in range(TAKE_BATCH):
                got = handle.take_message(msg_type, raw)
                if got is None:
                    break
                msg, info = got
                self._seq += 1
                source = int(info.get("source_timestamp") or 0) if isinstance(info, dict) else 0
                events.append((source, self._seq, callback, msg, info))
        if not events:
            return 0
        if len(events) > 1:
            events.sort(key=lambda e: (e[0], e[1]))
        for _, _, callback, msg, info in events:
            callback(msg, info)
        self.taken += len(events)
        return len(events)

    def run_executor(self) -> None:
        """Run the executor without waiting until nothing is ready."""
        self._last_executor = time.monotonic()
        self.executor_runs += 1
        executor = self._executor
        while True:
            try:
                handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0)
            except (TimeoutException, ShutdownException, ConditionReachedException):
                break
            handler()
            error = handler.exception()
            if error is not None:
                raise error
            handler.result()
        if self._entity_signature() != self._signature:
            self._build()


def _spec_of(name: str) -> ParameterSpec | None:
    """The spec of a parameter name: its own, or a joint's override's (``<joint>.<name>``)."""
    spec = _SPECS.get(name)
    if spec is None and is_joint_parameter(name) and "." in name:
        spec = _SPECS.get(name.rpartition(".")[2])
    return spec


def _error(text: str) -> int:
    print(f"{NODE_NAME}: error: {text}", file=sys.stderr, flush=True)
    return 2


def main(
    args: list[str] | None = None, *, stop: StopSignals | None = None, exiting: bool = False
) -> int:
    """Entry point (``ros2 run genbacklash_ros backlash_identifier``), in the ros2/examples
    style: Ctrl-C, SIGTERM and an external shutdown end the node quietly (exit 0, after the
    final checkpoint), however many come and whenever; invalid parameters (a bad value, an
    unknown ``-p`` name) end it with one line on stderr and exit status 2.

    Signals: rclpy's own handlers are not installed; ``stop`` (else one of this call's own,
    released when it returns: ignored from then on when ``exiting``, else restored) only
    sets a flag, which the wait loop (:class:`WaitLoop`) reads at its next wake-up (a
    message, or at most :data:`WAKE_S`). The node runs with one BLAS thread
    (:func:`~genbacklash_ros.blas_threads.one_blas_thread`). Then, in order: the
    node finishes (pending samples, final refit and estimate, checkpoint), the executor and
    the node are destroyed, rclpy shuts down.
    """
    owned = stop is None
    signals = StopSignals().install() if stop is None else stop
    try:
        with one_blas_thread():
            return _run(list(sys.argv if args is None else args), signals)
    finally:
        if owned:
            signals.release(exiting=exiting)


def _run(argv: list[str], stop: StopSignals) -> int:
    ros = parse_ros_arguments(argv)
    try:  # the params files as the DDS transport reads them, before rcl does; then `-p` names
        for path in ros.params_files:
            load_joint_set(path, ros.node_name, namespace=ros.namespace)
        ros.check_parameter_names()
    except GenBacklashError as err:
        return _error(str(err))
    if stop.requested:
        return 0
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # e.g. a params file rcl cannot parse
        return _error(f"ROS 2 could not start the node: {err}")
    node: BacklashIdentifierNode | None = None
    executor: SingleThreadedExecutor | None = None
    status = 0
    try:
        node = BacklashIdentifierNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        loop = WaitLoop(node, executor)
        # this thread takes the messages (the node's other threads, Fast DDS's included, were
        # started with the default scheduler and keep it)
        problem = apply_thread_priority(node.params.thread_priority)
        if problem:
            node.get_logger().warning(problem)
        try:
            with few_collections():  # the node built: its objects out of the collector's scans
                while not stop.requested:
                    loop.run_once(WAKE_S)
        finally:
            loop.close()
    except ExternalShutdownException:
        pass
    except GenBacklashError as err:  # invalid parameters at start
        status = _error(str(err))
    finally:
        if node is not None:
            before = stop.count
            node.finish()
            if stop.count > before:
                node.get_logger().info(
                    f"{stop.count - before} more interrupt(s) ignored while finishing"
                )
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    raise SystemExit(main(exiting=True))
