"""``genbacklash excite``: write a commissioning motion that makes the identifier converge.

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parser`. The motion is
:func:`genbacklash_core.excite.commissioning_trajectory`: from the start position to the
farther end of the range, two full sweeps timed for the online identifier, back to the start;
within the given position, velocity and acceleration limits. It is written as a CSV (``t,u``:
seconds, command) and optionally as a rosbag2 MCAP bag (``std_msgs/Float64MultiArray`` on
``/command``, logged at each command's time) to play to the drivetrain. ``--check`` runs it
through the simulated drivetrain of :mod:`genbacklash_core.scenarios` into the node's
identifier and prints when it converged.

Exit codes: 0 written (and, with ``--check``, converged); 2 bad input (a one-line reason on
stderr); 3 ``--check`` found that the identifier did not converge (the files are written).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_core.excite import (
    MotionLimits,
    Trajectory,
    check_commissioning,
    commissioning_trajectory,
)
from genbacklash_core.scenarios import OPERATION_BACKLASH, OperationSettings
from genbacklash_ros.bags.bagio import BagError, BagWriter
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, START_NS, command_message
from genbacklash_ros.cli.exit_codes import EXIT_NOT_CONVERGED, EXIT_OK
from genbacklash_ros.node.messages import Float64MultiArray

__all__ = ["add_parser", "cmd_excite", "write_trajectory_bag", "write_trajectory_csv"]


_USAGE = """\
genbacklash excite --range LO HI --v-max V --a-max A -o FILE.csv [--rate HZ] [--gap G]
                          [--start X] [--sweeps N] [--jog-points N] [--bag DIR]
                          [--topic TOPIC] [--check] [--seed S] [--plot FILE.png]"""

_DESCRIPTION = """\
Write a commissioning motion: the shortest trajectory after which the online identifier
(the node's default 'windowed' method) has converged, for drivetrains that can run one.

The motion goes from the start position (--start, default the middle of the range) to the
farther end of the range, sweeps to the other end and back (at up to --v-max), and returns to the
start. Both branches of the backlash are then seen over the whole range, with reversals that
cross the gap at both ends, and each sweep is timed (about 90 commands) so that the
identifier's first fit comes right after. A joint too slow for that gets more sweeps.
--jog-points N adds N short back-and-forth jogs spread over the range on the last sweep.

Every limit holds exactly: positions within --range, and the velocity and acceleration
computed by finite differences of the commands at --rate within --v-max and --a-max; the
motion starts and ends at rest. Moves are trapezoidal velocity profiles.

On the simulated drivetrain (2.4 rad of travel, 3 rad/s, 30 rad/s^2, 100 Hz) the motion
lasts 2.84 s and the identifier converged after 2.04-2.15 s in every run (5 backlash models,
40 seeds each).
"""

_EPILOG = """\
outputs:
  FILE.csv     header t,u: seconds from the first command, the command (position)
  --bag DIR    a rosbag2 directory (one MCAP file): std_msgs/Float64MultiArray on --topic
               (default /command, one element), logged at each command's time; play it to
               the drivetrain with 'ros2 bag play DIR'. DIR must not exist.
  --plot FILE  position, velocity and acceleration against their limits

--check runs the motion through the simulated drivetrain of the 'operation' scenario
(OPERATION_BACKLASH, its travel -1.2..1.2 rad mapped onto --range, 100 Hz commands held by
the servo, a 1 kHz encoder of 4096 counts/rev losing 2 % of its readings) into the node's
identifier, and prints when it converged and the free-run NRMSE of its estimate.

The summary on stderr gives the duration, the number of reversals and the peak velocity and
acceleration used. Exit status: 0 written; 2 bad input (one line on stderr); 3 --check: the
identifier did not converge within the motion.

examples:
  genbacklash excite --range -1.2 1.2 --v-max 3 --a-max 30 -o commissioning.csv
  genbacklash excite --range 0 3.1 --v-max 1.5 --a-max 10 --gap 0.05 -o c.csv --bag c_bag --check
"""


def _number(option: str, text: str | None, *, positive: bool = False) -> float:
    """``text`` as a finite number (positive when asked), or a one-line error."""
    if text is None:
        raise GenBacklashError(f"give {option}")
    try:
        value = float(text)
    except ValueError:
        raise GenBacklashError(f"{option} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise GenBacklashError(f"{option} must be finite, got {text!r}")
    if positive and not value > 0.0:
        raise GenBacklashError(f"{option} must be > 0, got {text}")
    return value


def _count(option: str, text: str | None, low: int) -> int | None:
    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        raise GenBacklashError(f"{option} must be a whole number, got {text!r}") from None
    if value < low:
        raise GenBacklashError(f"{option} must be >= {low}, got {value}")
    return value


def write_trajectory_csv(path: str | Path, trajectory: Trajectory) -> None:
    """Write ``t,u`` (seconds, command) with full float precision."""
    file = Path(path)
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        np.savetxt(
            file,
            np.column_stack([trajectory.t, trajectory.u]),
            delimiter=",",
            header="t,u",
            comments="",
            fmt="%.17g",
        )
    except OSError as err:
        raise GenBacklashError(f"cannot write {file}: {err.strerror or err}") from err


def write_trajectory_bag(
    path: str | Path, trajectory: Trajectory, topic: str = COMMAND_TOPIC
) -> int:
    """Write the commands as ``std_msgs/Float64MultiArray`` on ``topic`` (one element each),
    logged at each command's time from the simulated bags' start; how many were written."""
    period_ns = 1e9 / trajectory.command_rate
    with BagWriter(path) as writer:
        writer.add_topic(topic, Float64MultiArray.ros_type)
        for k, value in enumerate(trajectory.u.tolist()):
            writer.write(topic, START_NS + round(k * period_ns), command_message((value,)))
        return writer.count


def _plot(path: str | Path, trajectory: Trajectory) -> None:
    from matplotlib.figure import Figure

    lim = trajectory.limits
    t = trajectory.t
    fig = Figure(figsize=(7.0, 6.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    panels = (
        (trajectory.u, (lim.low, lim.high), "position (units)"),
        (trajectory.velocity[:-1], (-lim.v_max, lim.v_max), "velocity (units/s)"),
        (trajectory.acceleration, (-lim.a_max, lim.a_max), "acceleration (units/s²)"),
    )
    for ax, (values, bounds, label) in zip(axes, panels, strict=True):
        times = t if values.size == t.size else t[: values.size]
        ax.plot(times, values, lw=1.2)
        for bound in bounds:
            ax.axhline(bound, color="0.5", ls="--", lw=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_title(
        f"commissioning motion: {trajectory.duration:.2f} s, {trajectory.reversals} reversals"
    )
    axes[-1].set_xlabel("time (s)")
    file = Path(path)
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(file, dpi=110)
    except (OSError, ValueError) as err:
        raise GenBacklashError(f"cannot write the plot {file}: {err}") from err


def cmd_excite(args: argparse.Namespace) -> int:
    """Run ``genbacklash excite`` (see the module notes)."""
    if args.range is None:
        raise GenBacklashError("give the position range: --range LO HI")
    low = _number("--range LO", args.range[0])
    high = _number("--range HI", args.range[1])
    if not low < high:
        raise GenBacklashError(f"--range needs LO < HI, got {args.range[0]} {args.range[1]}")
    v_max = _number("--v-max", args.v_max, positive=True)
    a_max = _number("--a-max", args.a_max, positive=True)
    rate = _number("--rate", args.rate, positive=True)
    gap = None if args.gap is None else _number("--gap", args.gap, positive=True)
    start = None if args.start is None else _number("--start", args.start)
    sweeps = _count("--sweeps", args.sweeps, 1)
    jog_points = _count("--jog-points", args.jog_points, 0) or 0
    seed = _count("--seed", args.seed, 0) or 0
    if not args.output:
        raise GenBacklashError("give the output CSV: -o FILE.csv")
    if args.bag is not None and Path(args.bag).exists():
        raise BagError(f"{args.bag} exists already; remove it or choose another --bag")
    if not args.topic.startswith("/") or len(args.topic) < 2:
        raise GenBacklashError(f"--topic must be an absolute topic name, got {args.topic!r}")
    trajectory = commissioning_trajectory(
        MotionLimits(low, high, v_max, a_max),
        command_rate=rate,
        gap_hint=gap,
        start=start,
        sweeps=sweeps,
        jog_points=jog_points,
    )
    write_trajectory_csv(args.output, trajectory)
    written = [str(args.output)]
    if args.bag is not None:
        write_trajectory_bag(args.bag, trajectory, args.topic)
        written.append(str(args.bag))
    if args.plot:
        _plot(args.plot, trajectory)
        written.append(str(args.plot))
    print(
        f"wrote {' and '.join(written)}: {trajectory.u.size} commands at {rate:g} Hz, "
        f"{trajectory.duration:.2f} s, {trajectory.reversals} reversals, peak velocity "
        f"{trajectory.peak_velocity:.4g} (limit {v_max:g}), peak acceleration "
        f"{trajectory.peak_acceleration:.4g} (limit {a_max:g})",
        file=sys.stderr,
    )
    if not args.check:
        return EXIT_OK
    check = check_commissioning(
        trajectory, OPERATION_BACKLASH, seed, travel=OperationSettings().travel
    )
    if check.converged_at is not None:
        print(
            f"check: the identifier converged after {check.converged_at:.2f} s of the "
            f"{trajectory.duration:.2f} s motion (free-run NRMSE {check.nrmse:.4f} against "
            "the simulated drivetrain)"
        )
        return EXIT_OK
    print(
        f"check: the identifier did NOT converge within the {trajectory.duration:.2f} s "
        f"motion (state {check.state.value}: {check.reason}); try --sweeps "
        f"{(sweeps or 2) + 1}"
    )
    return EXIT_NOT_CONVERGED


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``excite`` on the ``genbacklash`` subcommand parsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "excite",
        help="write a short commissioning motion after which the identifier has converged",
        usage=_USAGE,
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # numbers are read by the command, so that a bad one is a one-line error (exit 2)
    parser.add_argument(
        "--range",
        nargs=2,
        metavar=("LO", "HI"),
        help="position range of the joint, command units (e.g. rad); required",
    )
    parser.add_argument("--v-max", metavar="V", help="velocity limit, units/s; required")
    parser.add_argument("--a-max", metavar="A", help="acceleration limit, units/s^2; required")
    parser.add_argument(
        "-o", "--output", metavar="FILE.csv", help="output CSV with columns t,u; required"
    )
    parser.add_argument(
        "--rate", default="100", metavar="HZ", help="command rate, Hz (default 100)"
    )
    parser.add_argument(
        "--gap",
        metavar="G",
        help="expected play in command units (c_L + c_R): sizes the jogs (3 gaps) and checks "
        "that the range holds at least 12 gaps",
    )
    parser.add_argument(
        "--start",
        metavar="X",
        help="where the joint rests before (and after) the motion; default the middle of the range",
    )
    parser.add_argument(
        "--sweeps",
        metavar="N",
        help="end-to-end sweeps after the way to the farther end (default 2; more for a "
        "joint too slow for a sweep of ~90 commands)",
    )
    parser.add_argument(
        "--jog-points",
        metavar="N",
        help="short back-and-forth jogs spread over the range on the last sweep (default 0)",
    )
    parser.add_argument(
        "--bag", metavar="DIR", help="also write a rosbag2 (MCAP) bag of the commands"
    )
    parser.add_argument(
        "--topic",
        default=COMMAND_TOPIC,
        help=f"the bag's command topic (default {COMMAND_TOPIC})",
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="simulate the motion on the default drivetrain and print when the identifier "
        "converged (exit 3 if it did not)",
    )
    parser.add_argument(
        "--seed", metavar="S", help="--check: seed of the simulated encoder (default 0)"
    )
    parser.add_argument(
        "--plot", metavar="FILE.png", help="also plot position, velocity and acceleration"
    )
    parser.set_defaults(func=cmd_excite)
    return parser
