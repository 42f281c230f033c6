"""``genbacklash replay`` (and the bag options of ``simulate`` and ``identify``).

Registered by :mod:`genbacklash_ros.cli` through :func:`add_parser`. Exit codes follow the
command line's: 0 when the whole bag was replayed, 2 for bad input -- including a bag found
corrupt or truncated part-way (the output written so far is closed and stays readable).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from genbacklash_core import GenBacklashError

from .bagio import BagError, read_aligned
from .csvio import Series, read_series_csv
from .parameters import load_params_file
from .replay import OUTPUT_TOPICS, ReplayResult, replay
from .simbags import COMMAND_TOPIC, ENCODER_TOPIC, SimulatedBag

__all__ = [
    "add_bag_input_options",
    "add_parser",
    "add_simulate_bag_options",
    "cmd_replay",
    "load_bag_series",
    "simulate_bag",
]

EXIT_OK = 0
EXIT_BAD_INPUT = 2

_DESCRIPTION = f"""\
Replay a recorded bag through the backlash_identifier node's pipeline, offline.

BAG is a rosbag2 directory (metadata.yaml + .mcap) or a bare .mcap file. The messages of
--command and --encoder are fed in log-time order to the same pipeline the live node runs
(the log time is the receive time), with the node's parameters (--params-file, overridden by
the options below; the message types come from the bag). OUT is a new rosbag2 MCAP
directory with the two input topics plus what the node publishes:
{OUTPUT_TOPICS["estimate"]}, {OUTPUT_TOPICS["compensated_command"]} (one per command) and
{OUTPUT_TOPICS["diagnostics"]}; rosbags, mcap-ros2-support and Foxglove read it.

Prints the final estimate (or --json) and writes an HTML report with plots when --report is
given. A progress bar runs on stderr. A bag found corrupt or truncated part-way stops the
replay there: OUT keeps what was written (closed properly), the reason goes to stderr and
the exit status is 2.
"""

_EPILOG = """\
examples:
  genbacklash replay bags/drivetrain --command /command --encoder /encoder -o out --report rep
  genbacklash replay run.mcap --command /cmd --encoder /joint_states --joint knee \\
      --model cascade --na 2 --nb 2 -o out --json
  genbacklash replay run --command /cmd --encoder /enc --params-file config/params.yaml -o out
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
        "sensor_msgs/JointState)",
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
        help="bag input: joint name in JointState messages (default: the first joint)",
    )
    parser.add_argument(
        "--command-index",
        metavar="I",
        type=int,
        default=None,
        help="bag input: element of a Float64MultiArray command (default 0)",
    )


def load_bag_series(args: argparse.Namespace) -> Series:
    """The aligned (u, y) samples of a bag given by ``args.data`` and the bag options.

    One sample per encoder message; the command held (the pipeline's alignment).
    """
    if not args.command_topic or not args.encoder_topic:
        raise BagError(
            f"{args.data} is a bag: say which topics to use with --command TOPIC and "
            "--encoder TOPIC"
        )
    series = read_aligned(
        args.data,
        args.command_topic,
        args.encoder_topic,
        joint=args.joint or "",
        command_index=args.command_index or 0,
    )
    if series.skipped:
        print(
            f"skipped {series.skipped} encoder samples before the first command",
            file=sys.stderr,
        )
    return Series(u=series.u, y=series.y)


BAG_SUFFIXES = (".mcap", ".db3")


def load_series(args: argparse.Namespace) -> Series:
    """The (u, y) data of ``args.data``: a CSV file, or a bag with the bag options.

    Shared by ``identify`` and ``diagnose``.
    """
    file = Path(args.data)
    if file.is_dir() or file.suffix.lower() in BAG_SUFFIXES:
        return load_bag_series(args)
    if not file.exists():
        raise GenBacklashError(f"{file} does not exist")
    return read_series_csv(file)


# --------------------------------------------------------------------------- simulate


