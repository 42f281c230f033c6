"""The node's parameters: one table of specifications, a validated frozen record, params YAML.

:data:`PARAMETER_SPECS` lists every parameter of the ``backlash_identifier`` node with its
type, default, description, unit and allowed range or choices: the rclpy node turns it into
``ParameterDescriptor`` s, the DDS transport and replay read the same values from a standard
ROS 2 parameters YAML (:func:`load_params_file`), and docs/node.md renders it as the reference
(:func:`parameter_table`). :class:`NodeParameters` holds one validated set;
:meth:`NodeParameters.replace` is what a set-parameters callback calls (the new set, or a
:class:`~genbacklash_core.GenBacklashError` whose message is the reason to reject).

Examples
--------
>>> params = NodeParameters.from_mapping({"degree": 2, "method": "recursive"})
>>> params.degree, params.method, params.window
(2, 'recursive', 1500)
>>> params.replace(degree=12)
Traceback (most recent call last):
...
genbacklash_core.errors.GenBacklashError: parameter 'degree' must lie in [1, 9], got 12
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeAlias

from genbacklash_core import (
    CompensatorOptions,
    GenBacklashError,
    OnlineIdentifier,
    RecursiveIdentifier,
    RecursiveSettings,
    Structure,
    WindowedIdentifier,
    WindowedSettings,
)
from genbacklash_core.guard import GuardSettings
from genbacklash_core.measured import TrackingJudgeSettings
from genbacklash_core.servo import ServoModel
from genbacklash_ros.node.messages import COMMAND_TYPES, ENCODER_TYPES, CommandType, EncoderType
from genbacklash_ros.node.sample_rule import ServoChoice

__all__ = [
    "JOINT_KEYS",
    "NODE_NAME",
    "PAIRS",
    "PARAMETER_SPECS",
    "NodeParameters",
    "ParameterSpec",
    "RosArguments",
    "command_line_parameters",
    "is_joint_parameter",
    "load_params_file",
    "parameter_table",
    "parse_param_overrides",
    "parse_ros_arguments",
    "read_params_file",
    "resolve_requested",
]

NODE_NAME = "backlash_identifier"

ParameterType: TypeAlias = Literal["string", "integer", "double", "bool"]
ParameterValue: TypeAlias = str | int | float | bool

# parameters every ROS 2 node has; a params file may set them, the transports handle them
_STANDARD = ("use_sim_time",)
_STANDARD_PREFIXES = ("qos_overrides.",)

_WINDOWED = WindowedSettings()
_RECURSIVE = RecursiveSettings()
_COMPENSATOR = CompensatorOptions()


@dataclass(frozen=True)
class ParameterSpec:
    """One node parameter: what the descriptor, the validation and docs/node.md say.

    Attributes
    ----------
    name : str
    type : {"string", "integer", "double", "bool"}
        The ROS 2 parameter type.
    default : str, int, float or bool
    description : str
    min, max : float or None
        Inclusive range of a number (None: unbounded on that side).
    choices : tuple of str
        Allowed values of a string (empty: any string).
    unit : str
    restarts : bool
        Changing it at run time restarts identification (a new identifier).
    """

    name: str
    type: ParameterType
    default: ParameterValue
    description: str
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] = ()
    unit: str = ""
    restarts: bool = False

    def check(self, value: object) -> ParameterValue:
        """``value`` converted to this parameter's type, or the reason it is not allowed."""
        name = f"parameter {self.name!r}"
        if self.type == "bool":
            if not isinstance(value, bool):
                raise GenBacklashError(f"{name} must be true or false, got {value!r}")
            return value
        if self.type == "string":
            if not isinstance(value, str):
                raise GenBacklashError(f"{name} must be a string, got {value!r}")
            if self.choices and value not in self.choices:
                allowed = ", ".join(repr(c) for c in self.choices)
                raise GenBacklashError(f"{name} must be one of {allowed}, got {value!r}")
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            kind = "a whole number" if self.type == "integer" else "a number"
            raise GenBacklashError(f"{name} must be {kind}, got {value!r}")
        if self.type == "integer":
            if not isinstance(value, int):
                raise GenBacklashError(f"{name} must be a whole number, got {value!r}")
            number: int | float = value
        else:
            number = float(value)
            if math.isnan(number):
                raise GenBacklashError(f"{name} must be a number, got NaN")
        low = -math.inf if self.min is None else self.min
        high = math.inf if self.max is None else self.max
        if not low <= number <= high:
            allowed = f"[{_show(low)}, {_show(high)}]"
            raise GenBacklashError(f"{name} must lie in {allowed}, got {value!r}")
        return number

    @property
    def range_text(self) -> str:
        """The allowed values as text (for docs/node.md and descriptors)."""
        if self.choices:
            return ", ".join(self.choices)
        if self.type == "bool":
            return "true, false"
        if self.min is None and self.max is None:
            return "any"
        low = "-inf" if self.min is None else _show(self.min)
        high = "inf" if self.max is None else _show(self.max)
        return f"[{low}, {high}]"


def _show(value: float) -> str:
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:g}"


