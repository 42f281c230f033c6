"""The ROS 2 messages the node uses, as plain frozen dataclasses, and adapters to and from them.

The dataclasses mirror ``builtin_interfaces/Time``, ``std_msgs/Header``, ``std_msgs/Float64``,
``std_msgs/Float64MultiArray`` (with its layout), ``sensor_msgs/JointState`` and
``diagnostic_msgs/DiagnosticArray`` field by field, with no ROS, DDS or bag library behind
them: every transport converts its own message objects into these (rosbags:
:mod:`genbacklash_ros.bags.rosbags_types`) and the message-level pipeline only ever sees these.
Sequences are tuples; time is integer nanoseconds once it leaves a message.

The adapters read one number out of a message -- the command of the identified joint, or
its encoder reading -- as ``(stamp_ns, value)``: ``stamp_ns`` is the header stamp in integer
nanoseconds (None for messages without a header) and ``value`` a finite float. Anything else
(index out of range, joint not found, empty or mismatched arrays, non-finite numbers, a
message of the wrong type) raises :class:`MessageError` with a one-line reason. They also
build the outgoing messages: the compensated command as a copy of the incoming command with
the value replaced, the estimate (GUIDE §4: ``layout.dim[0].label`` holds the comma-separated
parameter names) and the diagnostics.

Examples
--------
>>> msg = JointState(Header(Time(12, 500)), ("hip", "knee"), (0.1, 0.25))
>>> encoder_from_joint_state(msg, "knee")
(12000000500, 0.25)
>>> encoder_from_joint_state(msg, "ankle")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
genbacklash_ros.node.messages.MessageError: joint 'ankle' is not in the JointState names ...
>>> command_from_multi_array(Float64MultiArray(data=(0.5, 0.7)), 1)
(None, 0.7)
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Literal, TypeAlias

import numpy as np

from genbacklash_core import Estimate, EstimatorState, GenBacklashError

__all__ = [
    "COMMAND_TYPES",
    "ENCODER_TYPES",
    "CommandMessage",
    "CommandType",
    "DiagnosticArray",
    "DiagnosticStatus",
    "EncoderMessage",
    "EncoderType",
    "Float64",
    "Float64MultiArray",
    "Header",
    "JointState",
    "KeyValue",
    "Message",
    "MessageError",
    "MultiArrayDimension",
    "MultiArrayLayout",
    "Reading",
    "Time",
    "command_from_float64",
    "command_from_joint_state",
    "command_from_multi_array",
    "compensated_command",
    "diagnostic_array",
    "encoder_from_float64",
    "encoder_from_joint_state",
    "estimate_message",
    "level_of",
    "read_command",
    "read_encoder",
]

NS_PER_S = 1_000_000_000
_INT32 = (-(2**31), 2**31 - 1)
_UINT32_MAX = 2**32 - 1


class MessageError(GenBacklashError):
    """A message cannot be read as a command or encoder sample (the reason says why)."""


# --------------------------------------------------------------------------- the messages


def _whole(name: str, value: object, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise MessageError(f"{name} must be a whole number, got {value!r}")
    number = int(value)
    if not low <= number <= high:
        raise MessageError(f"{name} must lie in [{low}, {high}], got {number}")
    return number


def _tuple(obj: object, name: str) -> None:
    """Store the sequence field ``name`` of a frozen dataclass as a tuple."""
    value = getattr(obj, name)
    if type(value) is not tuple:
        if isinstance(value, np.ndarray):  # e.g. from a bag: plain Python numbers
            object.__setattr__(obj, name, tuple(value.tolist()))
            return
        if isinstance(value, (str, bytes)):
            raise MessageError(f"{name} must be a sequence, got the string {value!r}")
        try:
            object.__setattr__(obj, name, tuple(value))
        except TypeError as err:
            raise MessageError(f"{name} must be a sequence, got {value!r}") from err


@dataclass(frozen=True, slots=True)
class Time:
    """``builtin_interfaces/Time``: ``sec`` (int32) and ``nanosec`` in ``[0, 1e9)``.

    >>> Time.from_ns(-1)
    Time(sec=-1, nanosec=999999999)
    >>> Time(3, 5).to_ns()
    3000000005
    """

    ros_type: ClassVar[str] = "builtin_interfaces/msg/Time"

    sec: int = 0
    nanosec: int = 0

    def __post_init__(self) -> None:
        if type(self.sec) is int and type(self.nanosec) is int:  # fast path
            if _INT32[0] <= self.sec <= _INT32[1] and 0 <= self.nanosec < NS_PER_S:
                return
        object.__setattr__(self, "sec", _whole("Time.sec", self.sec, *_INT32))
        object.__setattr__(self, "nanosec", _whole("Time.nanosec", self.nanosec, 0, NS_PER_S - 1))

    @classmethod
    def from_ns(cls, ns: int) -> Time:
        """The time ``ns`` nanoseconds after the epoch (floor division: ``nanosec >= 0``)."""
        if type(ns) is not int:  # fast path: a Python int
            if isinstance(ns, bool) or not isinstance(ns, numbers.Integral):
                raise MessageError(f"a time in nanoseconds must be a whole number, got {ns!r}")
            ns = int(ns)
        sec, nanosec = divmod(ns, NS_PER_S)
        return cls(sec, nanosec)

    def to_ns(self) -> int:
        """Integer nanoseconds since the epoch."""
        return self.sec * NS_PER_S + self.nanosec


@dataclass(frozen=True, slots=True)
class Header:
    """``std_msgs/Header``: a stamp and a frame id."""

    ros_type: ClassVar[str] = "std_msgs/msg/Header"

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass(frozen=True, slots=True)
class Float64:
    """``std_msgs/Float64``."""

    ros_type: ClassVar[str] = "std_msgs/msg/Float64"

    data: float = 0.0


@dataclass(frozen=True, slots=True)
class MultiArrayDimension:
    """``std_msgs/MultiArrayDimension``: label, size and stride (uint32)."""

    ros_type: ClassVar[str] = "std_msgs/msg/MultiArrayDimension"

    label: str = ""
    size: int = 0
    stride: int = 0

    def __post_init__(self) -> None:
        for name in ("size", "stride"):
            value = getattr(self, name)
            if not (type(value) is int and 0 <= value <= _UINT32_MAX):  # fast path
                object.__setattr__(
                    self, name, _whole(f"MultiArrayDimension.{name}", value, 0, _UINT32_MAX)
                )


@dataclass(frozen=True, slots=True)
class MultiArrayLayout:
    """``std_msgs/MultiArrayLayout``: the dimensions and the data offset."""

    ros_type: ClassVar[str] = "std_msgs/msg/MultiArrayLayout"

    dim: tuple[MultiArrayDimension, ...] = ()
    data_offset: int = 0

    def __post_init__(self) -> None:
        _tuple(self, "dim")
        offset = self.data_offset
        if not (type(offset) is int and 0 <= offset <= _UINT32_MAX):  # fast path
            object.__setattr__(self, "data_offset", _whole("data_offset", offset, 0, _UINT32_MAX))


@dataclass(frozen=True, slots=True)
class Float64MultiArray:
    """``std_msgs/Float64MultiArray``: a layout and the data."""

    ros_type: ClassVar[str] = "std_msgs/msg/Float64MultiArray"

    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        _tuple(self, "data")


@dataclass(frozen=True, slots=True)
class JointState:
    """``sensor_msgs/JointState``: names with positions, velocities and efforts."""

    ros_type: ClassVar[str] = "sensor_msgs/msg/JointState"

    header: Header = field(default_factory=Header)
    name: tuple[str, ...] = ()
    position: tuple[float, ...] = ()
    velocity: tuple[float, ...] = ()
    effort: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        for name in ("name", "position", "velocity", "effort"):
            _tuple(self, name)


@dataclass(frozen=True, slots=True)
class KeyValue:
    """``diagnostic_msgs/KeyValue``."""

    ros_type: ClassVar[str] = "diagnostic_msgs/msg/KeyValue"

    key: str = ""
    value: str = ""


@dataclass(frozen=True, slots=True)
class DiagnosticStatus:
    """``diagnostic_msgs/DiagnosticStatus``; ``level`` is one of the class constants.

    ``level`` is a plain int here (as rosbags and DDS carry the ``byte`` field); rclpy wants
    it as ``bytes([level])``.
    """

    ros_type: ClassVar[str] = "diagnostic_msgs/msg/DiagnosticStatus"
    OK: ClassVar[int] = 0
    WARN: ClassVar[int] = 1
    ERROR: ClassVar[int] = 2
    STALE: ClassVar[int] = 3

    level: int = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: tuple[KeyValue, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "level", _whole("DiagnosticStatus.level", self.level, 0, 3))
        _tuple(self, "values")


@dataclass(frozen=True, slots=True)
class DiagnosticArray:
    """``diagnostic_msgs/DiagnosticArray``: a header and the statuses."""

    ros_type: ClassVar[str] = "diagnostic_msgs/msg/DiagnosticArray"

    header: Header = field(default_factory=Header)
    status: tuple[DiagnosticStatus, ...] = ()

    def __post_init__(self) -> None:
        _tuple(self, "status")


Message: TypeAlias = (
    Time
    | Header
    | Float64
    | MultiArrayDimension
    | MultiArrayLayout
    | Float64MultiArray
    | JointState
    | KeyValue
    | DiagnosticStatus
    | DiagnosticArray
)
CommandMessage: TypeAlias = Float64 | Float64MultiArray | JointState
EncoderMessage: TypeAlias = JointState | Float64
CommandType: TypeAlias = Literal["float64", "float64_multi_array", "joint_state"]
EncoderType: TypeAlias = Literal["joint_state", "float64"]
COMMAND_TYPES: tuple[CommandType, ...] = ("float64", "float64_multi_array", "joint_state")
ENCODER_TYPES: tuple[EncoderType, ...] = ("joint_state", "float64")

Reading: TypeAlias = tuple[int | None, float]
"""``(stamp_ns, value)``: the header stamp (None without a header) and a finite value."""


# --------------------------------------------------------------------------- reading


_NOT_NUMBERS = (str, bytes, bytearray, dict)  # sized and indexable, but no number sequences


def _finite(value: object, what: str) -> float:
    """``value`` as a finite float, or a :class:`MessageError` naming ``what``."""
    if type(value) is float:
        if -math.inf < value < math.inf:
            return value
        raise MessageError(f"{what} is not finite ({value})")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise MessageError(f"{what} is not a number, got {value!r}")
    try:
        number = float(value)
    except OverflowError as err:  # an integer beyond the float range
        raise MessageError(f"{what} is not finite (too large for a float)") from err
    if not math.isfinite(number):
        raise MessageError(f"{what} is not finite ({number})")
    return number


def _all_finite(values: Sequence[object], what: str) -> None:
    """Raise when any of ``values`` is not a finite number (fast path: a finite sum).

    ``math.fsum`` converts to Python floats first: no numpy warnings on overflow or inf - inf.
    """
    try:
        if math.isfinite(math.fsum(values)):  # type: ignore[arg-type]
            return
    except (TypeError, ValueError, OverflowError):
        pass  # not numbers, or an overflow of finite values: look at each
    try:
        items = list(values)
    except TypeError as err:
        raise MessageError(f"{what} must be a sequence of numbers, got {values!r}") from err
    for k, value in enumerate(items):
        _finite(value, f"{what}[{k}]")


def _stamp(msg: object, kind: str) -> int:
    try:
        stamp = msg.header.stamp  # type: ignore[attr-defined]
        return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)
    except (AttributeError, TypeError, ValueError, OverflowError) as err:
        raise MessageError(f"expected a {kind} with a header stamp, got {_kind(msg)}") from err


def _kind(msg: object) -> str:
    return type(msg).__name__


def _field(msg: object, name: str, expected: str) -> object:
    try:
        return getattr(msg, name)
    except AttributeError as err:
        raise MessageError(f"expected a {expected}, got {_kind(msg)}") from err


def _joint_index(msg: object, joint: str) -> int:
    """Index of ``joint`` in a JointState's names (0 for ``joint == ''``)."""
    names = _field(msg, "name", "JointState")
    if not isinstance(joint, str):
        raise MessageError(f"the joint name must be a string, got {joint!r}")
    if not joint:
        return 0
    try:
        listed_names: list[object] = list(names)  # type: ignore[call-overload]
    except TypeError as err:
        raise MessageError("JointState name must be a sequence") from err
    try:
        return listed_names.index(joint)
    except ValueError as err:
        more = ", ..." if len(listed_names) > 8 else ""
        listed = ", ".join(repr(n) for n in listed_names[:8]) + more
        raise MessageError(f"joint {joint!r} is not in the JointState names [{listed}]") from err


