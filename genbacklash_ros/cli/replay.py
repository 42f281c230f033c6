"""``genbacklash replay`` (and the bag options of ``simulate`` and ``identify``).

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parser`. Exit codes follow the
command line's: 0 when the whole bag was replayed, 2 for bad input -- including a bag found
corrupt or truncated part-way (the output written so far is closed and stays readable).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from genbacklash_core import GenBacklashError
from genbacklash_core.measured import OfflineBaseline
from genbacklash_core.scenarios import PHASE_KINDS
from genbacklash_ros.bags.bagio import BagError, node_outputs, read_aligned
from genbacklash_ros.bags.csvio import Series, dropped_note, read_series_csv
from genbacklash_ros.bags.replay import OUTPUT_TOPICS, ReplayResult, replay
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, MOTOR_TOPIC, SimulatedBag
from genbacklash_ros.cli.joints import ListOption, per_joint
from genbacklash_ros.cli.start import add_checkpoint_option, write_start
from genbacklash_ros.node.parameters import (
    PARAMETER_SPECS,
    NodeParameters,
    command_line_parameters,
    parameter_table,
    parse_param_overrides,
)
from genbacklash_ros.node.tracking_stage import record_baseline
from genbacklash_ros.physics.variants import DEFAULT_BANDWIDTH, VARIANTS

__all__ = [
    "BATCH_PARAMETERS",
    "CommandParameters",
    "add_bag_input_options",
    "add_node_parameter_options",
    "add_parser",
    "add_simulate_bag_options",
    "batch_parameters",
    "cmd_replay",
    "is_bag",
    "load_bag_series",
    "node_parameters",
    "simulate_bag",
]

EXIT_OK = 0
EXIT_BAD_INPUT = 2

_DESCRIPTION = f"""\
Replay a recorded bag through the backlash_identifier node's pipeline, offline.

BAG is a rosbag2 directory (metadata.yaml + .mcap) or a bare .mcap file. The messages of
--command and --encoder are fed in log-time order to the same pipeline the live node runs
(the log time is the receive time), with the node's parameters: the defaults, then
--params-file, then --param NAME=VALUE and the options --model --degree --na --nb --method
--joint --command-index (an option and a --param for the same parameter must agree). The
message types come from the bag; a replay identifies from the recorded command and neither
reads nor writes the node's checkpoint_file: --checkpoint FILE writes the final estimate
there, in the checkpoint format the node starts from (give the node checkpoint_file=FILE and
the same model, degree, na, nb). --list-params prints every parameter with its range. OUT
is a new rosbag2 MCAP directory with the two input topics plus what the node publishes:
{OUTPUT_TOPICS["estimate"]}, {OUTPUT_TOPICS["compensated_command"]} (one per command) and
{OUTPUT_TOPICS["diagnostics"]}; rosbags, mcap-ros2-support and Foxglove read it.

Prints the final estimate (or --json) and writes an HTML report with plots when --report is
given. A progress bar runs on stderr. A bag found corrupt or truncated part-way stops the
replay there: OUT keeps what was written (closed properly), the reason goes to stderr and
the exit status is 2.
"""

_EPILOG = """\
examples:
  genbacklash replay bags/drivetrain --command /command --encoder /encoder --joint drive_joint \\
      -o out --report rep
  genbacklash replay run.mcap --command /cmd --encoder /joint_states --joint knee \\
      --model cascade --na 2 --nb 2 -o out --json
  genbacklash replay run --command /cmd --encoder /enc --params-file config/params.yaml -o out
  genbacklash replay run --command /cmd --encoder /enc -o out --param method=recursive \\
      --param forgetting=0.999 --param gate_low=0.3
