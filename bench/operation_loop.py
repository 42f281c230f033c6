"""The node's pipeline in the loop on operation-shaped data (not physics; issue 23).

The operation scenario's motion and clocks (:class:`~genbacklash_ros.physics.loop.Clocks`:
moves, dwells, jogs; 100 Hz held commands with jitter; a 1 kHz load encoder with stamp
jitter, quantised at 4096 counts/rev, 2 % of the readings lost) drive a play-operator
drivetrain: the scenario's :data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`, eq. (20)
on each command the servo took, the load held between commands (no servo dynamics). Three
ways, as ``bench/physics_loop.py``: ``none`` (the commands as they are), ``true`` (through
the inverse of the true model) and ``node`` (the node's
:class:`~genbacklash_ros.node.pipeline.BacklashPipeline` with ``compensation_in_loop``, fed
each command and each reading as they happen; its compensated command is what the
drivetrain takes).

With ``--seeded-start OFFSET`` the node starts from ``genbacklash identify BAG --checkpoint
FILE`` on seed ``seed + OFFSET`` of the scenario written as a bag without compensation
(:func:`~genbacklash_ros.bags.simbags.write_operation_bag`, the same drivetrain); the
checkpoint holds that record's tracking without compensation (the judge's offline
baseline). ``--baseline-scale X`` multiplies it by ``X`` (a robustness run).

With ``--restart OFFSET`` the node is restarted from its own checkpoint, as
``bench/physics_loop.py --restart``: a fresh node on seed ``seed`` writes its checkpoints,
then a second node starts from the final one on seed ``seed + OFFSET``'s motion; the table
gives that second record's cuts and what the checkpoint carried (the live baseline, a
standing verdict of harm, or neither).

The numbers: the RMS load tracking error against no compensation, whole record and second
half, in percent; the judge's final state, ratio and which baseline it judged against.

``--param NAME=VALUE`` sets a node parameter of every node run (e.g. ``servo_model=auto``).

Run: ``python bench/operation_loop.py [--seeds 0 1 2 3 4 5] [--duration 40]
[--seeded-start OFFSET] [--baseline-scale X] [--restart OFFSET] [--param NAME=VALUE ...]``
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from _common import PHYSICS_TOPICS, cli_json, param_values, printed_section, rms

from genbacklash_core import compensate, simulate_backlash
from genbacklash_core.scenarios import OPERATION_BACKLASH, OperationSettings
from genbacklash_ros.bags.simbags import write_operation_bag
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.node.checkpoint import load_checkpoint, save_checkpoint
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.physics.loop import Clocks


def _loads(clocks: Clocks, sent: np.ndarray) -> np.ndarray:
    """The load at every encoder instant: the play operator on the commands taken, held."""
    x = simulate_backlash(OPERATION_BACKLASH, sent, x0=float(sent[0]))
    k = np.maximum(np.searchsorted(clocks.cmd_t, clocks.t, side="right") - 1, 0)
    return x[k]


def _node(clocks: Clocks, extra: dict[str, object]) -> tuple[np.ndarray, BacklashPipeline]:
    """The pipeline in the loop: each command answered, the load moved by its answer, each
    reading that arrives (quantised) fed as it happens."""
    pipe = BacklashPipeline(
        NodeParameters.from_mapping(
            {
                "command_type": "float64",
                "encoder_type": "float64",
                "compensation_in_loop": True,
                **extra,
            }
        )
    )
    values, cmd_t, t, q = clocks.values, clocks.cmd_t, clocks.t, clocks.quantum
    loads = np.empty(t.size)
    x, j = float(values[0]), 0
    for k in range(values.size):
        got = pipe.on_command_value(None, float(values[k]), int(cmd_t[k]))
        sent = float(values[k]) if got is None else got[1]
        x = float(simulate_backlash(OPERATION_BACKLASH, [sent], x0=x)[0])
        end = int(cmd_t[k + 1]) if k + 1 < values.size else int(t[-1]) + 1
        stop = int(np.searchsorted(t, end, side="left"))
        loads[j:stop] = x
        for i in range(j, stop):
            if clocks.received[i]:
                pipe.on_encoder_value(None, float(np.round(x / q) * q), int(t[i]))
        j = stop
    pipe.finish(refit=False)
    return loads, pipe


def _start(args: argparse.Namespace, seed: int, folder: Path) -> tuple[Path, float]:
    """identify's checkpoint on seed ``seed + OFFSET`` of the scenario; its offline
    baseline (rad rms, NaN: none)."""
    offline = seed + args.seeded_start
    bag = folder / f"operation-{offline}"
    if not bag.exists():
        write_operation_bag(bag, OperationSettings(duration=args.duration), offline)
    start = folder / f"operation-{offline}.json"
    cli_json(["identify", str(bag), *PHYSICS_TOPICS, "--json", "--checkpoint", str(start)])
    saved = load_checkpoint(start)
    base = saved.baseline
    if base is not None and args.baseline_scale != 1.0:
        base = dataclasses.replace(base, rms=base.rms * args.baseline_scale)
        save_checkpoint(start, dataclasses.replace(saved, baseline=base))
    return start, base.rms if base is not None else float("nan")


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--seeded-start", type=int, default=None, metavar="OFFSET")
    parser.add_argument("--baseline-scale", type=float, default=1.0, metavar="X")
    parser.add_argument("--restart", type=int, default=None, metavar="OFFSET")
    parser.add_argument("--quick", action="store_true", help="seed 0, 10 s (a smoke test)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.duration = [0], 10.0
    seeded = args.seeded_start is not None
    with (
        printed_section(
            "operation_loop",
            "### The node's pipeline in the loop on operation-shaped data (not physics)",
        ),
        one_blas_thread(),  # as the node runs
    ):
        print(
            "| seed | rms none (mrad) | cut true (%) | cut node (%) | 2nd half: true / node (%) "
            "| measured (state, ratio) | judged against |"
            + (" offline / none (mrad) |" if seeded else "")
            + (" checkpoint carried |" if args.restart is not None else "")
            + " s |"
        )
        print(
            "|---|---|---|---|---|---|---|"
            + ("---|" if seeded else "")
            + ("---|" if args.restart is not None else "")
            + "---|"
        )
        with tempfile.TemporaryDirectory() as tmp:
            for seed in args.seeds:
                began = time.perf_counter()
                extra = param_values(args.param)
                offline = float("nan")
                if seeded:
                    file, offline = _start(args, seed, Path(tmp))
                    run = Path(tmp) / "start.json"  # the node checkpoints over its start
                    run.write_bytes(file.read_bytes())
                    extra["checkpoint_file"] = str(run)
                carried, label = "", str(seed)
                if args.restart is not None:
                    run = Path(tmp) / "node.json"
                    run.unlink(missing_ok=True)
                    extra["checkpoint_file"] = str(run)
                    _node(Clocks(seed, args.duration), extra)  # the first node's run
                    saved = load_checkpoint(run)
                    carried = ", ".join(
                        name
                        for name, kept in (("baseline", saved.baseline), ("harm", saved.harm))
                        if kept is not None
                    )
                    carried = f" {carried or 'neither'} |"
                    seed += args.restart
                    label = f"{seed - args.restart} / {seed}"
                clocks = Clocks(seed, args.duration)
                half = clocks.t >= clocks.t[-1] // 2
                errors = {
                    "none": _loads(clocks, clocks.values) - clocks.desired,
                    "true": _loads(clocks, compensate(OPERATION_BACKLASH, clocks.values))
                    - clocks.desired,
                }
                loads, pipe = _node(clocks, extra)
                errors["node"] = loads - clocks.desired
                none = errors["none"]
                whole = {k: 100 * (1 - rms(e) / rms(none)) for k, e in errors.items()}
                late = {k: 100 * (1 - rms(e[half]) / rms(none[half])) for k, e in errors.items()}
                m = pipe.measured
                print(
                    f"| {label} | {1e3 * rms(none):.2f} | {whole['true']:.1f} "
                    f"| {whole['node']:.1f} | {late['true']:.1f} / {late['node']:.1f} "
                    f"| {m.state}, {m.ratio:.2f} | {m.baseline} |"
                    + (f" {1e3 * offline:.2f} / {1e3 * rms(none):.2f} |" if seeded else "")
                    + carried
                    + f" {time.perf_counter() - began:.1f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