def _index(index: object) -> int:
    """``command_index`` as an int, or a :class:`MessageError`."""
    if type(index) is int:  # fast path
        return index
    if isinstance(index, bool) or not isinstance(index, numbers.Integral):
        raise MessageError(f"command_index must be a whole number, got {index!r}")
    return int(index)


def _check_index(index: int, size: int) -> None:
    if not 0 <= index < size:
        values = "value" if size == 1 else "values"
        raise MessageError(
            f"command_index {index} is out of range: the Float64MultiArray holds {size} {values}"
        )


def _joint_position(msg: object, joint: str, *, whole: bool) -> tuple[int, float]:
    """The stamp and the position of ``joint``; ``whole`` checks every number is finite."""
    stamp = _stamp(msg, "JointState")
    index = _joint_index(msg, joint)
    names = _field(msg, "name", "JointState")
    position = _field(msg, "position", "JointState")
    try:
        n_names, n_pos = len(names), len(position)  # type: ignore[arg-type]
    except TypeError as err:
        raise MessageError("JointState name and position must be sequences") from err
    if isinstance(position, _NOT_NUMBERS):
        raise MessageError(
            f"JointState position must be a sequence of numbers, not {_kind(position)}"
        )
    if n_pos == 0:
        raise MessageError("JointState has no positions")
    if n_names and n_names != n_pos:
        raise MessageError(f"JointState has {n_names} names but {n_pos} positions")
    if index >= n_pos:
        raise MessageError(f"JointState has {n_pos} positions; joint index {index} is beyond")
    label = f"position of joint {joint!r}" if joint else "position[0]"
    try:
        raw = position[index]  # type: ignore[index]
    except (TypeError, KeyError, IndexError) as err:
        raise MessageError("JointState position must be a sequence") from err
    value = _finite(raw, label)
    if whole:
        for name in ("position", "velocity", "effort"):
            _all_finite(_field(msg, name, "JointState"), f"JointState {name}")  # type: ignore[arg-type]
    return stamp, value