def add_simulate_bag_options(parser: argparse.ArgumentParser) -> None:
    """``--bag DIR``, ``--scenario``, ``--duration``, ``--wear`` for ``simulate``."""
    parser.add_argument(
        "--bag",
        metavar="DIR",
        help=f"write a rosbag2 MCAP bag (a new directory): {COMMAND_TOPIC} "
        f"(std_msgs/Float64MultiArray) and {ENCODER_TOPIC} (sensor_msgs/JointState, joint "
        "drive_joint) at 1 kHz; with --example, one command per sample",
    )
    parser.add_argument(
        "--scenario",
        choices=("drivetrain",),
        help="drivetrain: encoder at 1 kHz, command at 100-1000 Hz with jitter, Example 1's "
        "curved branches, a gap that widens by --wear over the record, SNR 25 (needs --bag)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=12.0,
        help="drivetrain: record length in seconds (default 12)",
    )
    parser.add_argument(
        "--wear",
        type=float,
        default=0.2,
        help="drivetrain: relative growth of the gap over the record (default 0.2)",
    )


def simulate_bag(args: argparse.Namespace) -> int:
    """Write the bag ``simulate`` asked for (``--bag`` with ``--example`` or ``--scenario``)."""
    from .simbags import write_drivetrain_bag, write_example_bag

    if not args.bag:
        raise GenBacklashError("--scenario writes a bag: give --bag DIR")
    if args.output:
        raise GenBacklashError("give either -o FILE.csv or --bag DIR, not both")
    if args.scenario == "drivetrain":
        if args.example is not None:
            raise GenBacklashError("give either --example or --scenario, not both")
        if not args.duration > 0 or not 0 <= args.wear < 10:
            raise GenBacklashError("--duration must be > 0 and --wear in [0, 10)")
        made: SimulatedBag = write_drivetrain_bag(
            args.bag,
            seed=args.seed,
            duration=args.duration,
            wear=args.wear,
            snr=args.snr or 25.0,
        )
    elif args.example is not None:
        made = write_example_bag(
            args.bag, args.example, seed=args.seed, n_samples=args.samples, snr=args.snr
        )
    else:
        raise GenBacklashError("say what to simulate: --example N or --scenario drivetrain")
    topics = ", ".join(f"{t} ({m}, {n})" for t, (m, n) in made.counts.items())
    print(f"wrote {made.path}: {made.description}; {topics}", file=sys.stderr)
    return EXIT_OK


# --------------------------------------------------------------------------- replay


def _summary(result: ReplayResult) -> str:
    est = result.estimate
    lines = [f"{'parameter':<12}{'estimate':>12}{'2 sigma':>12}", "-" * 36]
    std = est.std()
    for name, value, sigma in zip(est.names, est.parameters, std, strict=True):
        lines.append(f"{name:<12}{value:>12.5f}{2 * sigma:>12.5f}")
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


def _remove_old_output(path: Path) -> None:
    """Delete a previous output bag (a rosbag2 directory or an .mcap file), nothing else."""
    if path.is_dir() and (path / "metadata.yaml").is_file():
        shutil.rmtree(path)
    elif path.is_file() and path.suffix == ".mcap":
        path.unlink()
    elif path.exists():
        raise BagError(f"--overwrite: {path} exists but is not a bag; not removing it")


def cmd_replay(args: argparse.Namespace) -> int:
    """Run ``genbacklash replay``."""
    params = load_params_file(args.params_file) if args.params_file else None
    if args.overwrite:
        _remove_old_output(Path(args.output))
    result = replay(
        args.bag,
        args.output,
        command_topic=args.command_topic,
        encoder_topic=args.encoder_topic,
        params=params,
        joint=args.joint,
        command_index=args.command_index,
        model=args.model,
        degree=args.degree,
        na=args.na,
        nb=args.nb,
        method=args.method,
        progress=not args.no_progress,
    )
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(_summary(result))
    if args.report:
        from .report import write_report

        index = write_report(result, args.report)
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
        "--overwrite", action="store_true", help="replace OUT if it is a bag from an earlier run"
    )
    parser.add_argument("--report", metavar="DIR", help="write PNG plots and index.html into DIR")
    parser.add_argument(
        "--params-file",
        metavar="FILE",
        help="ROS 2 parameters YAML for backlash_identifier (the options below override it)",
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
    parser.set_defaults(func=cmd_replay)
