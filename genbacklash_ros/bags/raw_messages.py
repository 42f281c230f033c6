"""Whole messages from raw CDR bytes, and a compensated command written back into them.

The rclpy node takes its command and encoder topics as raw CDR bytes (``raw=True``
subscriptions) and publishes the compensated command as bytes: rclpy's conversion of a
message to and from Python objects (a six-joint ``JointState``: about 26 us to take, 7 us more
to our dataclass; a command published: about 11 us) is most of what a 1 kHz topic costs the
node's message thread beyond the pipeline itself.

:class:`RawMessageCodec` decodes the bytes of one topic into the node's own message
(:mod:`genbacklash_ros.node.messages`) by the layout :func:`~genbacklash_ros.bags.cdr_layout.
learn_layout` learnt from the first message of that length: the constant parts (frame id,
names, array dimensions) come from that first message, the stamp and the floats straight from
the bytes. A message of another layout takes the ``slow`` decoder the transport gives (rclpy's
own deserializer and its conversion), so the result is always what the slow path gives.

:meth:`RawMessageCodec.encode` writes an outgoing message that differs from a decoded one
only in its floats (the compensated command: the command with some elements replaced) into a
copy of that message's bytes; anything else is for the transport to serialize as usual.

Examples
--------
>>> from genbacklash_ros.node.messages import Float64MultiArray
>>> from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore, to_rosbags
>>> store = jazzy_typestore()
>>> def cdr(msg):
...     return bytes(store.serialize_cdr(to_rosbags(msg, store), msg.ros_type))
>>> def slow(raw):
...     return from_rosbags(store.deserialize_cdr(raw, Float64MultiArray.ros_type))
>>> codec = RawMessageCodec(Float64MultiArray.ros_type, slow)
>>> first = codec.decode(cdr(Float64MultiArray(data=(0.5, -0.25))))  # learns the layout
>>> raw = cdr(Float64MultiArray(data=(0.1, 0.75)))
>>> msg = codec.decode(raw)  # a byte compare and an unpack
>>> msg.data, codec.fast, codec.slow
((0.1, 0.75), 1, 1)
>>> out = Float64MultiArray(msg.layout, (0.1, 0.8))
>>> slow(codec.encode(raw, msg, out)) == out
True
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from genbacklash_ros.bags.cdr_layout import FLOAT_ARRAYS, CdrLayout, learn_layout
from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore
from genbacklash_ros.node.messages import (
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    Message,
    Time,
)

__all__ = ["RawMessageCodec"]

_MAX_LAYOUTS = 8  # learnt layouts kept per topic (a topic rarely has more than one)
_unpack_stamp = struct.Struct("<iI").unpack_from


class _Learnt:
    """One layout and the message it was learnt from (its constant fields)."""

    __slots__ = ("fields", "layout", "template")

    def __init__(self, layout: CdrLayout, template: Message) -> None:
        self.layout = layout
        self.template = template
        # (field, offset, the struct that reads and writes its doubles)
        self.fields = tuple(
            (name, offset, struct.Struct(f"<{count}d")) for name, offset, count in layout.arrays
        )


class RawMessageCodec:
    """Our message from the raw CDR bytes of one topic, and back for a changed copy.

    Parameters
    ----------
    msgtype : str
        ROS type of the topic (``std_msgs/msg/Float64``, ``std_msgs/msg/Float64MultiArray``,
        ``sensor_msgs/msg/JointState``).
    slow : callable
        The full decoder of one message's bytes into our message (the transport's:
        rclpy's deserializer and its conversion); raises
        :class:`~genbacklash_ros.node.messages.MessageError` for bytes it rejects.

    Attributes
    ----------
    fast, slow : int
        Messages decoded by a learnt layout, and by the full decoder.
    """

    def __init__(self, msgtype: str, slow: Callable[[bytes], Message]) -> None:
        if msgtype not in FLOAT_ARRAYS:
            raise ValueError(f"no raw codec for message type {msgtype}")
        self.msgtype = msgtype
        self._slow = slow
        self._store = jazzy_typestore()
        self._learnt: dict[int, _Learnt | None] = {}
        # the bytes decode last read by a layout, and it: encode of the answer to them
        # (the command just decoded) does not compare their constant bytes again
        self._last: tuple[bytes, _Learnt] | None = None
        self.fast = 0
        self.slow = 0

    def _layout_of(self, raw: bytes) -> _Learnt | None:
        last = self._last
        if last is not None and last[0] is raw:
            return last[1]
        learnt = self._learnt.get(len(raw))
        if learnt is None or not learnt.layout.matches(raw):
            return None
        return learnt

    def decode(self, raw: bytes) -> Message:
        """Our message for ``raw`` (what ``slow`` gives for it)."""
        learnt = self._layout_of(raw)
        if learnt is None:
            return self._decode_slow(raw)
        self._last = (raw, learnt)
        self.fast += 1
        template = learnt.template
        values = {name: unpack.unpack_from(raw, at) for name, at, unpack in learnt.fields}
        if isinstance(template, Float64):
            return Float64(values["data"][0])
        if isinstance(template, Float64MultiArray):
            return Float64MultiArray(template.layout, values.get("data", ()))
        assert isinstance(template, JointState)  # the types FLOAT_ARRAYS holds
        sec, nanosec = _unpack_stamp(raw, learnt.layout.stamp_at)
        return JointState(
            Header(Time(sec, nanosec), template.header.frame_id),
            template.name,
            values.get("position", ()),
            values.get("velocity", ()),
            values.get("effort", ()),
        )

    def _decode_slow(self, raw: bytes) -> Message:
        msg = self._slow(raw)  # raises: not learnt either
        self.slow += 1
        if len(raw) not in self._learnt and len(self._learnt) < _MAX_LAYOUTS:
            self._learnt[len(raw)] = self._learn(raw, msg)
        return msg

    def _learn(self, raw: bytes, msg: Message) -> _Learnt | None:
        """The layout of ``raw`` when rosbags reads it as ``slow`` did (None: slow always)."""
        try:
            obj = self._store.deserialize_cdr(raw, self.msgtype)
            if repr(from_rosbags(obj)) != repr(msg):  # (repr: a NaN equals itself)
                return None
        except Exception:  # rosbags rejects what the middleware took: read those fully
            return None
        layout = learn_layout(self._store, self.msgtype, raw, obj)
        if layout is None:
            return None
        if isinstance(msg, JointState) and layout.stamp_at < 0:
            return None
        return _Learnt(layout, msg)

    def encode(self, raw: bytes, decoded: Message, out: Message) -> bytes | None:
        """The bytes of ``out``: ``raw`` (decoded to ``decoded`` by this codec) with its
        floats replaced by ``out``'s, when ``out`` differs from ``decoded`` in its floats
        alone and ``raw`` has a learnt layout; None otherwise (serialize ``out`` as usual)."""
        learnt = self._layout_of(raw)
        if learnt is None or type(out) is not type(decoded):
            return None
        if isinstance(out, Float64MultiArray):
            assert isinstance(decoded, Float64MultiArray)
            if out.layout is not decoded.layout and out.layout != decoded.layout:
                return None
        elif isinstance(out, JointState):
            assert isinstance(decoded, JointState)
            if out.header != decoded.header or out.name != decoded.name:
                return None
        patched = bytearray(raw)
        for name, at, pack in learnt.fields:
            values = getattr(out, name)
            if isinstance(out, Float64):
                values = (values,)
            if len(values) * 8 != pack.size:
                return None
            pack.pack_into(patched, at, *values)
        if not isinstance(out, Float64):
            for name in FLOAT_ARRAYS[self.msgtype]:
                if learnt.layout.array(name) is None and getattr(out, name):
                    return None  # empty in the bytes, not in ``out``
        return bytes(patched)

    def learnt_layouts(self) -> int:
        """How many layouts this codec reads by their bytes."""
        return sum(1 for learnt in self._learnt.values() if learnt is not None)
