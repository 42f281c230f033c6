"""RawMessageCodec: whole messages from CDR bytes are what the full decoder gives, for every
layout, and a compensated command written back into the bytes decodes to the compensated
message (the rclpy node's raw subscriptions)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_ros.bags.cdr_layout import learn_layout
from genbacklash_ros.bags.raw_messages import RawMessageCodec
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
)

STORE = jazzy_typestore()

numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-10.0, 10.0))
names = st.text(alphabet="abcdefghij_", min_size=0, max_size=12)
stamps = st.builds(Time, st.integers(0, 2**31 - 1), st.integers(0, 999_999_999))
joint_states = st.builds(
    JointState,
    st.builds(Header, stamps, names),
    st.lists(names, min_size=0, max_size=4),
    st.lists(numbers, max_size=4),
    st.lists(numbers, max_size=4),
    st.lists(numbers, max_size=4),
)
layouts = st.builds(
    MultiArrayLayout,
    st.lists(
        st.builds(MultiArrayDimension, names, st.integers(0, 9), st.integers(0, 9)), max_size=2
    ),
    st.integers(0, 3),
)
multi_arrays = st.builds(Float64MultiArray, layouts, st.lists(numbers, max_size=8))


def cdr(msg: Message, little_endian: bool = True) -> bytes:
    obj = to_rosbags(msg, STORE)
    return bytes(STORE.serialize_cdr(obj, msg.ros_type, little_endian=little_endian))


def slow_decoder(msgtype: str) -> tuple[list[int], object]:
    """The full decoder (rosbags here; the node gives rclpy's) and a count of its calls."""
    calls = [0]

    def slow(raw: bytes) -> Message:
        calls[0] += 1
        try:
            return from_rosbags(STORE.deserialize_cdr(raw, msgtype))
        except Exception as err:
            raise MessageError(f"does not decode: {err}") from err

    return calls, slow


def codec_for(msgtype: str) -> tuple[RawMessageCodec, list[int]]:
    calls, slow = slow_decoder(msgtype)
    return RawMessageCodec(msgtype, slow), calls  # type: ignore[arg-type]


def same(a: Message, b: Message) -> bool:
    """Equal, NaN for NaN (the floats by their bytes)."""
    return cdr(a) == cdr(b)


@settings(max_examples=120, deadline=None)
@given(
    st.one_of(
        st.lists(joint_states, min_size=1, max_size=6),
        st.lists(multi_arrays, min_size=1, max_size=6),
        st.lists(st.builds(Float64, numbers), min_size=1, max_size=5),
    )
)
def test_messages_decode_as_the_full_decoder(msgs: list[Message]) -> None:
    codec, _ = codec_for(msgs[0].ros_type)
    for msg in msgs + msgs:  # the second time round, every layout is learnt
        assert same(codec.decode(cdr(msg)), msg)


def test_a_steady_topic_is_decoded_by_its_learnt_layout() -> None:
    codec, calls = codec_for(JointState.ros_type)
    rng = np.random.default_rng(7)
    for k in range(50):
        msg = JointState(
            Header(Time(k, 1000 * k), "base"),
            ("a", "b", "c"),
            tuple(rng.normal(size=3).tolist()),
            tuple(rng.normal(size=3).tolist()),
            (),
        )
        assert codec.decode(cdr(msg)) == msg
    assert (codec.fast, codec.slow, calls[0]) == (49, 1, 1)
    # other names of the same lengths: the constant bytes differ, the full decoder reads it
    other = JointState(Header(Time(1, 2), "base"), ("x", "y", "z"), (1.0, 2.0, 3.0))
    other = JointState(other.header, other.name, other.position, (0.0, 0.0, 0.0))
    assert codec.decode(cdr(other)) == other
    assert calls[0] == 2


def test_big_endian_messages_take_the_full_decoder_always() -> None:
    codec, calls = codec_for(Float64MultiArray.ros_type)
    msg = Float64MultiArray(MultiArrayLayout((MultiArrayDimension("x", 2, 2),)), (0.5, 0.25))
    big = cdr(msg, little_endian=False)
    for _ in range(3):
        assert codec.decode(big) == msg
    assert (codec.fast, calls[0]) == (0, 3)
    assert codec.encode(big, msg, msg) is None


def test_junk_in_the_padding_is_neither_constant_nor_read() -> None:
    """rosbags writes zeros where CDR pads; a middleware may leave what its buffer held.
    The label "x" (2 bytes with its NUL) is padded by 2 bytes to the next uint32."""
    msg = Float64MultiArray(MultiArrayLayout((MultiArrayDimension("x", 2, 2),)), (0.5, 0.25))

    def junk(m: Float64MultiArray, pad: bytes) -> bytes:
        raw = bytearray(cdr(m))
        assert raw[14:16] == b"\0\0"
        raw[14:16] = pad
        return bytes(raw)

    codec, calls = codec_for(Float64MultiArray.ros_type)
    first = junk(msg, b"\x7f\x13")
    assert codec.decode(first) == msg
    later = Float64MultiArray(msg.layout, (0.75, -1.0))
    for pad in (b"\x7f\x13", b"\0\0", b"\xff\xfe"):  # whatever the padding holds
        assert codec.decode(junk(later, pad)) == later
    assert (codec.fast, calls[0]) == (3, 1)
    out = Float64MultiArray(msg.layout, (0.75, 2.0))
    written = codec.encode(junk(later, b"\x01\x02"), later, out)
    assert written is not None and written[14:16] == b"\x01\x02"
    assert from_rosbags(STORE.deserialize_cdr(written, msg.ros_type)) == out
    layout = learn_layout(STORE, msg.ros_type, first, STORE.deserialize_cdr(first, msg.ros_type))
    assert layout is not None and layout.matches(junk(later, b"\0\0"))
    # another label of the same length is not junk: its bytes are constant
    other = Float64MultiArray(MultiArrayLayout((MultiArrayDimension("y", 2, 2),)), (0.5, 0.25))
    assert not layout.matches(cdr(other))
    assert codec.decode(cdr(other)) == other


def test_bytes_that_do_not_decode_are_a_message_error() -> None:
    codec, _ = codec_for(JointState.ros_type)
    good = cdr(JointState(Header(Time(1, 2)), ("a",), (0.5,)))
    codec.decode(good)
    with pytest.raises(MessageError):
        codec.decode(good[:-3])


@settings(max_examples=60, deadline=None)
@given(multi_arrays, st.integers(0, 7), st.floats(-5.0, 5.0))
def test_a_compensated_multi_array_is_written_into_the_commands_bytes(
    msg: Float64MultiArray, index: int, value: float
) -> None:
    codec, _ = codec_for(Float64MultiArray.ros_type)
    raw = cdr(msg)
    codec.decode(raw)  # learns
    decoded = codec.decode(raw)
    if index >= len(msg.data):
        return
    out = compensated_command(decoded, value, "float64_multi_array", index=index)
    written = codec.encode(raw, decoded, out)
    assert written is not None
    assert same(from_rosbags(STORE.deserialize_cdr(written, msg.ros_type)), out)
    assert written == cdr(out)  # rosbags' own bytes for the compensated message


@settings(max_examples=60, deadline=None)
@given(joint_states, st.floats(-5.0, 5.0))
def test_a_compensated_joint_state_is_written_into_the_commands_bytes(
    msg: JointState, value: float
) -> None:
    codec, _ = codec_for(JointState.ros_type)
    raw = cdr(msg)
    codec.decode(raw)
    decoded = codec.decode(raw)
    if not msg.name or len(msg.position) < len(msg.name) or len(set(msg.name)) < len(msg.name):
        return
    out = compensated_command(decoded, value, "joint_state", joint=msg.name[0])
    assert codec.encode(raw, decoded, out) == cdr(out)


def test_anything_but_the_floats_changed_is_not_written_into_the_bytes() -> None:
    codec, _ = codec_for(JointState.ros_type)
    msg = JointState(Header(Time(3, 4), "f"), ("a", "b"), (1.0, 2.0), (), ())
    raw = cdr(msg)
    codec.decode(raw)
    decoded = codec.decode(raw)
    assert codec.encode(raw, decoded, decoded) == raw
    restamped = JointState(Header(Time(3, 5), "f"), msg.name, msg.position)
    renamed = JointState(msg.header, ("a", "c"), msg.position)
    longer = JointState(msg.header, msg.name, (1.0, 2.0, 3.0))
    filled = JointState(msg.header, msg.name, msg.position, (0.0, 0.0))
    for out in (restamped, renamed, longer, filled, Float64(1.0)):
        assert codec.encode(raw, decoded, out) is None
    arrays, _ = codec_for(Float64MultiArray.ros_type)
    cmd = Float64MultiArray(data=(0.1, 0.2))
    cmd_raw = cdr(cmd)
    arrays.decode(cmd_raw)
    got = arrays.decode(cmd_raw)
    relaid = Float64MultiArray(MultiArrayLayout((), 1), (0.1, 0.3))
    assert arrays.encode(cmd_raw, got, relaid) is None
    scalar, _ = codec_for(Float64.ros_type)
    one = cdr(Float64(0.5))
    scalar.decode(one)
    assert scalar.encode(one, scalar.decode(one), Float64(0.75)) == cdr(Float64(0.75))


def test_unknown_message_types_are_refused() -> None:
    with pytest.raises(ValueError, match="no raw codec"):
        RawMessageCodec("std_msgs/msg/String", lambda raw: Float64(0.0))
