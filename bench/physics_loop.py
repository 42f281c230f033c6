"""Compensation in closed loop on the physics drivetrains (issue 23, targets).

For each variant, servo bandwidth and seed, the same operation-shaped motion (moves, dwells,
jogs; 100 Hz held commands; a 1 kHz load encoder at 4096 counts/rev with stamp jitter and
2 % loss) drives a MuJoCo drivetrain (:mod:`genbacklash_ros.physics`) three ways:

* ``none``: the commands as they are (the uncompensated tracking error);
* ``true``: the commands through the inverse of the drivetrain's measured quasi-static
  characteristic (a compensator given the true play);
* ``node``: the node's own pipeline (:class:`~genbacklash_ros.node.pipeline.BacklashPipeline`,
  its defaults with ``compensation_in_loop``), fed each command and each encoder reading as
  they happen; its compensated command is what the simulated servo receives.

The numbers: the RMS load tracking error ``load - desired`` (the true load at every encoder
instant) and each compensator's cut against ``none`` in percent, over the whole record and
over its second half (the node learns in the first); the node's final play ``c_L + c_R``
against the geometric play; the guard's final trust and error ratio.

Run: ``python bench/physics_loop.py [--quick] [--seeds 0 1 2] [--bandwidths 20 60 100]
[--variants ...] [--duration 40] [--guard on|off]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np
from _common import printed_section

from genbacklash_core import Estimate, GuardVerdict, compensate
from genbacklash_core.scenarios import OperationSettings, operation_commands, timeline
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.physics.engine import Drivetrain, Trajectory
from genbacklash_ros.physics.truth import quasi_static
from genbacklash_ros.physics.variants import VARIANTS, DrivetrainParameters, variant


class Clocks:
    """The motion and the clocks of one seed (the operation scenario's)."""

    def __init__(self, seed: int, duration: float) -> None:
        cfg = OperationSettings(duration=duration)
        rng = np.random.default_rng([int(seed), 12])
        self.values, _ = operation_commands(rng, cfg)
        self.cmd_t, self.t = timeline(
            rng,
            self.values.size,
            command_rate=cfg.command_rate,
            encoder_rate=cfg.encoder_rate,
            command_jitter_ns=round(cfg.command_jitter * 1e9),
            stamp_jitter_ns=cfg.stamp_jitter * 1e9,
        )
        self.received = np.random.default_rng([int(seed), 31]).random(self.t.size) >= cfg.loss
        self.quantum = float(cfg.quantum)
        k = np.maximum(np.searchsorted(self.cmd_t, self.t, side="right") - 1, 0)
        self.desired = self.values[k]


def open_loop(params: DrivetrainParameters, clocks: Clocks, commands: np.ndarray) -> np.ndarray:
    """The load at every encoder instant for ``commands`` at the command stamps."""
    sim = Drivetrain(params, position=float(commands[0]))
    end = int(max(clocks.t[-1], clocks.cmd_t[-1])) + sim.step_ns
    return sim.follow(clocks.cmd_t, commands, end).load_at(clocks.t)


def node_loop(
    params: DrivetrainParameters, clocks: Clocks, *, guard: bool
) -> tuple[np.ndarray, Estimate, GuardVerdict]:
    """The node's pipeline in the loop: its compensated command drives the servo."""
    node = NodeParameters(
        command_type="float64",
        encoder_type="float64",
        compensation_in_loop=True,
        compensation_guard=guard,
    )
    pipe = BacklashPipeline(node)
    values, cmd_t, t = clocks.values, clocks.cmd_t, clocks.t
    sim = Drivetrain(params, position=float(values[0]))
    loads = np.empty(t.size)
    j, prev = 0, None
    for k in range(values.size):
        got = pipe.on_command_value(None, float(values[k]), int(cmd_t[k]))
        sent = float(values[k]) if got is None else got[1]
        end = int(cmd_t[k + 1]) if k + 1 < values.size else int(t[-1]) + sim.step_ns
        piece = sim.hold(sent, end)
        traj = piece if prev is None else Trajectory.concatenate([prev, piece])
        prev = piece
        stop = int(np.searchsorted(t, min(end, int(traj.t_ns[-1])), side="right"))
        if stop <= j:
            continue
        x = traj.load_at(t[j:stop])
        loads[j:stop] = x
        q = clocks.quantum
        for i in range(j, stop):
            if clocks.received[i]:
                y = float(np.round(x[i - j] / q) * q) if q else float(x[i - j])
                pipe.on_encoder_value(None, y, int(t[i]))
        j = stop
    pipe.finish(refit=False)
    return loads, pipe.estimate, pipe.guard


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e)))


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--bandwidths", type=float, nargs="+", default=[20.0, 60.0, 100.0])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS))
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--guard", choices=("on", "off"), default="on")
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.bandwidths, args.variants, args.duration = (
            [0],
            [60.0],
            ["near_ideal"],
            10.0,
        )
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section(
        "physics_loop",
        "### Compensation in closed loop, driven by the node's own compensated command",
    ):
        _tables(args)


def _tables(args: argparse.Namespace) -> None:
    print(
        "| variant | bandwidth (Hz) | seed | rms none (mrad) | cut true (%) | cut node (%) "
        "| 2nd half: cut true / node (%) | node play / geometric | guard (trust, ratio) | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.variants:
        for bw in args.bandwidths:
            params = variant(name, bandwidth=bw)
            truth = quasi_static(params, OperationSettings().travel)
            geometric = params.c_left + params.c_right
            for seed in args.seeds:
                start = time.perf_counter()
                clocks = Clocks(seed, args.duration)
                half = clocks.t >= clocks.t[-1] // 2
                errors = {
                    "none": open_loop(params, clocks, clocks.values) - clocks.desired,
                    "true": open_loop(params, clocks, compensate(truth.model, clocks.values))
                    - clocks.desired,
                }
                loads, est, verdict = node_loop(params, clocks, guard=args.guard == "on")
                errors["node"] = loads - clocks.desired
                whole = {k: 100 * (1 - _rms(e) / _rms(errors["none"])) for k, e in errors.items()}
                late = {
                    k: 100 * (1 - _rms(e[half]) / _rms(errors["none"][half]))
                    for k, e in errors.items()
                }
                model = est.model
                bl = getattr(model, "backlash", model)
                play = (bl.c_left + bl.c_right) / geometric if bl is not None else float("nan")
                print(
                    f"| {name} | {bw:g} | {seed} | {1e3 * _rms(errors['none']):.2f} "
                    f"| {whole['true']:.1f} | {whole['node']:.1f} "
                    f"| {late['true']:.1f} / {late['node']:.1f} | {play:.3f} "
                    f"| {verdict.trust:.2f}, {verdict.ratio:.2f} "
                    f"| {time.perf_counter() - start:.1f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
