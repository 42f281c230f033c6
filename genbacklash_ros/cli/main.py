"""The ``genbacklash`` command line (GUIDE §4).

Exit codes: 0 success; 2 bad input or options (a one-line reason on stderr); 3 the identifier
ran but did not converge (the result, with its reason, is still printed).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import json
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    __version__,
    paper_example,
)
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.cli import bag_input as bag_input_cli
from genbacklash_ros.cli import identify as identify_cli
from genbacklash_ros.cli import node_options as node_options_cli
from genbacklash_ros.cli import simulate as simulate_cli
from genbacklash_ros.cli.exit_codes import (
    EXIT_BAD_INPUT,
    EXIT_BROKEN_PIPE,
    EXIT_NOT_CONVERGED,
    EXIT_OK,
)
from genbacklash_ros.cli.joints import per_joint
from genbacklash_ros.cli.paths import check_paths
from genbacklash_ros.cli.start import add_checkpoint_option

__all__ = ["EXIT_BAD_INPUT", "EXIT_BROKEN_PIPE", "EXIT_NOT_CONVERGED", "EXIT_OK", "main"]


# commands defined in modules of their own: the module and the function that adds its
# parser(s); main() imports only the one a command line names (the node's module imports no
# middleware, the diagnosis its effects: each costs start-up time the others need not pay)
_COMMAND_MODULES: dict[str, tuple[str, str]] = {
    "diagnose": ("genbacklash_ros.cli.diagnose", "add_parser"),
    "replay": ("genbacklash_ros.cli.replay", "add_parser"),
    "node": ("genbacklash_ros.cli.node", "add_parser"),
    "excite": ("genbacklash_ros.cli.excite", "add_parser"),
    "export": ("genbacklash_ros.cli.export", "add_parser"),
    "readings": ("genbacklash_ros.cli.readings", "add_parser"),
    "fleet": ("genbacklash_ros.cli.fleet", "add_parsers"),
    "fleet-report": ("genbacklash_ros.cli.fleet", "add_parsers"),
}


def _cmd_simulate(args: argparse.Namespace) -> int:
    if not args.physics and (args.bandwidth is not None or args.motor_encoder):
        raise GenBacklashError("--bandwidth and --motor-encoder apply to --physics VARIANT")
    if args.bag or args.scenario or args.physics:
        return simulate_cli.simulate_bag(args)
    if args.example is None or not args.output:
        raise GenBacklashError("give --example N and -o FILE.csv (or --bag DIR for a bag)")
    example = paper_example(args.example)
    data = example.generate(args.seed, n_samples=args.samples, snr=args.snr)
    write_series_csv(args.output, Series(u=data.u, y=data.y))
    print(
        f"wrote {args.output}: Example {example.number}, {data.u.size} samples, |u| < "
        f"{example.u_max}, SNR {args.snr or example.snr}",
        file=sys.stderr,
    )
    return EXIT_OK


def _cmd_demo(args: argparse.Namespace) -> int:
    if args.live:
        from genbacklash_ros.demo.live import main_live

        return main_live(args)
    example = paper_example(args.example)
    data = example.generate(args.seed)
    cascade = isinstance(example.model, Cascade)
    print(
        f"Paper Example {example.number}: {'cascade' if cascade else 'general backlash'}, "
        f"N = {example.n_samples}, |u| < {example.u_max}, SNR {example.snr}, seed {args.seed}\n"
    )
    series = Series(u=data.u, y=data.y)
    result = identify_cli.identify(series, model="cascade" if cascade else "backlash", degree=3)
    print(identify_cli.parameter_table(result, example.model))
    print(identify_cli.summary(result))
    from genbacklash_ros.reports.plots import save_identification_plots

    out = Path(args.out)
    write_series_csv(out / "data.csv", series)
    plots = save_identification_plots(result, out, data.u, data.y, example.model, unit="")
    for path in plots:  # the paper's examples have no unit
        print(f"wrote {path}")
    (out / "result.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    print(f"wrote {out / 'result.json'} and {out / 'data.csv'}")
    return EXIT_OK if result.converged else EXIT_NOT_CONVERGED


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {value}")
    return value


def _int_in(low: int, high: int, note: str = "") -> Callable[[str], int]:
    """An argparse ``type``: a whole number in ``low..high`` (``note`` follows the range in
    the error)."""

    def whole_number(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must lie in {low}..{high}{note}, got {value}")
        return value

    return whole_number


_joint_count = _int_in(1, 12)
_thread_priority = _int_in(0, 99, " (0: no real-time)")


_BATCH_USES = (
    "{command} uses model, degree, na, nb, settle_time and servo_model, servo_dead_time, "
    "servo_time_constant (a bag, or a CSV with t: the same row rules; servo_model=auto "
    "estimates the servo from the whole record) and, for a bag, joint, command_index; the others "
    "are validated, then ignored (a note on stderr names those set to other than their "
    "defaults). Bags are read with header stamps, one sample per encoder message (the node's "
    "default stamp_source and sample_period)."
)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser (exposed for tests and documentation); with ``command`` one of
    the commands defined in modules of their own, only its parser besides the built-in
    ones (what :func:`main` parses a command line of it with)."""
    parser = argparse.ArgumentParser(
        prog="genbacklash",
        description=(
            "Identify and cancel general backlash (gear play with curved branches) from "
            "actuator commands and encoder readings."
        ),
        epilog="Run 'genbacklash COMMAND --help' for the options of a command.",
    )
    parser.add_argument("--version", action="version", version=f"genbacklash {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    ident = sub.add_parser(
        "identify",
        help="identify a general backlash (or backlash + linear dynamics) from data",
        description=(
            "Identify a general backlash from a CSV with header columns u (command) and y "
            "(measured position), optional t. The paper's iteration (Voeroes, §3-4) runs from "
            "m_1 = +/-1, c = 0.001, then an output-error refinement brings it to maximum-"
            "likelihood accuracy. Exit status 3 when it did not converge. The node's start "
            "comes from a checkpoint file (its checkpoint_file parameter): --checkpoint FILE "
            "writes one; the --json output is a report, not that file."
        ),
    )
    ident.add_argument(
        "data",
        metavar="DATA",
        help="CSV file with columns u,y[,t], or a rosbag2 directory / .mcap file (then give "
        "--command and --encoder: one sample per encoder message, the command held)",
    )
    bag_input_cli.add_bag_input_options(ident, required=False)
    ident.add_argument(
        "--model",
        choices=("backlash", "cascade"),
        default=None,
        help="backlash alone (y is the backlash output) or backlash followed by linear "
        "dynamics (default: backlash)",
    )
    ident.add_argument(
        "--degree",
        type=_positive_int,
        default=None,
        help="polynomial degree of each branch; 1 = ideal backlash (default 3)",
    )
    ident.add_argument(
        "--na",
        type=_positive_int,
        default=None,
        help="cascade: number of input terms r of the linear block, a_1=1 included (default 2)",
    )
    ident.add_argument(
        "--nb",
        type=_non_negative_int,
        default=None,
        help="cascade: number of output terms p of the linear block (default 2)",
    )
    ident.add_argument(
        "--sign",
        choices=("auto", "+1", "-1"),
        default="auto",
        help="increasing (+1) or decreasing (-1) branches; auto detects it",
    )
    ident.add_argument(
        "--no-refine",
        action="store_true",
        help="skip the output-error refinement (plain paper iteration)",
    )
    ident.add_argument(
        "--max-iterations", type=_positive_int, default=30, help="iteration limit (default 30)"
    )
    ident.add_argument(
        "--drop-nonfinite",
        action="store_true",
        help="drop NaN/inf samples instead of stopping with an error",
    )
    ident.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (the documented contract) instead of a table; it is not "
        "the node's start: for that, write --checkpoint FILE",
    )
    add_checkpoint_option(ident)
    ident.add_argument(
        "--plot", metavar="DIR", help="also write characteristic.png and history.png into DIR"
    )
    node_options_cli.add_node_parameter_options(ident, used=_BATCH_USES.format(command="identify"))
    ident.set_defaults(
        func=per_joint(
            identify_cli.cmd_identify, data="data", dirs=("plot",), files=("checkpoint",)
        )
    )

    sim = sub.add_parser(
        "simulate",
        help="write synthetic data of the paper's examples",
        description=(
            "Simulate one of the paper's four examples (uniform random input, white output "
            "noise at the paper's SNR = std(output)/std(noise)) and write a CSV with columns u,y "
            "(-o), or a rosbag2 MCAP bag (--bag) of it or of the --scenario drivetrain."
        ),
    )
    sim.add_argument(
        "--example",
        type=int,
        choices=(1, 2, 3, 4),
        default=None,
        help="1, 2: general backlash (increasing, decreasing); 3, 4: cascade",
    )
    sim.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    sim.add_argument(
        "--samples",
        type=_positive_int,
        default=None,
        help="number of samples (default: the paper's N)",
    )
    sim.add_argument(
        "--snr",
        type=_positive_float,
        default=None,
        help="signal-to-noise ratio (default: the paper's)",
    )
    sim.add_argument("-o", "--output", metavar="FILE.csv", help="output CSV")
    simulate_cli.add_simulate_bag_options(sim)
    sim.set_defaults(func=_cmd_simulate)

    demo = sub.add_parser(
        "demo",
        help="simulate a paper example and identify it; or (--live) a simulated arm and the "
        "node in a ROS 2 graph",
        description=(
            "The bundled main job: simulate the paper's Example 3 (or --example), identify it, "
            "print a truth-vs-estimate table and write characteristic.png, history.png, "
            "result.json and data.csv into --out.\n\n"
            "--live: the node at work without hardware. Starts two ROS 2 nodes: the "
            "identifier node (genbacklash node, its own process) and a simulated arm (physics "
            "drivetrains: a servo, the play as contact, the load's inertia) that publishes "
            "/joint_states, sends its desired moves on /command and obeys only "
            "/compensated_command, with an uncompensated twin beside it. Prints, once a "
            "second per joint, the play the node estimates against the geometric play, the "
            "tracking error with and without compensation and the compensation's state; a "
            "table at the end. Needs rclpy ([ros]) and mujoco ([physics])."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument(
        "--example",
        type=int,
        choices=(1, 2, 3, 4),
        default=3,
        help="paper example (default 3: cascade)",
    )
    demo.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    demo.add_argument(
        "--out", default="demo_output", metavar="DIR", help="output directory (default demo_output)"
    )
    live = demo.add_argument_group("live (--live)")
    live.add_argument(
        "--live", action="store_true", help="a simulated arm and the identifier node, live"
    )
    live.add_argument(
        "--joints", type=_joint_count, default=1, metavar="N", help="joints of the arm (default 1)"
    )
    live.add_argument(
        "--duration",
        type=_positive_float,
        default=40.0,
        metavar="S",
        help="seconds of motion (default 40)",
    )
    live.add_argument(
        "--physics",
        choices=("near_ideal", "coasting", "compliant", "gravity"),
        default="near_ideal",
        help="the joints' physics drivetrain (default near_ideal)",
    )
    live.add_argument(
        "--bandwidth",
        type=_positive_float,
        default=60.0,
        metavar="HZ",
        help="servo bandwidth (default 60)",
    )
    live.add_argument(
        "--encoder-rate",
        type=_positive_float,
        default=500.0,
        metavar="HZ",
        help="JointState messages per second (default 500)",
    )
    live.add_argument(
        "--transport",
        choices=("rclpy", "dds"),
        default="rclpy",
        help="the identifier node's transport (default rclpy)",
    )
    live.add_argument(
        "--thread-priority",
        type=_thread_priority,
        default=0,
        metavar="P",
        help="the node's thread_priority: its message thread under SCHED_FIFO at P (1-99; "
        "needs CAP_SYS_NICE), identification in a child process (default 0: neither)",
    )
    demo.set_defaults(func=_cmd_demo)
    wanted = (
        [_COMMAND_MODULES[command]] if command in _COMMAND_MODULES else _COMMAND_MODULES.values()
    )
    for module, function in dict.fromkeys(wanted):
        getattr(importlib.import_module(module), function)(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``genbacklash`` console script."""
    code = _run(argv)
    if argv is None:
        # the console script's own call: the process ends next, and the interpreter's
        # final garbage collection would walk every object still alive (rosbags' typestore
        # alone is thousands of classes) only to find no garbage worth the time: ~0.06 s of
        # CPU after a replay (BENCHMARKS.md "Replay throughput"). Frozen, they are not
        # walked; everything was written and closed before this point.
        gc.freeze()
    return code


def _run(argv: Sequence[str] | None) -> int:
    """The command of ``argv`` (None: the process's own arguments), its exit status."""
    words = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(words[0] if words else None)
    args = parser.parse_args(words)
    args.entry_point = argv is None  # the console script's own call (see `node`)
    try:
        check_paths(args)  # before any work: no output may destroy an input
        # one BLAS thread for every command, as the node and replay run: the batch fits'
        # last bits (and so a diagnosis's path) then do not depend on the machine's cores
        with one_blas_thread():
            code: int = args.func(args)
        sys.stdout.flush()  # a buffered stdout (no PYTHONUNBUFFERED) fails here, not at exit
    except GenBacklashError as err:
        print(f"genbacklash {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"genbacklash {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of stdout went away (`genbacklash identify ... | head -1`): stop quietly,
        # and point stdout at /dev/null so that the interpreter's final flush cannot fail too
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    return code


if __name__ == "__main__":
    sys.exit(main())