PARAMETER_SPECS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        "model",
        "string",
        "backlash",
        "Model structure: a general backlash alone, or followed by linear dynamics.",
        choices=("backlash", "cascade"),
        restarts=True,
    ),
    ParameterSpec("degree", "integer", 3, "Polynomial degree of each branch.", 1, 9, restarts=True),
    ParameterSpec(
        "na",
        "integer",
        2,
        "Cascade only: order r of the linear block's x terms (a_1 = 1).",
        1,
        10,
        restarts=True,
    ),
    ParameterSpec(
        "nb",
        "integer",
        2,
        "Cascade only: order p of the linear block's y terms.",
        0,
        10,
        restarts=True,
    ),
    ParameterSpec(
        "method",
        "string",
        "windowed",
        "Online identifier: warm-started iterations over a sliding window, or recursive "
        "least squares with per-branch forgetting.",
        choices=("windowed", "recursive"),
        restarts=True,
    ),
    ParameterSpec(
        "window",
        "integer",
        _WINDOWED.window,
        "Windowed method: regression rows remembered (a backlash alone: pairs of consecutive "
        "readings whose input moved, forgotten only where new rows cover the same input "
        "region; a cascade: samples, a dwell's only until the dynamics settle). More: more "
        "accurate; fewer: tracks wear faster.",
        20,
        10_000_000,
        unit="rows",
        restarts=True,
    ),
    ParameterSpec(
        "forgetting",
        "double",
        _RECURSIVE.forgetting,
        "Recursive method: each branch remembers its newest 1 / (1 - forgetting) regression "
        "rows (pairs of consecutive readings whose input moved), and every input region a "
        "few rows however old.",
        0.5,
        1.0,
        restarts=True,
    ),
    ParameterSpec(
        "joint",
        "string",
        "",
        "Joint name in JointState messages (command and encoder); empty: the first joint.",
    ),
    ParameterSpec(
        "command_index",
        "integer",
        0,
        "Float64MultiArray command: index of the identified joint's element.",
        0,
        65_535,
    ),
    ParameterSpec(
        "command_type",
        "string",
        "float64_multi_array",
        "Message type of the command topic (std_msgs/Float64, std_msgs/Float64MultiArray, "
        "sensor_msgs/JointState); compensated_command has the same type.",
        choices=COMMAND_TYPES,
    ),
    ParameterSpec(
        "encoder_type",
        "string",
        "joint_state",
        "Message type of the encoder topic (sensor_msgs/JointState or std_msgs/Float64).",
        choices=ENCODER_TYPES,
    ),
    ParameterSpec(
        "gear_input",
        "string",
        "command",
        "What the identifier takes as the gear's input: the command (the servo's answer "
        "modelled by settle_time), or the motor-side position a motor encoder publishes on "
        "motor_encoder (dual encoders): each encoder reading is paired with the motor "
        "reading of its stamp, and the compensated command is the inverse of the identified "
        "motor-to-load backlash at the desired load position.",
        choices=("command", "motor_encoder"),
        restarts=True,
    ),
    ParameterSpec(
        "motor_encoder_type",
        "string",
        "joint_state",
        "Message type of the motor_encoder topic (sensor_msgs/JointState or std_msgs/Float64; "
        "gear_input motor_encoder).",
        choices=ENCODER_TYPES,
        restarts=True,
    ),
    ParameterSpec(
        "motor_joint",
        "string",
        "",
        "Joint name in the motor_encoder JointState; empty: the joint parameter's.",
        restarts=True,
    ),
    ParameterSpec(
        "compensate",
        "bool",
        True,
        "Publish the inverse-backlash compensated command (false: the command passes through).",
    ),
    ParameterSpec(
        "compensation_in_loop",
        "bool",
        False,
        "The compensated command drives the drivetrain, so identify from it, and judge "
        "compensation by the tracking it measures; false (and in replay): identify from the "
        "raw command (a node whose command does drive the drivetrain says so in /diagnostics). "
        "With gear_input motor_encoder the identifier reads the motor either way; this then "
        "only says whether the compensated command drives the drivetrain.",
        restarts=True,
    ),
    ParameterSpec(
        "compensation_guard",
        "bool",
        True,
        "Judge from the data whether compensation helps and fade it out where it does not: "
        "the model's error on the commands against the error with no model, and, with "
        "compensation_in_loop, the tracking error measured with compensation against without "
        "it (after a baseline without it, a trial at up to half weight); false: only report "
        "the judgements.",
    ),
    ParameterSpec(
        "u_min", "double", -math.inf, "Lower limit of the compensated command.", unit="command"
    ),
    ParameterSpec(
        "u_max", "double", math.inf, "Upper limit of the compensated command.", unit="command"
    ),
    ParameterSpec(
        "max_rate",
        "double",
        math.inf,
        "Largest change of the compensated command between two command messages.",
        1e-12,
        None,
        unit="command/message",
    ),
    ParameterSpec(
        "gate_low",
        "double",
        _COMPENSATOR.gate_low,
        "Estimate confidence at or below which the command passes through uncorrected.",
        0.0,
        1.0,
    ),
    ParameterSpec(
        "gate_high",
        "double",
        _COMPENSATOR.gate_high,
        "Estimate confidence from which the full correction is applied (fades in between).",
        0.0,
        1.0,
    ),
    ParameterSpec(
        "checkpoint_file",
        "string",
        "",
        "JSON file the estimate is saved to (atomically) and warm-started from; empty: none.",
    ),
    ParameterSpec(
        "checkpoint_period",
        "double",
        10.0,
        "Data time between two checkpoints.",
        0.1,
        86_400.0,
        unit="s",
    ),
    ParameterSpec(
        "publish_rate",
        "double",
        10.0,
        "Rate of ~/estimate, on the data's clock.",
        0.01,
        1000.0,
        unit="Hz",
    ),
    ParameterSpec(
        "settle_time",
        "double",
        0.005,
        "Time a new command takes the servo to reach (its settling): samples taken sooner "
        "after the command changed are not identified from (a backlash alone, where commands "
        "change more slowly than the encoder samples); 0: every sample. Not applied with "
        "gear_input motor_encoder (the motor's reading is the gear's input: nothing to settle).",
        0.0,
        1.0,
        unit="s",
        restarts=True,
    ),
    ParameterSpec(
        "servo_model",
        "string",
        "none",
        "The servo between the command and the gear (a dead time and a first-order lag, "
        "genbacklash_core.servo): none (the gear's input is the command, with the settling "
        "rule), auto (estimated with the play from the first servo_window of data, then "
        "fixed), fixed (servo_dead_time, servo_time_constant). With a servo the identifier's "
        "input is the modelled servo output and the compensator aims it.",
        choices=("none", "auto", "fixed"),
        restarts=True,
    ),
    ParameterSpec(
        "servo_dead_time",
        "double",
        0.0,
        "The servo's dead time (servo_model fixed).",
        0.0,
        1.0,
        unit="s",
        restarts=True,
    ),
    ParameterSpec(
        "servo_time_constant",
        "double",
        0.0,
        "The servo's first-order lag time constant (servo_model fixed).",
        0.0,
        1.0,
        unit="s",
        restarts=True,
    ),
    ParameterSpec(
        "servo_window",
        "double",
        5.0,
        "Data time the node collects before it estimates the servo (servo_model auto); "
        "batch identify and diagnose estimate it from the whole record.",
        1.0,
        600.0,
        unit="s",
        restarts=True,
    ),
    ParameterSpec(
        "sample_period",
        "double",
        0.0,
        "Identification sample period on a fixed time grid; 0: one sample per encoder message.",
        0.0,
        10.0,
        unit="s",
        restarts=True,
    ),
    ParameterSpec(
        "stamp_source",
        "string",
        "header",
        "Time of a message: its header stamp (receive time for messages without one or with "
        "a zero stamp), or always the receive time.",
        choices=("header", "receive"),
        restarts=True,
    ),
    ParameterSpec(
        "thread_priority",
        "integer",
        0,
        "Real-time priority (SCHED_FIFO) of the thread that takes the messages and answers "
        "the commands, as ros2_control's thread_priority; 0: the default scheduler. Above 0 "
        "identification runs in a child process of its own, so that the message thread never "
        "waits for the interpreter lock of a thread it preempts. Needs CAP_SYS_NICE or an "
        "rtprio limit; without them the node warns and runs on the default scheduler. Read-only.",
        0,
        99,
    ),
)

