"""The bag (or CSV) input of ``identify``, ``diagnose`` and ``replay``: the topic, joint and
motor-encoder options, and the series the batch commands read through the node's row rules
(:func:`~genbacklash_ros.node.sample_rule.select_rows`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.bagio import BagError, read_aligned
from genbacklash_ros.bags.csvio import Series, dropped_note, read_series_csv
from genbacklash_ros.cli.joints import ListOption
from genbacklash_ros.node.parameters import (
    NodeParameters,
)

__all__ = [
    "BAG_SUFFIXES",
    "add_bag_input_options",
    "is_bag",
    "load_bag_series",
    "load_series",
    "motor_selection",
    "servo_dict",
    "servo_line",
]


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
