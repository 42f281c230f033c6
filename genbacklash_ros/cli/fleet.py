"""``genbacklash fleet`` and ``genbacklash fleet-report``: an archive of bags on Dask, results
in a database, wear trends.

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parsers`. Exit codes follow
the command line's: 0 when every bag has its rows (whatever their status), 1 when the
cluster lost bags (re-run to retry them), 2 for bad input.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from genbacklash_core import GenBacklashError
from genbacklash_ros.cli.exit_codes import EXIT_LOST, EXIT_OK
from genbacklash_ros.cli.node_options import (
    BATCH_PARAMETERS,
    add_node_parameter_options,
    node_parameters,
)
from genbacklash_ros.node.parameters import PARAMETER_SPECS

__all__ = ["add_parsers", "cmd_fleet", "cmd_fleet_report", "parse_joint"]


_FLEET_DESCRIPTION = """\
Analyse every bag of an archive on a Dask cluster and store one row per bag and joint in a
database: the batch estimate with standard deviations, its fit, the diagnose findings, and
with --replay the online estimate of the node's pipeline.

ARCHIVE is a directory tree of bags: rosbag2 directories (metadata.yaml + .mcap) and bare
.mcap files. The drivetrain and time of each bag come from its path,

  ARCHIVE/ROBOT[/JOINT][/...]/NAME     e.g. fleet/robot-07/elbow/2024-03-05T08-30-00/