_SPECS: dict[str, ParameterSpec] = {spec.name: spec for spec in PARAMETER_SPECS}

#: Parameters checked against each other: ``u_min < u_max``, ``gate_low <= gate_high``.
PAIRS: tuple[tuple[str, str], ...] = (("u_min", "u_max"), ("gate_low", "gate_high"))


def _pair_problem(low_name: str, low: object, high_name: str, high: object) -> str | None:
    """Why a pair of values is inconsistent, or None."""
    if not isinstance(low, int | float) or not isinstance(high, int | float):
        return None  # the value checks report these
    if low_name == "u_min" and not low < high:
        return f"parameter 'u_min' ({low:g}) must be below 'u_max' ({high:g})"
    if low_name != "u_min" and low > high:
        return f"parameter {low_name!r} ({low:g}) must not exceed {high_name!r} ({high:g})"
    return None


@dataclass(frozen=True)
class NodeParameters:
    """The validated parameters of the ``backlash_identifier`` node (see :data:`PARAMETER_SPECS`).

    Every field is checked against its spec in ``__post_init__`` (a
    :class:`~genbacklash_core.GenBacklashError` names the parameter and the allowed range),
    then the cross-checks: ``u_min < u_max`` and ``gate_low <= gate_high``.

    Examples
    --------
    >>> NodeParameters(gate_low=0.8, gate_high=0.5)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: parameter 'gate_low' (0.8) must not exceed ...
    >>> NodeParameters(model="cascade").structure()
    Structure(degree=3, na=2, nb=2, sign=1.0)
    """

    model: Literal["backlash", "cascade"] = "backlash"
    degree: int = 3
    na: int = 2
    nb: int = 2
    method: Literal["windowed", "recursive"] = "windowed"
    window: int = _WINDOWED.window
    forgetting: float = _RECURSIVE.forgetting
    joint: str = ""
    command_index: int = 0
    command_type: CommandType = "float64_multi_array"
    encoder_type: EncoderType = "joint_state"
    gear_input: Literal["command", "motor_encoder"] = "command"
    motor_encoder_type: EncoderType = "joint_state"
    motor_joint: str = ""
    compensate: bool = True
    compensation_in_loop: bool = False
    compensation_guard: bool = True
    u_min: float = -math.inf
    u_max: float = math.inf
    max_rate: float = math.inf
    gate_low: float = _COMPENSATOR.gate_low
    gate_high: float = _COMPENSATOR.gate_high
    checkpoint_file: str = ""
    checkpoint_period: float = 10.0
    publish_rate: float = 10.0
    settle_time: float = 0.005
    servo_model: Literal["none", "auto", "fixed"] = "none"
    servo_dead_time: float = 0.0
    servo_time_constant: float = 0.0
    servo_window: float = 5.0
    sample_period: float = 0.0
    stamp_source: Literal["header", "receive"] = "header"
    thread_priority: int = 0

    def __post_init__(self) -> None:
        for spec in PARAMETER_SPECS:
            object.__setattr__(self, spec.name, spec.check(getattr(self, spec.name)))
        for low, high in PAIRS:
            problem = _pair_problem(low, getattr(self, low), high, getattr(self, high))
            if problem:
                raise GenBacklashError(problem)
        if self.gear_input == "motor_encoder" and self.sample_period:
            raise GenBacklashError(
                "parameter 'gear_input' motor_encoder pairs each encoder reading with the motor "
                "reading of its stamp: it needs sample_period 0 (one sample per encoder "
                f"reading), got sample_period {self.sample_period:g}"
            )

    @classmethod
    def from_mapping(cls, values: Mapping[str, object]) -> NodeParameters:
        """Parameters from a name -> value mapping; unset ones keep their defaults.

        Unknown names are an error that lists them with their close matches (a typo must
        not pass silently; all the names are in ``genbacklash replay --list-params``).

        >>> NodeParameters.from_mapping({"degre": 2})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        genbacklash_core.errors.GenBacklashError: unknown parameter(s) 'degre' (close matches: ...)
        """
        unknown = sorted(str(k) for k in values if k not in _SPECS)
        if unknown:
            names = ", ".join(repr(k) for k in unknown)
            if len(unknown) == 1:
                hints = f" ({_close_matches(unknown[0])})"
            else:
                hints = ": " + "; ".join(f"{k!r}: {_close_matches(k)}" for k in unknown)
            raise GenBacklashError(f"unknown parameter(s) {names}{hints}")
        return cls(**values)  # type: ignore[arg-type]

    def replace(self, **changes: object) -> NodeParameters:
        """A validated copy with ``changes`` applied (for a set-parameters callback).

        >>> NodeParameters().replace(publish_rate=0.0)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        genbacklash_core.errors.GenBacklashError: parameter 'publish_rate' must lie in [0.01, ...
        """
        merged: dict[str, object] = dict(self.to_mapping())
        unknown = [k for k in changes if k not in _SPECS]
        if unknown:
            return NodeParameters.from_mapping(changes)  # raises, naming them
        merged.update(changes)
        return NodeParameters.from_mapping(merged)

    def to_mapping(self) -> dict[str, ParameterValue]:
        """Name -> value, in :data:`PARAMETER_SPECS` order."""
        return {spec.name: getattr(self, spec.name) for spec in PARAMETER_SPECS}

    def restart_needed(self, other: NodeParameters) -> bool:
        """True when going from ``self`` to ``other`` changes a parameter that restarts
        identification (see :attr:`ParameterSpec.restarts`)."""
        return any(
            getattr(self, s.name) != getattr(other, s.name) for s in PARAMETER_SPECS if s.restarts
        )

    def structure(self, sign: float = 1.0) -> Structure:
        """The model structure these parameters ask for (``na = nb = 0`` for a backlash)."""
        if self.model == "cascade":
            return Structure(self.degree, self.na, self.nb, sign)
        return Structure(self.degree, 0, 0, sign)

    def make_identifier(self, sign: float | None = None) -> OnlineIdentifier:
        """A fresh online identifier of the chosen ``method`` (non-finite samples dropped).

        ``sign`` is the branch sense when known (e.g. from a checkpoint); None detects it.
        """
        structure = self.structure()
        if self.method == "recursive":
            return RecursiveIdentifier(
                structure.degree,
                structure.na,
                structure.nb,
                sign=sign,
                settings=dataclasses.replace(
                    _RECURSIVE, forgetting=self.forgetting, nonfinite="drop"
                ),
            )
        return WindowedIdentifier(
            structure.degree,
            structure.na,
            structure.nb,
            sign=sign,
            settings=dataclasses.replace(_WINDOWED, window=self.window, nonfinite="drop"),
        )

    def compensator_options(self) -> CompensatorOptions:
        """Limits, rate limit and confidence gating of the compensator."""
        return CompensatorOptions(
            u_min=self.u_min,
            u_max=self.u_max,
            max_rate=self.max_rate,
            gate_low=self.gate_low,
            gate_high=self.gate_high,
        )

    def guard_settings(self) -> GuardSettings:
        """How the compensation guard judges (:class:`~genbacklash_core.guard.GuardSettings`)."""
        return GuardSettings(enabled=self.compensation_guard)

    def judge_settings(self) -> TrackingJudgeSettings:
        """How the measured tracking is judged
        (:class:`~genbacklash_core.measured.TrackingJudgeSettings`): its verdict counts only
        while the compensated command drives the drivetrain and the guard is on."""
        return TrackingJudgeSettings(in_loop=self.compensation_in_loop and self.compensation_guard)

    def servo(self) -> ServoChoice:
        """The servo the rows model (:mod:`genbacklash_core.servo`): None, ``"auto"`` or
        the fixed model. A cascade keeps the command as its input (None).

        >>> NodeParameters(servo_model="fixed", servo_dead_time=0.002).servo()
        ServoModel(dead_time=0.002, time_constant=0.0)
        """
        if self.model != "backlash" or self.servo_model == "none":
            return None
        if self.servo_model == "auto":
            return "auto"
        return ServoModel(self.servo_dead_time, self.servo_time_constant)

    @property
    def settle_ns(self) -> int:
        """``settle_time`` in integer nanoseconds."""
        return round(self.settle_time * 1e9)

    @property
    def motor_input(self) -> bool:
        """The gear's input is a motor encoder's reading (``gear_input``)."""
        return self.gear_input == "motor_encoder"

    @property
    def motor_joint_name(self) -> str:
        """The joint read from a motor encoder JointState: ``motor_joint``, else ``joint``."""
        return self.motor_joint or self.joint

    @property
    def sample_period_ns(self) -> int:
        """``sample_period`` in integer nanoseconds (0: sample at the encoder stamps)."""
        return round(self.sample_period * 1e9)

    @property
    def publish_period_ns(self) -> int:
        """Period of ``~/estimate`` in integer nanoseconds."""
        return max(round(1e9 / self.publish_rate), 1)

    @property
    def checkpoint_period_ns(self) -> int:
        """``checkpoint_period`` in integer nanoseconds."""
        return round(self.checkpoint_period * 1e9)


