"""The command or encoder value of a raw CDR message, fast, for bag replay.

Replay reads tens of thousands of messages a second; decoding each with rosbags' generic
deserializer (and converting it to our dataclass) costs about 50 us, far more than the
pipeline. Yet the messages of one topic almost always share one byte layout: the same frame id,
joint names and array lengths, only stamps and numbers change. :class:`RawValueReader`
therefore decodes the first message of each layout with rosbags and our adapters
(:func:`~genbacklash_ros.node.messages.read_command` /
:func:`~genbacklash_ros.node.messages.read_encoder`), and *learns* from rosbags' own serializer
where that layout keeps its stamp and its float arrays: it re-serializes the message with
sentinel values in those fields and looks where they land. A later message of the same length
whose every other byte equals the learnt message's (names, lengths, counts, padding) has its
numbers at the same offsets, so its value is one ``struct.unpack_from``. Anything else --
another length, another joint order, a big-endian message, a message rosbags does not write
back byte for byte -- takes the full rosbags path, so the result is always the adapters'
result.

:meth:`RawValueReader.patch` writes a compensated value into a copy of a command's bytes:
the compensated command of :func:`~genbacklash_ros.node.messages.compensated_command`, serialized.

Examples
--------
>>> from genbacklash_ros.node.messages import Float64MultiArray
>>> from genbacklash_ros.bags.rosbags_types import jazzy_typestore, to_rosbags
>>> store = jazzy_typestore()
>>> def cdr(msg):
...     return bytes(store.serialize_cdr(to_rosbags(msg, store), msg.ros_type))
>>> reader = RawValueReader(Float64MultiArray.ros_type, "command", index=1)
>>> reader.read(cdr(Float64MultiArray(data=(0.5, -0.25))))  # learns the layout
(0, -0.25)
>>> reader.read(cdr(Float64MultiArray(data=(0.1, 0.75))))  # a byte compare and an unpack
(0, 0.75)
>>> reader.fast, reader.slow
(1, 1)
>>> raw = reader.patch(cdr(Float64MultiArray(data=(0.1, 0.75))), 0.8)
>>> reader.read(raw)
(0, 0.8)
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np

from genbacklash_ros.bags.cdr_layout import CdrLayout, learn_layout
from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore, to_rosbags
from genbacklash_ros.node.messages import (
    NS_PER_S,
    CommandType,
    EncoderType,
    Float64,
    Float64MultiArray,
    JointState,
    MessageError,
    compensated_command,
    read_command,
    read_encoder,
)

__all__ = ["RawValueReader", "UndecodableMessage"]

Role = Literal["command", "encoder"]

_KINDS: dict[str, str] = {
    Float64.ros_type: "float64",
    Float64MultiArray.ros_type: "float64_multi_array",
    JointState.ros_type: "joint_state",
}
_MAX_LAYOUTS = 8  # learnt layouts kept per reader (a topic rarely has more than one)
_unpack_d = struct.Struct("<d").unpack_from
_unpack_stamp = struct.Struct("<iI").unpack_from
_pack_d = struct.Struct("<d").pack


class UndecodableMessage(MessageError):
    """The bytes are not a CDR message of the reader's type (a corrupt message)."""


@dataclass(frozen=True, slots=True)
class _Layout:
    """Where one byte layout keeps the value this reader reads."""

    learnt: CdrLayout  # the layout's constant bytes, stamp and float arrays
    value_at: int  # offset of the value read
    checked: tuple[tuple[int, int], ...]  # (offset, count) of floats that must be finite


def _rows_of(
    raws: Sequence[bytes], index: np.ndarray, length: int, layout: _Layout
) -> tuple[np.ndarray, np.ndarray]:
    """The messages ``raws[index]`` (all ``length`` bytes long) as the rows of a read-only
    ``(messages, length)`` byte array, and which rows hold the layout's constant bytes."""
    joined = b"".join([raws[k] for k in index.tolist()])
    rows = np.frombuffer(joined, dtype=np.uint8).reshape(index.size, length)
    good = np.ones(index.size, dtype=bool)
    for start, expected in layout.learnt.constant:
        # each row's run of bytes as one opaque value, compared whole (a memcmp per row:
        # ~30 % less than the bytes compared one by one and then reduced per row)
        kind = np.dtype((np.void, len(expected)))
        runs = np.ascontiguousarray(rows[:, start : start + len(expected)]).view(kind)[:, 0]
        good &= runs == np.frombuffer(expected, kind)[0]
    return rows, good


