"""How much a physics record's tracking cut moves when nothing is compensated (issue 23).

The first-rule target reads each record's cut ``1 - rms(e_node) / rms(e_none)``: the node's
compensated run against the same commands run uncompensated. On drivetrains with Coulomb
friction a load's state after a stick-slip episode depends on the smallest difference in
what drove it, so two runs that differ by far less than the encoder resolves can end in
different states and track differently for the rest of the record. This bench measures that
floor directly: for each record the same commands are run again with a *null perturbation*
(``--amplitude`` rad, default 1 µrad, a thousandth of an encoder count, added to the commands
over ``--window`` seconds starting at a seeded random time in ``[--earliest, --latest]`` s),
``--draws`` times, and each null run's "cut" against the unperturbed run is reported like a
compensator's: whole record and second half. A compensated run's cut between the null runs'
extremes is not distinguishable from the chaos of the drivetrain itself.

Physics data: MuJoCo drivetrains (:mod:`genbacklash_ros.physics`), the operation-shaped
motion and clocks of ``bench/physics_loop.py`` (moves, dwells, jogs; 100 Hz held commands; a
1 kHz load encoder at 4096 counts/rev with stamp jitter and 2 % loss).

Run: ``python bench/physics_null.py [--seeds 0 1 2] [--bandwidths 20 60 100]
[--variants ...] [--duration 40] [--draws 4] [--amplitude 1e-6] [--window 4]
[--earliest 4] [--latest 20]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np
from _common import parse_physics_arguments, physics_parser, printed_section, rms

from genbacklash_ros.physics.loop import Clocks, open_loop
from genbacklash_ros.physics.variants import VARIANTS, variant


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = physics_parser(__doc__, duration=40.0)
    parser.add_argument("--draws", type=int, default=4, help="null runs per record")
    parser.add_argument("--amplitude", type=float, default=1e-6, help="rad added (default 1e-6)")
    parser.add_argument("--window", type=float, default=4.0, help="seconds it is added over")
    parser.add_argument("--earliest", type=float, default=4.0, help="earliest start (s)")
    parser.add_argument("--latest", type=float, default=20.0, help="latest start (s)")
    return parse_physics_arguments(parser, argv)


def null_cuts(
    name: str, bandwidth: float, seed: int, args: argparse.Namespace
) -> tuple[list[float], list[float]]:
    """Each null run's cut against the unperturbed run, whole record and second half (%)."""
    params = variant(name, bandwidth=bandwidth)
    clocks = Clocks(seed, args.duration)
    none = open_loop(params, clocks, clocks.values) - clocks.desired
    half = clocks.t >= clocks.t[-1] // 2
    rng = np.random.default_rng([seed, round(bandwidth), list(VARIANTS).index(name)])
    whole, second = [], []
    for _ in range(args.draws):
        start = rng.uniform(args.earliest, args.latest)
        inside = (clocks.cmd_t >= start * 1e9) & (clocks.cmd_t < (start + args.window) * 1e9)
        values = np.where(inside, clocks.values + args.amplitude, clocks.values)
        e = open_loop(params, clocks, values) - clocks.desired
        whole.append(100 * (1 - rms(e) / rms(none)))
        second.append(100 * (1 - rms(e[half]) / rms(none[half])))
    return whole, second


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section("physics_null", "### The cut's floor: null perturbations (physics data)"):
        print(
            f"Null perturbations: {args.amplitude:g} rad over {args.window:g} s from a "
            f"random start in [{args.earliest:g}, {args.latest:g}] s, {args.draws} per record; "
            f"{args.duration:g} s records.\n"
        )
        print(
            "| variant | bandwidth (Hz) | seed | null cuts, whole record (%) "
            "| null cuts, 2nd half (%) | worst whole / 2nd half (%) | s |"
        )
        print("|---|---|---|---|---|---|---|")
        for name in args.variants:
            for bw in args.bandwidths:
                for seed in args.seeds:
                    began = time.perf_counter()
                    whole, second = null_cuts(name, bw, seed, args)
                    print(
                        f"| {name} | {bw:g} | {seed} "
                        f"| {', '.join(f'{c:+.1f}' for c in whole)} "
                        f"| {', '.join(f'{c:+.1f}' for c in second)} "
                        f"| {min(whole):+.1f} / {min(second):+.1f} "
                        f"| {time.perf_counter() - began:.1f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