def resolve_requested(
    current: NodeParameters, requested: Mapping[str, object]
) -> tuple[NodeParameters, tuple[str, ...]]:
    """The parameters a running node applies when it holds the values ``requested``.

    The rule for changing parameters one at a time (``ros2 param set``, which sends one
    parameter per request): each value is checked on its own when it is set, and refused
    with the reason when it is invalid (a type, range or choice); the pairs of :data:`PAIRS`
    are checked on the values the node holds after the request. While a pair is
    inconsistent (the first of two ``ros2 param set`` that move it, in either order), both
    its values stay at ``current``'s and every other value applies; the pair applies as soon
    as it is consistent again. So a pair moves with two sets in any order, and the node never
    runs on an inconsistent pair.

    Parameters
    ----------
    current : NodeParameters
        What the node runs with now (always consistent).
    requested : mapping
        Name -> value the node holds (``current``'s values where not given); every value
        already valid on its own.

    Returns
    -------
    params : NodeParameters
        What to run with.
    pending : tuple of str
        One line per pair left at ``current``'s values: what is inconsistent and what is
        kept.

    Examples
    --------
    >>> now = NodeParameters()
    >>> params, pending = resolve_requested(now, {"gate_low": 0.7, "publish_rate": 5.0})
    >>> params.gate_low, params.publish_rate
    (0.2, 5.0)
    >>> print(pending[0])  # doctest: +NORMALIZE_WHITESPACE
    parameter 'gate_low' (0.7) must not exceed 'gate_high' (0.5): running on gate_low 0.2,
    gate_high 0.5 until the pair is consistent (set the other one next)
    >>> resolve_requested(now, {"gate_low": 0.7, "gate_high": 0.9})[0].gate_low
    0.7
    """
    merged: dict[str, object] = {**current.to_mapping(), **requested}
    pending: list[str] = []
    for low, high in PAIRS:
        problem = _pair_problem(low, merged[low], high, merged[high])
        if problem:
            kept_low, kept_high = getattr(current, low), getattr(current, high)
            merged[low], merged[high] = kept_low, kept_high
            pending.append(
                f"{problem}: running on {low} {kept_low:g}, {high} {kept_high:g} until the "
                "pair is consistent (set the other one next)"
            )
    return NodeParameters.from_mapping(merged), tuple(pending)


