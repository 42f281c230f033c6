"""The play c_L + c_R found on physics drivetrains, online and batch (issue 23, targets).

For each variant, servo bandwidth and seed, a bag of a MuJoCo drivetrain
(:mod:`genbacklash_ros.physics`) in operation (moves, dwells, jogs; 100 Hz held commands; a
1 kHz load encoder at 4096 counts/rev, stamp jitter, 2 % loss; no compensation) is

* replayed through the node (``genbacklash replay``'s pipeline, defaults), and
* identified in batch (``genbacklash identify`` on the bag, defaults: degree 3, the node's
  rows),

and the play of each is compared with the geometric play of the slot (and with each
other). The CLI is run in process (``genbacklash_ros.cli.main.main``) so the numbers are the
commands' own.

With ``--motor-encoder`` the bags also hold a motor encoder (``/motor_encoder``: the rotor,
sampled with the load encoder, its own 2 % lost) and both commands take it as the gear's
input (``--motor-encoder /motor_encoder``: the node's ``gear_input`` motor_encoder, no
settling rule).

Run: ``python bench/physics_accuracy.py [--seeds 0 1 2] [--bandwidths 20 60 100]
[--variants ...] [--duration 40] [--param NAME=VALUE ...] [--motor-encoder]``
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
from pathlib import Path

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.cli.main import main as genbacklash
from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.variants import VARIANTS, variant

TOPICS = ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"]


def _run(args: list[str]) -> dict[str, object]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        genbacklash(args)
    return dict(json.loads(out.getvalue()))


def _play(result: dict[str, object]) -> float:
    """c_L + c_R of identify's JSON or of replay's (its ``model`` holds the same shape)."""
    shape = result.get("model") if "backlash" not in result else result
    assert isinstance(shape, dict)
    bl = shape["backlash"]
    assert isinstance(bl, dict)
    return float(bl["c_left"]) + float(bl["c_right"])


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--bandwidths", type=float, nargs="+", default=[20.0, 60.0, 100.0])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS))
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument(
        "--motor-encoder",
        action="store_true",
        help="the motor encoder as the gear's input (replay and identify --motor-encoder)",
    )
    args = parser.parse_args()
    extra = [w for p in args.param for w in ("--param", p)]
    if args.motor_encoder:
        extra += ["--motor-encoder", "/motor_encoder"]
    input_label = " (motor encoder)" if args.motor_encoder else ""
    print(
        f"| variant | bandwidth (Hz) | seed | geometric play (mrad) | online{input_label} / "
        f"geometric | batch{input_label} / geometric | online / batch | s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.variants:
            for bw in args.bandwidths:
                params = variant(name, bandwidth=bw)
                geometric = params.c_left + params.c_right
                for seed in args.seeds:
                    start = time.perf_counter()
                    bag = Path(tmp) / f"{name}-{bw:g}-{seed}"
                    write_physics_bag(
                        bag,
                        params,
                        OperationSettings(duration=args.duration),
                        seed,
                        motor_encoder=args.motor_encoder,
                    )
                    online = _play(
                        _run(
                            [
                                "replay",
                                str(bag),
                                *TOPICS,
                                "-o",
                                str(bag) + "-out",
                                "--json",
                                "--no-progress",
                                *extra,
                            ]
                        )
                    )
                    batch = _play(_run(["identify", str(bag), *TOPICS, "--json", *extra]))
                    print(
                        f"| {name} | {bw:g} | {seed} | {1e3 * geometric:.1f} "
                        f"| {online / geometric:.3f} | {batch / geometric:.3f} "
                        f"| {online / batch:.3f} | {time.perf_counter() - start:.1f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
