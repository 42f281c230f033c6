"""RawValueReader: reading values straight from CDR bytes gives exactly what rosbags'
deserializer and our adapters give, for every layout, and falls back when unsure."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_ros.bags.raw_values import RawValueReader
from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore, to_rosbags
from genbacklash_ros.node.messages import (
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    Message,
    MessageError,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
    compensated_command,
    read_command,
    read_encoder,
)

STORE = jazzy_typestore()

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-10.0, 10.0),
    st.floats(-10.0, 10.0),
)
names = st.text(alphabet="abcdefghij_", min_size=0, max_size=12)
stamps = st.builds(Time, st.integers(0, 2**31 - 1), st.integers(0, 999_999_999))


def cdr(msg: Message, little_endian: bool = True) -> bytes:
    obj = to_rosbags(msg, STORE)
    if little_endian:
        return bytes(STORE.serialize_cdr(obj, msg.ros_type))
    return bytes(STORE.serialize_cdr(obj, msg.ros_type, little_endian=False))


def reference(msg: Message, role: str, kind: str, index: int, joint: str) -> object:
    """What the adapters make of the decoded message (a value, or the error type)."""
    decoded = from_rosbags(STORE.deserialize_cdr(cdr(msg), msg.ros_type))
    try:
        if role == "command":
            stamp, value = read_command(decoded, kind, index=index, joint=joint)  # type: ignore[arg-type]
        else:
            stamp, value = read_encoder(decoded, kind, joint=joint)  # type: ignore[arg-type]
    except MessageError:
        return MessageError
    return (stamp or 0, value)


def attempt(reader: RawValueReader, raw: bytes) -> object:
    try:
        return reader.read(raw)
    except MessageError:
        return MessageError


@st.composite
def joint_states(draw: st.DrawFn) -> JointState:
    n = draw(st.integers(0, 4))
    joint_names = tuple(draw(st.lists(names, min_size=n, max_size=n)))
    position = tuple(draw(st.lists(numbers, min_size=n, max_size=n)))
    extra = draw(st.sampled_from([0, n]))
    velocity = tuple(draw(st.lists(numbers, min_size=extra, max_size=extra)))
    effort = tuple(draw(st.lists(numbers, min_size=extra, max_size=extra)))
    frame = draw(names)
    return JointState(Header(draw(stamps), frame), joint_names, position, velocity, effort)


@st.composite
def multi_arrays(draw: st.DrawFn) -> Float64MultiArray:
    n = draw(st.integers(0, 5))
    data = tuple(draw(st.lists(numbers, min_size=n, max_size=n)))
    label = draw(names)
    dims = (MultiArrayDimension(label, n, n),) if draw(st.booleans()) else ()
    return Float64MultiArray(MultiArrayLayout(dims, draw(st.integers(0, 3))), data)


def _same(got: object, want: object) -> bool:
    if isinstance(got, tuple) and isinstance(want, tuple):
        return got[0] == want[0] and (
            got[1] == want[1] or (math.isnan(got[1]) and math.isnan(want[1]))
        )
    return got == want


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.lists(joint_states(), min_size=1, max_size=12), st.sampled_from(["", "a", "b", "ab"]))
def test_joint_state_encoder_and_command_match_the_adapters(
    msgs: list[JointState], joint: str
) -> None:
    for role in ("encoder", "command"):
        reader = RawValueReader(JointState.ros_type, role, joint=joint)  # type: ignore[arg-type]
        for msg in msgs:
            want = reference(msg, role, "joint_state", 0, joint)
            assert _same(attempt(reader, cdr(msg)), want), (role, msg)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.lists(multi_arrays(), min_size=1, max_size=12), st.integers(0, 3))
def test_multi_array_command_matches_the_adapters(
    msgs: list[Float64MultiArray], index: int
) -> None:
    reader = RawValueReader(Float64MultiArray.ros_type, "command", index=index)
    for msg in msgs:
        raw = cdr(msg)
        want = reference(msg, "command", "float64_multi_array", index, "")
        assert _same(attempt(reader, raw), want), msg
        if isinstance(want, tuple):  # a readable command: the patched copy is the
            patched = reader.patch(raw, 0.125)  # compensated command, serialized
            assert patched == cdr(
                compensated_command(msg, 0.125, "float64_multi_array", index=index)
            )


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(numbers, min_size=1, max_size=10))
def test_float64_both_roles(values: list[float]) -> None:
    for role in ("command", "encoder"):
        reader = RawValueReader(Float64.ros_type, role)  # type: ignore[arg-type]
        for value in values:
            want = reference(Float64(value), role, "float64", 0, "")
            assert _same(attempt(reader, cdr(Float64(value))), want)


def test_a_steady_topic_is_read_by_its_learnt_layout() -> None:
    reader = RawValueReader(JointState.ros_type, "encoder", joint="wheel")
    for k in range(50):
        msg = JointState(Header(Time(k, 5), "base"), ("drive", "wheel"), (0.1 * k, -0.2 * k))
        assert reader.read(cdr(msg)) == (k * 1_000_000_000 + 5, -0.2 * k)
    assert (reader.slow, reader.fast) == (1, 49)
    # the same length with the joints swapped: the names differ, so the full path decides
    swapped = JointState(Header(Time(60), "base"), ("wheel", "drive"), (7.0, 8.0))
    assert reader.read(cdr(swapped)) == (60_000_000_000, 7.0)
    assert reader.slow == 2


def test_big_endian_messages_take_the_full_path() -> None:
    reader = RawValueReader(JointState.ros_type, "encoder", joint="j")
    msg = JointState(Header(Time(3, 7)), ("j",), (1.5,))
    for _ in range(3):
        assert reader.read(cdr(msg, little_endian=False)) == (3_000_000_007, 1.5)
    assert reader.fast == 0


def test_bytes_that_do_not_decode_are_a_message_error() -> None:
    reader = RawValueReader(JointState.ros_type, "encoder")
    good = cdr(JointState(Header(Time(1)), ("j",), (0.5,)))
    reader.read(good)
    with pytest.raises(MessageError, match="does not decode"):
        reader.read(good[:9])
    with pytest.raises(MessageError, match="not finite"):
        reader.read(cdr(JointState(Header(Time(2)), ("j",), (math.nan,))))
    with pytest.raises(MessageError, match="no encoder adapter"):
        RawValueReader(Float64MultiArray.ros_type, "encoder")
    with pytest.raises(MessageError, match="not finite"):
        RawValueReader(Float64.ros_type, "command").patch(cdr(Float64(1.0)), math.inf)


def _many_matches_one_by_one(reader_args: tuple[str, str, int, str], raws: list[bytes]) -> None:
    """``read_many`` reads what ``read`` reads, and leaves the rest (not ok) to it."""
    msgtype, role, index, joint = reader_args
    many = RawValueReader(msgtype, role, index=index, joint=joint)  # type: ignore[arg-type]
    one = RawValueReader(msgtype, role, index=index, joint=joint)  # type: ignore[arg-type]
    stamps, values, ok = many.read_many(raws)
    assert stamps.dtype == np.int64 and ok.shape == values.shape == (len(raws),)
    for k, raw in enumerate(raws):
        want = attempt(one, raw)
        if ok[k]:
            assert (int(stamps[k]), float(values[k])) == want
        else:  # read() decides: the same value (another layout) or the error
            assert _same(attempt(many, raw), want)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.lists(joint_states(), min_size=1, max_size=20), st.sampled_from(["", "a", "ab"]))
def test_read_many_joint_states(msgs: list[JointState], joint: str) -> None:
    raws = [cdr(m) for m in msgs] * 2  # again: by the layouts learnt the first time
    for role in ("encoder", "command"):
        _many_matches_one_by_one((JointState.ros_type, role, 0, joint), raws)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.lists(multi_arrays(), min_size=1, max_size=20), st.integers(0, 3))
def test_read_many_multi_arrays(msgs: list[Float64MultiArray], index: int) -> None:
    raws = [cdr(m) for m in msgs] * 2
    _many_matches_one_by_one((Float64MultiArray.ros_type, "command", index, ""), raws)


def test_read_many_steady_topic_and_damage() -> None:
    msgs = [JointState(Header(Time(k, 5), "b"), ("d", "w"), (0.1 * k, -0.2 * k)) for k in range(40)]
    raws = [cdr(m) for m in msgs]
    raws[7] = raws[7][:20]  # damaged: another length, left to read()
    raws[9] = cdr(JointState(Header(Time(9), "b"), ("d", "w"), (math.nan, 1.0)))  # not finite
    raws[11] = raws[11][:30] + b"\xff" + raws[11][31:]  # a constant byte differs
    reader = RawValueReader(JointState.ros_type, "encoder", joint="d")
    stamps, values, ok = reader.read_many(raws)
    assert np.flatnonzero(~ok).tolist() == [7, 9, 11]
    assert values[ok].tolist() == [0.1 * k for k in range(40) if k not in (7, 9, 11)]
    assert stamps[ok].tolist() == [k * 10**9 + 5 for k in range(40) if k not in (7, 9, 11)]
    empty = reader.read_many([])
    assert [a.size for a in empty] == [0, 0, 0]
    # read_all: what read_many leaves is read one by one; only the adapters' rejects stay out
    stamps, values, ok = reader.read_all(raws)
    for k, raw in enumerate(raws):
        try:
            expected = reader.read(raw)
        except MessageError:
            assert not ok[k]
        else:
            assert ok[k] and (int(stamps[k]), float(values[k])) == expected
    assert not ok[7] and not ok[9] and ok[11]


def test_read_many_takes_a_message_only_with_every_constant_byte() -> None:
    """One message per byte, that byte changed: ``read_many`` takes exactly the messages
    whose constant bytes are all the layout's (a change in the stamp or a float read is
    not a change of layout), as ``read`` judges them one by one."""
    base = JointState(Header(Time(3, 5), "frame"), ("d", "w"), (0.25, -0.5))
    raw = cdr(base)
    reader = RawValueReader(JointState.ros_type, "encoder", joint="d")
    reader.read(raw)  # learns the layout
    (layout,) = reader._layouts.values()
    assert layout is not None
    changed = [raw[:k] + bytes([raw[k] ^ 0x10]) + raw[k + 1 :] for k in range(len(raw))]
    _, _, ok = reader.read_many([raw, *changed])
    expected = [layout.learnt.matches(r) for r in changed]
    assert ok.tolist() == [True, *expected]
    constant = {start + i for start, run in layout.learnt.constant for i in range(len(run))}
    assert [not e for e in expected] == [k in constant for k in range(len(raw))]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.lists(multi_arrays(), min_size=1, max_size=15),
    st.integers(0, 3),
    st.lists(st.floats(-10.0, 10.0), min_size=15, max_size=15),
)
def test_patch_many_is_patch_one_by_one(
    msgs: list[Float64MultiArray], index: int, sent: list[float]
) -> None:
    """The compensated commands patched in numpy steps are :meth:`patch`'s, byte for byte
    (layouts learnt or not, a constant byte that differs, a command patch cannot take)."""
    reader = RawValueReader(Float64MultiArray.ros_type, "command", index=index)
    raws = [cdr(m) for m in msgs]
    readable = []
    for raw in raws:  # learn the layouts; patch takes only commands the reader can read
        try:
            reader.read(raw)
        except MessageError:
            continue
        readable.append(raw)
    if len(readable) > 2:
        damaged = bytearray(readable[1])
        damaged[-1] ^= 0xFF  # a constant byte (the padding or the data after the value) differs
        readable[1] = bytes(damaged)
    values = np.array(sent[: len(readable)])
    expected = []
    for raw, value in zip(readable, values.tolist(), strict=True):
        try:
            expected.append(reader.patch(raw, value))
        except MessageError:
            expected.append(MessageError)
    if MessageError in expected:
        with pytest.raises(MessageError):
            reader.patch_many(readable, values)
    else:
        assert reader.patch_many(readable, values) == expected
