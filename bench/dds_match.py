"""DDS match: commands lost after a running rclpy (Fast DDS) publisher matches the DDS node.

    python bench/dds_match.py [--quick] [--trials N] [--rate HZ] [--seconds S]

Per trial, on a DDS domain of its own: ``tests/ros/transports/match_player.py`` (rclpy from the
ROS 2 wheels, Fast DDS) starts and publishes a ``Float64MultiArray`` command and a
``JointState`` reading at ``rate`` Hz; 0.5 s later ``genbacklash node --transport dds`` is
started as its own process, as a node joins a running robot. From the first tick at which the
player counts the node's subscription (``get_subscription_count``, checked before every
command) it publishes for ``seconds`` more without a pause; a command is lost when no
``compensated_command`` with its sequence number came back (also reported: the median reply
latency). Writes ``bench/output/dds_match.md``. Default 10 trials at 1 kHz, 1.2 s
each (``--quick``: 3).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import ROOT, command_line, machine_description, md_table, write_section

sys.path.insert(0, str(ROOT))
from tests.ros.transports._dds import match_trial
from tests.ros.transports._ros2 import domain_id

PARAMS = "/**:\n  ros__parameters:\n    command_type: float64_multi_array\n    joint: j\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3 trials")
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seconds", type=float, default=1.2)
    args = parser.parse_args(argv)
    trials = 3 if args.quick else args.trials
    started = time.perf_counter()
    rows: list[list[object]] = []
    lost_counts: list[int] = []
    with tempfile.TemporaryDirectory(prefix="dds_match_") as tmp_name:
        tmp = Path(tmp_name)
        params = tmp / "params.yaml"
        params.write_text(PARAMS)
        for i in range(trials):
            log = tmp / f"node{i}.log"
            summary, status = match_trial(
                domain_id(), params, log, rate=args.rate, seconds=args.seconds
            )
            sent = summary["k_last"] - summary["k_match"] + 1
            lost = summary["lost"]
            lost_counts.append(len(lost))
            span = (
                f"{lost[0] - summary['k_match']}-{lost[-1] - summary['k_match']}" if lost else "-"
            )
            latency = summary["latency_ms"]
            rows.append(
                [
                    i + 1,
                    sent,
                    len(lost),
                    span,
                    f"{latency:.2f}" if latency is not None else "-",
                    status,
                ]
            )
            print(f"trial {i + 1}: {len(lost)} of {sent} lost, node exit {status}", flush=True)
    seconds = time.perf_counter() - started
    table = md_table(
        [
            "trial",
            "commands after the match",
            "lost",
            "lost commands (index after the match)",
            "reply latency, median (ms)",
            "node exit",
        ],
        rows,
    )
    total = int(np.sum(lost_counts))
    print(table)
    write_section(
        "dds_match",
        f"""## DDS match (issue 24)

`{command_line()}`. Machine: {machine_description()}. Run time {seconds:.0f} s.

An rclpy publisher (Fast DDS) already publishing a command and a reading at
{args.rate:.0f} Hz; `genbacklash node --transport dds` started 0.5 s later as its own process;
from the tick at which the publisher counts the node's subscription it keeps publishing for
{args.seconds:g} s. Lost: commands from that tick on without a `compensated_command`.

{table}

In all: {total} of {sum(int(r[1]) for r in rows)} lost over {trials} trials
(target: 0 lost).
""",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
