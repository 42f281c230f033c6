"""Compensation in closed loop on the physics drivetrains (issue 23, targets).

For each variant, servo bandwidth and seed, the same operation-shaped motion (moves, dwells,
jogs; 100 Hz held commands; a 1 kHz load encoder at 4096 counts/rev with stamp jitter and
2 % loss) drives a MuJoCo drivetrain (:mod:`genbacklash_ros.physics`) three ways:

* ``none``: the commands as they are (the uncompensated tracking error);
* ``true``: the commands through the inverse of the drivetrain's measured quasi-static
  characteristic (a compensator given the true play);
* ``node``: the node's own pipeline (:class:`~genbacklash_ros.node.pipeline.BacklashPipeline`,
  its defaults with ``compensation_in_loop``), fed each command and each encoder reading as
  they happen; its compensated command is what the simulated servo receives. With
  ``--motor-encoder`` the node's input is a motor encoder instead (``gear_input``
  motor_encoder): the rotor read at each encoder instant, quantised alike, 2 % lost on its
  own draw, fed just before the load's reading of the same stamp.

With ``--seeded-start OFFSET`` the node starts as a user would start it from an offline
result: seed ``seed + OFFSET`` of the same drivetrain is written as a bag without
compensation (the same motion's kind, another draw), ``genbacklash identify BAG --checkpoint
FILE`` (with ``--motor-encoder /motor_encoder`` when the node's input is one) writes the
node's start, and the pipeline in the loop takes it (its ``checkpoint_file``). The table
adds the start's play against the geometric one, and the record's tracking without
compensation the checkpoint holds (the judge's baseline on that start: ``offline``) against
this record's. ``--baseline-scale X`` multiplies that stored baseline by ``X`` and
``--no-offline-baseline`` removes it (the start then measures its baseline first, as before
it was stored); ``--offline-variant NAME`` identifies the start on another variant's record
(a mismatched offline record). The robustness runs of issue 23 use them.

With ``--restart OFFSET`` the node is restarted from its own checkpoint: a fresh node runs
seed ``seed`` writing its checkpoints (``checkpoint_file``), then a second node starts from
the fresh run's final checkpoint on seed ``seed + OFFSET``'s motion (the same drivetrain),
twice: with what the checkpoint carries (the judge's live baseline, issue 23 ckpt-1, or its
standing verdict of harm, which the restart holds) and with both removed (what a node's
checkpoint held before: the restart measures its 3 s first and tries the model again).
The table gives the second record's cuts.

With ``--late-stamps MS`` the node gets the readings stamped as a busy publisher stamps them
(:func:`~genbacklash_ros.physics.loop.late_stamps`: busy for MS on average after each command,
the readings taken meanwhile stamped together when it is done), as the live demo's arm
publishes them; the physics is sampled at the readings' true instants.

The numbers: the RMS load tracking error ``load - desired`` (the true load at every encoder
instant) and each compensator's cut against ``none`` in percent, over the whole record and
over its second half (the node learns in the first); the node's final play ``c_L + c_R``
against the geometric play; the guard's final trust and error ratio.

Run: ``python bench/physics_loop.py [--seeds 0 1 2] [--bandwidths 20 60 100]
[--variants ...] [--duration 40] [--guard on|off] [--delay-ms 0]
[--param NAME=VALUE ...] [--motor-encoder] [--seeded-start OFFSET] [--baseline-scale X]
[--no-offline-baseline] [--offline-variant NAME] [--restart OFFSET] [--late-stamps MS]``
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from _common import (
    PHYSICS_TOPICS,
    cli_json,
    json_play,
    param_values,
    parse_physics_arguments,
    physics_parser,
    physics_records,
    printed_section,
    rms,
)

from genbacklash_core import compensate
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.node.checkpoint import load_checkpoint, save_checkpoint, warm_start
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.loop import Clocks, node_loop, open_loop
from genbacklash_ros.physics.variants import VARIANTS, variant


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = physics_parser(__doc__, duration=40.0)
    parser.add_argument("--guard", choices=("on", "off"), default="on")
    parser.add_argument(
        "--delay-ms",
        type=float,
        default=0.0,
        help="the servo takes the node's answer this long after the command (default 0)",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a node parameter for the node's pipeline (e.g. servo_model=auto)",
    )
    parser.add_argument(
        "--motor-encoder", action="store_true", help="the node's input: a motor encoder"
    )
    parser.add_argument(
        "--seeded-start",
        type=int,
        default=None,
        metavar="OFFSET",
        help="start the node from `genbacklash identify --checkpoint` on seed + OFFSET's "
        "record of the same drivetrain (no compensation in it)",
    )
    parser.add_argument(
        "--baseline-scale",
        type=float,
        default=1.0,
        metavar="X",
        help="with --seeded-start: multiply the checkpoint's offline baseline by X",
    )
    parser.add_argument(
        "--no-offline-baseline",
        action="store_true",
        help="with --seeded-start: remove the checkpoint's offline baseline",
    )
    parser.add_argument(
        "--offline-variant",
        choices=list(VARIANTS),
        default=None,
        help="with --seeded-start: identify the start on this variant's record",
    )
    parser.add_argument(
        "--restart",
        type=int,
        default=None,
        metavar="OFFSET",
        help="restart the node from its own final checkpoint on seed + OFFSET's motion, with "
        "the checkpoint's baseline and without it",
    )
    parser.add_argument(
        "--late-stamps",
        type=float,
        default=0.0,
        metavar="MS",
        help="the readings stamped by a publisher busy MS on average after each command "
        "(the live demo's arm; default 0: stamped when taken)",
    )
    args = parse_physics_arguments(parser, argv)
    if not math.isfinite(args.late_stamps) or args.late_stamps < 0.0:
        parser.error(f"--late-stamps must be a time in ms >= 0, got {args.late_stamps:g}")
    return args


def _seeded_start(
    args: argparse.Namespace, name: str, bw: float, seed: int, folder: Path
) -> tuple[Path, float, float]:
    """Identify seed ``seed + args.seeded_start`` of the drivetrain (``--offline-variant``'s
    when given) offline with the CLI and write the node's start; the file, the start's play
    (rad) and its offline baseline as the node takes it (rad rms, NaN: none). The node
    must take it."""
    params = variant(args.offline_variant or name, bandwidth=bw)
    offline = seed + args.seeded_start
    bag = folder / f"{name}-{bw:g}-{offline}"
    write_physics_bag(
        bag,
        params,
        OperationSettings(duration=args.duration),
        offline,
        motor_encoder=args.motor_encoder,
    )
    start = folder / f"{name}-{bw:g}-{offline}.json"
    motor = ["--motor-encoder", "/motor_encoder"] if args.motor_encoder else []
    result = cli_json(
        ["identify", str(bag), *PHYSICS_TOPICS, "--json", "--checkpoint", str(start), *motor]
    )
    shutil.rmtree(bag)
    saved = load_checkpoint(start)
    if args.no_offline_baseline or args.baseline_scale != 1.0:
        base = saved.baseline
        if base is not None and not args.no_offline_baseline:
            base = dataclasses.replace(base, rms=base.rms * args.baseline_scale)
        else:
            base = None
        save_checkpoint(start, dataclasses.replace(saved, baseline=base))
    taken = warm_start(NodeParameters.from_mapping({"checkpoint_file": str(start)}))
    if taken.prior is None or taken.problem:
        raise SystemExit(f"the node did not take the start {start}: {taken.note}")
    offline = taken.baseline.rms if taken.baseline is not None else float("nan")
    return start, json_play(result), offline


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section(
        "physics_loop",
        "### Compensation in closed loop, driven by the node's own compensated command",
    ):
        # one BLAS thread, as the node and replay run (genbacklash_ros.blas_threads): the fits'
        # last bits, and so the loop's path, do not then depend on the machine's core count
        with tempfile.TemporaryDirectory() as tmp, one_blas_thread():
            if args.restart is not None:
                _restart_tables(args, Path(tmp))
            else:
                _tables(args, Path(tmp))


def _cuts(errors: dict[str, np.ndarray], half: np.ndarray) -> dict[str, tuple[float, float]]:
    """Each run's cut against ``none`` (%): over the whole record and its second half."""
    none = errors["none"]
    return {
        k: (100 * (1 - rms(e) / rms(none)), 100 * (1 - rms(e[half]) / rms(none[half])))
        for k, e in errors.items()
    }


