"""Fuzzing the message adapters and converters: a reading, a message, or a clear MessageError.

Every adapter of :mod:`genbacklash_ros.node.messages` and every converter of
:mod:`genbacklash_ros.bags.rosbags_types` and :mod:`genbacklash_ros.transports.dds_convert` gets
arbitrary input: finite and non-finite numbers, huge integers, numpy scalars, strings and None where
numbers belong; empty, mismatched and non-sequence JointState arrays; unknown joints; negative,
huge and non-integer indices; messages of the wrong class and duck-typed objects with missing
or odd fields; stamps far outside int32 seconds. The answer must be a value (finite where the
adapter promises it) or a :class:`~genbacklash_ros.node.messages.MessageError` whose one-line text
says what is wrong; any other exception fails the test. ``tests/ros/node/test_messages.py`` fuzzes
well-formed float lists; this file covers the rest. Every test is derandomised.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from types import SimpleNamespace
from typing import Any, TypeVar

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from genbacklash_core import Estimate, EstimatorState, Structure, paper_example
from genbacklash_ros.node.messages import (
    COMMAND_TYPES,
    ENCODER_TYPES,
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
    compensated_command,
    diagnostic_array,
    estimate_message,
    level_of,
    read_command,
    read_encoder,
)

T = TypeVar("T")

FUZZ = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)

# --------------------------------------------------------------------------- strategies

SPECIAL_FLOATS = (
    0.0,
    -0.0,
    1.0,
    -2.5,
    1e300,
    -1e300,
    1.7976931348623157e308,
    5e-324,
    math.nan,
    math.inf,
    -math.inf,
)
reals = st.one_of(
    st.floats(-10.0, 10.0),
    st.sampled_from(SPECIAL_FLOATS),
    st.floats(),
    st.integers(-(10**400), 10**400),
    st.sampled_from(
        [np.float64(1.5), np.float32(np.inf), np.int64(-3), np.float64(np.nan), Fraction(1, 3)]
    ),
)
junk = st.sampled_from([None, "1.5", "abc", b"x", 1j, True, False, [], [1.0], {"a": 1}, object()])
anything = st.one_of(reals, reals, junk)
finite = st.floats(allow_nan=False, allow_infinity=False)


def sequences(elements: st.SearchStrategy[Any], max_size: int = 5) -> st.SearchStrategy[Any]:
    """Tuples, lists or numpy arrays of ``elements``."""
    return st.lists(elements, max_size=max_size).flatmap(
        lambda items: (
            st.sampled_from([tuple(items), list(items)]) | st.just(items).map(_as_float_array)
        )
    )


def _as_float_array(items: list[Any]) -> Any:
    try:
        return np.array(items, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        return tuple(items)


joint_names = st.sampled_from(["a", "b", "c", "", "knee", "a"])
joints = st.sampled_from(["", "a", "b", "z", "knee"]) | st.sampled_from([None, 3, b"a", ["a"]])
indices = st.one_of(
    st.integers(-3, 8),
    st.sampled_from([2**31, -(2**63), 10**30, np.int64(1), np.uint8(0)]),
    st.sampled_from([1.0, 1.5, math.nan, None, "1", True]),
)
stamps_sec = st.one_of(st.integers(-(2**31), 2**31 - 1), st.sampled_from([0, -1, 2**31 - 1]))
times = st.builds(Time, stamps_sec, st.integers(0, 999_999_999))
headers = st.builds(Header, times, st.sampled_from(["", "base", "é"]))


@st.composite
def joint_states(draw: st.DrawFn) -> JointState:
    """JointStates with names and positions of any lengths and any values."""
    element = st.one_of(reals, reals, reals, junk)
    return JointState(
        draw(headers),
        tuple(draw(st.lists(joint_names, max_size=4))),
        draw(sequences(element, 4)),
        draw(sequences(element, 4)),
        draw(sequences(element, 4)),
    )


layouts = st.builds(
    MultiArrayLayout,
    st.lists(
        st.builds(MultiArrayDimension, st.text(max_size=5), st.integers(0, 9), st.integers(0, 9)),
        max_size=2,
    ).map(tuple),
    st.integers(0, 3),
)
multi_arrays = st.builds(Float64MultiArray, layouts, sequences(st.one_of(reals, reals, junk), 6))
float64s = st.builds(Float64, anything)


@st.composite
def duck_messages(draw: st.DrawFn) -> SimpleNamespace:
    """Objects with some of the fields of a message, holding anything."""
    fields: dict[str, Any] = {}
    if draw(st.booleans()):
        sec = draw(st.one_of(stamps_sec, st.sampled_from([math.inf, math.nan, 2**80, "5", None])))
        nanosec = draw(st.one_of(st.integers(0, 10**9), st.sampled_from([-1, 1.5, None])))
        stamp = SimpleNamespace(sec=sec, nanosec=nanosec)
        fields["header"] = draw(st.sampled_from([SimpleNamespace(stamp=stamp), None, 5]))
    for name in ("name", "position", "velocity", "effort", "data"):
        if draw(st.booleans()):
            fields[name] = draw(
                st.one_of(
                    sequences(st.one_of(reals, junk, joint_names), 4),
                    junk,
                    st.just({0: 1.0}),
                    st.just({1.0, 2.0}),
                )
            )
    return SimpleNamespace(**fields)


other_messages = st.sampled_from(
    [
        None,
        5,
        "msg",
        Time(1, 2),
        Header(),
        KeyValue("k", "v"),
        DiagnosticArray(),
        DiagnosticStatus(1, "n"),
        MultiArrayLayout(),
    ]
)
messages = st.one_of(joint_states(), multi_arrays, float64s, duck_messages(), other_messages)


@st.composite
def estimates(draw: st.DrawFn) -> Any:
    """Estimates of any parameters (finite or not), empty ones, or not an Estimate at all."""
    kind = draw(st.sampled_from(["values", "values", "truth", "empty", "junk"]))
    structure = Structure(draw(st.integers(1, 3)), *draw(st.sampled_from([(0, 0), (2, 1)])))
    size = structure.n_parameters
    if kind == "junk":
        return draw(st.one_of(junk, st.just(structure), st.just(np.zeros(size))))
    if kind == "empty":
        return Estimate.empty(structure, samples=draw(st.integers(0, 10)))
    if kind == "truth":
        structure = Structure(3)
        size = structure.n_parameters
        parameters = paper_example(1).model.parameters()
    else:
        values = st.one_of(st.floats(-3.0, 3.0), st.sampled_from(SPECIAL_FLOATS))
        parameters = np.array(draw(st.lists(values, min_size=size, max_size=size)))
    return Estimate(
        structure,
        parameters,
        np.diag(np.full(size, draw(st.sampled_from([1e-4, math.nan, math.inf, 0.0])))),
        draw(st.sampled_from([0.01, math.nan, math.inf, 1e300])),
        draw(st.floats(0.0, 1.0)),
        draw(st.sampled_from(list(EstimatorState))),
        draw(st.floats(0.0, 1.0)),
        draw(st.integers(0, 10**12)),
        draw(st.text(max_size=20)),
    )


# --------------------------------------------------------------------------- helpers


def outcome(function: Callable[..., T], *args: Any, **kwargs: Any) -> T | None:
    """``function``'s result, or None after a MessageError with a one-line reason.

    Any other exception propagates and fails the test.
    """
    try:
        return function(*args, **kwargs)
    except MessageError as err:
        text = str(err)
        assert text.strip() and "\n" not in text, repr(text)
        return None


def is_reading(reading: object) -> bool:
    if not (isinstance(reading, tuple) and len(reading) == 2):
        return False
    stamp, value = reading
    stamp_ok = stamp is None or type(stamp) is int
    return stamp_ok and type(value) is float and math.isfinite(value)


def as_number(value: object) -> float | None:
    """``value`` as the finite float an adapter reads, or None when it cannot be one."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        return None
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return None
    return number if math.isfinite(number) else None


