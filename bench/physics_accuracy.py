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
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from _common import (
    PHYSICS_TOPICS,
    cli_json,
    json_play,
    parse_physics_arguments,
    physics_parser,
    printed_section,
)

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.variants import variant

# the head of BENCHMARKS.md's physics section (this script's part comes first in run_all.py;
# csv_vs_bag, physics_loop and physics_diagnose add their subsections after it)
PHYSICS_HEADING = "## Physics drivetrains (issue 23)"
PHYSICS_INTRO = """
What is measured: drivetrains simulated by a rigid-body engine (MuJoCo, `genbacklash_ros.physics`),
not by the play operator. A PD position servo (bandwidth 20, 60 or 100 Hz, critically damped on
the engaged inertia, torque limit 10 N m) drives a rotor of 2e-3 kg m^2; a pin on the rotor sits
in a slot of the load with 4 degrees of play (geometric c_L 32.4 mrad, c_R 37.4 mrad, play 69.8
mrad), contact stiff and frictionless. The variants (`genbacklash_ros.physics.variants`):

| variant | load inertia (kg m^2) | Coulomb (N m) | viscous (N m s/rad) | besides |
|---|---|---|---|---|
| near_ideal | 2e-4 | 0.4 | 0.02 | rigid: the load stops with the motor |
| coasting | 2e-3 | 0.01 | 0.001 | rigid: the load coasts into the play when the motor stops |
| compliant | 1e-3 | 0.02 | 0.005 | a spring of 20 N m/rad after the play (rings at ~22 Hz) |
| gravity | 1e-3 | 0.1 | 0.01 | m g l = 0.12 N m: one flank held where abs(q) < 0.59 rad |

Inputs: the operation scenario's motion and clocks on them (moves between targets, dwells,
jogs; commands held at 100 Hz with 1 ms jitter; a 1 kHz load encoder at 4096 counts/rev with
stamp jitter and 2 % of readings lost), integrated at 4 kHz.

Each record below is written as a bag, then replayed (`genbacklash replay`: the node's pipeline,
defaults) and identified in batch (`genbacklash identify`, defaults: degree 3); the play of each
is compared with the geometric play.
"""

SUBSECTION = "### The play found, online and in batch (no compensation in the record)"


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = physics_parser(__doc__, duration=40.0)
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument(
        "--motor-encoder",
        action="store_true",
        help="the motor encoder as the gear's input (replay and identify --motor-encoder)",
    )
    args = parse_physics_arguments(parser, argv)
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section(
        "physics_accuracy",
        f"{PHYSICS_HEADING}\n\n{PHYSICS_INTRO.strip()}\n\n{SUBSECTION}",
    ):
        _tables(args)


def _tables(args: argparse.Namespace) -> None:
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
                    online = json_play(
                        cli_json(
                            [
                                "replay",
                                str(bag),
                                *PHYSICS_TOPICS,
                                "-o",
                                str(bag) + "-out",
                                "--json",
                                "--no-progress",
                                *extra,
                            ]
                        )
                    )
                    batch = json_play(
                        cli_json(["identify", str(bag), *PHYSICS_TOPICS, "--json", *extra])
                    )
                    print(
                        f"| {name} | {bw:g} | {seed} | {1e3 * geometric:.1f} "
                        f"| {online / geometric:.3f} | {batch / geometric:.3f} "
                        f"| {online / batch:.3f} | {time.perf_counter() - start:.1f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
