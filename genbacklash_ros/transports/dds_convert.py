"""Conversion between :mod:`genbacklash_ros.node.messages` and the DDS wire types.

:mod:`genbacklash_ros.transports.dds_types` declares each ROS 2 message as a cyclonedds
``IdlStruct`` with the same field names as our frozen dataclasses. :func:`to_dds` turns one of our
messages into its wire type (tuples become lists), :func:`from_dds` turns a received wire
object back into ours. :data:`DDS_TYPES` maps a ROS type name (``std_msgs/msg/Float64``) to
its wire class, e.g. to create a topic.

This module imports cyclonedds; import it only where the DDS transport is used.

Examples
--------
>>> from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
>>> msg = JointState(Header(Time(3, 5), "base"), ("j1",), (0.25,))
>>> wire = to_dds(msg)
>>> type(wire).__name__, wire.position
('JointState_', [0.25])
>>> from_dds(type(wire).deserialize(wire.serialize())) == msg
True
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from genbacklash_ros.node.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    KeyValue,
    Message,
    MessageError,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)
from genbacklash_ros.transports import dds_types

__all__ = ["DDS_TYPES", "from_dds", "to_dds"]

# cyclonedds' IDL field annotations are runtime descriptors mypy cannot read: use the wire
# classes untyped (the tests check the values and the bytes).
_T: Any = dds_types
Time_ = _T.Time_
Header_ = _T.Header_
Float64_ = _T.Float64_
MultiArrayDimension_ = _T.MultiArrayDimension_
MultiArrayLayout_ = _T.MultiArrayLayout_
Float64MultiArray_ = _T.Float64MultiArray_
JointState_ = _T.JointState_
KeyValue_ = _T.KeyValue_
DiagnosticStatus_ = _T.DiagnosticStatus_
DiagnosticArray_ = _T.DiagnosticArray_

DDS_TYPES: dict[str, type[Any]] = {
    Time.ros_type: Time_,
    Header.ros_type: Header_,
    Float64.ros_type: Float64_,
    MultiArrayDimension.ros_type: MultiArrayDimension_,
    MultiArrayLayout.ros_type: MultiArrayLayout_,
    Float64MultiArray.ros_type: Float64MultiArray_,
    JointState.ros_type: JointState_,
    KeyValue.ros_type: KeyValue_,
    DiagnosticStatus.ros_type: DiagnosticStatus_,
    DiagnosticArray.ros_type: DiagnosticArray_,
}
"""ROS type name -> the cyclonedds wire class."""


# --------------------------------------------------------------------------- ours -> DDS


def _time(m: Time) -> Any:
    return Time_(m.sec, m.nanosec)


def _header(m: Header) -> Any:
    return Header_(_time(m.stamp), m.frame_id)


def _layout(m: MultiArrayLayout) -> Any:
    dims = [MultiArrayDimension_(d.label, d.size, d.stride) for d in m.dim]
    return MultiArrayLayout_(dims, m.data_offset)


def _status(m: DiagnosticStatus) -> Any:
    values = [KeyValue_(v.key, v.value) for v in m.values]
    return DiagnosticStatus_(m.level, m.name, m.message, m.hardware_id, values)


def to_dds(msg: Message) -> Any:
    """The cyclonedds wire object for one of our messages (same field names and values).

    Raises :class:`~genbacklash_ros.node.messages.MessageError` for a type without a wire type or
    a field it cannot convert (e.g. a data value that is not a number).
    """
    try:
        return _to_dds(msg)
    except MessageError:
        raise
    except (AttributeError, TypeError, ValueError, OverflowError) as err:
        raise MessageError(f"cannot convert a {type(msg).__name__} to DDS: {err}") from err


def _to_dds(msg: Message) -> Any:
    if isinstance(msg, Float64):
        return Float64_(float(msg.data))
    if isinstance(msg, Float64MultiArray):
        return Float64MultiArray_(_layout(msg.layout), [float(v) for v in msg.data])
    if isinstance(msg, JointState):
        return JointState_(
            _header(msg.header),
            list(msg.name),
            [float(v) for v in msg.position],
            [float(v) for v in msg.velocity],
            [float(v) for v in msg.effort],
        )
    if isinstance(msg, DiagnosticArray):
        return DiagnosticArray_(_header(msg.header), [_status(s) for s in msg.status])
    if isinstance(msg, Time):
        return _time(msg)
    if isinstance(msg, Header):
        return _header(msg)
    if isinstance(msg, MultiArrayLayout):
        return _layout(msg)
    if isinstance(msg, MultiArrayDimension):
        return MultiArrayDimension_(msg.label, msg.size, msg.stride)
    if isinstance(msg, KeyValue):
        return KeyValue_(msg.key, msg.value)
    if isinstance(msg, DiagnosticStatus):
        return _status(msg)
    raise MessageError(f"no DDS type for {type(msg).__name__}")


# --------------------------------------------------------------------------- DDS -> ours


def _time_back(o: Any) -> Time:
    return Time(int(o.sec), int(o.nanosec))


def _header_back(o: Any) -> Header:
    return Header(_time_back(o.stamp), str(o.frame_id))


def _dim_back(o: Any) -> MultiArrayDimension:
    return MultiArrayDimension(str(o.label), int(o.size), int(o.stride))


def _layout_back(o: Any) -> MultiArrayLayout:
    return MultiArrayLayout(tuple(_dim_back(d) for d in o.dim), int(o.data_offset))


def _kv_back(o: Any) -> KeyValue:
    return KeyValue(str(o.key), str(o.value))


def _status_back(o: Any) -> DiagnosticStatus:
    return DiagnosticStatus(
        int(o.level),
        str(o.name),
        str(o.message),
        str(o.hardware_id),
        tuple(_kv_back(v) for v in o.values),
    )


_FROM: dict[type[Any], Callable[[Any], Message]] = {
    Float64_: lambda o: Float64(float(o.data)),
    Float64MultiArray_: lambda o: Float64MultiArray(_layout_back(o.layout), tuple(o.data)),
    JointState_: lambda o: JointState(
        _header_back(o.header),
        tuple(o.name),
        tuple(o.position),
        tuple(o.velocity),
        tuple(o.effort),
    ),
    DiagnosticArray_: lambda o: DiagnosticArray(
        _header_back(o.header), tuple(_status_back(s) for s in o.status)
    ),
    Time_: _time_back,
    Header_: _header_back,
    MultiArrayLayout_: _layout_back,
    MultiArrayDimension_: _dim_back,
    KeyValue_: _kv_back,
    DiagnosticStatus_: _status_back,
}


def from_dds(obj: object) -> Message:
    """Our message for a cyclonedds wire object of :mod:`genbacklash_ros.transports.dds_types`.

    Raises :class:`~genbacklash_ros.node.messages.MessageError` for another type or fields our
    dataclasses reject.
    """
    convert = _FROM.get(type(obj))
    if convert is None:
        raise MessageError(f"no conversion from the DDS type {type(obj).__name__}")
    try:
        return convert(obj)
    except MessageError:
        raise
    except (AttributeError, TypeError, ValueError, OverflowError) as err:
        raise MessageError(f"cannot convert a {type(obj).__name__}: {err}") from err