# --------------------------------------------------------------------------- reading


@FUZZ
@given(
    msg=messages,
    command_type=st.sampled_from([*COMMAND_TYPES, "float32", "", None]),
    index=indices,
    joint=joints,
)
def test_read_command(msg: Any, command_type: Any, index: Any, joint: Any) -> None:
    reading = outcome(read_command, msg, command_type, index=index, joint=joint)
    if reading is None:
        return
    assert is_reading(reading), reading
    value = reading[1]
    if command_type == "float64":
        assert value == as_number(msg.data)
    elif command_type == "float64_multi_array":
        assert value == as_number(msg.data[int(index)])
        assert all(as_number(v) is not None for v in msg.data)  # the echo stays finite
    else:
        names = list(msg.name)
        k = names.index(joint) if joint else 0
        assert value == as_number(msg.position[k])
        for field in ("position", "velocity", "effort"):
            assert all(as_number(v) is not None for v in getattr(msg, field))


@FUZZ
@given(
    msg=messages,
    encoder_type=st.sampled_from([*ENCODER_TYPES, "float32", None]),
    joint=joints,
)
def test_read_encoder(msg: Any, encoder_type: Any, joint: Any) -> None:
    reading = outcome(read_encoder, msg, encoder_type, joint=joint)
    if reading is None:
        return
    assert is_reading(reading), reading
    stamp, value = reading
    if encoder_type == "joint_state":
        names = list(msg.name)
        assert not names or len(names) == len(msg.position)
        assert value == as_number(msg.position[names.index(joint) if joint else 0])
        assert stamp is not None
    else:
        assert value == as_number(msg.data) and stamp is None


