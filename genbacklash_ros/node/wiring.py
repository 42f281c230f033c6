"""Say what is wrong with the wiring: publishers of another type on a subscribed topic.

A subscriber of ``std_msgs/Float64MultiArray`` on ``/command`` receives nothing from a
publisher of ``std_msgs/Float64`` there (DDS does not match the two), so a node that only
counts messages sees silence. What discovery shows is enough to say why: the transports ask
it (rclpy: ``Node.get_publishers_info_by_topic``; DDS: the built-in publication topic) and
hand the types seen to :func:`type_mismatches`, whose lines go into the node's diagnostics
with :func:`annotate`. Pure functions on names: no middleware is imported here.

Type names are accepted in the ROS 2 form (``std_msgs/msg/Float64``), the short form
(``std_msgs/Float64``) and the DDS form (``std_msgs::msg::dds_::Float64_``); messages use the
ROS 2 form.

Examples
--------
>>> print(type_mismatch("/command", "std_msgs::msg::dds_::Float64_",
...                     "std_msgs/msg/Float64MultiArray", "command_type"))
a publisher of std_msgs/msg/Float64 on /command, where the node subscribes \
std_msgs/msg/Float64MultiArray: its messages do not reach the node; to read them set \
parameter command_type to float64 (it selects the type)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence

from genbacklash_ros.node.messages import DiagnosticArray, DiagnosticStatus, KeyValue

__all__ = [
    "READER_DEPTH",
    "TYPE_CHOICES",
    "WIRING_KEY",
    "annotate",
    "ros_type_name",
    "selected_type",
    "type_mismatch",
    "type_mismatches",
]

#: For each parameter that selects a subscription's type: ROS 2 type name -> its value.
TYPE_CHOICES: Mapping[str, Mapping[str, str]] = {
    "command_type": {
        "std_msgs/msg/Float64": "float64",
        "std_msgs/msg/Float64MultiArray": "float64_multi_array",
        "sensor_msgs/msg/JointState": "joint_state",
    },
    "encoder_type": {
        "sensor_msgs/msg/JointState": "joint_state",
        "std_msgs/msg/Float64": "float64",
    },
    "motor_encoder_type": {
        "sensor_msgs/msg/JointState": "joint_state",
        "std_msgs/msg/Float64": "float64",
    },
}

#: History depth of the node's ``command`` and ``encoder`` subscriptions, in both transports
#: (4 s at 500 Hz, 2 s at 1 kHz). The middleware's receive thread stores and acknowledges
#: samples into this cache while the Python side is busy (a refit's hand-over, a loaded
#: machine descheduling the process); with ROS 2's depth of 10 (5 for sensor data) a stall of
#: 20 ms at 500 Hz overwrote commands before the node took them. Depth is local to the reader,
#: not part of QoS matching, so peers match as before.
READER_DEPTH = 2000

#: History depth of the node's ``compensated_command`` writer, in both transports. A reliable
#: writer resends only what its history still holds: with ROS 2's depth of 10, a subscriber
#: descheduled while the node answers a backlog (the node catching up after a stall publishes
#: hundreds of answers at once) overflowed its socket buffer (about 270 small packets) and
#: lost every answer beyond it for good; measured, a Fast DDS subscriber stopped 0.3 s during
#: a burst of 3,000 got 266 (depth 10) and 3,000 (depth 3,000). Depth is local to the
#: writer, not part of QoS matching, so peers match as before.
ANSWER_DEPTH = READER_DEPTH

#: The diagnostics key that carries the wiring problems (``ok`` when there are none).
WIRING_KEY = "wiring"


def ros_type_name(name: str) -> str:
    """``name`` in the ROS 2 form ``pkg/msg/Type``.

    >>> ros_type_name("std_msgs::msg::dds_::Float64_"), ros_type_name("std_msgs/Float64")
    ('std_msgs/msg/Float64', 'std_msgs/msg/Float64')
    """
    text = name.strip()
    if "::" in text:
        parts = [p for p in text.split("::") if p != "dds_"]
        if parts:
            parts[-1] = parts[-1].removesuffix("_")
        return "/".join(parts)
    parts = text.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return text


def selected_type(parameter: str, value: str) -> str:
    """The ROS 2 type a type-selecting parameter's value subscribes.

    >>> selected_type("encoder_type", "joint_state")
    'sensor_msgs/msg/JointState'
    """
    for type_name, choice in TYPE_CHOICES.get(parameter, {}).items():
        if choice == value:
            return type_name
    raise KeyError(f"{parameter}={value!r} selects no known type")


def type_mismatch(topic: str, seen_type: str, expected_type: str, parameter: str) -> str:
    """One line: a publisher of ``seen_type`` on ``topic``, where the node subscribes
    ``expected_type``, the type ``parameter`` selects; the value that reads it, if any.

    >>> print(type_mismatch("/encoder", "geometry_msgs/msg/Twist",
    ...                     "sensor_msgs/msg/JointState", "encoder_type"))
    a publisher of geometry_msgs/msg/Twist on /encoder, where the node subscribes \
