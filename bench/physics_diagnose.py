"""Does ``diagnose`` name a physics drivetrain's dominant effect first? (issue 23, targets)

For each variant, servo bandwidth and seed a MuJoCo drivetrain (:mod:`genbacklash_ros.physics`)
runs the operation scenario (moves, dwells, jogs; 100 Hz held commands; a 1 kHz load encoder
at 4096 counts/rev with jitter and 2 % loss) and is written as a bag with a motor encoder. The
bag is read as ``genbacklash diagnose BAG --command /command --encoder /encoder --joint
drive_joint`` reads it (:func:`~genbacklash_ros.bags.bagio.read_aligned`, the node's samples
and breaks) and diagnosed with the command's defaults; the first named effect is compared with
the variant's dominant effect:

============ ===================================================================
variant      dominant effect (named first)
============ ===================================================================
near_ideal   the servo between the command and the gear: ``time_delay`` or
             ``input_lag`` (``linear_dynamics``, a lag after the play, is
             counted apart: the servo sits before it)
coasting     ``coasting_load``
compliant    ``compliant_coupling``
gravity      ``load_torque``
============ ===================================================================

The near-ideal drivetrain is also diagnosed with its motor encoder as the input
(``--command /motor_encoder``): there the play operator is the whole story, and nothing should
be named. Last, operation-shaped records of the core's scenario
(:func:`~genbacklash_core.diagnose.synthetic.operation_case`, clean and with a servo lag) must
not be given a physical name.

``--max-steps 1`` (the default here) stops the loop after its first accepted effect (the
first round with its tie-break; the pairs' look-ahead needs two steps): the target is about
the first name, and later rounds cost minutes a record on this machine. ``--max-steps 6`` is
the command's own setting.

Run: ``python bench/physics_diagnose.py [--quick] [--seeds 0 1 2] [--bandwidths 20 60 100]
[--variants ...] [--duration 30] [--max-steps 1] [--jobs 2] [--operation-seeds 0 1 2]
[--motor-bandwidths 20 60 100]`` (records run seed by seed, bandwidth by bandwidth, and print
as they finish)
"""

from __future__ import annotations

import os

# one BLAS thread (as bench/diagnose.py): on a shared machine a multi-threaded BLAS spins
# against the other processes, and the fits' least-squares steps take several times longer
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from _common import parse_physics_arguments, physics_parser, printed_section

from genbacklash_core.diagnose import DiagnoseSettings, diagnose, operation_case
from genbacklash_core.diagnose.physics import PHYSICS_NAMES
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.bagio import read_aligned
from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.variants import variant

DOMINANT: dict[str, tuple[str, ...]] = {
    "near_ideal": ("time_delay", "input_lag"),
    "coasting": ("coasting_load",),
    "compliant": ("compliant_coupling",),
    "gravity": ("load_torque",),
}
SERVO_AFTER = ("linear_dynamics",)  # a lag named after the play: counted apart


def _diagnose_bag(
    bag: Path, command: str, max_steps: int
) -> tuple[tuple[str, ...], float, float, float]:
    series = read_aligned(bag, command, "/encoder", joint="drive_joint")
    result = diagnose(
        series.u,
        series.y,
        settings=DiagnoseSettings(max_steps=max_steps),
        breaks=series.breaks,
    )
    return result.effects, result.gap_initial, result.gap_final, result.floor.gap


def _record(job: tuple[str, float, int, float, int, str, bool]) -> str:
    name, bandwidth, seed, duration, max_steps, tmp, motor = job
    start = time.perf_counter()
    bag = Path(tmp) / f"{name}-{bandwidth:g}-{seed}"
    write_physics_bag(
        bag,
        variant(name, bandwidth=bandwidth),
        OperationSettings(duration=duration),
        seed,
        motor_encoder=True,
    )
    named, before, after, floor = _diagnose_bag(bag, "/command", max_steps)
    first = named[0] if named else "-"
    verdict = "yes" if first in DOMINANT[name] else "no"
    if name == "near_ideal" and first in SERVO_AFTER:
        verdict = "no (lag after)"
    row = (
        f"| {name} | {bandwidth:g} | {seed} | command | {', '.join(named) or '-'} | {verdict} "
        f"| {before:.4f} | {after:.4f} | {floor:.5f} "
    )
    rows = [row + f"| {time.perf_counter() - start:.0f} |"]
    if name == "near_ideal" and motor:
        start = time.perf_counter()
        named, before, after, floor = _diagnose_bag(bag, "/motor_encoder", max_steps)
        verdict = "yes" if not named else "no"
        rows.append(
            f"| {name} | {bandwidth:g} | {seed} | motor encoder | {', '.join(named) or '-'} "
            f"| {verdict} | {before:.4f} | {after:.4f} | {floor:.5f} "
            f"| {time.perf_counter() - start:.0f} |"
        )
    return "\n".join(rows)


def _operation(job: tuple[tuple[str, ...], int, int]) -> str:
    effects, seed, max_steps = job
    start = time.perf_counter()
    case = operation_case(effects, seed)
    result = diagnose(
        case.u, case.y, settings=DiagnoseSettings(max_steps=max_steps), breaks=case.breaks
    )
    named = result.effects
    false = [n for n in named if n in PHYSICS_NAMES]
    return (
        f"| {', '.join(effects) or 'clean'} | {seed} | {', '.join(named) or '-'} "
        f"| {'yes' if not false else 'no'} | {time.perf_counter() - start:.0f} |"
    )


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = physics_parser(__doc__, duration=30.0)
    parser.add_argument("--max-steps", type=int, default=1)
    parser.add_argument(
        "--motor-bandwidths",
        type=float,
        nargs="*",
        default=[20.0, 60.0, 100.0],
        help="bandwidths at which near_ideal is also diagnosed with the motor encoder as input",
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--operation-seeds", type=int, nargs="*", default=[0, 1, 2])
    args = parse_physics_arguments(parser, argv)
    if args.quick:
        args.motor_bandwidths, args.operation_seeds = [], []
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section(
        "physics_diagnose",
        "### diagnose names the dominant effect (issue 23, deliverable 4)",
    ):
        _tables(args)


def _tables(args: argparse.Namespace) -> None:
    print(
        "| variant | bandwidth (Hz) | seed | input | named | dominant first | misfit before "
        "| misfit after | floor | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(args.jobs) as pool:
        jobs = [
            (name, bw, seed, args.duration, args.max_steps, tmp, bw in args.motor_bandwidths)
            for seed in args.seeds
            for bw in args.bandwidths
            for name in args.variants
        ]
        for future in as_completed([pool.submit(_record, job) for job in jobs]):
            print(future.result(), flush=True)  # as each finishes: sort the table after
        if args.operation_seeds:
            print()
            print("| operation record | seed | named | no physical name | s |")
            print("|---|---|---|---|---|")
            operation_jobs = [
                (effects, seed, args.max_steps)
                for effects in ((), ("input_lag",))
                for seed in args.operation_seeds
            ]
            for done in as_completed([pool.submit(_operation, job) for job in operation_jobs]):
                print(done.result(), flush=True)


if __name__ == "__main__":
    main()