# --------------------------------------------------------------------------- building


@FUZZ
@given(
    msg=st.one_of(joint_states(), multi_arrays, float64s, messages),
    value=anything,
    command_type=st.sampled_from([*COMMAND_TYPES, "float32", None]),
    index=indices,
    joint=joints,
)
def test_compensated_command(
    msg: Any, value: Any, command_type: Any, index: Any, joint: Any
) -> None:
    out = outcome(compensated_command, msg, value, command_type, index=index, joint=joint)
    readable = outcome(read_command, msg, command_type, index=index, joint=joint)
    number = as_number(value)
    ours = {"float64": object, "float64_multi_array": Float64MultiArray, "joint_state": JointState}
    if readable is not None and number is not None and isinstance(msg, ours[command_type]):
        assert out is not None  # what read_command accepts, the compensator can answer
    if out is None:
        return
    assert number is not None
    if isinstance(out, Float64):
        assert out.data == number
    elif isinstance(out, Float64MultiArray):
        assert out.data[index] == number and out.layout == msg.layout
        assert len(out.data) == len(msg.data)
    else:
        k = list(msg.name).index(joint) if joint else 0
        assert out.position[k] == number and len(out.position) == len(msg.position)
        assert out.header == msg.header and out.name == msg.name
        assert out.velocity == msg.velocity and out.effort == msg.effort
    if readable is not None:  # a readable command reads back as the value sent
        assert read_command(out, command_type, index=index, joint=joint) == (readable[0], number)


@FUZZ
@given(estimate=estimates())
def test_estimate_message(estimate: Any) -> None:
    msg = outcome(estimate_message, estimate)
    if msg is None:
        assert not (isinstance(estimate, Estimate) and estimate.available)
        return
    assert isinstance(estimate, Estimate) and estimate.available
    assert all(math.isfinite(v) for v in msg.data)
    assert msg.layout.dim[0].label.split(",") == list(estimate.names)
    assert msg.layout.dim[0].size == len(msg.data)


