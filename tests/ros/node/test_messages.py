"""Message dataclasses, adapters, outgoing messages and the rosbags CDR round trip."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import Estimate, EstimatorState, GenBacklashError, Structure, paper_example
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
    command_from_float64,
    command_from_joint_state,
    command_from_multi_array,
    compensated_command,
    diagnostic_array,
    encoder_from_float64,
    encoder_from_joint_state,
    estimate_message,
    level_of,
    read_command,
    read_encoder,
)

pytest.importorskip("rosbags", reason="rosbags is not installed: no CDR serializer to check")

from genbacklash_ros.bags.rosbags_types import (
    from_rosbags,
    jazzy_typestore,
    to_rosbags,
)

STORE = jazzy_typestore()


def converged_estimate() -> Estimate:
    truth = paper_example(1).model
    return Estimate(
        Structure(3), truth.parameters(), np.eye(8) * 1e-4, 0.02, 0.6, "converged", 0.9, 500
    )


def cdr_round_trip(msg: Message) -> Message:
    raw = STORE.serialize_cdr(to_rosbags(msg, STORE), msg.ros_type)
    return from_rosbags(STORE.deserialize_cdr(raw, msg.ros_type))


# --------------------------------------------------------------------------- round trips

SAMPLES: list[Message] = [
    Time(-3, 999_999_999),
    Header(Time(12, 34), "base_link"),
    Float64(-0.125),
    MultiArrayDimension("joints", 3, 3),
    MultiArrayLayout((MultiArrayDimension("a", 2, 2),), 1),
    Float64MultiArray(MultiArrayLayout((MultiArrayDimension("x", 2, 2),)), (1.5, -2.0)),
    Float64MultiArray(),
    JointState(Header(Time(5, 6), "f"), ("hip", "knee"), (0.1, 0.2), (1.0, 2.0), ()),
    JointState(),
    KeyValue("state", "converged"),
    DiagnosticStatus(2, "node", "bad", "hw", (KeyValue("k", "v"),)),
    DiagnosticArray(Header(Time(1, 2)), (DiagnosticStatus(1, "a"), DiagnosticStatus(3, "b"))),
]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_every_type_round_trips_through_rosbags_cdr(msg: Message) -> None:
    assert cdr_round_trip(msg) == msg


def test_cdr_bytes_equal_those_of_natively_built_rosbags_messages() -> None:
    types = STORE.types
    native = types["sensor_msgs/msg/JointState"](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=7, nanosec=8), frame_id="f"
        ),
        name=["j"],
        position=np.array([0.25]),
        velocity=np.array([], dtype=np.float64),
        effort=np.array([], dtype=np.float64),
    )
    ours = JointState(Header(Time(7, 8), "f"), ("j",), (0.25,))
    kind = JointState.ros_type
    assert bytes(STORE.serialize_cdr(to_rosbags(ours), kind)) == bytes(
        STORE.serialize_cdr(native, kind)
    )


def test_outgoing_messages_round_trip() -> None:
    est = converged_estimate()
    for msg in (
        estimate_message(est),
        diagnostic_array(10**9, est, level=DiagnosticStatus.OK, message="ok"),
    ):
        assert cdr_round_trip(msg) == msg


def test_from_rosbags_rejects_unknown_types() -> None:
    other = STORE.types["std_msgs/msg/String"](data="x")
    with pytest.raises(MessageError, match="no conversion from message type 'std_msgs/msg/String'"):
        from_rosbags(other)
    with pytest.raises(MessageError, match="no conversion"):
        from_rosbags(object())


def test_diagnostic_level_given_as_bytes_is_read() -> None:
    class RclpyLike:
        __msgtype__ = "diagnostic_msgs/msg/DiagnosticStatus"
        level = b"\x02"
        name = "n"
        message = "m"
        hardware_id = ""
        values = ()

    assert from_rosbags(RclpyLike()) == DiagnosticStatus(2, "n", "m")


# --------------------------------------------------------------------------- dataclasses


def test_time_conversions_and_validation() -> None:
    assert Time.from_ns(-1) == Time(-1, 999_999_999)
    assert Time.from_ns(1_500_000_000).to_ns() == 1_500_000_000
    with pytest.raises(MessageError, match=r"Time.nanosec must lie in \[0, 999999999\]"):
        Time(0, 10**9)
    with pytest.raises(MessageError, match=r"Time\.sec must be a whole number"):
        Time(1.5, 0)  # type: ignore[arg-type]
    with pytest.raises(MessageError, match=r"Time\.sec must lie in"):
        Time.from_ns(2**80)


def test_sequences_are_stored_as_tuples() -> None:
    msg = JointState(name=["a"], position=np.array([1.0]))  # type: ignore[arg-type]
    assert msg.name == ("a",) and msg.position == (1.0,)
    hash(Float64MultiArray(data=[1.0, 2.0]))  # type: ignore[arg-type]
    with pytest.raises(MessageError, match="name must be a sequence, got the string"):
        JointState(name="abc")  # type: ignore[arg-type]


def test_diagnostic_level_is_checked() -> None:
    with pytest.raises(MessageError, match=r"level must lie in \[0, 3\]"):
        DiagnosticStatus(7)
    assert issubclass(MessageError, GenBacklashError)


# --------------------------------------------------------------------------- adapters


def test_command_adapters() -> None:
    assert command_from_float64(Float64(0.5)) == (None, 0.5)
    assert command_from_multi_array(Float64MultiArray(data=(0.1, 0.2)), 1) == (None, 0.2)
    js = JointState(Header(Time(2, 5)), ("a", "b"), (0.3, 0.4))
    assert command_from_joint_state(js, "b") == (2_000_000_005, 0.4)
    assert command_from_joint_state(js, "") == (2_000_000_005, 0.3)
    assert read_command(Float64(1.0), "float64") == (None, 1.0)
    assert read_command(Float64MultiArray(data=(3.0,)), "float64_multi_array") == (None, 3.0)


def test_encoder_adapters() -> None:
    assert encoder_from_float64(Float64(-1.0)) == (None, -1.0)
    js = JointState(Header(Time(1)), ("a", "b"), (0.3, 0.4), (math.nan, 0.0))
    assert encoder_from_joint_state(js, "a") == (1_000_000_000, 0.3)  # other NaNs do not matter
    assert read_encoder(js, "joint_state", joint="b") == (1_000_000_000, 0.4)
    assert read_encoder(Float64(2.0), "float64") == (None, 2.0)
    no_names = JointState(Header(Time(1)), (), (0.7,))
    assert encoder_from_joint_state(no_names, "") == (1_000_000_000, 0.7)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: command_from_multi_array(Float64MultiArray(data=(1.0,)), 2), "out of range"),
        (lambda: command_from_multi_array(Float64MultiArray(), 0), "Float64MultiArray is empty"),
        (
            lambda: command_from_multi_array(Float64MultiArray(data=(1.0, math.nan)), 0),
            r"data\[1\] is not finite",
        ),
        (lambda: command_from_float64(Float64(math.inf)), "Float64 data is not finite"),
        (lambda: command_from_float64(JointState()), "expected a Float64, got JointState"),
        (
            lambda: command_from_multi_array(Float64(1.0), 0),
            "expected a Float64MultiArray, got Float64",
        ),
        (
            lambda: encoder_from_joint_state(JointState(name=("a",), position=(1.0,)), "b"),
            r"joint 'b' is not in the JointState names \['a'\]",
        ),
        (
            lambda: encoder_from_joint_state(JointState(name=("a", "b"), position=(1.0,)), "a"),
            "JointState has 2 names but 1 positions",
        ),
        (lambda: encoder_from_joint_state(JointState(), ""), "JointState has no positions"),
        (
            lambda: encoder_from_joint_state(Float64(1.0), "a"),
            "expected a JointState with a header stamp, got Float64",
        ),
        (
            lambda: command_from_joint_state(
                JointState(name=("a",), position=(1.0,), effort=(math.nan,)), "a"
            ),
            r"JointState effort\[0\] is not finite",
        ),
        (lambda: encoder_from_float64(Float64("1.0")), "is not a number"),  # type: ignore[arg-type]
        (lambda: encoder_from_float64(Float64(True)), "is not a number"),
    ],
)
def test_adapter_errors_are_message_errors_with_a_reason(call: object, match: str) -> None:
    with pytest.raises(MessageError, match=match):
        call()  # type: ignore[operator]


def test_numpy_arrays_and_extreme_values_give_no_warnings() -> None:
    msg = Float64MultiArray(data=np.array([1e308, 1e308, -np.inf]))
    assert type(msg.data[0]) is float
    with pytest.raises(MessageError, match=r"data\[2\] is not finite"):
        command_from_multi_array(msg, 0)
    assert command_from_multi_array(Float64MultiArray(data=(1e308, 1e308)), 1) == (None, 1e308)


def test_long_name_lists_are_shortened_in_the_reason() -> None:
    names = tuple(f"j{k}" for k in range(20))
    msg = JointState(name=names, position=tuple(range(20)))
    with pytest.raises(MessageError, match=r"'j7', \.\.\.\]$"):
        encoder_from_joint_state(msg, "x")


# --------------------------------------------------------------------------- outgoing


def test_compensated_command_copies_the_incoming_message() -> None:
    assert compensated_command(Float64(1.0), 2.0, "float64") == Float64(2.0)
    layout = MultiArrayLayout((MultiArrayDimension("j", 3, 3),))
    arr = Float64MultiArray(layout, (0.1, 0.2, 0.3))
    out = compensated_command(arr, 9.0, "float64_multi_array", index=2)
    assert out == Float64MultiArray(layout, (0.1, 0.2, 9.0))
    js = JointState(Header(Time(3, 4), "f"), ("a", "b"), (0.1, 0.2), (1.0, 2.0), (5.0, 6.0))
    out_js = compensated_command(js, -1.0, "joint_state", joint="b")
    assert isinstance(out_js, JointState)
    assert out_js.header == js.header and out_js.position == (0.1, -1.0)
    assert out_js.velocity == js.velocity and out_js.effort == js.effort
    with pytest.raises(MessageError, match="compensated command is not finite"):
        compensated_command(Float64(1.0), math.nan, "float64")


def test_estimate_message_names_the_parameters() -> None:
    est = converged_estimate()
    msg = estimate_message(est)
    assert msg.layout.dim[0].label.split(",") == list(est.names)
    assert msg.layout.dim[0].size == 8 and msg.layout.data_offset == 0
    assert msg.data == tuple(est.parameters.tolist())
    with pytest.raises(MessageError, match="holds no parameters yet"):
        estimate_message(Estimate.empty(Structure(3)))


def test_diagnostics_hold_every_parameter_and_no_nan() -> None:
    est = converged_estimate()
    diag = diagnostic_array(
        2_500_000_000, est, level=DiagnosticStatus.WARN, message="m", extra=[("k", "v")]
    )
    assert diag.header.stamp == Time(2, 500_000_000)
    values = {kv.key: kv.value for kv in diag.status[0].values}
    for key in ("state", "confidence", "residual", "excitation", "samples", "reason", "k"):
        assert key in values
    for name, value in zip(est.names, est.parameters, strict=True):
        assert float(values[name]) == pytest.approx(float(value))
    empty = diagnostic_array(0, Estimate.empty(Structure(2)), level=1, message="w")
    texts = [kv.value for kv in empty.status[0].values]
    assert "n/a" in texts and not any("nan" in t.lower() for t in texts)


def test_levels_of_states() -> None:
    assert level_of(EstimatorState.CONVERGED) == DiagnosticStatus.OK
    assert level_of(EstimatorState.CONVERGING) == DiagnosticStatus.OK
    assert level_of(EstimatorState.WARMING_UP) == DiagnosticStatus.WARN
    assert level_of(EstimatorState.NO_EXCITATION) == DiagnosticStatus.WARN
    assert level_of(EstimatorState.DIVERGED) == DiagnosticStatus.ERROR


# --------------------------------------------------------------------------- fuzz

ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True)
FINITE = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(data=st.lists(ANY_FLOAT, max_size=6), index=st.integers(-2, 8))
def test_fuzz_multi_array_command(data: list[float], index: int) -> None:
    msg = Float64MultiArray(data=tuple(data))
    try:
        stamp, value = command_from_multi_array(msg, index)
    except MessageError:
        ok = 0 <= index < len(data) and all(math.isfinite(v) for v in data)
        assert not ok
        return
    assert stamp is None and value == data[index] and math.isfinite(value)
    assert all(math.isfinite(v) for v in data)


@settings(max_examples=150, deadline=None)
@given(
    names=st.lists(st.sampled_from(["a", "b", "c"]), max_size=4),
    position=st.lists(ANY_FLOAT, max_size=4),
    joint=st.sampled_from(["", "a", "b", "z"]),
    sec=st.integers(-(2**31), 2**31 - 1),
)
def test_fuzz_joint_state_encoder(
    names: list[str], position: list[float], joint: str, sec: int
) -> None:
    msg = JointState(Header(Time(sec, 0)), tuple(names), tuple(position))
    try:
        stamp, value = encoder_from_joint_state(msg, joint)
    except MessageError as err:
        assert str(err) and "\n" not in str(err)
        return
    index = names.index(joint) if joint else 0
    assert stamp == sec * 10**9 and value == position[index] and math.isfinite(value)


@settings(max_examples=100, deadline=None)
@given(value=ANY_FLOAT)
def test_fuzz_float64(value: float) -> None:
    try:
        assert command_from_float64(Float64(value)) == (None, value)
    except MessageError:
        assert not math.isfinite(value)


@settings(max_examples=60, deadline=None)
@given(
    names=st.lists(
        st.text(st.characters(exclude_characters="\x00", exclude_categories=("Cs",)), max_size=5),
        max_size=3,
    ),
    values=st.lists(FINITE, max_size=3),
    ns=st.integers(-(2**62), 2**62),
)
def test_fuzz_joint_state_cdr_round_trip(names: list[str], values: list[float], ns: int) -> None:
    sec, _ = divmod(ns, 10**9)
    if not -(2**31) <= sec < 2**31:
        return
    msg = JointState(Header(Time.from_ns(ns), "f"), tuple(names), tuple(values), tuple(values))
    assert cdr_round_trip(msg) == msg
