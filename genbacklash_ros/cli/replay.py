"""``genbacklash replay``: a recorded bag through the node's pipeline, offline.

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parser`. Exit codes follow the
command line's: 0 when the whole bag was replayed, 2 for bad input -- including a bag found
corrupt or truncated part-way (the output written so far is closed and stays readable).
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from genbacklash_core.measured import OfflineBaseline
from genbacklash_ros.bags.bagio import node_outputs
from genbacklash_ros.bags.replay import OUTPUT_TOPICS, ReplayResult, replay
from genbacklash_ros.cli.bag_input import add_bag_input_options, motor_selection
from genbacklash_ros.cli.exit_codes import EXIT_BAD_INPUT, EXIT_OK
from genbacklash_ros.cli.joints import per_joint
from genbacklash_ros.cli.node_options import (
    SET_BY_REPLAY,
    add_node_parameter_options,
    node_parameters,
)
from genbacklash_ros.cli.start import add_checkpoint_option, write_start
from genbacklash_ros.node.parameters import (
    PARAMETER_SPECS,
)
from genbacklash_ros.node.tracking_stage import record_baseline

__all__ = [
    "RAD_PARAMETERS",
    "add_parser",
    "cmd_replay",
    "play_line",
    "replay_baseline",
]


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
    used = [s.name for s in PARAMETER_SPECS if s.name not in SET_BY_REPLAY]
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
