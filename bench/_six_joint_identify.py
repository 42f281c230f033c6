"""The six-joint node's identification alone, in process: CPU, cold starts, convergence (a
helper run by hand, its numbers kept in BENCHMARKS.md by hand).

The six windowed identifiers of the node's identify child (``WindowedIdentifier(3)`` each),
fed the data of ``bench/six_joint.py`` (six drivetrains of the operation scenario, 1 kHz
commands and readings, no loss) in batches of 128 samples, one BLAS thread. Per seed it
prints the identification's CPU (``time.process_time``, best of ``--reps``), the cold
starts (``WindowFitter._start_fit`` calls: attempts, failures, their CPU in the last
repetition), and per joint the time to the first estimate, to a valid one (the play
``c_L + c_R`` within 5 % of the truth from then on), to convergence (``converged`` from then
on), and the final errors.

To compare two codes, run it from compiled ``git archive`` copies, alternating, with
``PYTHONPATH`` at each copy (as in BENCHMARKS.md, "Online identification").

Run: ``python bench/_six_joint_identify.py [--seeds 0 1 2] [--seconds 20] [--reps 3]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from six_joint import FACTORS, JOINTS, arm_data

import genbacklash_core.online.fitter as fitter_module
from genbacklash_core import WindowedIdentifier
from genbacklash_core.estimate import EstimatorState
from genbacklash_core.scenarios import OPERATION_BACKLASH, worn
from genbacklash_ros.blas_threads import one_blas_thread

BATCH = 128  # samples per update_many, as the node's feeds
VALID_PLAY = 0.05  # relative play error of a valid estimate


class ColdStarts:
    """Counts the windowed identifiers' cold-start attempts (a wrapper of ``_start_fit``)."""

    def __init__(self) -> None:
        self.attempts = 0
        self.failed = 0
        self.cpu = 0.0
        self._original = fitter_module.WindowFitter._start_fit

    def __enter__(self) -> ColdStarts:
        original = self._original

        def counted(fitter: Any, *args: Any) -> Any:
            start = time.process_time()
            outcome = original(fitter, *args)
            self.cpu += time.process_time() - start
            self.attempts += 1
            self.failed += isinstance(outcome, str)
            return outcome

        fitter_module.WindowFitter._start_fit = counted  # type: ignore[method-assign]
        return self

    def __exit__(self, *exc: object) -> None:
        fitter_module.WindowFitter._start_fit = self._original  # type: ignore[method-assign]


def feed(u: np.ndarray, y: np.ndarray) -> list[list[tuple[int, EstimatorState, Any]]]:
    """Six identifiers fed the data; per joint, after each batch, (samples, state, p)."""
    identifiers = [WindowedIdentifier(3) for _ in JOINTS]
    history: list[list[tuple[int, EstimatorState, Any]]] = [[] for _ in JOINTS]
    for k0 in range(0, u.shape[1], BATCH):
        for j, identifier in enumerate(identifiers):
            est = identifier.update_many(u[j, k0 : k0 + BATCH], y[j, k0 : k0 + BATCH])
            history[j].append((k0 + BATCH, est.state, est.parameters))
    return history


def since(flags: Sequence[tuple[int, bool]]) -> int | None:
    """The first sample from which every flag holds to the end (None: never)."""
    start = None
    for at, ok in flags:
        if ok and start is None:
            start = at
        elif not ok:
            start = None
    return start


def seconds(samples: int | None) -> str:
    return "never" if samples is None else f"{samples / 1000:.3f} s"


def run(seed: int, duration: float, reps: int) -> str:
    models = [worn(OPERATION_BACKLASH, f) for f in FACTORS]
    u, y = arm_data(models, duration, seed)
    cpus = []
    with one_blas_thread():
        for _ in range(reps - 1):
            start = time.process_time()
            feed(u, y)
            cpus.append(time.process_time() - start)
        with ColdStarts() as cold:  # the last repetition counts the cold starts
            start = time.process_time()
            history = feed(u, y)
            cpus.append(time.process_time() - start)
    lines = [
        f"seed {seed}, {duration:g} s: identification CPU best {min(cpus):.3f} s "
        f"(all {', '.join(f'{c:.3f}' for c in cpus)}); cold attempts {cold.attempts}, "
        f"failed {cold.failed}, their CPU {cold.cpu:.3f} s (last repetition)"
    ]
    n = 3
    for j, steps in enumerate(history):
        truth = models[j].parameters()
        play = truth[n] + truth[2 * n + 1]

        def play_error(p: Any, play: float = play) -> float:
            return float(abs(p[n] + p[2 * n + 1] - play) / play)

        first = next((at for at, state, _ in steps if state is not EstimatorState.WARMING_UP), None)
        valid = since(
            [(at, p is not None and play_error(p) < VALID_PLAY) for at, state, p in steps]
        )
        converged = since([(at, state is EstimatorState.CONVERGED) for at, state, _ in steps])
        final = steps[-1][2]
        errors = (
            f"final play error {play_error(final):.2e}, max |p - truth| "
            f"{float(np.max(np.abs(final - truth))):.2e}"
            if final is not None
            else "no estimate"
        )
        lines.append(
            f"  joint {j}: first estimate {seconds(first)}, valid {seconds(valid)}, "
            f"converged {seconds(converged)}, {errors}, {steps[-1][1].value}"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--reps", type=int, default=3)
    args = parser.parse_args(argv)
    for seed in args.seeds:
        print(run(seed, args.seconds, args.reps), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
