"""How much of a whole record's tracking cut the node's start costs (issue 23, physics data).

The target "the node's compensation cuts the RMS load tracking error by at least the cut of a
compensator given the true play, minus 10 points" is read over the whole record. A node that
starts with nothing learns before it compensates, and every second it does not compensate
counts at the full uncompensated error. This bench measures how much of the record that
leaves to meet the target, whatever the learning method:

* ``first (s)``: when the node's compensation first moved the load. The node's loads equal
  the uncompensated run's to the bit until its first compensated command (the same
  simulation, the same commands), so this is the first reading where the two differ.
* ``true from first``: the whole-record cut of a hybrid that runs uncompensated until that
  time and then exactly as the true-play compensator does (its errors spliced in): what a
  perfect model adopted when the node adopted its first one would reach.
* ``latest start (s)``: the latest such switch-over time whose hybrid still cuts within 10
  points of the true-play compensator over the whole record (searched in 0.1 s steps). A
  node that has not compensated by then cannot meet the whole-record target however good
  its model becomes.
* the node's own cut over the record and over each quarter, against the true compensator's.

Physics data: MuJoCo drivetrains (:mod:`genbacklash_ros.physics`), the operation-shaped
motion and clocks of ``bench/physics_loop.py`` (moves, dwells, jogs; 100 Hz held commands; a
1 kHz load encoder at 4096 counts/rev with stamp jitter and 2 % loss), the command as the
node's input, its defaults (the compensation guard on, ``compensation_in_loop``).

Run: ``python bench/physics_start.py [--seeds 0 1 2] [--bandwidths 20 60 100]
[--variants near_ideal] [--duration 40]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np
from _common import (
    parse_physics_arguments,
    physics_parser,
    physics_records,
    printed_section,
    rms,
)

from genbacklash_core import compensate
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.physics.loop import Clocks, node_loop, open_loop

TARGET_POINTS = 10.0
"""The whole-record target's allowance below the true-play compensator's cut (points)."""

STEP_S = 0.1
"""The switch-over times searched for ``latest start`` (s)."""


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = physics_parser(__doc__, duration=40.0)
    parser.set_defaults(variants=["near_ideal"])
    return parse_physics_arguments(parser, argv)


def cut(error: np.ndarray, none: np.ndarray) -> float:
    """The cut of ``error`` against the uncompensated ``none`` (%)."""
    return 100.0 * (1.0 - rms(error) / rms(none))


def first_difference(a: np.ndarray, b: np.ndarray) -> int | None:
    """The first index where ``a`` and ``b`` differ, None when they never do."""
    differ = np.flatnonzero(a != b)
    return int(differ[0]) if differ.size else None


def latest_start(seconds: np.ndarray, none: np.ndarray, true: np.ndarray, need: float) -> float:
    """The latest switch-over time (s, a multiple of :data:`STEP_S`) at which running
    uncompensated before it and as ``true`` after cuts at least ``need`` % over the whole
    record; NaN when even a switch-over at 0 does not."""
    for k in range(int(seconds[-1] / STEP_S), -1, -1):
        at = k * STEP_S
        if cut(np.where(seconds < at, none, true), none) >= need:
            return at
    return float("nan")


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with (
        one_blas_thread(),
        printed_section(
            "physics_start", "### What the node's start costs the whole-record cut (physics data)"
        ),
    ):
        print(
            "| variant | bandwidth (Hz) | seed | cut true (%) | cut node (%) | first (s) "
            "| true from first (%) | latest start (s) | node / true by quarter (%) | s |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|")
        for record in physics_records(args):
            name, bw, seed = record.name, record.bandwidth, record.seed
            params, truth = record.params, record.truth
            began = time.perf_counter()
            clocks = Clocks(seed, args.duration)
            seconds = (clocks.t - clocks.t[0]) / 1e9
            plain = open_loop(params, clocks, clocks.values)
            none = plain - clocks.desired
            true_commands = compensate(truth.model, clocks.values)
            true = open_loop(params, clocks, true_commands) - clocks.desired
            loads, _, _, _ = node_loop(params, clocks, guard=True)
            node = loads - clocks.desired
            index = first_difference(loads, plain)
            first = float("nan") if index is None else float(seconds[index])
            spliced = (
                float("nan") if index is None else cut(np.where(seconds < first, none, true), none)
            )
            need = cut(true, none) - TARGET_POINTS
            quarters = np.minimum((4 * seconds / seconds[-1]).astype(int), 3)
            by_quarter = ", ".join(
                f"{cut(node[quarters == q], none[quarters == q]):.0f} / "
                f"{cut(true[quarters == q], none[quarters == q]):.0f}"
                for q in range(4)
            )
            print(
                f"| {name} | {bw:g} | {seed} | {cut(true, none):.1f} "
                f"| {cut(node, none):.1f} | {first:.2f} | {spliced:.1f} "
                f"| {latest_start(seconds, none, true, need):.1f} | {by_quarter} "
                f"| {time.perf_counter() - began:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