# --------------------------------------------------------------------------- ROS arguments


@dataclass(frozen=True)
class RosArguments:
    """What a node's ``--ros-args`` say about its parameters: the params files in order, and
    the namespace and name they are matched against.

    Attributes
    ----------
    params_files : tuple of str
    parameters : tuple of (str, str, str)
        The ``-p``/``--param`` rules in order as ``(node, name, value)``: ``node`` is the
        node-name prefix of ``-p node:name:=value`` (``""`` without one: every node), ``value``
        the YAML text.
    namespace : str
        From ``-r __ns:=/arm`` (``""``: the root namespace).
    node_name : str
        From ``-r __node:=name`` (default :data:`NODE_NAME`).
    """

    params_files: tuple[str, ...] = ()
    namespace: str = ""
    node_name: str = NODE_NAME
    parameters: tuple[tuple[str, str, str], ...] = ()

    def node_parameters(self) -> dict[str, str]:
        """Name -> value text of the ``-p`` rules that apply to this node (rules without a
        node prefix, and those whose prefix matches the node as a params-file section key
        would), later rules winning."""
        chosen: dict[str, str] = {}
        for node, name, value in self.parameters:
            if node:
                try:
                    applies, _ = _matches(node, self.node_name, self.namespace, Path("-p"))
                except GenBacklashError:  # not a node name rcl accepts: rcl says so itself
                    continue
                if not applies:
                    continue
            chosen[name] = value
        return chosen

    def check_parameter_names(self) -> None:
        """Refuse a ``-p`` name the node does not have, naming the close matches (a typo must
        not pass silently: rcl takes any name, and the node would ignore it).

        >>> parse_ros_arguments(["n", "--ros-args", "-p", "degre:=2"]).check_parameter_names()
        Traceback (most recent call last):
        ...
        genbacklash_core.errors.GenBacklashError: -p: unknown parameter 'degre' (close matches: ...)
        """
        for name in self.node_parameters():
            if name not in _SPECS and not _is_standard(name) and not is_joint_parameter(name):
                raise GenBacklashError(_unknown_name(name, "-p"))