def command_from_float64(msg: object) -> Reading:
    """The command in a ``std_msgs/Float64`` (no header: the stamp is None).

    >>> command_from_float64(Float64(0.5))
    (None, 0.5)
    """
    return None, _finite(_field(msg, "data", "Float64"), "Float64 data")


def command_from_multi_array(msg: object, index: int) -> Reading:
    """Element ``index`` of a ``std_msgs/Float64MultiArray`` (no header: the stamp is None).

    Every element must be finite: the compensated command echoes the others unchanged.

    >>> command_from_multi_array(Float64MultiArray(data=(0.1,)), 3)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_ros.node.messages.MessageError: command_index 3 is out of range: ... holds 1 value
    """
    data = _field(msg, "data", "Float64MultiArray")
    if isinstance(data, _NOT_NUMBERS):
        raise MessageError(
            f"expected a Float64MultiArray, got {_kind(msg)} with {_kind(data)} data"
        )
    try:
        size = len(data)  # type: ignore[arg-type]
    except TypeError as err:
        raise MessageError(f"expected a Float64MultiArray, got {_kind(msg)}") from err
    if size == 0:
        raise MessageError("the Float64MultiArray is empty")
    index = _index(index)
    _check_index(index, size)
    try:
        raw = data[index]  # type: ignore[index]
    except (TypeError, KeyError, IndexError) as err:
        raise MessageError("Float64MultiArray data must be a sequence") from err
    value = _finite(raw, f"Float64MultiArray data[{index}]")
    _all_finite(data, "Float64MultiArray data")  # type: ignore[arg-type]
    return None, value


