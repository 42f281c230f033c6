"""CSV vs bag: identify on a physics bag and on a CSV of its readings (issue 23, target).

For each variant and seed a bag of a MuJoCo drivetrain in operation (the physics section's
records: 60 Hz servo by default, 100 Hz held commands, a 1 kHz encoder with 2 % loss) is
written, its readings exported with ``genbacklash readings``, and ``genbacklash identify
--json`` (defaults: a backlash of degree 3) run on both, in process. Reported: the play
``c_L + c_R`` of each and the largest absolute difference of any number in the two JSON
outputs. "Before" is the CSV read as the CSV path read it before the rows had one owner (the
stamps' breaks only: no settling rule, no bridging; ``read_series_csv`` without the rules),
identified the same way.

Run: ``python bench/csv_vs_bag.py [--seeds 0 1 2] [--variants ...] [--duration 40]``
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from collections.abc import Sequence
from pathlib import Path

from _common import PHYSICS_TOPICS, cli_json, json_play, printed_section

from genbacklash_core import identify_backlash
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.csvio import read_series_csv
from genbacklash_ros.cli.main import main as genbacklash
from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.variants import VARIANTS, variant


def _max_difference(a: object, b: object) -> float:
    """The largest |a - b| over the numbers of two JSON values of the same shape (inf where
    the shapes differ)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            return float("inf")
        return max((_max_difference(a[k], b[k]) for k in a), default=0.0)
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return float("inf")
        return max((_max_difference(x, y) for x, y in zip(a, b, strict=True)), default=0.0)
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        return 0.0 if a == b else float("inf")
    if isinstance(a, int | float) and isinstance(b, int | float):
        return abs(float(a) - float(b))
    return 0.0 if a == b else float("inf")


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS))
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--bandwidth", type=float, default=None, help="servo bandwidth, Hz")
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a node parameter for both identify runs (e.g. servo_model=auto)",
    )
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.variants, args.duration = [0], ["near_ideal"], 10.0
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section("csv_vs_bag", "### CSV vs bag"):
        _tables(args)


def _tables(args: argparse.Namespace) -> None:
    extra = [w for p in args.param for w in ("--param", p)]
    print(
        "| variant | seed | play, bag (mrad) | play, CSV (mrad) | max abs difference, any "
        "JSON number | before: play, CSV (mrad) | before: CSV - bag (mrad) |"
    )
    print("|---|---|---|---|---|---|---|")
    worst_play = worst_any = worst_before = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.variants:
            params = variant(
                name, **({} if args.bandwidth is None else {"bandwidth": args.bandwidth})
            )
            for seed in args.seeds:
                bag = Path(tmp) / f"{name}-{seed}"
                csv = Path(tmp) / f"{name}-{seed}.csv"
                write_physics_bag(bag, params, OperationSettings(duration=args.duration), seed)
                with contextlib.redirect_stderr(io.StringIO()):
                    genbacklash(["readings", str(bag), *PHYSICS_TOPICS, "-o", str(csv)])
                from_bag = cli_json(["identify", str(bag), *PHYSICS_TOPICS, "--json", *extra])
                from_csv = cli_json(["identify", str(csv), "--json", *extra])
                old = read_series_csv(csv)  # the stamps' breaks only: the CSV path before
                before = identify_backlash(old.u, old.y, 3, breaks=old.breaks).model
                play_bag, play_csv = json_play(from_bag), json_play(from_csv)
                play_before = before.c_left + before.c_right
                worst_play = max(worst_play, abs(play_csv - play_bag))
                worst_any = max(worst_any, _max_difference(from_bag, from_csv))
                worst_before = max(worst_before, abs(play_before - play_bag))
                print(
                    f"| {name} | {seed} | {1e3 * play_bag:.4f} | {1e3 * play_csv:.4f} | "
                    f"{_max_difference(from_bag, from_csv):.1e} | {1e3 * play_before:.4f} | "
                    f"{1e3 * (play_before - play_bag):+.4f} |",
                    flush=True,
                )
    print()
    print(
        f"max |play, CSV - play, bag| = {worst_play:.1e} rad over {len(args.variants)} variants "
        f"x {len(args.seeds)} seeds (any JSON number: {worst_any:.1e}); before: "
        f"{1e3 * worst_before:.2f} mrad"
    )


if __name__ == "__main__":
    main()