_ROS_OPTIONS_WITH_VALUE = frozenset(
    {"-r", "--remap", "-p", "--param", "--params-file", "-e", "--enclave", "--log-level"}
    | {"--log-config-file", "--log-file-name"}
)


def parse_ros_arguments(argv: Sequence[str]) -> RosArguments:
    """The params files, namespace and node name in a command line's ``--ros-args``
    sections (each up to ``--`` or the next ``--ros-args``), as rcl reads them.

    >>> ros = parse_ros_arguments(["node", "--ros-args", "-r", "__ns:=/arm", "--params-file",
    ...     "a.yaml", "-p", "degree:=2", "--", "x", "--ros-args", "--params-file", "b.yaml"])
    >>> ros.params_files, ros.namespace, ros.node_name
    (('a.yaml', 'b.yaml'), '/arm', 'backlash_identifier')
    """
    files: list[str] = []
    rules: list[tuple[str, str, str]] = []
    namespace = ""
    node_name = NODE_NAME
    inside = False
    items = iter(argv)
    for item in items:
        if item == "--ros-args":
            inside = True
            continue
        if not inside:
            continue
        if item == "--":
            inside = False
            continue
        if item not in _ROS_OPTIONS_WITH_VALUE:
            continue
        value = next(items, "")
        if item == "--params-file":
            files.append(value)
        elif item in ("-p", "--param"):
            target, sep, text = value.partition(":=")
            if sep:  # (rcl refuses a rule without ':=' itself)
                node, _, name = target.rpartition(":")
                rules.append((node, name, text))
        elif item in ("-r", "--remap"):
            source, _, target = value.partition(":=")
            source = source.rsplit(":", 1)[-1]  # node-specific remaps: `name:__ns:=...`
            if source == "__ns":
                namespace = target
            elif source in ("__node", "__name"):
                node_name = target
    return RosArguments(tuple(files), namespace, node_name, tuple(rules))


# --------------------------------------------------------------------------- params YAML


def _flatten(prefix: str, values: Mapping[Any, Any]) -> Iterator[tuple[str, object]]:
    """``{"a": {"b": 1}}`` -> ``("a.b", 1)``: ROS 2 nests dotted parameter names."""
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            yield from _flatten(f"{name}.", value)
        else:
            yield name, value


_TOKEN = re.compile(r"[A-Za-z0-9_]+")


def _section_pattern(key: str, file: Path) -> re.Pattern[str]:
    """The regular expression rcl matches a node's fully qualified name against, for one
    top-level key of a params file.

    rcl puts a ``/`` before a key without one; ``/**`` stands for any number of namespace
    tokens (none included) and ``/*`` for exactly one token. Tokens are alphanumerics and
    ``_``, or a whole ``*`` / ``**``: rcl refuses the file otherwise (``backlash_*``), and so
    does this reader. Checked against rcl on this machine (tests/ros/node/test_parameters.py).
    """
    tokens = key.strip().lstrip("/").split("/")
    regex = ""
    for token in tokens:
        if token == "**":
            regex += "(?:/[A-Za-z0-9_]+)*"
        elif token == "*":
            regex += "/[A-Za-z0-9_]+"
        elif _TOKEN.fullmatch(token):
            regex += "/" + token
        else:
            raise GenBacklashError(
                f"params file {file}: section {key!r} is not a node name ROS 2 accepts "
                "(names of alphanumerics and '_' separated by '/', or a whole '*' or '**'; "
                "e.g. '/**/backlash_identifier')"
            )
    return re.compile(regex)


def _matches(key: str, node_name: str, namespace: str | None, file: Path) -> tuple[bool, bool]:
    """``(applies, specific)``: whether a top-level YAML key applies to the node, and whether
    it is addressed to the node by name (its last token is the node's name, e.g.
    ``backlash_identifier``, ``/arm/backlash_identifier``, ``/**/backlash_identifier``)
    rather than to every node (``/**``, ``/arm/*``).

    With a ``namespace`` the key applies as rcl applies it to the node
    ``/<namespace>/<node_name>`` (``backlash_identifier:`` is ``/backlash_identifier`` and
    does not apply under a namespace; ``/**/backlash_identifier:`` and ``/**:`` do). With
    ``namespace=None`` (tools without a namespace: replay, identify, diagnose) it applies
    when it would in some namespace.
    """
    pattern = _section_pattern(key, file)
    last = key.strip().rstrip("/").rsplit("/", 1)[-1]
    specific = last == node_name
    if namespace is None:
        return specific or last in ("*", "**"), specific
    inner = namespace.strip("/")
    fqn = f"/{inner}/{node_name}" if inner else f"/{node_name}"
    return pattern.fullmatch(fqn) is not None, specific


