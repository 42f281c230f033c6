"""Converters between our messages and the DDS wire types: values and CDR bytes."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

dds_convert = pytest.importorskip(
    "genbacklash_ros.transports.dds_convert", reason="cyclonedds missing"
)

from genbacklash_ros.bags.rosbags_types import jazzy_typestore, to_rosbags  # noqa: E402
from genbacklash_ros.node import checkpoint_writer  # noqa: E402
from genbacklash_ros.node.messages import (  # noqa: E402
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    KeyValue,
    MessageError,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)
from genbacklash_ros.transports import dds_node  # noqa: E402

from_dds, to_dds = dds_convert.from_dds, dds_convert.to_dds

floats = st.floats(allow_nan=False, allow_infinity=False, width=64)
text = st.text(max_size=12)
times = st.builds(Time, st.integers(-(2**31), 2**31 - 1), st.integers(0, 999_999_999))
headers = st.builds(Header, times, text)
messages = st.one_of(
    st.builds(Float64, floats),
    st.builds(
        Float64MultiArray,
        st.builds(
            MultiArrayLayout,
            st.lists(
                st.builds(
                    MultiArrayDimension, text, st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)
                ),
                max_size=3,
            ).map(tuple),
            st.integers(0, 2**32 - 1),
        ),
        st.lists(floats, max_size=8).map(tuple),
    ),
    st.builds(
        JointState,
        headers,
        st.lists(text, max_size=4).map(tuple),
        st.lists(floats, max_size=4).map(tuple),
        st.lists(floats, max_size=4).map(tuple),
        st.lists(floats, max_size=4).map(tuple),
    ),
    st.builds(
        DiagnosticArray,
        headers,
        st.lists(
            st.builds(
                DiagnosticStatus,
                st.integers(0, 3),
                text,
                text,
                text,
                st.lists(st.builds(KeyValue, text, text), max_size=3).map(tuple),
            ),
            max_size=2,
        ).map(tuple),
    ),
)


@settings(max_examples=150, deadline=None)
@given(messages)
def test_round_trip_through_cdr(msg: object) -> None:
    wire = to_dds(msg)  # type: ignore[arg-type]
    assert from_dds(type(wire).deserialize(wire.serialize())) == msg


@settings(max_examples=60, deadline=None)
@given(messages)
def test_bytes_equal_rosbags(msg: object) -> None:
    store = jazzy_typestore()
    ros_type = msg.ros_type  # type: ignore[attr-defined]
    theirs = bytes(store.serialize_cdr(to_rosbags(msg, store), ros_type))  # type: ignore[arg-type]
    assert to_dds(msg).serialize() == theirs  # type: ignore[arg-type]


def test_types_are_mapped_by_ros_name() -> None:
    assert dds_convert.DDS_TYPES["sensor_msgs/msg/JointState"].__name__ == "JointState_"
    assert type(to_dds(Time(1, 2))).__name__ == "Time_"
    assert from_dds(to_dds(Header(Time(1, 2), "x"))) == Header(Time(1, 2), "x")


def test_unknown_types_raise() -> None:
    with pytest.raises(MessageError, match="no DDS type"):
        to_dds("not a message")  # type: ignore[arg-type]
    with pytest.raises(MessageError, match="no conversion"):
        from_dds(np.zeros(2))


def test_bad_wire_values_raise_message_error() -> None:
    wire = to_dds(DiagnosticArray(status=(DiagnosticStatus(1),)))
    wire.status[0].level = 9
    with pytest.raises(MessageError, match="level"):
        from_dds(wire)


@pytest.mark.parametrize("module", [dds_convert, dds_node, checkpoint_writer])
def test_doctests(module: object) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)  # type: ignore[arg-type]
    assert result.failed == 0 and result.attempted > 0