def command_from_joint_state(msg: object, joint: str) -> Reading:
    """The position of ``joint`` (``''``: the first) in a ``sensor_msgs/JointState`` command.

    Every position, velocity and effort must be finite: the compensated command echoes them.
    """
    return _joint_position(msg, joint, whole=True)


def encoder_from_joint_state(msg: object, joint: str) -> Reading:
    """The position of ``joint`` (``''``: the first) in a ``sensor_msgs/JointState``.

    Only that position must be finite; the other joints' readings are not looked at.
    """
    return _joint_position(msg, joint, whole=False)


def encoder_from_float64(msg: object) -> Reading:
    """The encoder reading in a ``std_msgs/Float64`` (no header: the stamp is None)."""
    return None, _finite(_field(msg, "data", "Float64"), "Float64 data")


def read_command(
    msg: object, command_type: CommandType, *, index: int = 0, joint: str = ""
) -> Reading:
    """The command in ``msg`` of ``command_type`` (``index``/``joint`` select the element).

    >>> read_command(JointState(Header(Time(1)), ("a",), (0.3,)), "joint_state", joint="a")
    (1000000000, 0.3)
    """
    if command_type == "float64_multi_array":
        return command_from_multi_array(msg, index)
    if command_type == "joint_state":
        return command_from_joint_state(msg, joint)
    if command_type == "float64":
        return command_from_float64(msg)
    raise MessageError(f"command_type must be one of {', '.join(COMMAND_TYPES)}")


