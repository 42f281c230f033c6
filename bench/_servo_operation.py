"""The servo model on operation-shaped data, which has no servo (issue 23; a helper run by
hand, its table kept in BENCHMARKS.md by hand).

The operation scenario (``genbacklash_core.scenarios.operation_record``: moves, dwells, jogs;
100 Hz held commands; a 1 kHz encoder at 4096 counts/rev, stamp jitter, 2 % loss; the
mildly curved ``OPERATION_BACKLASH``) holds the play operator of the paper with the command
as its input: no servo between them. ``servo_model=auto`` should find no dead time or lag
there and change nothing. Each seed goes through the node's pipeline (its defaults: the
windowed identifier) message by message, as ``bench/operation.py`` feeds it (its
``run_pipeline``), once with ``servo_model=none`` and once with ``auto``:

* the final play ``c_L + c_R`` against the true play, and the final estimate's free-run
  NRMSE against the noise-free truth (as ``bench/operation.py`` reads it);
* the compensated commands the node published, applied to the true drivetrain: the RMS load
  tracking error's cut over the second half, against no compensation;
* with ``auto``: the servo it estimated (dead time, time constant).

Run: ``python bench/_servo_operation.py [--seeds 0 1 2 3 4 5] [--duration 60]``
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from operation import run_pipeline

from genbacklash_core.scenarios import OperationSettings, operation_record


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    parser.add_argument("--duration", type=float, default=60.0)
    args = parser.parse_args(argv)
    print(
        "| seed | true play (mrad) | play none / auto (mrad) | auto / none | NRMSE vs truth "
        "none / auto | 2nd-half cut none / auto (%) | servo found: dead time, lag (ms) "
        "| s none / auto |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for seed in args.seeds:
        rec = operation_record(OperationSettings(duration=args.duration), seed)
        true_play = float(rec.c_left[-1] + rec.c_right[-1])
        none = run_pipeline(rec, "windowed", servo_model="none")
        auto = run_pipeline(rec, "windowed", servo_model="auto")
        servo = auto["servo"]
        found = (
            f"{1e3 * float(servo['dead_time']):.3f}, {1e3 * float(servo['time_constant']):.3f}"
            if isinstance(servo, dict) and "dead_time" in servo
            else str(servo)
        )
        print(
            f"| {seed} | {1e3 * true_play:.2f} "
            f"| {1e3 * float(none['play']):.2f} / {1e3 * float(auto['play']):.2f} "
            f"| {float(auto['play']) / float(none['play']):.4f} "
            f"| {float(none['nrmse']):.5f} / {float(auto['nrmse']):.5f} "
            f"| {100 * float(none['cut']):.1f} / {100 * float(auto['cut']):.1f} | {found} "
            f"| {float(none['seconds']):.1f} / {float(auto['seconds']):.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