@FUZZ
@given(
    stamp_ns=st.one_of(
        st.integers(-(2**70), 2**70),
        st.sampled_from([0, -1, np.int64(5), 1.5, math.nan, math.inf, None, "7", True]),
    ),
    estimate=estimates(),
    level=st.one_of(st.integers(-2, 5), st.sampled_from([1.0, None, "1", b"\x01", True])),
    message=st.one_of(st.text(max_size=10), junk),
    name=st.one_of(st.just("backlash_identifier"), junk),
    extra=st.one_of(
        st.lists(st.tuples(st.text(max_size=4), st.text(max_size=4)), max_size=3),
        st.lists(st.one_of(st.tuples(anything, anything), junk), max_size=2),
        junk,
    ),
)
def test_diagnostic_array(
    stamp_ns: Any, estimate: Any, level: Any, message: Any, name: Any, extra: Any
) -> None:
    diag = outcome(
        diagnostic_array, stamp_ns, estimate, level=level, message=message, name=name, extra=extra
    )
    if diag is None:
        return
    assert isinstance(estimate, Estimate)
    assert diag.header.stamp.to_ns() == int(stamp_ns)
    (status,) = diag.status
    assert 0 <= status.level <= 3
    texts = [kv.value for kv in status.values]
    assert all(isinstance(kv.key, str) and isinstance(kv.value, str) for kv in status.values)
    for kv in status.values[:-1] if not extra else status.values:
        if kv.key in estimate.names or kv.key in ("confidence", "residual", "excitation"):
            assert kv.value == "n/a" or math.isfinite(float(kv.value)), kv  # no NaN written
    assert texts[0] == estimate.state.value
    # what the adapter builds, the bag and DDS serialisers take
    rosbags_types = pytest.importorskip("genbacklash_ros.bags.rosbags_types")
    store = rosbags_types.jazzy_typestore()
    raw = store.serialize_cdr(rosbags_types.to_rosbags(diag, store), diag.ros_type)
    assert rosbags_types.from_rosbags(store.deserialize_cdr(raw, diag.ros_type)) == diag


@FUZZ
@given(state=st.one_of(st.sampled_from(list(EstimatorState)), junk, st.text(max_size=5)))
def test_level_of(state: Any) -> None:
    assert level_of(state) in (0, 1, 2, 3)


# --------------------------------------------------------------------------- the dataclasses


@FUZZ
@given(
    ns=st.one_of(
        st.integers(-(2**70), 2**70), st.sampled_from([np.int64(-7), 1.0, math.inf, None, "1"])
    ),
    sec=st.one_of(st.integers(-(2**40), 2**40), junk, st.sampled_from([1.0, math.nan])),
    nanosec=st.one_of(st.integers(-5, 2 * 10**9), junk),
    size=st.one_of(st.integers(-5, 2**33), junk, st.just(1.5)),
    offset=st.one_of(st.integers(-5, 2**33), junk),
    level=st.one_of(st.integers(-5, 10), junk),
    sequence=st.one_of(sequences(anything), junk, st.text(max_size=3)),
)
def test_message_constructors(
    ns: Any, sec: Any, nanosec: Any, size: Any, offset: Any, level: Any, sequence: Any
) -> None:
    stamp = outcome(Time.from_ns, ns)
    if stamp is not None:
        assert stamp.to_ns() == int(ns) and 0 <= stamp.nanosec < 10**9
    time = outcome(Time, sec, nanosec)
    if time is not None:
        assert -(2**31) <= time.sec < 2**31 and 0 <= time.nanosec < 10**9
    dim = outcome(MultiArrayDimension, "d", size, size)
    if dim is not None:
        assert type(dim.size) is int and 0 <= dim.size < 2**32
    layout = outcome(MultiArrayLayout, (), offset)
    if layout is not None:
        assert type(layout.data_offset) is int and 0 <= layout.data_offset < 2**32
    status = outcome(DiagnosticStatus, level)
    if status is not None:
        assert status.level in (0, 1, 2, 3)
    for build in (
        lambda: Float64MultiArray(data=sequence),
        lambda: JointState(name=sequence, position=sequence),
        lambda: DiagnosticArray(status=sequence),
    ):
        built = outcome(build)
        if built is not None:
            assert all(
                type(getattr(built, f)) is tuple
                for f in built.__dataclass_fields__
                if f in ("data", "name", "position", "status")
            )


# --------------------------------------------------------------------------- converters


well_formed = st.one_of(
    st.builds(Float64, st.floats()),
    st.builds(Float64MultiArray, layouts, st.lists(st.floats(), max_size=6).map(tuple)),
    st.builds(
        JointState,
        headers,
        st.lists(st.text(max_size=4), max_size=3).map(tuple),
        st.lists(st.floats(), max_size=3).map(tuple),
        st.lists(st.floats(), max_size=3).map(tuple),
        st.lists(st.floats(), max_size=3).map(tuple),
    ),
)
ill_formed = st.one_of(
    st.builds(Float64, junk),
    st.builds(Float64MultiArray, layouts, sequences(st.one_of(reals, junk), 4)),
    joint_states(),
    st.builds(JointState, headers, sequences(st.one_of(joint_names, junk), 3)),
    other_messages,
    duck_messages(),
)