the time from the first YYYY-MM-DD[THH-MM-SS] (or YYYYMMDD[_HHMMSS]) in NAME, else in the
nearest directory holding one, else the bag's first message; ROBOT and JOINT are the first
two directory components that are not a bare date (no ROBOT: the archive's name). The bag's
metadata custom_data keys genbacklash.robot and genbacklash.joint override the path. A bag
that names no joint is analysed for each --joint, else for the node parameter joint (empty:
the encoder's first joint).

Re-runs skip the bags already in the database with the same content hash and settings; a
bag that cannot be read gets a row with the reason and the rest goes on; a run killed
half-way resumes where it stopped (each bag's rows are committed together).
"""

_FLEET_EPILOG = """\
examples:
  genbacklash fleet /data/bags --db fleet.db
  genbacklash fleet /data/bags --workers 2 --joint elbow=1 --joint wrist=2 --param degree=2
  genbacklash fleet /data/bags --scheduler tcp://10.0.0.5:8786 --db postgresql+psycopg://me@db/fleet
  genbacklash fleet-report fleet.db --play-limit 0.15 -o fleet_report
"""

_REPORT_DESCRIPTION = """\
Wear trends from a fleet database: per drivetrain (robot, joint), the play c_L + c_R of its
'ok' bags against time with 2-sigma bars, a weighted straight-line trend (its uncertainty
scaled up by the scatter when the bags scatter more than their standard deviations say), and
the date the trend crosses --play-limit with Fieller's interval. Writes index.html (the
ranking by days to service and the plots), fleet.png, one PNG per drivetrain and
summary.json into -o DIR, and prints the ranking (or the JSON with --json).
"""


def parse_joint(text: str) -> tuple[str, int | None]:
    """``NAME`` or ``NAME=INDEX`` (the command's Float64MultiArray element).

    >>> parse_joint("elbow=2"), parse_joint("wrist")
    (('elbow', 2), ('wrist', None))
    """
    name, sep, index = text.partition("=")
    name = name.strip()
    if not name:
        raise argparse.ArgumentTypeError(f"expected NAME or NAME=INDEX, got {text!r}")
    if not sep:
        return name, None
    try:
        value = int(index)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(
            f"the command index of --joint {text!r} must be a whole number >= 0"
        )
    return name, value


def cmd_fleet(args: argparse.Namespace) -> int:
    """Run ``genbacklash fleet``."""
    from genbacklash_ros.fleet.archive import discover
    from genbacklash_ros.fleet.database import ResultStore
    from genbacklash_ros.fleet.job import FleetSettings, JointRequest, check_archive
    from genbacklash_ros.fleet.runner import fleet_client, run_fleet

    used = [*BATCH_PARAMETERS, "joint", "command_index"]
    if args.replay:
        used = [s.name for s in PARAMETER_SPECS]
    cli = node_parameters(args, used)
    settings = FleetSettings(
        command_topic=args.command_topic,
        encoder_topic=args.encoder_topic,
        params=cli.params,
        joints=tuple(JointRequest(name, index) for name, index in args.joints),
        diagnose=not args.no_diagnose,
        diagnose_from_params=any(name in cli.given for name in BATCH_PARAMETERS),
        validation=args.validation,
        replay=args.replay,
        max_nrmse=args.max_nrmse,
    )
    # a wrong ARCHIVE, one without bags or without the topics stops here, before a cluster
    check_archive(args.archive, discover(args.archive), settings)
    store = ResultStore(args.db)
    try:
        with fleet_client(
            args.scheduler, workers=args.workers, processes=not args.threads
        ) as client:
            run = run_fleet(args.archive, store, settings, client, progress=not args.no_progress)
    finally:
        store.close()
    print(run.summary())
    for item in run.lost:
        print(f"genbacklash fleet: lost {item}", file=sys.stderr)
    return EXIT_LOST if run.lost else EXIT_OK


def _parse_date(text: str) -> int:
    from genbacklash_ros.fleet.archive import parse_timestamp

    value = parse_timestamp(text)
    if value is None:
        raise argparse.ArgumentTypeError(f"expected YYYY-MM-DD[THH:MM:SS], got {text!r}")
    return value


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from err
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def cmd_fleet_report(args: argparse.Namespace) -> int:
    """Run ``genbacklash fleet-report``."""
    from genbacklash_ros.fleet.database import ResultStore, iso_utc
    from genbacklash_ros.fleet.report import write_fleet_report
    from genbacklash_ros.fleet.summary import summarise

    if not 0.0 < args.level < 1.0:
        raise GenBacklashError(f"--level must lie in (0, 1), got {args.level}")
    store = ResultStore(args.db, create=False)
    try:
        rows = store.results()
    finally:
        store.close()
    if not rows:
        raise GenBacklashError(f"{args.db} holds no results; run 'genbacklash fleet' first")
    summary = summarise(rows, gap_limit=args.gap_limit, level=args.level, as_of_ns=args.as_of)
    index = write_fleet_report(summary, args.output)
    if args.json:
        print(summary.to_json())
    else:
        print(f"{'rank':>4}  {'drivetrain':<28}{'days to service':>16}  {'interval':<24}note")
        for d in summary.drivetrains:
            days = "-" if d.days_to_service is None else f"{d.days_to_service:.1f}"
            as_of = summary.as_of_ns or 0
            if d.crossing_low_ns is not None and d.crossing_high_ns is not None:
                lo = (d.crossing_low_ns - as_of) / 86_400e9
                hi = (d.crossing_high_ns - as_of) / 86_400e9
                interval = f"[{lo:.1f}, {hi:.1f}]"
            else:
                interval = "-"
            name = f"{d.robot}/{d.joint}"
            print(f"{d.rank:>4}  {name:<28}{days:>16}  {interval:<24}{d.note}")
        flagged = [(d, bag) for d in summary.drivetrains for bag in d.truncated]
        if flagged:
            print("truncated bags (their readable part analysed):")
        for d, bag in flagged:
            when = (iso_utc(bag.recorded_ns) or "no date")[:10]
            print(f"  {d.robot}/{d.joint} {when} {bag.bag_path}: {bag.flag} ({bag.status})")
    print(f"wrote {index}", file=sys.stderr)
    return EXIT_OK


def add_parsers(subparsers: Any) -> None:
    """Register ``fleet`` and ``fleet-report`` on the ``genbacklash`` command line."""
    fleet = subparsers.add_parser(
        "fleet",
        help="analyse an archive of bags on Dask into a results database",
        description=_FLEET_DESCRIPTION,
        epilog=_FLEET_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    fleet.add_argument("archive", metavar="ARCHIVE", help="root directory of the bag tree")
    fleet.add_argument(
        "--db",
        default="fleet.db",
        metavar="URL",
        help="results database: an SQLAlchemy URL, or a file path for SQLite (default fleet.db)",
    )
    fleet.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="address of a running Dask scheduler (e.g. tcp://host:8786); default: a local "
        "cluster on this machine",
    )
    fleet.add_argument(
        "--workers",
        type=int,
        default=2,
        metavar="N",
        help="local cluster: worker processes, one thread each (default 2)",
    )
    fleet.add_argument(
        "--threads",
        action="store_true",
        help="local cluster: workers are threads of this process (starts at once; for small "
        "archives and tests: numpy and the bag reader hold the GIL part of the time)",
    )
    fleet.add_argument(
        "--command",
        dest="command_topic",
        default="/command",
        metavar="TOPIC",
        help="command topic in every bag (default /command)",
    )
    fleet.add_argument(
        "--encoder",
        dest="encoder_topic",
        default="/encoder",
        metavar="TOPIC",
        help="encoder topic in every bag (default /encoder)",
    )
    fleet.add_argument(
        "--joint",
        dest="joints",
        action="append",
        type=parse_joint,
        default=[],
        metavar="NAME[=INDEX]",
        help="a joint to analyse in bags whose path or metadata names none (repeatable); "
        "INDEX: its element of a Float64MultiArray command (default: the command_index "
        "parameter)",
    )
    fleet.add_argument(
        "--replay",
        action="store_true",
        help="also replay each bag through the node's pipeline (the online estimate; slower)",
    )
    fleet.add_argument(
        "--no-diagnose", action="store_true", help="skip the discrepancy workflow (faster)"
    )
    fleet.add_argument(
        "--validation",
        type=float,
        default=0.3,
        metavar="FRACTION",
        help="fraction of each record the diagnosis holds out (default 0.3)",
    )
    fleet.add_argument(
        "--max-nrmse",
        type=_positive,
        default=0.02,
        metavar="X",
        help="a converged fit with a free-run NRMSE above X is stored as poor_fit, which the "
        "trends leave out (default 0.02)",
    )
    fleet.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_node_parameter_options(
        fleet,
        used="fleet uses model, degree, na, nb (the structure identified, and diagnose's "
        "start when any is given), joint and command_index; with --replay all of them.",
    )
    fleet.set_defaults(func=cmd_fleet)

    report = subparsers.add_parser(
        "fleet-report",
        help="wear trends from a fleet database: ranking by time to service, HTML, PNG, JSON",
        description=_REPORT_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    report.add_argument("db", metavar="DB", help="the database 'genbacklash fleet' wrote")
    report.add_argument(
        "--play-limit",
        "--gap-limit",  # its former name (the play was called the gap)
        dest="gap_limit",
        type=_positive,
        required=True,
        metavar="RAD",
        help="play c_L + c_R in rad (not mrad) at which a drivetrain needs service; "
        "--gap-limit is the same option",
    )
    report.add_argument(
        "-o",
        "--output",
        default="fleet_report",
        metavar="DIR",
        help="directory for index.html, the PNGs and summary.json (default fleet_report)",
    )
    report.add_argument(
        "--as-of",
        type=_parse_date,
        default=None,
        metavar="DATE",
        help="count days to service from DATE (default: the newest bag)",
    )
    report.add_argument(
        "--level",
        type=float,
        default=0.95,
        help="confidence level of the crossing intervals (default 0.95)",
    )
    report.add_argument("--json", action="store_true", help="print the JSON summary")
    report.set_defaults(func=cmd_fleet_report)