def read_params_file(
    path: str | Path, node_name: str = NODE_NAME, *, namespace: str | None = None
) -> dict[str, object]:
    """The parameters a ROS 2 params YAML sets for ``node_name``, merged in file order.

    A section applies to the node ``/<namespace>/<node_name>`` as rcl decides it (see
    :func:`_matches`: ``/**``, ``/**/backlash_identifier``, ``/arm/backlash_identifier``,
    ``/arm/*``, ...; ``namespace=None``: in any namespace); each holds ``ros__parameters``
    (nested keys are joined with dots, as ROS does). Later sections override earlier ones.
    Parameters every node has (``use_sim_time``, ``qos_overrides.*``) are left out. Names
    from sections addressed to every node (``/**``) that this node does not know are
    ignored (they may be meant for other nodes); names in a section that names the node are
    kept, so that :func:`load_params_file` reports them.
    """
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as err:
        raise GenBacklashError(f"cannot read params file {file}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise GenBacklashError(f"params file {file} is not UTF-8 text: {err}") from err
    import yaml  # here: a replay without a params file does not pay for the import

    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as err:
        where = getattr(err, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        # the parser's problem alone: its message also quotes the line over several lines
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise GenBacklashError(f"params file {file} is not valid YAML{line}: {problem}") from err
    if document is None:
        return {}
    if not isinstance(document, Mapping):
        raise GenBacklashError(
            f"params file {file} must map node names to 'ros__parameters', got "
            f"{type(document).__name__}"
        )
    merged: dict[str, object] = {}
    for key, section in document.items():
        applies, specific = _matches(str(key), node_name, namespace, file)
        if not applies:
            continue
        if not isinstance(section, Mapping) or "ros__parameters" not in section:
            raise GenBacklashError(
                f"params file {file}: section {key!r} must hold a 'ros__parameters' mapping"
            )
        params = section["ros__parameters"]
        if params is None:
            continue
        if not isinstance(params, Mapping):
            raise GenBacklashError(
                f"params file {file}: {key!r} ros__parameters must be a mapping of names"
            )
        for name, value in _flatten("", params):
            if name in _STANDARD or name.startswith(_STANDARD_PREFIXES):
                continue
            if specific or name in _SPECS or is_joint_parameter(name):
                merged[name] = value
    return merged


def load_params_file(
    path: str | Path, node_name: str = NODE_NAME, *, namespace: str | None = None
) -> NodeParameters:
    """:class:`NodeParameters` from a standard ROS 2 params YAML (see :func:`read_params_file`).

    Unknown names in a section naming the node and invalid values are errors naming the
    file. Both transports read a params file with this function (the rclpy node before rcl
    does), so a file means the same to both: the same sections apply under the same
    namespace, a whole number is taken for a double (``publish_rate: 10``), and a value out
    of range stops the node with the same one-line reason.
    """
    return _params_from_file(path, read_params_file(path, node_name, namespace=namespace))


def _params_from_file(path: str | Path, values: Mapping[str, object]) -> NodeParameters:
    try:
        return NodeParameters.from_mapping(values)
    except GenBacklashError as err:
        raise GenBacklashError(f"params file {Path(path)}: {err}") from err


# --------------------------------------------------------------------------- command line


def _is_standard(name: str) -> bool:
    return name in _STANDARD or name.startswith(_STANDARD_PREFIXES)


#: Names that select several joints in one node (:mod:`genbacklash_ros.node.joints`).
JOINT_KEYS = ("joints", "command_indices")


def is_joint_parameter(name: str) -> bool:
    """True for ``joints``, ``command_indices`` and a ``<joint>.<name>`` override's *form*
    (:mod:`genbacklash_ros.node.joints` checks the joint against ``joints``).

    >>> is_joint_parameter("joints"), is_joint_parameter("elbow.degree")
    (True, True)
    >>> is_joint_parameter("elbow.degre"), is_joint_parameter("degree")
    (False, False)
    """
    if name in JOINT_KEYS:
        return True
    joint, dot, rest = name.rpartition(".")
    return bool(dot) and bool(joint) and rest in _SPECS


def _close_matches(name: str) -> str:
    close = difflib.get_close_matches(name, list(_SPECS), n=3, cutoff=0.6)
    return f"close matches: {', '.join(close)}" if close else "no close match"


def _unknown_name(name: str, option: str = "--param") -> str:
    text = f"{option}: unknown parameter {name!r} ({_close_matches(name)})"
    return text + ("; --list-params prints all names" if option == "--param" else "")


def _yaml_value(item: str, text: str) -> object:
    """``text`` read as the YAML scalar a params file would hold; empty: the empty string."""
    if not text.strip():
        return ""
    import yaml

    try:
        value: object = yaml.safe_load(text)
    except yaml.YAMLError as err:
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise GenBacklashError(f"--param {item}: the value is not valid YAML ({problem})") from err
    return value


def parse_param_overrides(items: Iterable[str]) -> dict[str, object]:
    """``NAME=VALUE`` items of ``--param`` -> ``{name: value}``, values not yet validated.

    VALUE is read as a YAML scalar, as a params file holds it (``2``, ``recursive``,
    ``false``, ``0.3``, ``.inf``); an empty VALUE is the empty string. Unknown names are an
    error listing the close matches; the standard ``use_sim_time`` / ``qos_overrides.*`` are
    accepted, as in a params file. Giving one name twice with different values is an error.

    >>> parse_param_overrides(["degree=2", "method=recursive", "compensate=false"])
    {'degree': 2, 'method': 'recursive', 'compensate': False}
    >>> parse_param_overrides(["degre=2"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: --param: unknown parameter 'degre' (close ...
    """
    values: dict[str, object] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise GenBacklashError(
                f"--param takes NAME=VALUE (e.g. --param degree=2), got {item!r}"
            )
        if name not in _SPECS and not _is_standard(name):
            raise GenBacklashError(_unknown_name(name))
        value = _yaml_value(item, text)
        if name in values and (type(values[name]), values[name]) != (type(value), value):
            raise GenBacklashError(
                f"--param {name} is given twice with different values "
                f"({values[name]!r} and {value!r}); give it once"
            )
        values[name] = value
    return values


def _option_name(name: str) -> str:
    return "--" + name.replace("_", "-")


def _as_typed(value: object) -> str:
    """A value as it is written on a command line (``''`` for the empty string)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str) and (not value or value != value.strip()):
        return repr(value)
    return str(value)


def command_line_parameters(
    params_file: str | Path | None,
    overrides: Mapping[str, object],
    options: Mapping[str, object] | None = None,
) -> tuple[NodeParameters, dict[str, object]]:
    """The node parameters a command line asks for, and the names it sets.

    Precedence: defaults < ``params_file`` < ``overrides`` (``--param``, from
    :func:`parse_param_overrides`). ``options`` are a command's own options for parameters of
    the same name (``--degree``, ``--joint``, ...; None: not given): the command applies them
    over the params file itself, and one given both ways must agree with ``--param`` (an error
    otherwise, never a silent choice). The file and the overrides are validated by
    :meth:`NodeParameters.from_mapping`, with the params file's error text (prefixed by the
    file, or by ``--param``).

    Returns
    -------
    params : NodeParameters
        Defaults, updated by the params file, then by ``--param``.
    given : dict
        Name -> value of every parameter the params file or ``--param`` sets (after
        ``--param``; standard ROS ones such as ``use_sim_time`` included, unvalidated).
    """
    file_values = read_params_file(params_file) if params_file else {}
    if params_file:
        _check_joint_values(params_file, file_values)
    node_values = {k: v for k, v in file_values.items() if not is_joint_parameter(k)}
    if params_file:
        _params_from_file(params_file, node_values)
    own = {k: v for k, v in overrides.items() if k in _SPECS}
    try:
        params = NodeParameters.from_mapping({**node_values, **own})
    except GenBacklashError as err:
        raise GenBacklashError(f"--param: {err}") from err
    for name, value in (options or {}).items():
        if value is None or name not in own:
            continue
        chosen = getattr(params, name)
        if chosen != value or isinstance(chosen, bool) != isinstance(value, bool):
            raise GenBacklashError(
                f"{_option_name(name)} {_as_typed(value)} and --param "
                f"{name}={_as_typed(chosen)} disagree; give {name} once"
            )
    given: dict[str, object] = {**file_values, **overrides}
    for name in given:
        if name in _SPECS:
            given[name] = getattr(params, name)
    return params, given


def _check_joint_values(path: str | Path, values: Mapping[str, object]) -> None:
    """A node params file's ``joints``, ``command_indices`` and ``<joint>.<name>`` checked as
    the node checks them (the commands take their joints from ``--joint``, not from these)."""
    if not any(is_joint_parameter(k) for k in values):
        return
    from genbacklash_ros.node.joints import JointSet  # (joints imports this module)

    try:
        JointSet.from_mapping(values)
    except GenBacklashError as err:
        raise GenBacklashError(f"params file {Path(path)}: {err}") from err


def parameter_table() -> str:
    """The parameter reference as a Markdown table (for docs/node.md).

    >>> print(parameter_table().splitlines()[0])
    | name | type | default | range | unit | description |
    """
    lines = [
        "| name | type | default | range | unit | description |",
        "|---|---|---|---|---|---|",
    ]
    for spec in PARAMETER_SPECS:
        default = spec.default
        if isinstance(default, bool):
            shown = "true" if default else "false"
        elif isinstance(default, float):
            shown = _show(default)
        elif isinstance(default, str):
            shown = f"`{default!r}`" if default == "" else f"`{default}`"
        else:
            shown = str(default)
        note = " Restarts identification." if spec.restarts else ""
        lines.append(
            f"| `{spec.name}` | {spec.type} | {shown} | {spec.range_text} | {spec.unit} | "
            f"{spec.description}{note} |"
        )
    return "\n".join(lines)
