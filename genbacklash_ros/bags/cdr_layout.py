"""Where the numbers of a message's CDR bytes sit, learnt from rosbags' own serializer.

The messages of one topic almost always share one byte layout: the same frame id, joint
names and array lengths; only the stamp and the floats change. :func:`learn_layout` finds,
for one message, where its header stamp and each float array lie in its bytes, by
re-serializing it with rosbags (the message's bytes must come back byte for byte) with
sentinel values in those fields and looking where they land. Every other byte is
*constant*: a later message of the same length that holds the same constant bytes (names,
lengths, counts) has its numbers at the same offsets (:meth:`CdrLayout.matches`). Padding
bytes where rosbags writes zeros but the message holds something else (a middleware may
leave what its buffer held) are neither constant nor read. A message that rosbags does not
write back at the same length and encapsulation (big-endian, bytes after its end) has no
layout, and its readers take rosbags' (or the middleware's) full decoder instead.

Used by :class:`~genbacklash_ros.bags.raw_values.RawValueReader` (bag replay: one value per
message) and :class:`~genbacklash_ros.bags.raw_messages.RawMessageCodec` (the rclpy node's
raw subscriptions: the whole message, and the compensated command written back).

Examples
--------
>>> from genbacklash_ros.node.messages import Float64MultiArray
>>> from genbacklash_ros.bags.rosbags_types import jazzy_typestore, to_rosbags
>>> store = jazzy_typestore()
>>> obj = to_rosbags(Float64MultiArray(data=(0.5, -0.25)), store)
>>> raw = bytes(store.serialize_cdr(obj, "std_msgs/msg/Float64MultiArray"))
>>> layout = learn_layout(store, "std_msgs/msg/Float64MultiArray", raw, obj)
>>> layout.arrays  # (field, offset, count): after the 4-byte CDR header and 16 bytes
(('data', 20, 2),)
>>> layout.matches(raw), layout.stamp_at
(True, -1)
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FLOAT_ARRAYS", "CdrLayout", "learn_layout"]

FLOAT_ARRAYS: dict[str, tuple[str, ...]] = {  # the float fields of each type ("data": a scalar)
    "std_msgs/msg/Float64": ("data",),
    "std_msgs/msg/Float64MultiArray": ("data",),
    "sensor_msgs/msg/JointState": ("position", "velocity", "effort"),
}
_SCALAR = "std_msgs/msg/Float64"
_STAMP_SEC = 0x5EC5A17D  # sentinels: values no real message field holds
_STAMP_NSEC = 0x3C0FFEE7


def _sentinels(n: int, base: float) -> np.ndarray:
    return base * (1.0 + np.arange(1, n + 1) * 2.0**-20)


@dataclass(frozen=True, slots=True)
class CdrLayout:
    """Where one byte layout of a message type keeps its numbers.

    Attributes
    ----------
    length : int
        The length of the messages of this layout, in bytes.
    constant : tuple of (int, bytes)
        ``(offset, bytes)`` every message of the layout holds.
    stamp_at : int
        Offset of ``header.stamp`` (int32 sec, uint32 nanosec); -1: no header.
    arrays : tuple of (str, int, int)
        ``(field, offset, count)`` of each non-empty float field (little-endian doubles).
    """

    length: int
    constant: tuple[tuple[int, bytes], ...]
    stamp_at: int
    arrays: tuple[tuple[str, int, int], ...]

    def matches(self, raw: bytes) -> bool:
        """Whether ``raw`` has this layout (its length and every constant byte)."""
        if len(raw) != self.length:
            return False
        for start, expected in self.constant:
            if not raw.startswith(expected, start):
                return False
        return True

    def array(self, name: str) -> tuple[int, int] | None:
        """``(offset, count)`` of the float field ``name`` (None: empty or not a field)."""
        for field, offset, count in self.arrays:
            if field == name:
                return offset, count
        return None


def learn_layout(store: Any, msgtype: str, raw: bytes, obj: Any) -> CdrLayout | None:
    """The layout of ``raw``, a message of ``msgtype`` that rosbags' ``store`` decoded to
    ``obj``; None when rosbags does not write it back at the same length and encapsulation,
    or differs from it in more than padding (read it fully always)."""

    def serialize(message: Any) -> bytes:
        return bytes(store.serialize_cdr(message, msgtype))

    names = FLOAT_ARRAYS.get(msgtype)
    if names is None:
        return None
    scalar = msgtype == _SCALAR
    try:
        canonical = serialize(obj)
        if len(canonical) != len(raw) or canonical[:4] != raw[:4]:
            return None  # another length or encapsulation (big-endian, trailing bytes)
        # where rosbags writes another byte than ``raw`` holds, ``raw`` has junk in padding
        # (rosbags writes zeros; a middleware may leave what its buffer held): not constant
        junk = [k for k in range(len(raw)) if raw[k] != canonical[k]] if canonical != raw else []
        probe = obj
        if hasattr(obj, "header"):
            stamp = dataclasses.replace(obj.header.stamp, sec=_STAMP_SEC, nanosec=_STAMP_NSEC)
            probe = dataclasses.replace(probe, header=dataclasses.replace(obj.header, stamp=stamp))
        counts = {name: 1 if scalar else len(getattr(obj, name)) for name in names}
        for k, name in enumerate(names):
            if counts[name]:
                values = _sentinels(counts[name], 1.5e300 * (k + 1))
                probe = dataclasses.replace(probe, **{name: values[0] if scalar else values})
        seen = serialize(probe)
        if len(seen) != len(raw):
            return None
        variable: list[tuple[int, int]] = []
        stamp_at = -1
        if hasattr(obj, "header"):
            stamp_at = seen.find(struct.pack("<iI", _STAMP_SEC, _STAMP_NSEC))
            if stamp_at < 0:
                return None
            variable.append((stamp_at, stamp_at + 8))
        arrays: list[tuple[str, int, int]] = []
        for k, name in enumerate(names):
            n = counts[name]
            if not n:
                continue
            block = _sentinels(n, 1.5e300 * (k + 1)).astype("<f8").tobytes()
            found = seen.find(block)
            if found < 0 or seen.find(block, found + 1) >= 0:
                return None
            arrays.append((name, found, n))
            variable.append((found, found + 8 * n))
    except (AttributeError, TypeError, ValueError, struct.error):
        return None
    if any(start <= k < end for k in junk for start, end in variable):
        return None  # a number's own bytes differ: not padding
    variable += [(k, k + 1) for k in junk]
    variable.sort()
    constant: list[tuple[int, bytes]] = []
    pos = 0
    for start, end in variable:
        if start > pos:
            constant.append((pos, raw[pos:start]))
        pos = max(pos, end)
    if pos < len(raw):
        constant.append((pos, raw[pos:]))
    return CdrLayout(len(raw), tuple(constant), stamp_at, tuple(arrays))