"""


def add_bag_input_options(parser: argparse.ArgumentParser, *, required: bool) -> None:
    """``--command TOPIC --encoder TOPIC [--joint NAME] [--command-index I]``.

    Stored as ``command_topic``, ``encoder_topic``, ``joint``, ``command_index`` (``command``
    is the sub-command's name).
    """
    parser.add_argument(
        "--command",
        metavar="TOPIC",
        dest="command_topic",
        required=required,
        help="bag input: command topic (std_msgs/Float64, std_msgs/Float64MultiArray or "
        "sensor_msgs/JointState); a topic the bag lacks stops with the bag's topics and types",
    )
    parser.add_argument(
        "--encoder",
        metavar="TOPIC",
        dest="encoder_topic",
        required=required,
        help="bag input: encoder topic (sensor_msgs/JointState or std_msgs/Float64)",
    )
    parser.add_argument(
        "--joint",
        metavar="NAME",
        default=None,
        action=ListOption,
        help="bag input: joint name in JointState messages (needed when they hold several "
        "joints; a name the bag lacks stops with the names it has). Repeat it (or give "
        "a,b,c) for several joints from one bag: each is run on its own, --json prints an "
        "object keyed by joint, output directories get a sub-directory per joint",
    )
    parser.add_argument(
        "--command-index",
        metavar="I",
        type=int,
        default=None,
        action=ListOption,
        help="bag input: element of a Float64MultiArray command (default 0; one beyond the "
        "array stops with its length); with several --joint, one per joint in the same order",
    )
    parser.add_argument(
        "--motor-encoder",
        metavar="TOPIC",
        dest="motor_topic",
        default=None,
        help="bag input: a motor encoder's topic (sensor_msgs/JointState or std_msgs/Float64; "
        "dual encoders, e.g. an ODrive's or moteus's own): its reading, paired with the "
        "encoder reading of the same stamp, is the gear's input instead of the command "
        "(the node's gear_input motor_encoder; no settle_time); the commands are still read "
        "and compensated",
    )
    parser.add_argument(
        "--motor-joint",
        metavar="NAME",
        dest="motor_joint",
        default=None,
        help="bag input: joint name in the motor encoder's JointState (default: the "
        "parameter motor_joint, else --joint)",
    )


def motor_selection(
    args: argparse.Namespace, params: NodeParameters | None, joint: str
) -> tuple[str | None, str]:
    """The motor encoder's topic (None: the command is the gear's input) and joint of a bag
    command line: ``--motor-encoder``, ``--motor-joint`` (else the parameter ``motor_joint``,
    else ``joint``). Parameters that say ``gear_input`` motor_encoder need the topic."""
    topic = getattr(args, "motor_topic", None)
    chosen = getattr(args, "motor_joint", None)
    if chosen is None:
        chosen = params.motor_joint if params is not None else ""
    if topic is None and params is not None and params.motor_input:
        raise BagError(
            "the parameters say gear_input motor_encoder: name the motor encoder's topic with "
            "--motor-encoder TOPIC"
        )
    if topic is None and getattr(args, "motor_joint", None) is not None:
        raise BagError("--motor-joint needs --motor-encoder TOPIC (the motor encoder's topic)")
    return topic, chosen or joint


def load_bag_series(
    args: argparse.Namespace, params: NodeParameters | None = None, *, bridge: bool = False
) -> Series:
    """The aligned (u, y) samples of a bag given by ``args.data`` and the bag options.

    One sample per encoder message; the command held (the pipeline's alignment) and the
    sample rule's ``breaks``, with lost readings along monotone commands bridged when
    ``bridge`` (a backlash alone). ``joint`` and ``command_index`` come from the options,
    else from ``params``.
    """
    if not args.command_topic or not args.encoder_topic:
        raise BagError(
            f"{args.data} is a bag: say which topics to use with --command TOPIC and "
            "--encoder TOPIC"
        )
    joint = args.joint if args.joint is not None else params.joint if params else ""
    index = args.command_index
    if index is None:
        index = params.command_index if params else 0
    motor_topic, motor_joint = motor_selection(args, params, joint)
    series = read_aligned(
        args.data,
        args.command_topic,
        args.encoder_topic,
        joint=joint,
        command_index=index,
        bridge=bridge,
        settle_ns=params.settle_ns if params is not None else 0,
        servo=params.servo() if params is not None else None,
        motor_topic=motor_topic,
        motor_joint=motor_joint,
        # the record's tracking without compensation: only a checkpoint stores it
        baseline=bool(getattr(args, "checkpoint", None)),
    )
    if series.skipped:
        print(
            f"skipped {series.skipped} encoder samples before the first command",
            file=sys.stderr,
        )
    t = (series.t - series.t[0]) / 1e9 if series.t.size else None  # seconds from the first
    return Series(
        u=series.u,
        y=series.y,
        t=t,
        breaks=series.breaks,
        servo=series.servo,
        servo_fit=series.servo_fit,
        baseline=series.baseline,
    )


def servo_dict(series: Series) -> dict[str, object]:
    """The servo model of the rows for the JSON: its values, and how it was estimated."""
    assert series.servo is not None  # the caller checked
    out: dict[str, object] = dict(series.servo.to_dict())
    out["estimated"] = series.servo_fit is not None
    if series.servo_fit is not None:
        fit = series.servo_fit
        out.update(misfit=fit.misfit, misfit_without=fit.none_misfit, candidates=fit.evaluated)
    return out


def servo_line(series: Series) -> str:
    """One line on the servo model of the rows (text output)."""
    assert series.servo is not None  # the caller checked
    servo = series.servo
    how = "estimated with the play" if series.servo_fit is not None else "given"
    return (
        f"servo: dead time {1e3 * servo.dead_time:.2f} ms, lag {1e3 * servo.time_constant:.2f} "
        f"ms ({how}); the play is on the servo's output"
    )


BAG_SUFFIXES = (".mcap", ".db3")


def is_bag(data: str | Path) -> bool:
    """Whether ``data`` is read as a bag (a directory, ``.mcap`` or ``.db3``), not a CSV."""
    file = Path(data)
    return file.is_dir() or file.suffix.lower() in BAG_SUFFIXES


def load_series(
    args: argparse.Namespace, params: NodeParameters | None = None, *, bridge: bool = False
) -> Series:
    """The (u, y) data of ``args.data``: a CSV file, or a bag with the bag options.

    Shared by ``identify`` and ``diagnose``; ``params`` supply ``joint`` and
    ``command_index`` where the options do not. A CSV row that is not all finite numbers
    stops with its line number, or with ``--drop-nonfinite`` is dropped and named on stderr.
    A bag and a CSV with ``t`` go through the same row rules
    (:func:`~genbacklash_ros.node.sample_rule.select_rows`: ``bridge``, ``settle_time``).
    """
    file = Path(args.data)
    if is_bag(file):
        return load_bag_series(args, params, bridge=bridge)
    if getattr(args, "motor_topic", None) is not None:
        raise GenBacklashError(
            f"--motor-encoder is a bag option; {file} is a CSV: name its motor column "
            "'motor' instead of 'u' (genbacklash readings --motor-encoder writes one)"
        )
    if not file.exists():
        raise GenBacklashError(f"{file} does not exist")
    drop = bool(getattr(args, "drop_nonfinite", False))
    # a CSV of readings (with t) takes the rows a bag of them would: the same rules
    series = read_series_csv(
        file,
        bad_rows="drop" if drop else "raise",
        bridge=bridge,
        settle_ns=params.settle_ns if params is not None else 0,
        servo=params.servo() if params is not None else None,
    )
    if series.dropped:  # --drop-nonfinite: say what went, never silently
        print(f"genbacklash {args.command}: {dropped_note(file, series.dropped)}", file=sys.stderr)
    return series


# --------------------------------------------------------------------------- node parameters

# what identify and diagnose use of the node's parameters (the rest is validated, then ignored)
BATCH_PARAMETERS = ("model", "degree", "na", "nb")
# ... and the rule for which samples are rows (genbacklash_core.settling), on bags and on
# a CSV with t (the same rule: genbacklash_ros.node.sample_rule.select_rows)
_ROW_PARAMETERS = ("settle_time", "servo_model", "servo_dead_time", "servo_time_constant")
_BAG_PARAMETERS = ("joint", "command_index", "gear_input", "motor_joint")
# set by the replay itself (genbacklash_ros.bags.replay): the bag's message types, the recorded
# command, no checkpoint
_SET_BY_REPLAY = (
    "command_type",
    "encoder_type",
    "motor_encoder_type",
    "compensation_in_loop",
    "checkpoint_file",
)


def batch_parameters(data: str | Path) -> tuple[str, ...]:
    """The node parameters ``identify`` / ``diagnose`` use for ``data`` (a CSV or a bag)."""
    return BATCH_PARAMETERS + _ROW_PARAMETERS + (_BAG_PARAMETERS if is_bag(data) else ())


class _ListParams(argparse.Action):
    """``--list-params``: print the parameter table and exit 0 (like ``--help``)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.update(nargs=0, default=argparse.SUPPRESS)
        super().__init__(option_strings, argparse.SUPPRESS, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        try:
            print(parameter_table(), flush=True)
        except BrokenPipeError:  # `--list-params | head`: stop quietly, as main() does
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            parser.exit(141)
        parser.exit(0)


def add_node_parameter_options(
    parser: argparse.ArgumentParser, *, used: str, params_file: bool = True
) -> None:
    """``[--params-file FILE] --param NAME=VALUE ... --list-params``; ``used`` says (for the
    help) which parameters the command uses."""
    if params_file:
        parser.add_argument(
            "--params-file",
            metavar="FILE",
            help="the node's ROS 2 parameters YAML (backlash_identifier or /** section), "
            "validated as by 'genbacklash node'; options and --param override it",
        )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a node parameter, repeatable, e.g. --param degree=2 --param "
        "method=recursive; VALUE is read as in a params file (2, recursive, false, 0.3, .inf) "
        "and validated the same way; it overrides --params-file, and an option for the same "
        f"parameter must agree with it. {used} --list-params prints every parameter",
    )
    parser.add_argument(
        "--list-params",
        action=_ListParams,
        help="print the node's parameters (type, default, range, unit, meaning) and exit",
    )


class CommandParameters(NamedTuple):
    """The node parameters of one command line (see :func:`node_parameters`)."""

    params: NodeParameters
    given: dict[str, object]
    overrides: dict[str, object]


def node_parameters(args: argparse.Namespace, used: Collection[str]) -> CommandParameters:
    """Defaults < ``--params-file`` < ``--param`` (validated as a params file is), checked
    against the command's options of the same names (``--degree`` ...: they must agree with
    ``--param``).

    Parameters set (by the file or ``--param``) to other than their defaults that the command
    does not use (not in ``used``) are named in one note on stderr.
    """
    overrides = parse_param_overrides(args.param)
    options = {s.name: getattr(args, s.name, None) for s in PARAMETER_SPECS}
    params, given = command_line_parameters(args.params_file, overrides, options)
    # the command's own options (--degree, --na, --nb, --joint, --command-index ...) take
    # the node parameters' ranges: the same check for every command, before any work
    for name, value in options.items():
        if value is None:
            continue
        try:
            params.replace(**{name: value})
        except GenBacklashError as err:
            raise GenBacklashError(f"--{name.replace('_', '-')} {value}: {err}") from err
    defaults = {s.name: s.default for s in PARAMETER_SPECS}
    unused = [
        name
        for name, value in given.items()
        if name not in used and (name not in defaults or value != defaults[name])
    ]
    if unused:
        print(
            f"genbacklash {args.command}: note: {', '.join(unused)} not used by "
            f"{args.command} (validated, ignored)",
            file=sys.stderr,
        )
    return CommandParameters(params, given, overrides)


# --------------------------------------------------------------------------- simulate


OPERATION_SCENARIOS = PHASE_KINDS
"""``--scenario`` values that simulate a drivetrain in normal operation (issue 12)."""

_SCENARIO_HELP = """\
Bag scenarios (--bag DIR). 'drivetrain' is the paper-style random input: a new uniform
command in (-2, 2) every 1-10 ms, Example 1's branches, white noise at SNR 25. The others
are a drivetrain in normal operation (genbacklash_core.scenarios): 100 Hz position commands
held by the servo, a 1 kHz encoder quantised to 4096 counts/rev, stamped at its jittered
sampling instants, some readings lost; a few degrees of play with mildly curved branches.
'operation': point-to-point moves with dwells and jogs; 'one_way': a slow traverse in one
direction (one branch only); 'pick_and_place': the same two targets again and again;
'sine_sweep': a sine over most of the travel, 0.05 -> 0.5 Hz. --phases chains them. Every
bag stores its truth (models at start and end, dead zones over time) in its metadata
(custom_data 'genbacklash.truth'), which 'replay --report' draws.
"""


PHYSICS_VARIANTS = tuple(VARIANTS)
"""``--physics`` values (:data:`genbacklash_ros.physics.variants.VARIANTS`)."""

_PHYSICS_HELP = """\
--physics VARIANT runs the operation scenario's motion, clocks and encoder on a drivetrain
simulated by MuJoCo (pip install 'genbacklash[physics]'): a position servo (--bandwidth, 10 N m)
drives a rotor whose pin sits in a slot of the load with 4 degrees of play. near_ideal: a
stiff, frictional load; coasting: a load that coasts into the play; compliant: a spring
coupling after the play; gravity: gravity holds the load on one flank over part of the
travel. The truth in the metadata is the quasi-static characteristic measured by a slow sweep
in the simulator; the geometric play and every physics parameter are stored with it.
"""


def add_simulate_bag_options(parser: argparse.ArgumentParser) -> None:
    """The bag options of ``simulate``: ``--bag DIR``, ``--scenario``, ``--phases``,
    ``--duration``, ``--wear``, ``--loss``, ``--noise``, ``--straight``, ``--physics``,
    ``--bandwidth``, ``--motor-encoder``."""
    parser.add_argument(
        "--bag",
        metavar="DIR",
        help=f"write a rosbag2 MCAP bag (a new directory): {COMMAND_TOPIC} "
        f"(std_msgs/Float64MultiArray, element 0 the drivetrain) and {ENCODER_TOPIC} "
        "(sensor_msgs/JointState, joint drive_joint) at 1 kHz; with --example, one command "
        "per sample",
    )
    group = parser.add_argument_group("bag scenarios", _SCENARIO_HELP)
    group.add_argument(
        "--scenario",
        choices=("drivetrain", *OPERATION_SCENARIOS),
        help="what the drivetrain does (needs --bag): drivetrain (paper-style random input), "
        "operation, one_way, pick_and_place, sine_sweep",
    )
    group.add_argument(
        "--phases",
        metavar="KIND:SECONDS[,...]",
        help="chain operation scenarios, run one after the other, e.g. "
        "'operation:30,one_way:120,operation:30' (needs --bag; instead of --scenario and "
        "--duration)",
    )
    group.add_argument(
        "--duration",
        type=float,
        metavar="SECONDS",
        default=None,
        help="record length in seconds (default: 60 for the operation scenarios, 12 for "
        "drivetrain)",
    )
    group.add_argument(
        "--wear",
        type=float,
        metavar="FRACTION",
        default=None,
        help="growth of both dead zones c_L, c_R over the record, linear in time "
        "(0.2: 20%% wider at the end; default 0.2)",
    )
    group.add_argument(
        "--loss",
        type=float,
        metavar="P",
        default=None,
        help="operation scenarios: probability that an encoder reading is lost (absent from "
        "the bag), in [0, 0.95] (default 0.02)",
    )
    group.add_argument(
        "--noise",
        type=float,
        metavar="RAD",
        default=None,
        help="operation scenarios: standard deviation of white encoder noise before "
        "quantisation, radians (default 0: quantisation only)",
    )
    group.add_argument(
        "--straight",
        action="store_true",
        help="operation scenarios: straight branches (the ideal backlash, same play) instead "
        "of mildly curved ones",
    )
    physics = parser.add_argument_group("physics drivetrains", _PHYSICS_HELP)
    physics.add_argument(
        "--physics",
        metavar="VARIANT",
        choices=PHYSICS_VARIANTS,
        default=None,
        help="simulate the operation scenario on a physics drivetrain: "
        f"{', '.join(PHYSICS_VARIANTS)} (needs --bag; takes --duration (default 40) or "
        "--phases, --loss, --noise)",
    )
    physics.add_argument(
        "--bandwidth",
        type=float,
        metavar="HZ",
        default=None,
        help=f"--physics: the servo's bandwidth, Hz (default {DEFAULT_BANDWIDTH:g})",
    )
    physics.add_argument(
        "--motor-encoder",
        action="store_true",
        help=f"--physics: also write the rotor's position on {MOTOR_TOPIC} "
        "(sensor_msgs/JointState, joint drive_joint)",
    )


_PHASES_FORM = "expected KIND:SECONDS[,KIND:SECONDS...] with KIND one of " + ", ".join(
    OPERATION_SCENARIOS
)


def _record_phases(
    args: argparse.Namespace, kind: str, *, default: float, longest: float = math.inf
) -> tuple[tuple[str, float], ...]:
    """The motion of a simulated record: ``--phases``, or ``--duration`` seconds of ``kind``
    (``default`` when not given, at most ``longest``)."""
    if args.phases:
        if args.duration is not None:
            raise GenBacklashError("--phases sets the length of the record: drop --duration")
        return parse_phases(args.phases)
    duration = default if args.duration is None else args.duration
    if not (math.isfinite(duration) and 0 < duration <= longest):
        limit = "be > 0" if math.isinf(longest) else f"lie in (0, {longest:g}]"
        raise GenBacklashError(f"--duration must {limit} seconds, got {duration:g}")
    return ((kind, float(duration)),)


def parse_phases(text: str) -> tuple[tuple[str, float], ...]:
    """``"operation:30,one_way:120"`` -> ``(("operation", 30.0), ("one_way", 120.0))``.

    Raises :class:`GenBacklashError` (one line) for anything else.
    """
    import math

    phases: list[tuple[str, float]] = []
    for item in text.split(","):
        kind, sep, seconds = item.strip().partition(":")
        if not sep:
            raise GenBacklashError(
                f"bad --phases {text!r}: {item.strip()!r} has no ':SECONDS'; {_PHASES_FORM}"
            )
        kind = kind.strip()
        if kind not in OPERATION_SCENARIOS:
            raise GenBacklashError(f"bad --phases {text!r}: unknown phase {kind!r}; {_PHASES_FORM}")
        try:
            value = float(seconds)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise GenBacklashError(
                f"bad --phases {text!r}: the {kind} phase needs a length in seconds > 0, got "
                f"{seconds.strip()!r}"
            )
        phases.append((kind, value))
    return tuple(phases)


def _write_operation_bag(args: argparse.Namespace) -> SimulatedBag:
    """An operation scenario (``--scenario operation|...`` or ``--phases``) as a bag."""
    import math

    from genbacklash_ros.bags.simbags import operation_settings, write_operation_bag

    if args.snr is not None or args.samples is not None:
        raise GenBacklashError(
            "--snr and --samples apply to --example and --scenario drivetrain; the operation "
            "scenarios take --duration and --noise"
        )
    phases = _record_phases(args, args.scenario, default=60.0)
    wear = 0.2 if args.wear is None else args.wear
    loss = 0.02 if args.loss is None else args.loss
    noise = 0.0 if args.noise is None else args.noise
    if not 0.0 <= wear <= 10.0:
        raise GenBacklashError(f"--wear must lie in [0, 10], got {wear:g}")
    if not 0.0 <= loss <= 0.95:
        raise GenBacklashError(f"--loss must lie in [0, 0.95], got {loss:g}")
    if not (math.isfinite(noise) and noise >= 0.0):
        raise GenBacklashError(f"--noise must be >= 0 radians, got {noise:g}")
    settings = operation_settings(phases, wear=wear, loss=loss, noise=noise, straight=args.straight)
    return write_operation_bag(args.bag, settings, args.seed)


def _write_physics_bag(args: argparse.Namespace) -> SimulatedBag:
    """``--physics VARIANT``: the operation scenario on a physics drivetrain as a bag."""
    import math

    from genbacklash_ros.physics import require_mujoco

    if not args.bag:
        raise GenBacklashError("--physics writes a bag: give --bag DIR")
    clashing = [
        name
        for name, given in (
            ("-o", bool(args.output)),
            ("--example", args.example is not None),
            ("--scenario", bool(args.scenario)),
            ("--wear", args.wear is not None),
            ("--straight", args.straight),
            ("--snr", args.snr is not None),
            ("--samples", args.samples is not None),
        )
        if given
    ]
    if clashing:
        raise GenBacklashError(
            f"--physics does not take {', '.join(clashing)} (it takes --duration or --phases, "
            "--loss, --noise, --bandwidth, --motor-encoder, --seed)"
        )
    phases = _record_phases(args, "operation", default=40.0, longest=3600.0)
    loss = 0.02 if args.loss is None else args.loss
    noise = 0.0 if args.noise is None else args.noise
    if not 0.0 <= loss <= 0.95:
        raise GenBacklashError(f"--loss must lie in [0, 0.95], got {loss:g}")
    if not (math.isfinite(noise) and noise >= 0.0):
        raise GenBacklashError(f"--noise must be >= 0 radians, got {noise:g}")
    from genbacklash_core.scenarios import OperationSettings
    from genbacklash_ros.physics.variants import BANDWIDTH_RANGE, variant

    low, high = BANDWIDTH_RANGE
    if args.bandwidth is not None and not low <= args.bandwidth <= high:  # NaN fails too
        raise GenBacklashError(
            f"--bandwidth must lie in [{low:g}, {high:g}] Hz, got {args.bandwidth:g}"
        )
    params = variant(args.physics, bandwidth=args.bandwidth)
    require_mujoco()
    from genbacklash_ros.physics.bag import write_physics_bag

    settings = OperationSettings(phases=phases, loss=loss, noise=noise)
    return write_physics_bag(
        args.bag, params, settings, args.seed, motor_encoder=args.motor_encoder
    )


def simulate_bag(args: argparse.Namespace) -> int:
    """Write the bag ``simulate`` asked for (``--bag`` with ``--example``, ``--scenario``,
    ``--phases`` or ``--physics``)."""
    import math

    from genbacklash_ros.bags.simbags import write_drivetrain_bag, write_example_bag

    if getattr(args, "physics", None):
        physics = _write_physics_bag(args)
        topics = ", ".join(f"{t} ({m}, {n})" for t, (m, n) in physics.counts.items())
        print(f"wrote {physics.path}: {physics.description}; {topics}", file=sys.stderr)
        return EXIT_OK
    phases = getattr(args, "phases", None)
    what = "--phases" if phases else "--scenario"
    if not args.bag:
        raise GenBacklashError(f"{what} writes a bag: give --bag DIR")
    if args.output:
        raise GenBacklashError("give either -o FILE.csv or --bag DIR, not both")
    if args.example is not None and (args.scenario or phases):
        raise GenBacklashError(f"give either --example or {what}, not both")
    if args.scenario and phases:
        raise GenBacklashError("give either --scenario or --phases, not both")
    operation = bool(phases) or args.scenario in OPERATION_SCENARIOS
    if not operation:
        extra = [
            name
            for name, given in (
                ("--loss", args.loss is not None),
                ("--noise", args.noise is not None),
                ("--straight", args.straight),
            )
            if given
        ]
        if extra:
            raise GenBacklashError(
                f"{', '.join(extra)} appl{'ies' if len(extra) == 1 else 'y'} to the operation "
                f"scenarios (--scenario "
                f"{'|'.join(OPERATION_SCENARIOS)} or --phases)"
            )
    made: SimulatedBag
    if operation:
        made = _write_operation_bag(args)
    elif args.scenario == "drivetrain":
        duration = 12.0 if args.duration is None else args.duration
        wear = 0.2 if args.wear is None else args.wear
        if not (math.isfinite(duration) and duration > 0) or not 0 <= wear <= 10:
            raise GenBacklashError("--duration must be > 0 and --wear in [0, 10]")
        made = write_drivetrain_bag(
            args.bag, seed=args.seed, duration=duration, wear=wear, snr=args.snr or 25.0
        )
    elif args.example is not None:
        if args.duration is not None or args.wear is not None:
            raise GenBacklashError(
                "--duration and --wear apply to --scenario and --phases; --example takes --samples"
            )
        made = write_example_bag(
            args.bag, args.example, seed=args.seed, n_samples=args.samples, snr=args.snr
        )
    else:
        raise GenBacklashError(
            "say what to simulate: --example N, --scenario "
            f"{'|'.join(('drivetrain', *OPERATION_SCENARIOS))} or --phases KIND:SECONDS,..."
        )
    topics = ", ".join(f"{t} ({m}, {n})" for t, (m, n) in made.counts.items())
    print(f"wrote {made.path}: {made.description}; {topics}", file=sys.stderr)
    return EXIT_OK


# --------------------------------------------------------------------------- replay


RAD_PARAMETERS = ("c_left", "c_right")
"""The parameters in the units of u and y: rad on a drivetrain (the slopes have none)."""


def play_line(play: float, std: float) -> str:
    """The play ``c_L + c_R`` with its 2-sigma uncertainty, in rad (``std`` NaN: unknown).

    >>> play_line(0.1034, 0.00025)
    'play c_L + c_R = 0.10340 rad +/- 0.00050 rad (2 sigma)'
    """
    if not math.isfinite(play):
        return "play c_L + c_R: no estimate yet"
    band = f" +/- {2 * std:.5f} rad (2 sigma)" if math.isfinite(std) else ""
    return f"play c_L + c_R = {play:.5f} rad{band}"


def _summary(result: ReplayResult) -> str:
    est = result.estimate
    lines = [f"{'parameter':<12}{'estimate':>12}{'2 sigma':>12}", "-" * 36]
    std = est.std()
    for name, value, sigma in zip(est.names, est.parameters, std, strict=True):
        unit = "  rad" if name in RAD_PARAMETERS else ""
        lines.append(f"{name:<12}{value:>12.5f}{2 * sigma:>12.5f}{unit}")
    lines.append(play_line(*est.play()))
    servo = result.servo
    if servo is not None:  # servo_model: the play is on the servo's modelled output
        if "dead_time" in servo:
            dead, lag = float(servo["dead_time"]), float(servo["time_constant"])  # type: ignore[arg-type]
            lines.append(
                f"servo ({servo['state']}): dead time {1e3 * dead:.2f} ms, lag {1e3 * lag:.2f} ms"
                + (f"; {servo['note']}" if "note" in servo else "")
            )
        else:
            lines.append(f"servo: {servo['state']}")
    stats = result.stats
    dropped = {k: n for k, n in stats.dropped.items() if n}
    rate = result.messages_in / result.seconds if result.seconds > 0 else 0.0
    lines.append(
        f"state {est.state.value} (confidence {est.confidence:.2f}); {est.reason}".rstrip("; ")
    )
    lines.append(
        f"{result.messages_in} messages in ({rate:,.0f}/s), {result.messages_out} written to "
        f"{result.output}; {stats.compensated} compensated commands"
        + (f"; dropped {dropped}" if dropped else "")
    )
    return "\n".join(lines)


def replay_baseline(result: ReplayResult) -> OfflineBaseline | None:
    """The replayed record's tracking without compensation, as the node's judge measures it
    (:func:`~genbacklash_ros.node.tracking_stage.record_baseline` on the recorded commands
    and encoder readings); None when the record may hold compensation: it holds a node's
    outputs (:func:`~genbacklash_ros.bags.bagio.node_outputs`) or was replayed with
    ``compensation_in_loop`` (the recorded command would not be what drove the drivetrain)."""
    if result.params.compensation_in_loop or node_outputs(result.input_topics):
        return None
    h = result.history
    return record_baseline(h.command_t, h.command_raw, h.encoder_t, h.encoder_y)


def cmd_replay(args: argparse.Namespace) -> int:
    """Run ``genbacklash replay``."""
    used = [s.name for s in PARAMETER_SPECS if s.name not in _SET_BY_REPLAY]
    params = node_parameters(args, used).params
    joint = args.joint if args.joint is not None else params.joint
    motor_topic, motor_joint = motor_selection(args, params, joint)
    result = replay(
        args.bag,
        args.output,
        command_topic=args.command_topic,
        encoder_topic=args.encoder_topic,
        motor_topic=motor_topic,
        motor_joint=motor_joint if motor_topic is not None else None,
        params=params,
        joint=args.joint,
        command_index=args.command_index,
        model=args.model,
        degree=args.degree,
        na=args.na,
        nb=args.nb,
        method=args.method,
        progress=not args.no_progress,
        prefetch=not args.no_prefetch,
    )
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(_summary(result))
    if args.checkpoint:
        history = result.history
        times = history.estimate_t or history.encoder_t
        last = times[-1] if times else 0
        write_start(args.checkpoint, result.estimate, last, "replay", replay_baseline(result))
    if args.report:
        from genbacklash_ros.progress import Progress
        from genbacklash_ros.reports.replay import write_report

        with Progress("genbacklash replay: report", enabled=not args.no_progress) as bar:
            index = write_report(result, args.report, progress=bar.set_stage)
        print(f"wrote {index}", file=sys.stderr)
    if result.error:
        print(
            f"genbacklash replay: error: {result.error}; kept {result.output} (a valid bag "
            f"of the {result.messages_in} messages read)",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    return EXIT_OK


def add_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``replay`` on the ``genbacklash`` command line."""
    parser = subparsers.add_parser(
        "replay",
        help="replay a bag through the node: estimate, compensated commands, report",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    add_bag_input_options(parser, required=True)
    parser.add_argument(
        "-o", "--output", required=True, metavar="OUT", help="output bag directory (new)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace OUT if it is a bag an earlier genbacklash run wrote (it holds "
        "genbacklash-output.json and nothing but the bag); with several --joint, each "
        "OUT/<joint> that is; anything else is never removed",
    )
    parser.add_argument("--report", metavar="DIR", help="write PNG plots and index.html into DIR")
    add_checkpoint_option(parser)
    parser.add_argument(
        "--params-file",
        metavar="FILE",
        help="ROS 2 parameters YAML for backlash_identifier (--param and the options below "
        "override it)",
    )
    add_node_parameter_options(
        parser,
        used="All parameters apply except command_type, encoder_type, motor_encoder_type "
        "(from the bag), compensation_in_loop (false) and checkpoint_file (none).",
        params_file=False,
    )
    parser.add_argument("--model", choices=("backlash", "cascade"), default=None)
    parser.add_argument("--degree", type=int, default=None, help="branch polynomial degree")
    parser.add_argument("--na", type=int, default=None, help="cascade: x terms r (a_1 = 1)")
    parser.add_argument("--nb", type=int, default=None, help="cascade: y terms p")
    parser.add_argument(
        "--method",
        choices=("windowed", "recursive"),
        default=None,
        help="online identifier (default: windowed)",
    )
    parser.add_argument(
        "--json", action="store_true", help="print the final estimate as one JSON object"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--no-prefetch",
        action="store_true",
        help="read the bag in this process (default: one block ahead in a child process "
        "when a second CPU is free, i.e. the load average is below the CPUs; the same "
        "output, less wall time, a little more CPU; GENBACKLASH_PREFETCH=0 is the same, "
        "=1 reads ahead whatever the load)",
    )
    parser.set_defaults(
        func=per_joint(
            cmd_replay,
            data="bag",
            dirs=("output", "report"),
            files=("checkpoint",),
            report="report",
        )
    )
