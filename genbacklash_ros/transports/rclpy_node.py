"""The ``backlash_identifier`` ROS 2 node (rclpy, ROS 2 Jazzy).

A thin node in the style of ros2/examples: it declares the parameters of
:data:`~genbacklash_ros.node.parameters.PARAMETER_SPECS` with descriptors (description, ranges),
converts incoming messages to :mod:`genbacklash_ros.node.messages` and hands them with their
receive time to the one :class:`~genbacklash_ros.node.pipeline.BacklashPipeline`, and publishes
what it returns. All logic is in the pipeline.

* subscribes ``command`` (default QoS, depth 10; the type is the ``command_type`` parameter)
  and ``encoder`` (``qos_profile_sensor_data``);
* publishes ``~/estimate``, ``compensated_command`` (the command's type) and ``/diagnostics``
  (also on a 1 Hz timer with level STALE while no message arrives);
* a set-parameters callback validates changes with
  :meth:`~genbacklash_ros.node.parameters.NodeParameters.replace` and rejects them with the reason;
  accepted ones reach the pipeline in a post-set callback. ``command_type`` and
  ``encoder_type`` are read-only (they fix the subscription types: set them in the params
  file);
* checkpoints are written on a background thread (atomic file writes);
* everything runs on the executor's one thread (``rclpy.spin``).

rclpy is imported here only, and this module only when the rclpy transport is chosen.
Run it with ``ros2 run genbacklash_ros backlash_identifier --ros-args --params-file
config/params.yaml``, ``ros2 launch genbacklash_ros backlash_identifier.launch.py`` or
``genbacklash node --transport rclpy``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import rclpy  # type: ignore[import-not-found]
from diagnostic_msgs.msg import (  # type: ignore[import-not-found]
    DiagnosticArray as RosDiagnosticArray,
)
from diagnostic_msgs.msg import DiagnosticStatus as RosDiagnosticStatus
from diagnostic_msgs.msg import KeyValue as RosKeyValue
from rcl_interfaces.msg import (  # type: ignore[import-not-found]
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.executors import ExternalShutdownException  # type: ignore[import-not-found]
from rclpy.node import Node  # type: ignore[import-not-found]
from rclpy.qos import qos_profile_sensor_data  # type: ignore[import-not-found]
from sensor_msgs.msg import JointState as RosJointState  # type: ignore[import-not-found]
from std_msgs.msg import Float64 as RosFloat64  # type: ignore[import-not-found]
from std_msgs.msg import Float64MultiArray as RosFloat64MultiArray
from std_msgs.msg import MultiArrayDimension as RosMultiArrayDimension

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.checkpoint_writer import BackgroundCheckpointWriter
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
from genbacklash_ros.node.parameters import (
    NODE_NAME,
    PARAMETER_SPECS,
    NodeParameters,
    ParameterSpec,
)
from genbacklash_ros.node.pipeline import BacklashPipeline, Output

__all__ = ["BacklashIdentifierNode", "descriptor", "from_ros", "main", "to_ros"]

DEFAULT_DEPTH = 10  # ROS 2 default QoS: KEEP_LAST 10, RELIABLE, VOLATILE
READ_ONLY = frozenset({"command_type", "encoder_type"})
_ROS_COMMAND = {
    "float64": RosFloat64,
    "float64_multi_array": RosFloat64MultiArray,
    "joint_state": RosJointState,
}
_ROS_ENCODER = {"joint_state": RosJointState, "float64": RosFloat64}


# --------------------------------------------------------------------------- descriptors


def descriptor(spec: ParameterSpec) -> Any:
    """The ``ParameterDescriptor`` of one parameter (description, range, read-only)."""
    text = spec.description
    if spec.unit:
        text += f" [{spec.unit}]"
    if spec.restarts:
        text += " Changing it restarts identification."
    desc = ParameterDescriptor(
        name=spec.name,
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
        for spec in PARAMETER_SPECS:
            self.declare_parameter(spec.name, spec.default, descriptor(spec))
        values = {s.name: self.get_parameter(s.name).value for s in PARAMETER_SPECS}
        self._params = NodeParameters.from_mapping(values)  # raises: the node does not start
        self._checkpoints = BackgroundCheckpointWriter(
            on_error=lambda reason: self.get_logger().warning(reason)
        )
        self._pipeline = BacklashPipeline(self._params, checkpoint_writer=self._checkpoints)
        if self._pipeline.warm_start_note:
            self.get_logger().info(self._pipeline.warm_start_note)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        command_type = _ROS_COMMAND[self._params.command_type]
        encoder_type = _ROS_ENCODER[self._params.encoder_type]
        # not `_publishers`: rclpy's Node keeps its own list under that name and
        # destroy_node() walks it (a dict there ends every shutdown in a KeyError)
        self._outputs = {
            "compensated_command": self.create_publisher(
                command_type, "compensated_command", DEFAULT_DEPTH
            ),
            "estimate": self.create_publisher(RosFloat64MultiArray, "~/estimate", DEFAULT_DEPTH),
            "diagnostics": self.create_publisher(RosDiagnosticArray, "/diagnostics", DEFAULT_DEPTH),
        }
        self._command_sub = self.create_subscription(
            command_type, "command", self._on_command, DEFAULT_DEPTH
        )
        self._encoder_sub = self.create_subscription(
            encoder_type, "encoder", self._on_encoder, qos_profile_sensor_data
        )
        self._data_since_tick = False
        self._timer = self.create_timer(1.0, self._on_tick)
        self._finished = False

    # ------------------------------------------------------------------ parameters

    def _validate_parameters(self, parameters: Sequence[Any]) -> Any:
        """Accept a change only when :meth:`NodeParameters.replace` accepts it."""
        changes = {p.name: p.value for p in parameters if p.name in self._params.to_mapping()}
        try:
            self._params.replace(**changes)
        except GenBacklashError as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: Sequence[Any]) -> None:
        changes = {p.name: p.value for p in parameters if p.name in self._params.to_mapping()}
        if not changes:
            return
        self._params = self._params.replace(**changes)
        self._pipeline.set_params(self._params)
        self.get_logger().info(f"parameters changed: {changes}")

    # ------------------------------------------------------------------ callbacks

    def _now_ns(self) -> int:
        return int(self.get_clock().now().nanoseconds)

    def _on_command(self, msg: Any) -> None:
        self._data_since_tick = True
        try:
            ours = from_ros(msg)
        except MessageError as err:
            self.get_logger().warning(f"command: {err}", throttle_duration_sec=5.0)
            return
        self._publish(self._pipeline.on_command(ours, self._now_ns()))  # type: ignore[arg-type]

    def _on_encoder(self, msg: Any) -> None:
        self._data_since_tick = True
        try:
            ours = from_ros(msg)
        except MessageError as err:
            self.get_logger().warning(f"encoder: {err}", throttle_duration_sec=5.0)
            return
        self._publish(self._pipeline.on_encoder(ours, self._now_ns()))

    def _on_tick(self) -> None:
        """1 Hz: diagnostics with level STALE when no message arrived during the second."""
        if not self._data_since_tick:
            self._publish([self._pipeline.diagnostics(self._now_ns(), stale=True)])
        self._data_since_tick = False

    def _publish(self, outputs: list[Output]) -> None:
        for output in outputs:
            self._outputs[output.topic].publish(to_ros(output.message))

    # ------------------------------------------------------------------ shutdown

    def finish(self) -> None:
        """Feed what is pending, publish the final estimate (when the context is still up)
        and write the final checkpoint."""
        if self._finished:
            return
        self._finished = True
        outputs = self._pipeline.finish()
        try:
            if rclpy.ok():
                self._publish(outputs)
        except Exception as err:  # the middleware may be shutting down: keep the checkpoint
            self.get_logger().warning(f"final outputs not published: {err}")
        self._checkpoints.close()


def main(args: list[str] | None = None) -> int:
    """Entry point (``ros2 run genbacklash_ros backlash_identifier``), in the ros2/examples
    style: Ctrl-C and an external shutdown end the node quietly, after the final checkpoint.
    """
    rclpy.init(args=args)
    node: BacklashIdentifierNode | None = None
    try:
        node = BacklashIdentifierNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except GenBacklashError as err:  # invalid parameters at start
        print(f"backlash_identifier: error: {err}", flush=True)
        return 2
    finally:
        if node is not None:
            node.finish()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
