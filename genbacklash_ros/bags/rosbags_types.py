"""Conversion between :mod:`genbacklash_ros.node.messages` and rosbags' message objects.

rosbags (0.11) generates one dataclass per ROS message type in a typestore
(``get_typestore(Stores.ROS2_JAZZY)``); its CDR serializer (``typestore.serialize_cdr`` /
``deserialize_cdr``) writes the bytes ROS 2 puts on the wire and in bags. :func:`to_rosbags`
turns one of our messages into the typestore's object (float sequences as float64 arrays, as
rosbags wants them), :func:`from_rosbags` turns a rosbags object (or anything with the same
fields and a ``__msgtype__``) back into ours.

Examples
--------
>>> from genbacklash_ros.node.messages import Float64MultiArray
>>> store = jazzy_typestore()
>>> msg = Float64MultiArray(data=(0.5, -1.25))
>>> raw = store.serialize_cdr(to_rosbags(msg, store), msg.ros_type)
>>> from_rosbags(store.deserialize_cdr(raw, msg.ros_type)) == msg
True
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

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

__all__ = ["from_rosbags", "jazzy_typestore", "to_rosbags"]


@functools.cache
def jazzy_typestore() -> Typestore:
    """The ROS 2 Jazzy typestore (built once; rosbags' typestores are not changed here)."""
    return get_typestore(Stores.ROS2_JAZZY)


def _floats(values: tuple[float, ...]) -> np.ndarray[Any, np.dtype[np.float64]]:
    return np.asarray(values, dtype=np.float64)


def to_rosbags(msg: Message, typestore: Typestore | None = None) -> Any:
    """The rosbags object of ``typestore`` (default Jazzy) for one of our messages.

    Serialise it with ``typestore.serialize_cdr(obj, msg.ros_type)``. Raises
    :class:`~genbacklash_ros.node.messages.MessageError` for a message (or field) it cannot convert.
    """
    store = jazzy_typestore() if typestore is None else typestore
    types = store.types

    def convert(m: Message) -> Any:
        cls = types[m.ros_type]
        if isinstance(m, Time):
            return cls(sec=m.sec, nanosec=m.nanosec)
        if isinstance(m, Header):
            return cls(stamp=convert(m.stamp), frame_id=m.frame_id)
        if isinstance(m, Float64):
            return cls(data=float(m.data))
        if isinstance(m, MultiArrayDimension):
            return cls(label=m.label, size=m.size, stride=m.stride)
        if isinstance(m, MultiArrayLayout):
            return cls(dim=[convert(d) for d in m.dim], data_offset=m.data_offset)
        if isinstance(m, Float64MultiArray):
            return cls(layout=convert(m.layout), data=_floats(m.data))
        if isinstance(m, JointState):
            return cls(
                header=convert(m.header),
                name=list(m.name),
                position=_floats(m.position),
                velocity=_floats(m.velocity),
                effort=_floats(m.effort),
            )
        if isinstance(m, KeyValue):
            return cls(key=m.key, value=m.value)
        if isinstance(m, DiagnosticStatus):
            return cls(
                level=m.level,
                name=m.name,
                message=m.message,
                hardware_id=m.hardware_id,
                values=[convert(v) for v in m.values],
            )
        if isinstance(m, DiagnosticArray):
            return cls(header=convert(m.header), status=[convert(s) for s in m.status])
        raise MessageError(f"no rosbags conversion for {type(m).__name__}")

    try:
        return convert(msg)
    except MessageError:
        raise
    except (AttributeError, KeyError, TypeError, ValueError, OverflowError) as err:
        raise MessageError(f"cannot convert a {type(msg).__name__} to rosbags: {err}") from err


def _floats_back(values: Any) -> tuple[float, ...]:
    if isinstance(values, np.ndarray):
        return tuple(values.tolist())
    return tuple(float(v) for v in values)


def _time(obj: Any) -> Time:
    return Time(int(obj.sec), int(obj.nanosec))


def _header(obj: Any) -> Header:
    return Header(_time(obj.stamp), str(obj.frame_id))


def _dimension(obj: Any) -> MultiArrayDimension:
    return MultiArrayDimension(str(obj.label), int(obj.size), int(obj.stride))


def _layout(obj: Any) -> MultiArrayLayout:
    return MultiArrayLayout(tuple(_dimension(d) for d in obj.dim), int(obj.data_offset))


def _key_value(obj: Any) -> KeyValue:
    return KeyValue(str(obj.key), str(obj.value))


def _status(obj: Any) -> DiagnosticStatus:
    level = obj.level
    if isinstance(level, (bytes, bytearray)):  # rclpy carries the byte field as bytes
        level = level[0]
    return DiagnosticStatus(
        int(level),
        str(obj.name),
        str(obj.message),
        str(obj.hardware_id),
        tuple(_key_value(v) for v in obj.values),
    )


_FROM: dict[str, Callable[[Any], Message]] = {
    Time.ros_type: _time,
    Header.ros_type: _header,
    Float64.ros_type: lambda o: Float64(float(o.data)),
    MultiArrayDimension.ros_type: _dimension,
    MultiArrayLayout.ros_type: _layout,
    Float64MultiArray.ros_type: lambda o: Float64MultiArray(
        _layout(o.layout), _floats_back(o.data)
    ),
    JointState.ros_type: lambda o: JointState(
        _header(o.header),
        tuple(str(n) for n in o.name),
        _floats_back(o.position),
        _floats_back(o.velocity),
        _floats_back(o.effort),
    ),
    KeyValue.ros_type: _key_value,
    DiagnosticStatus.ros_type: _status,
    DiagnosticArray.ros_type: lambda o: DiagnosticArray(
        _header(o.header), tuple(_status(s) for s in o.status)
    ),
}


def from_rosbags(obj: object) -> Message:
    """Our message for a rosbags message object (dispatch on its ``__msgtype__``).

    Raises :class:`~genbacklash_ros.node.messages.MessageError` for a type we do not use or an
    object whose fields do not match.
    """
    msgtype = getattr(obj, "__msgtype__", None)
    convert = _FROM.get(msgtype) if isinstance(msgtype, str) else None
    if convert is None:
        raise MessageError(f"no conversion from message type {msgtype or type(obj).__name__!r}")
    try:
        return convert(obj)
    except (AttributeError, TypeError, ValueError, IndexError, OverflowError) as err:
        if isinstance(err, MessageError):
            raise
        raise MessageError(f"cannot convert a {msgtype}: {err}") from err