@FUZZ
@given(msg=well_formed)
def test_rosbags_round_trip_keeps_non_finite_values(msg: Any) -> None:
    """NaN, +-inf, -0.0 and the extremes survive CDR: the bytes carry them unchanged."""
    rosbags_types = pytest.importorskip("genbacklash_ros.bags.rosbags_types")
    store = rosbags_types.jazzy_typestore()
    raw = store.serialize_cdr(rosbags_types.to_rosbags(msg, store), msg.ros_type)
    back = rosbags_types.from_rosbags(store.deserialize_cdr(raw, msg.ros_type))
    assert repr(back) == repr(msg)  # repr: NaN compares unequal to itself


@FUZZ
@given(msg=well_formed)
def test_dds_round_trip_keeps_non_finite_values(msg: Any) -> None:
    dds_convert = pytest.importorskip("genbacklash_ros.transports.dds_convert")
    wire = dds_convert.to_dds(msg)
    back = dds_convert.from_dds(type(wire).deserialize(wire.serialize()))
    assert repr(back) == repr(msg)


@FUZZ
@given(msg=ill_formed)
def test_converters_to_wire_types(msg: Any) -> None:
    """Anything handed to the converters becomes a wire object or a clear MessageError."""
    rosbags_types = pytest.importorskip("genbacklash_ros.bags.rosbags_types")
    outcome(rosbags_types.to_rosbags, msg)
    dds_convert = pytest.importorskip("genbacklash_ros.transports.dds_convert")
    outcome(dds_convert.to_dds, msg)


ROS_TYPES = [
    Time.ros_type,
    Header.ros_type,
    Float64.ros_type,
    MultiArrayDimension.ros_type,
    MultiArrayLayout.ros_type,
    Float64MultiArray.ros_type,
    JointState.ros_type,
    KeyValue.ros_type,
    DiagnosticStatus.ros_type,
    DiagnosticArray.ros_type,
    "std_msgs/msg/String",
]


@st.composite
def rosbags_like(draw: st.DrawFn) -> SimpleNamespace:
    """Objects that claim a message type (``__msgtype__``) with fields holding anything."""
    field_values = st.one_of(
        anything,
        sequences(anything, 3),
        st.text(max_size=3),
        st.just(SimpleNamespace(sec=math.inf, nanosec=0)),
        st.just(SimpleNamespace(stamp=SimpleNamespace(sec=2**40, nanosec=-1), frame_id=3)),
        st.just(b""),
    )
    names = (
        "sec nanosec stamp frame_id data layout dim data_offset label size stride name "
        "position velocity effort key value level message hardware_id values header status"
    ).split()
    fields = {n: draw(field_values) for n in names if draw(st.integers(0, 3))}
    return SimpleNamespace(__msgtype__=draw(st.sampled_from(ROS_TYPES)), **fields)


@FUZZ
@given(obj=rosbags_like() | junk)
def test_from_rosbags(obj: Any) -> None:
    rosbags_types = pytest.importorskip("genbacklash_ros.bags.rosbags_types")
    msg = outcome(rosbags_types.from_rosbags, obj)
    if msg is not None:
        assert msg.ros_type == obj.__msgtype__


@FUZZ
@given(data=st.data(), kind=st.sampled_from(ROS_TYPES[:-1]))
def test_from_dds(data: st.DataObject, kind: str) -> None:
    """Wire objects whose fields hold anything (cyclonedds does not check on construction)."""
    dds_convert = pytest.importorskip("genbacklash_ros.transports.dds_convert")
    cls = dds_convert.DDS_TYPES[kind]
    fields = {
        name: data.draw(st.one_of(anything, sequences(anything, 3), st.text(max_size=3)), name)
        for name in cls.__dataclass_fields__
    }
    msg = outcome(dds_convert.from_dds, cls(**fields))
    if msg is not None:
        assert msg.ros_type == kind
    outcome(dds_convert.from_dds, data.draw(junk | st.just(fields)))