def read_encoder(msg: object, encoder_type: EncoderType, *, joint: str = "") -> Reading:
    """The encoder reading in ``msg`` of ``encoder_type`` (``joint`` selects the joint)."""
    if encoder_type == "joint_state":
        return encoder_from_joint_state(msg, joint)
    if encoder_type == "float64":
        return encoder_from_float64(msg)
    raise MessageError(f"encoder_type must be one of {', '.join(ENCODER_TYPES)}")


# --------------------------------------------------------------------------- building


def compensated_command(
    msg: CommandMessage,
    value: float,
    command_type: CommandType,
    *,
    index: int = 0,
    joint: str = "",
) -> CommandMessage:
    """A copy of the command ``msg`` with its command replaced by ``value``.

    Of the same type as ``msg`` and stamped like it (a JointState keeps its header); the
    other elements (other joints) are echoed unchanged. ``msg`` must be readable by
    :func:`read_command` with the same arguments.

    >>> cmd = Float64MultiArray(data=(0.1, 0.2, 0.3))
    >>> compensated_command(cmd, 0.9, "float64_multi_array", index=1).data
    (0.1, 0.9, 0.3)
    """
    number = _finite(value, "the compensated command")
    if command_type == "float64":
        return Float64(number)
    if command_type == "float64_multi_array":
        if not isinstance(msg, Float64MultiArray):
            raise MessageError(f"expected a Float64MultiArray, got {_kind(msg)}")
        data = list(msg.data)
        index = _index(index)
        _check_index(index, len(data))
        data[index] = number
        return Float64MultiArray(msg.layout, tuple(data))
    if command_type == "joint_state":
        if not isinstance(msg, JointState):
            raise MessageError(f"expected a JointState, got {_kind(msg)}")
        position = list(msg.position)
        k = _joint_index(msg, joint)
        if k >= len(position):
            raise MessageError(
                f"JointState has {len(position)} positions; joint index {k} is beyond"
            )
        position[k] = number
        return JointState(msg.header, msg.name, tuple(position), msg.velocity, msg.effort)
    raise MessageError(f"command_type must be one of {', '.join(COMMAND_TYPES)}")


