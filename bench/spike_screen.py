"""The encoder spike screen on clean and on spiked records (issue 22, deliverable 3).

    python bench/spike_screen.py [--quick] [--seeds 20] [--duration 40] [--kinds ...] [--jobs 2]

For every simulated scenario and seed, a bag is written the way ``genbacklash simulate``
writes it (the operation-shaped scenarios of :mod:`genbacklash_core.scenarios`:
``operation``, ``one_way``, ``pick_and_place``, ``sine_sweep``; the paper-style
``drivetrain``; and, with ``--physics``, the MuJoCo drivetrains of
:mod:`genbacklash_ros.physics`, their default servo) and replayed by
:func:`genbacklash_ros.bags.replay.replay` -- the code ``genbacklash replay`` runs, default
parameters. Then:

* **clean**: the bag as simulated (no spike; quantisation, jitter, 2 % loss, wear; the
  drivetrain scenario has white noise at SNR 25). Every ``encoder_spike`` drop is false.
* **spiked**: the same bag with 1 % of the encoder readings (seeded, never two in a row)
  displaced by 10-50 encoder counts (4096 counts/rev) up or down. A spike is *caught* when
  the pipeline dropped the reading it displaced; a drop of any other reading is false.

The dropped readings are found by wrapping
:meth:`~genbacklash_ros.node.health.StreamHealth.screen` (the times of the samples it takes
out); the counts are checked against the pipeline's own ``encoder_spike`` count.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from _common import printed_section

from genbacklash_core.scenarios import PHASE_KINDS, OperationSettings
from genbacklash_ros.bags.bagio import BagReader, BagWriter
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.bags.simbags import (
    operation_settings,
    write_drivetrain_bag,
    write_operation_bag,
)
from genbacklash_ros.node import health as health_module
from genbacklash_ros.node.messages import JointState

COMMAND, ENCODER, JOINT = "/command", "/encoder", "drive_joint"
COUNT = 2 * math.pi / 4096  # one encoder count of the simulated encoders
SPIKE_SHARE = 0.01
SPIKE_COUNTS = (10, 50)
WEAR = 0.2  # genbacklash simulate's default


@dataclass(frozen=True)
class Outcome:
    """One replay: spike drops false and caught, spikes injected."""

    kind: str
    seed: int
    spiked: bool
    injected: int
    screened: int  # injected spikes that reached the screen with a trusted estimate
    caught: int
    false: int
    pipeline_spikes: int  # the pipeline's own encoder_spike count (caught + false)
    seconds: float


def _write_clean(kind: str, seed: int, path: Path, duration: float) -> None:
    if kind == "drivetrain":
        write_drivetrain_bag(path, seed=seed, duration=min(duration, 12.0))
    elif kind.startswith("physics:"):
        from genbacklash_ros.physics.bag import write_physics_bag
        from genbacklash_ros.physics.variants import variant

        params = variant(kind.split(":", 1)[1])
        write_physics_bag(path, params, OperationSettings(duration=duration), seed)
    else:
        write_operation_bag(path, operation_settings(((kind, duration),), wear=WEAR), seed)


def _spike(src: Path, dst: Path, seed: int) -> set[int]:
    """Copy ``src`` to ``dst`` with spikes in ``JOINT``'s readings; their stamps."""
    rng = np.random.default_rng([seed, 2201])
    stamps: set[int] = set()
    with BagReader(src) as reader, BagWriter(dst) as writer:
        for key, value in (reader.custom_data or {}).items():
            writer.set_custom_data(key, value)
        writer.add_topic(COMMAND, reader.topic(COMMAND).msgtype)
        writer.add_topic(ENCODER, reader.topic(ENCODER).msgtype)
        previous = False
        for item in reader.messages([COMMAND, ENCODER]):
            msg = item.message
            if item.topic == ENCODER and isinstance(msg, JointState):
                hit = not previous and rng.random() < SPIKE_SHARE
                previous = hit
                if hit:
                    k = msg.name.index(JOINT)
                    size = rng.integers(SPIKE_COUNTS[0], SPIKE_COUNTS[1] + 1) * COUNT
                    position = list(msg.position)
                    position[k] += size if rng.random() < 0.5 else -size
                    msg = dataclasses.replace(msg, position=tuple(position))
                    stamps.add(msg.header.stamp.to_ns())
            writer.write(item.topic, item.log_time_ns, msg)
    return stamps


