"""Shutdown: SIGINT/SIGTERM at random moments while the node is fed at 1 kHz (issue 24).

    python bench/shutdown.py [--quick] [--trials N] [--transport rclpy|dds] [--seed S]
                             [--thread-priority P]

A feeder process (rclpy, Fast DDS) publishes a command and a reading at 1 kHz; for each trial
``genbacklash node`` is started as its own process, and once the feeder sees it subscribed it
gets, after a random 0-1.5 s, a SIGINT, a SIGTERM, two SIGINTs 0-500 ms apart or a SIGTERM
then a SIGINT 0-500 ms apart. A trial is clean when the node exits 0 with no "Traceback" on
stderr. Prints the counts per kind (and each unclean trial's stderr tail) and writes
``bench/output/shutdown.md`` (``shutdown_dds.md`` for ``--transport dds``). ``--trials`` per
kind (default 50; ``--quick`` 5). About 2 s a trial: 7 minutes for 50 of each kind.
``--thread-priority P`` runs the node with ``thread_priority: P`` (identification in a child
process); a trial is then clean only if that child has ended too, within 5 s of the node
(``bench/output/shutdown_priority.md``).
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from _common import ROOT, command_line, machine_description, md_table, write_section

sys.path.insert(0, str(ROOT))
from tests.ros.transports._ros2 import domain_id
from tests.ros.transports._shutdown import KINDS, Feeder, trial, write_params


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="5 trials of each kind")
    parser.add_argument("--trials", type=int, default=50, help="trials of each kind")
    parser.add_argument("--transport", choices=("rclpy", "dds"), default="rclpy")
    parser.add_argument("--seed", type=int, default=24)
    parser.add_argument("--thread-priority", type=int, default=0, metavar="P", help="0-99")
    args = parser.parse_args()
    trials = 5 if args.quick else args.trials
    rng = random.Random(args.seed)
    plan: list[tuple[str, float, float]] = []
    for _ in range(trials):
        plan += [(kind, rng.uniform(0.0, 1.5), rng.uniform(0.0, 0.5)) for kind in KINDS]
    clean: Counter[str] = Counter()
    codes: dict[str, Counter[int]] = {kind: Counter() for kind in KINDS}
    started = time.perf_counter()
    feeder = Feeder(domain_id())
    try:
        with tempfile.TemporaryDirectory() as tmp:
            params = write_params(Path(tmp), args.thread_priority)
            for i, (kind, delay, gap) in enumerate(plan):
                outcome = trial(feeder, args.transport, params, kind, delay, gap)
                codes[kind][outcome.returncode] += 1
                if outcome.clean:
                    clean[kind] += 1
                else:
                    print(f"trial {i}: {outcome.describe()}", file=sys.stderr)
    finally:
        feeder.close()
    seconds = time.perf_counter() - started
    rows = [
        [
            kind,
            f"{clean[kind]} / {trials}",
            ", ".join(f"{code}: {n}" for code, n in sorted(codes[kind].items())),
        ]
        for kind in KINDS
    ]
    table = md_table(["signals", "exit 0, no traceback", "exit codes"], rows)
    print(table)
    name = "shutdown" if args.transport == "rclpy" else f"shutdown_{args.transport}"
    title = args.transport
    if args.thread_priority:
        name += "_priority"
        title += f", thread_priority {args.thread_priority} (no child process left)"
    write_section(
        name,
        f"""## Shutdown, {title} (issue 24)

`{command_line()}`. Machine: {machine_description()}. Run time {seconds:.0f} s.

`genbacklash node --transport {args.transport}` as its own process, fed a command and a
reading at 1 kHz by an rclpy process; the signal(s) come 0-1.5 s after the node subscribed
(the second 0-500 ms after the first).

{table}

Target - 50 of 50 exit 0 with no traceback, for every kind.
""",
    )


if __name__ == "__main__":
    main()
