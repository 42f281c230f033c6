"""``genbacklash readings``: a bag's readings as a CSV that identify and diagnose read alike.

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parser`. The CSV holds one
row per encoder reading that follows the first command: ``t`` (the reading's stamp, integer
nanoseconds, as the bag path takes it: the header stamp, else the log time), ``u`` (the
command held at that stamp) and ``y`` (the reading). Nothing of the row rules is applied:
``identify`` and ``diagnose`` apply them to the CSV as to the bag
(:func:`~genbacklash_ros.node.sample_rule.select_rows`), so both give the same answer.

What a CSV of readings cannot hold -- a reading the adapters rejected (its mark breaks the
chain in the bag), a command no reading held (it counts in the bag's monotone test over a
gap) -- can make the rows differ. The command therefore reads the CSV back and compares its
rows with the bag's under identify's rules (a backlash: settling and bridging; a cascade:
neither) and says on stderr whether they are the same.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.bagio import AlignedSeries, read_aligned
from genbacklash_ros.bags.csvio import Series, read_series_csv, write_readings_csv
from genbacklash_ros.cli.bag_input import add_bag_input_options, motor_selection
from genbacklash_ros.cli.joints import per_joint
from genbacklash_ros.cli.node_options import add_node_parameter_options, node_parameters

__all__ = ["add_parser", "cmd_readings", "rows_differ"]

_USED = ("joint", "command_index", "settle_time", "gear_input", "motor_joint")


def rows_differ(bag: AlignedSeries, csv: Series) -> int:
    """How many rows of the CSV differ from the bag's (in u, y, breaks; a length mismatch
    counts the rows one has beyond the other)."""
    n = min(bag.u.size, csv.u.size)
    extra = abs(bag.u.size - csv.u.size)
    breaks_csv = np.zeros(csv.u.size, dtype=bool) if csv.breaks is None else csv.breaks
    same = (bag.u[:n] == csv.u[:n]) & (bag.y[:n] == csv.y[:n]) & (bag.breaks[:n] == breaks_csv[:n])
    return int(np.count_nonzero(~same)) + extra


def cmd_readings(args: argparse.Namespace) -> int:
    """Write the readings CSV, then check that it gives the bag's rows."""
    import sys

    params = node_parameters(args, _USED).params
    joint = args.joint if args.joint is not None else params.joint
    index = args.command_index if args.command_index is not None else params.command_index
    motor_topic, motor_joint = motor_selection(args, params, joint)

    def rows(bridge: bool, settle_ns: int) -> AlignedSeries:
        return read_aligned(
            args.bag,
            args.command_topic,
            args.encoder_topic,
            joint=joint,
            command_index=index,
            bridge=bridge,
            settle_ns=settle_ns,
            motor_topic=motor_topic,
            motor_joint=motor_joint,
        )

    every = rows(False, 0)  # every reading after the first command, no rule applied
    try:
        write_readings_csv(args.output, every.t, every.u, every.y, motor=motor_topic is not None)
    except OSError as err:
        raise GenBacklashError(f"cannot write {args.output}: {err.strerror or err}") from err
    print(
        f"wrote {args.output}: {every.t.size} readings (t in ns, "
        + (
            "motor the motor reading of the stamp, y; readings without one left out)"
            if motor_topic is not None
            else "u the command held, y)"
        )
        + (
            f"; {every.skipped} readings before the first command left out" if every.skipped else ""
        ),
        file=sys.stderr,
    )
    differ = []
    for label, bridge in (("a backlash", True), ("a cascade", False)):
        settle = params.settle_ns
        bag = rows(bridge, settle)
        csv = read_series_csv(args.output, bridge=bridge, settle_ns=settle)
        count = rows_differ(bag, csv)
        if count:
            differ.append(f"{count} of {bag.u.size} rows for {label}")
    if differ:
        print(
            f"note: the CSV's rows differ from the bag's ({', '.join(differ)}): the bag has "
            "rejected readings or commands no reading held, which a CSV of readings cannot "
            "carry; identify the bag itself for its answer",
            file=sys.stderr,
        )
    else:
        print(
            "checked: identify and diagnose take the same rows from the CSV as from the bag",
            file=sys.stderr,
        )
    return 0


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``readings`` on the ``genbacklash`` subcommand parsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "readings",
        help="write a bag's readings (t, command held, encoder) as a CSV",
        description=(
            "Write a bag's encoder readings as a CSV with columns t (ns), u (the command "
            "held at the reading), y (the reading), one row per reading after the first "
            "command. identify and diagnose apply the same row rules to it as to the bag "
            "(the servo's settling rule, lost readings bridged), so a CSV and a bag of the "
            "same readings give the same answer; the command reads the CSV back and says "
            "whether its rows are the bag's. With --motor-encoder the input column is "
            "'motor' (the motor encoder's reading of each stamp; readings without one are "
            "left out), which identify and diagnose take as the gear's input."
        ),
    )
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    add_bag_input_options(parser, required=True)
    parser.add_argument("-o", "--output", metavar="FILE.csv", required=True, help="output CSV")
    add_node_parameter_options(
        parser, used="readings uses joint, command_index and settle_time (for the check)."
    )
    # several joints: one CSV each, the output name holding {joint}
    parser.set_defaults(func=per_joint(cmd_readings, data="bag", files=("output",)))
    return parser