def run_one(kind: str, seed: int, spiked: bool, duration: float) -> Outcome:
    """Write, maybe spike and replay one bag; count the drops."""
    with tempfile.TemporaryDirectory(prefix="gb-spike-") as tmp:  # honours TMPDIR
        clean = Path(tmp) / "clean"
        _write_clean(kind, seed, clean, duration)
        bag, injected = clean, set[int]()
        if spiked:
            bag = Path(tmp) / "spiked"
            injected = _spike(clean, bag, seed)
        dropped: list[int] = []
        judged: list[int] = []  # samples the screen judged with a trusted estimate
        original = health_module.StreamHealth.screen

        def screen(self: Any, times: np.ndarray, *args: Any, **kwargs: Any) -> Any:
            out = original(self, times, *args, **kwargs)
            if out.keep is not None and any(e.key == "encoder_spike" for e in out.events):
                dropped.extend(times[~out.keep].tolist())
            if self._spikes._converged and self._spikes.scale is not None:
                judged.extend(times.tolist())
            return out

        health_module.StreamHealth.screen = screen  # type: ignore[method-assign]
        started = time.perf_counter()
        try:
            result = replay(
                bag, Path(tmp) / "out", command_topic=COMMAND, encoder_topic=ENCODER, joint=JOINT
            )
        finally:
            health_module.StreamHealth.screen = original  # type: ignore[method-assign]
        seconds = time.perf_counter() - started
    spikes = int(result.stats.dropped.get("encoder_spike", 0))
    caught = len(injected.intersection(dropped))
    screened = len(injected.intersection(judged))
    if spiked and "DEBUG" in __import__("os").environ:
        inj = np.array(sorted(injected))
        for t in sorted(set(dropped) - injected):
            j = np.searchsorted(inj, t)
            near = min(abs(t - inj[max(j - 1, 0)]), abs(t - inj[min(j, inj.size - 1)]))
            print("false", (t - 1700000000000000000) / 1e9, near / 1e6, "ms from a spike")
    return Outcome(
        kind, seed, spiked, len(injected), screened, caught, spikes - caught, spikes, seconds
    )


def _task(job: tuple[str, int, bool, float]) -> Outcome:
    return run_one(*job)


def _arguments(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds 0..N-1 (default 20)")
    parser.add_argument("--duration", type=float, default=40.0, help="seconds (default 40)")
    parser.add_argument("--kinds", nargs="*", default=[*PHASE_KINDS, "drivetrain"])
    parser.add_argument("--physics", nargs="*", default=None, help="physics variants too")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--clean-only", action="store_true")
    parser.add_argument("--spiked-only", action="store_true", help="the spiked records alone")
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.duration = 2, 10.0
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = _arguments(argv)
    with printed_section(
        "spike_screen_physics" if args.physics is not None and not args.kinds else "spike_screen",
        "## Spike screen (issue 22)" if args.kinds else "### Spike screen: the physics drivetrains",
    ):
        _tables(args)


def _tables(args: argparse.Namespace) -> None:
    kinds = list(args.kinds)
    if args.physics is not None:
        from genbacklash_ros.physics.variants import VARIANTS

        kinds += [f"physics:{v}" for v in (args.physics or VARIANTS)]
    modes = [False] if args.clean_only else [True] if args.spiked_only else [False, True]
    jobs = [(k, s, m, args.duration) for k in kinds for m in modes for s in range(args.seeds)]
    started = time.perf_counter()
    outcomes: list[Outcome] = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for outcome in pool.map(_task, jobs):  # in order; each record logged as it is done
            outcomes.append(outcome)
            print(f"<!-- {outcome} -->", file=sys.stderr, flush=True)
    print(
        "| scenario | seeds | clean: false spike drops (bags with any) | spiked: injected "
        "| judged | caught | caught / judged | caught / injected | false drops |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    total_false = total_inj = total_caught = total_seen = 0
    for kind in kinds:
        clean = [o for o in outcomes if o.kind == kind and not o.spiked]
        spiked = [o for o in outcomes if o.kind == kind and o.spiked]
        false = sum(o.false for o in clean)
        bad = sum(o.false > 0 for o in clean)
        total_false += false
        row = f"| {kind} | {len(clean)} | {false} ({bad}) |"
        if spiked:
            inj = sum(o.injected for o in spiked)
            got = sum(o.caught for o in spiked)
            total_inj += inj
            total_caught += got
            sfalse = sum(o.false for o in spiked)
            seen = sum(o.screened for o in spiked)
            total_seen += seen
            row += (
                f" {inj} | {seen} | {got} | {got / max(seen, 1):.1%} | {got / max(inj, 1):.1%} "
                f"| {sfalse} |"
            )
        else:
            row += " - | - | - | - | - | - |"
        print(row)
        for o in clean:
            if o.false:
                print(f"<!-- {kind} seed {o.seed}: {o.false} false drops -->", file=sys.stderr)
    share = total_caught / max(total_inj, 1)
    print(
        f"\ntotal: {total_false} false spike drops on clean records; "
        f"{total_caught} of {total_inj} injected spikes caught ({share:.2%}), of the "
        f"{total_seen} judged with a trusted estimate {total_caught / max(total_seen, 1):.2%}; "
        f"{time.perf_counter() - started:.0f} s"
    )


if __name__ == "__main__":
    main()