sensor_msgs/msg/JointState: its messages do not reach the node; parameter encoder_type \
selects the type and reads sensor_msgs/msg/JointState or std_msgs/msg/Float64
    """
    seen = ros_type_name(seen_type)
    expected = ros_type_name(expected_type)
    text = (
        f"a publisher of {seen} on {topic}, where the node subscribes {expected}: its "
        "messages do not reach the node"
    )
    choices = TYPE_CHOICES.get(parameter, {})
    if seen in choices:
        fix = f"to read them set parameter {parameter} to {choices[seen]} (it selects the type)"
        return f"{text}; {fix}"
    if choices:
        return f"{text}; parameter {parameter} selects the type and reads {' or '.join(choices)}"
    return f"{text}; parameter {parameter} selects the type"


def type_mismatches(
    topic: str, expected_type: str, parameter: str, seen_types: Iterable[str]
) -> tuple[str, ...]:
    """A :func:`type_mismatch` line per distinct type other than ``expected_type`` among the
    publishers' ``seen_types`` on ``topic`` (discovery's view), in the order first seen.

    >>> type_mismatches("/command", "std_msgs/msg/Float64", "command_type",
    ...                 ["std_msgs::msg::dds_::Float64_", "std_msgs/msg/Float64"])
    ()
    """
    expected = ros_type_name(expected_type)
    others = dict.fromkeys(ros_type_name(t) for t in seen_types)
    return tuple(
        type_mismatch(topic, seen, expected, parameter) for seen in others if seen != expected
    )


def annotate(
    diagnostics: DiagnosticArray, problems: Sequence[str], key: str = WIRING_KEY
) -> DiagnosticArray:
    """``diagnostics`` with ``problems`` in each status: the value of ``key`` (default
    :data:`WIRING_KEY`; ``ok`` without problems), and with problems the level raised to at
    least WARN and the lines appended to the message.

    >>> status = DiagnosticStatus(DiagnosticStatus.OK, "backlash_identifier", "converged")
    >>> out = annotate(DiagnosticArray(status=(status,)), ["a publisher of ..."])
    >>> out.status[0].level, out.status[0].message, out.status[0].values[-1].key
    (1, 'converged; a publisher of ...', 'wiring')
    """
    value = "; ".join(problems) if problems else "ok"
    statuses = []
    for status in diagnostics.status:
        changes: dict[str, object] = {
            "values": (*status.values, KeyValue(key, value)),
        }
        if problems:
            changes["level"] = max(status.level, DiagnosticStatus.WARN)
            changes["message"] = "; ".join(p for p in (status.message, *problems) if p)
        statuses.append(dataclasses.replace(status, **changes))  # type: ignore[arg-type]
    return dataclasses.replace(diagnostics, status=tuple(statuses))