def _restart_tables(args: argparse.Namespace, folder: Path) -> None:
    """``--restart``: a fresh run writing checkpoints, then the restart from its final one
    with the baseline or harm it carries and without either (module notes)."""
    extra = param_values(args.param)
    print(
        "| variant | bandwidth (Hz) | seed / restart seed "
        "| fresh run: cut node, whole / 2nd half (%), measured (state, ratio) "
        "| stored baseline (mrad over s) | stored harm (play mrad, ratio, held s) "
        "| rms none (mrad) | cut true (%) "
        "| restart as stored: whole / 2nd half (%) "
        "| restart with neither: whole / 2nd half (%) | measured at the end, as stored / "
        "with neither (state, ratio) | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    delay = round(args.delay_ms * 1e6)
    for record in physics_records(args):
        name, bw, seed = record.name, record.bandwidth, record.seed
        params, truth = record.params, record.truth
        began = time.perf_counter()
        run = folder / "node.json"
        run.unlink(missing_ok=True)
        node = {**extra, "checkpoint_file": str(run)}
        first = Clocks(seed, args.duration, late_ms=args.late_stamps)
        loads, _, _, judged = node_loop(
            params, first, guard=args.guard == "on", delay_ns=delay, extra=node,
            motor=args.motor_encoder,
        )  # fmt: skip
        none = open_loop(params, first, first.values, delay) - first.desired
        fresh = 100 * (1 - rms(loads - first.desired) / rms(none))
        late = first.t >= first.t[-1] // 2
        fresh_late = 100 * (1 - rms((loads - first.desired)[late]) / rms(none[late]))
        saved = load_checkpoint(run)
        clocks = Clocks(seed + args.restart, args.duration, late_ms=args.late_stamps)
        half = clocks.t >= clocks.t[-1] // 2
        errors = {
            "none": open_loop(params, clocks, clocks.values, delay) - clocks.desired,
            "true": open_loop(params, clocks, compensate(truth.model, clocks.values), delay)
            - clocks.desired,
        }
        states = []
        bare = dataclasses.replace(saved, baseline=None, harm=None)
        for key, kept in (("with", saved), ("without", bare)):
            save_checkpoint(run, kept)
            loads, _, _, measured = node_loop(
                params, clocks, guard=args.guard == "on", delay_ns=delay, extra=node,
                motor=args.motor_encoder,
            )  # fmt: skip
            errors[key] = loads - clocks.desired
            states.append(f"{measured.state}, {measured.ratio:.2f}")
        cut = _cuts(errors, half)
        base = saved.baseline
        stored = f"{1e3 * base.rms:.2f} over {base.seconds:.1f}" if base else "none"
        harm = saved.harm
        held = f"{1e3 * harm.play:.1f}, {harm.ratio:.2f}, {harm.held:.1f}" if harm else "none"
        print(
            f"| {name} | {bw:g} | {seed} / {seed + args.restart} "
            f"| {fresh:.1f} / {fresh_late:.1f}, {judged.state}, {judged.ratio:.2f} "
            f"| {stored} | {held} | {1e3 * rms(errors['none']):.2f} "
            f"| {cut['true'][0]:.1f} "
            f"| {cut['with'][0]:.1f} / {cut['with'][1]:.1f} "
            f"| {cut['without'][0]:.1f} / {cut['without'][1]:.1f} "
            f"| {' / '.join(states)} | {time.perf_counter() - began:.1f} |",
            flush=True,
        )


def _tables(args: argparse.Namespace, folder: Path) -> None:
    extra = param_values(args.param)
    seeded = args.seeded_start is not None
    print(
        "| variant | bandwidth (Hz) | seed | rms none (mrad) | cut true (%) | cut node (%) "
        "| 2nd half: cut true / node (%) | node play / geometric | guard (trust, ratio) "
        "| measured (state, ratio) |"
        + (" start play / geometric | offline / none (mrad) | judged against |" if seeded else "")
        + " s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|" + ("---|---|---|" if seeded else ""))
    for record in physics_records(args):
        name, bw, seed = record.name, record.bandwidth, record.seed
        params, truth = record.params, record.truth
        geometric = params.c_left + params.c_right
        start = time.perf_counter()
        run_extra = dict(extra)
        start_play, offline = "", float("nan")
        if seeded:
            file, offline_play, offline = _seeded_start(args, name, bw, seed, folder)
            run = folder / "start.json"  # the node checkpoints over its start
            shutil.copyfile(file, run)
            run_extra["checkpoint_file"] = str(run)
            start_play = f" {offline_play / geometric:.3f} |"
        clocks = Clocks(seed, args.duration, late_ms=args.late_stamps)
        half = clocks.t >= clocks.t[-1] // 2
        delay = round(args.delay_ms * 1e6)
        true_commands = compensate(truth.model, clocks.values)
        errors = {
            "none": open_loop(params, clocks, clocks.values, delay) - clocks.desired,
            "true": open_loop(params, clocks, true_commands, delay) - clocks.desired,
        }
        loads, est, verdict, measured = node_loop(
            params,
            clocks,
            guard=args.guard == "on",
            delay_ns=delay,
            extra=run_extra,
            motor=args.motor_encoder,
        )
        errors["node"] = loads - clocks.desired
        whole = {k: 100 * (1 - rms(e) / rms(errors["none"])) for k, e in errors.items()}
        late = {k: 100 * (1 - rms(e[half]) / rms(errors["none"][half])) for k, e in errors.items()}
        model = est.model
        bl = getattr(model, "backlash", model)
        play = (bl.c_left + bl.c_right) / geometric if bl is not None else float("nan")
        print(
            f"| {name} | {bw:g} | {seed} | {1e3 * rms(errors['none']):.2f} "
            f"| {whole['true']:.1f} | {whole['node']:.1f} "
            f"| {late['true']:.1f} / {late['node']:.1f} | {play:.3f} "
            f"| {verdict.trust:.2f}, {verdict.ratio:.2f} "
            f"| {measured.state}, {measured.ratio:.2f} |{start_play}"
            + (
                f" {1e3 * offline:.2f} / {1e3 * rms(errors['none']):.2f} | {measured.baseline} |"
                if seeded
                else ""
            )
            + f" {time.perf_counter() - start:.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