def estimate_message(estimate: Estimate) -> Float64MultiArray:
    """The ``~/estimate`` message (GUIDE §4): the parameters, named in ``dim[0].label``.

    Raises :class:`MessageError` while the estimate holds no parameters (never publishes NaN).

    >>> from genbacklash_core import paper_example, Structure
    >>> import numpy as np
    >>> truth = paper_example(1).model
    >>> est = Estimate(Structure(3), truth.parameters(), np.eye(8), 0.0, 1.0, "converged", 1.0, 9)
    >>> msg = estimate_message(est)
    >>> msg.layout.dim[0].label
    'm_left_1,m_left_2,m_left_3,c_left,m_right_1,m_right_2,m_right_3,c_right'
    >>> msg.data[3], msg.layout.dim[0].size
    (0.7, 8)
    """
    if not isinstance(estimate, Estimate):
        raise MessageError(f"expected an Estimate, got {_kind(estimate)}")
    if not estimate.available:
        raise MessageError("the estimate holds no parameters yet (warming up)")
    names = estimate.names
    size = len(names)
    dim = MultiArrayDimension(",".join(names), size, size)
    return Float64MultiArray(MultiArrayLayout((dim,), 0), tuple(estimate.parameters.tolist()))


def _text(value: float) -> str:
    return format(value, ".9g") if math.isfinite(value) else "n/a"


def diagnostic_array(
    stamp_ns: int,
    estimate: Estimate,
    *,
    level: int,
    message: str,
    name: str = "backlash_identifier",
    hardware_id: str = "",
    extra: Iterable[tuple[str, str]] = (),
) -> DiagnosticArray:
    """A ``/diagnostics`` message with one status describing ``estimate``.

    Values, in order: ``state``, ``confidence``, ``residual``, ``excitation``, ``samples``,
    every parameter by name (``n/a`` while unknown: no non-finite number is ever written),
    ``reason``, then ``extra``.

    >>> from genbacklash_core import Structure
    >>> diag = diagnostic_array(
    ...     5, Estimate.empty(Structure(1)), level=DiagnosticStatus.WARN, message="warming up"
    ... )
    >>> status = diag.status[0]
    >>> status.level, [kv.key for kv in status.values][:5], status.values[5].value
    (1, ['state', 'confidence', 'residual', 'excitation', 'samples'], 'n/a')
    """
    if not isinstance(estimate, Estimate):
        raise MessageError(f"expected an Estimate, got {_kind(estimate)}")
    for label, text in (("message", message), ("name", name), ("hardware_id", hardware_id)):
        if not isinstance(text, str):
            raise MessageError(f"the diagnostic {label} must be a string, got {text!r}")
    values = [
        KeyValue("state", estimate.state.value),
        KeyValue("confidence", _text(estimate.confidence)),
        KeyValue("residual", _text(estimate.residual)),
        KeyValue("excitation", _text(estimate.excitation)),
        KeyValue("samples", str(estimate.samples)),
    ]
    params = estimate.parameters.tolist()
    values += [KeyValue(n, _text(v)) for n, v in zip(estimate.names, params, strict=True)]
    values.append(KeyValue("reason", estimate.reason))
    try:
        pairs = [(k, v) for k, v in extra]
    except (TypeError, ValueError) as err:
        raise MessageError(f"extra must be (key, value) pairs, got {extra!r}") from err
    for k, v in pairs:
        if not (isinstance(k, str) and isinstance(v, str)):
            raise MessageError(f"extra keys and values must be strings, got {(k, v)!r}")
    values += [KeyValue(k, v) for k, v in pairs]
    status = DiagnosticStatus(level, name, message, hardware_id, tuple(values))
    return DiagnosticArray(Header(Time.from_ns(stamp_ns)), (status,))


def level_of(state: EstimatorState) -> int:
    """Diagnostic level of an estimator state: OK while it has a trusted estimate or
    converges, WARN while warming up or without excitation, ERROR when diverged.

    >>> level_of(EstimatorState.DIVERGED)
    2
    """
    if state is EstimatorState.DIVERGED:
        return DiagnosticStatus.ERROR
    if state in (EstimatorState.WARMING_UP, EstimatorState.NO_EXCITATION):
        return DiagnosticStatus.WARN
    return DiagnosticStatus.OK
