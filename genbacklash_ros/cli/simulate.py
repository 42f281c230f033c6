"""``genbacklash simulate``'s bag options and writers: a drivetrain, an operation scenario
(phases of moves, dwells, jogs) or a physics drivetrain (MuJoCo) written as a rosbag2 bag
with its truth in the metadata.
"""

from __future__ import annotations

import argparse
import math
import sys

from genbacklash_core import GenBacklashError
from genbacklash_core.scenarios import PHASE_KINDS
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, MOTOR_TOPIC, SimulatedBag
from genbacklash_ros.cli.exit_codes import EXIT_OK
from genbacklash_ros.physics.variants import DEFAULT_BANDWIDTH, VARIANTS

__all__ = [
    "OPERATION_SCENARIOS",
    "PHYSICS_VARIANTS",
    "add_simulate_bag_options",
    "parse_phases",
    "simulate_bag",
]


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
