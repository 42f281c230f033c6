"""The table of the node's parameters (:data:`PARAMETER_SPECS`: type, default, description,
unit, range or choices), the names it knows (close matches for a misspelt one, the
per-joint forms) and the reference table docs/node.md renders from it."""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Literal, TypeAlias

from genbacklash_core import (
    CompensatorOptions,
    GenBacklashError,
    RecursiveSettings,
    WindowedSettings,
)
from genbacklash_ros.node.messages import COMMAND_TYPES, ENCODER_TYPES

NODE_NAME = "backlash_identifier"

ParameterType: TypeAlias = Literal["string", "integer", "double", "bool"]
ParameterValue: TypeAlias = str | int | float | bool

# parameters every ROS 2 node has; a params file may set them, the transports handle them
STANDARD_NAMES = ("use_sim_time",)
STANDARD_PREFIXES = ("qos_overrides.",)

WINDOWED_DEFAULTS = WindowedSettings()
RECURSIVE_DEFAULTS = RecursiveSettings()
COMPENSATOR_DEFAULTS = CompensatorOptions()


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
        WINDOWED_DEFAULTS.window,
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
        RECURSIVE_DEFAULTS.forgetting,
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
        COMPENSATOR_DEFAULTS.gate_low,
        "Estimate confidence at or below which the command passes through uncorrected.",
        0.0,
        1.0,
    ),
    ParameterSpec(
        "gate_high",
        "double",
        COMPENSATOR_DEFAULTS.gate_high,
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

SPECS_BY_NAME: dict[str, ParameterSpec] = {spec.name: spec for spec in PARAMETER_SPECS}

#: Parameters checked against each other: ``u_min < u_max``, ``gate_low <= gate_high``.
PAIRS: tuple[tuple[str, str], ...] = (("u_min", "u_max"), ("gate_low", "gate_high"))


def pair_problem(low_name: str, low: object, high_name: str, high: object) -> str | None:
    """Why a pair of values is inconsistent, or None."""
    if not isinstance(low, int | float) or not isinstance(high, int | float):
        return None  # the value checks report these
    if low_name == "u_min" and not low < high:
        return f"parameter 'u_min' ({low:g}) must be below 'u_max' ({high:g})"
    if low_name != "u_min" and low > high:
        return f"parameter {low_name!r} ({low:g}) must not exceed {high_name!r} ({high:g})"
    return None


def is_standard(name: str) -> bool:
    return name in STANDARD_NAMES or name.startswith(STANDARD_PREFIXES)


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
    return bool(dot) and bool(joint) and rest in SPECS_BY_NAME


def close_matches(name: str) -> str:
    close = difflib.get_close_matches(name, list(SPECS_BY_NAME), n=3, cutoff=0.6)
    return f"close matches: {', '.join(close)}" if close else "no close match"


def unknown_name(name: str, option: str = "--param") -> str:
    text = f"{option}: unknown parameter {name!r} ({close_matches(name)})"
    return text + ("; --list-params prints all names" if option == "--param" else "")


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