class RawValueReader:
    """Read the command (or encoder) value of raw CDR messages of one topic.

    Parameters
    ----------
    msgtype : str
        ROS type of the topic (``std_msgs/msg/Float64``, ``std_msgs/msg/Float64MultiArray``,
        ``sensor_msgs/msg/JointState``).
    role : {"command", "encoder"}
        Which adapter's rules apply (a command's other elements must be finite as well: the
        compensated command echoes them; an encoder's other joints are not looked at).
    index : int
        ``command_index`` (Float64MultiArray commands).
    joint : str
        Joint name (JointState; ``''``: the first).

    Attributes
    ----------
    fast, slow : int
        Messages read by a learnt layout, and by rosbags' deserializer.
    """

    def __init__(self, msgtype: str, role: Role, *, index: int = 0, joint: str = "") -> None:
        kind = _KINDS.get(msgtype)
        if kind is None or (role == "encoder" and kind == "float64_multi_array"):
            raise MessageError(f"no {role} adapter for message type {msgtype}")
        self.msgtype = msgtype
        self.role = role
        self.kind = kind
        self.index = index
        self.joint = joint
        self.fast = 0
        self.slow = 0
        self._store = jazzy_typestore()
        self._layouts: dict[int, _Layout | None] = {}

    # ------------------------------------------------------------------ reading

    def read(self, raw: bytes) -> tuple[int, float]:
        """``(header stamp in ns or 0, value)`` of one message; :class:`MessageError` when
        the message does not decode or the adapters reject it (as they would the decoded
        message)."""
        layout = self._layouts.get(len(raw))
        if layout is not None and layout.learnt.matches(raw):
            return self._read_fast(raw, layout)
        return self._read_slow(raw)

    def read_many(self, raws: Sequence[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`read` of many messages at once, in numpy steps per learnt layout.

        Returns ``(stamps, values, ok)``: int64 header stamps (0: none), float values and
        whether each message was read so. A message not ``ok`` (another layout, not finite,
        damaged) is for :meth:`read` to read or reject, one by one; for the others the
        results are :meth:`read`'s. The first message of a length not seen yet is read by
        :meth:`read` here to learn its layout.
        """
        n = len(raws)
        stamps = np.zeros(n, dtype=np.int64)
        values = np.full(n, math.nan)
        ok = np.zeros(n, dtype=bool)
        if n == 0:
            return stamps, values, ok
        lengths = np.fromiter(map(len, raws), dtype=np.int64, count=n)
        for length in np.unique(lengths).tolist():
            if length not in self._layouts and len(self._layouts) < _MAX_LAYOUTS:
                first = int(np.argmax(lengths == length))
                try:
                    self.read(raws[first])  # learns the layout (its value is read again)
                except MessageError:
                    pass
            layout = self._layouts.get(length)
            if layout is None:
                continue
            index = np.flatnonzero(lengths == length)
            rows, good = _rows_of(raws, index, length, layout)
            at = layout.value_at
            value = rows[:, at : at + 8].copy().view("<f8")[:, 0]
            good &= np.isfinite(value)
            for offset, count in layout.checked:
                floats = rows[:, offset : offset + 8 * count].copy().view("<f8")
                good &= np.isfinite(floats).all(axis=1)
            if layout.learnt.stamp_at >= 0:
                at = layout.learnt.stamp_at
                sec = rows[:, at : at + 4].copy().view("<i4")[:, 0].astype(np.int64)
                nanosec = rows[:, at + 4 : at + 8].copy().view("<u4")[:, 0].astype(np.int64)
                stamps[index] = np.where(good, sec * NS_PER_S + nanosec, 0)
            values[index[good]] = value[good]
            ok[index[good]] = True
            self.fast += int(np.count_nonzero(good))
        return stamps, values, ok

    def read_all(self, raws: Sequence[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`read_many`, and :meth:`read` for each message it leaves: ``(stamps, values,
        ok)`` with ``ok`` False only where the adapters reject the message."""
        stamps, values, ok = self.read_many(raws)
        for k in np.flatnonzero(~ok).tolist():
            try:
                stamps[k], values[k] = self.read(raws[k])
            except MessageError:
                continue
            ok[k] = True
        return stamps, values, ok

    def _read_fast(self, raw: bytes, layout: _Layout) -> tuple[int, float]:
        (value,) = _unpack_d(raw, layout.value_at)
        for offset, count in layout.checked:
            floats = np.frombuffer(raw, "<f8", count, offset)
            if not np.isfinite(floats).all():
                return self._read_slow(raw)  # the adapters word the error
        if not math.isfinite(value):
            return self._read_slow(raw)
        stamp = 0
        if layout.learnt.stamp_at >= 0:
            sec, nanosec = _unpack_stamp(raw, layout.learnt.stamp_at)
            stamp = sec * NS_PER_S + nanosec
        self.fast += 1
        return stamp, value

    def _decode(self, raw: bytes) -> tuple[Any, Any]:
        try:
            obj = self._store.deserialize_cdr(raw, self.msgtype)
        except Exception as err:  # rosbags' deserializer: struct, index, unicode errors
            text = " ".join(str(err).split()) or type(err).__name__
            raise UndecodableMessage(f"a {self.msgtype} message does not decode: {text}") from err
        return obj, from_rosbags(obj)

    def _read_slow(self, raw: bytes) -> tuple[int, float]:
        obj, msg = self._decode(raw)
        if self.role == "command":
            kind: Any = self.kind
            stamp, value = read_command(msg, kind, index=self.index, joint=self.joint)
        else:
            enc: EncoderType = "float64" if self.kind == "float64" else "joint_state"
            stamp, value = read_encoder(msg, enc, joint=self.joint)
        self.slow += 1
        if len(raw) not in self._layouts and len(self._layouts) < _MAX_LAYOUTS:
            self._layouts[len(raw)] = self._learn(raw, obj, msg)
        return stamp or 0, value

    # ------------------------------------------------------------------ learning

    def _serialize(self, obj: Any) -> bytes:
        return bytes(self._store.serialize_cdr(obj, self.msgtype))

    def _value_index(self, msg: object) -> int:
        if self.kind == "float64_multi_array":
            return self.index
        if self.kind == "joint_state" and self.joint:
            return list(msg.name).index(self.joint)  # type: ignore[attr-defined]
        return 0

    def _learn(self, raw: bytes, obj: Any, msg: object) -> _Layout | None:
        """The layout of ``raw``, from rosbags' serializer (None: read it slowly always)."""
        learnt = learn_layout(self._store, self.msgtype, raw, obj)
        if learnt is None:
            return None
        main = learnt.array("data" if self.kind != "joint_state" else "position")
        if main is None:
            return None
        offset, count = main
        index = self._value_index(msg)
        if not 0 <= index < count:
            return None
        checked: tuple[tuple[int, int], ...] = ()
        if self.role == "command" and self.kind != "float64":
            # the adapters want every element finite
            checked = tuple((at, n) for _, at, n in learnt.arrays)
        return _Layout(learnt, offset + 8 * index, checked)

    # ------------------------------------------------------------------ writing

    def patch_many(self, raws: Sequence[bytes], values: np.ndarray) -> list[bytes]:
        """:meth:`patch` of many commands, in numpy steps per learnt layout (a message of
        another layout, or a value that is not finite, goes through :meth:`patch`)."""
        n = len(raws)
        out: list[bytes | None] = [None] * n
        lengths = np.fromiter(map(len, raws), dtype=np.int64, count=n)
        sent = np.asarray(values, dtype="<f8")
        for length in np.unique(lengths).tolist() if n and self.role == "command" else []:
            layout = self._layouts.get(length)
            if layout is None:
                continue
            index = np.flatnonzero(lengths == length)
            rows, good = _rows_of(raws, index, length, layout)
            good &= np.isfinite(sent[index])
            at = layout.value_at
            rows = rows.copy()  # writable
            rows[:, at : at + 8] = sent[index].view(np.uint8).reshape(index.size, 8)
            patched = rows.tobytes()
            for j, k in enumerate(index.tolist()):
                if good[j]:
                    out[k] = patched[j * length : (j + 1) * length]
        return [
            self.patch(raw, float(value)) if done is None else done
            for raw, value, done in zip(raws, sent.tolist(), out, strict=True)
        ]

    def patch(self, raw: bytes, value: float) -> bytes:
        """The bytes of the compensated command: ``raw`` (a command this reader read) with
        its value replaced by ``value`` (finite), everything else (stamp, other elements)
        unchanged."""
        if self.role != "command":
            raise MessageError("only commands are patched")
        if not math.isfinite(value):
            raise MessageError(f"the compensated command is not finite ({value})")
        layout = self._layouts.get(len(raw))
        if layout is not None and layout.learnt.matches(raw):
            at = layout.value_at
            return raw[:at] + _pack_d(float(value)) + raw[at + 8 :]
        _obj, msg = self._decode(raw)
        kind = cast(CommandType, self.kind)
        out = compensated_command(
            msg,
            value,
            kind,
            index=self.index,
            joint=self.joint,
        )
        return self._serialize(to_rosbags(out, self._store))
