"""Do the 2-sigma bands hold the truth while the gap wears, and on physics data? (issue 22)

    python bench/coverage.py [--quick] [--seeds 5] [--physics-seeds 3] [--jobs 1]

Each record is written as a bag and replayed with ``genbacklash_ros.bags.replay.replay``
(what ``genbacklash replay`` runs: the node's pipeline, default parameters), once per
identifier. Every estimate the replay published after the first ``converged`` one is checked
against the true dead zones at its data time (the bag's truth, ``c_left``, ``c_right`` every
0.25 s, interpolated): is ``|estimate - truth| <= 2 sigma``, with sigma the standard
deviation the replay's report draws (the published covariance)? Coverage is the share of
those estimates; the target is >= 90 %. Each replay runs twice: with the bands as published
(*after*) and without their free-run model term (*before*: the tracking fit not given the
recent readings, which is the band of the commit before that term, bit for bit); the same
run, the same records.

Inputs (the wear scenarios, ``--seeds`` seeds each):

* ``operation 30 s, +20 %``: the bundled operation bag's settings (``genbacklash simulate
  --scenario operation``): 100 Hz held commands, trapezoidal moves, dwells and jogs, a 1 kHz
  encoder (4096 counts/rev, 50 us stamp jitter, 2 % lost), both dead zones 20 % wider at
  the end;
* ``operation 10 min, +50 %``: the same operation, the wear of BENCHMARKS' wear table;
* ``drivetrain 12 s, +20 %``: the paper-style random input (``--scenario drivetrain``:
  commands at 100-1000 Hz, SNR 25).

Physics data (no wear: the play is fixed by the geometry; ``--physics-seeds`` seeds): the
MuJoCo drivetrains (``simulate --physics VARIANT``, 40 s of operation) near_ideal, coasting,
compliant and gravity with a 60 Hz servo, and near_ideal with a 20 and a 100 Hz servo, the
band checked against the bag's truth (the quasi-static characteristic a slow sweep
measures). On each physics bag ``genbacklash identify --json`` runs too: is its play within
2 of its standard deviations of the quasi-static play, with ``play_std`` (statistical and
model error) and with ``play_std_statistical`` alone (the standard deviation before the
model-error part)? ``--physics-first-seed 3 --physics-seeds 2`` runs held-out seeds 3-4.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from _common import (
    PHYSICS_TOPICS,
    cli_json,
    command_line,
    json_play,
    machine_description,
    md_table,
    write_section,
)
from tqdm import tqdm

from genbacklash_core.online import bands as bands_module
from genbacklash_core.online import feeds as feeds_module
from genbacklash_core.online.tracking import DeadZoneDrift, dead_zone_drift
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.bags.simbags import (
    SimulatedBag,
    read_truth,
    write_drivetrain_bag,
    write_operation_bag,
)

METHODS = ("windowed", "recursive")
TARGET = 0.90
PHYSICS = (
    ("near_ideal", 60.0),
    ("coasting", 60.0),
    ("compliant", 60.0),
    ("gravity", 60.0),
    ("near_ideal", 20.0),
    ("near_ideal", 100.0),
)


def operation(seconds: float, wear: float) -> Callable[[Path, int], SimulatedBag]:
    settings = OperationSettings(duration=seconds, phases=(("operation", seconds),), wear=wear)
    return lambda path, seed: write_operation_bag(path, settings, seed)


def drivetrain(path: Path, seed: int) -> SimulatedBag:
    return write_drivetrain_bag(path, seed=seed, duration=12.0, wear=0.2)


SCENARIOS: dict[str, Callable[[Path, int], SimulatedBag]] = {
    "operation 30 s, +20 %": operation(30.0, 0.2),
    "drivetrain 12 s, +20 %": drivetrain,
    "operation 10 min, +50 %": operation(600.0, 0.5),
}


@contextlib.contextmanager
def model_term(on: bool) -> Iterator[None]:
    """The bands as published (``on``), or without their free-run model term (the bands
    before it: the tracking fit not given the recent readings, so
    :meth:`DeadZoneDrift.tracking_covariance` adds the one-step rows' model term alone, as
    the commit before it did, bit for bit)."""
    if on:
        yield
        return

    def without_model(*args: Any) -> DeadZoneDrift | None:
        return dead_zone_drift(*args[:4])

    # the windowed identifier's fit is its feed's, the recursive identifier's its bands'
    modules = (feeds_module, bands_module)
    for module in modules:
        module.dead_zone_drift = without_model  # type: ignore[attr-defined]
    try:
        yield
    finally:
        for module in modules:
            module.dead_zone_drift = dead_zone_drift  # type: ignore[attr-defined]


def coverage(bag: Path, method: str, joint: str | None, model: bool = True) -> dict[str, float]:
    """Replay ``bag`` with ``method``; the bands' coverage of the truth after convergence."""
    with tempfile.TemporaryDirectory(prefix="gb-coverage-") as tmp, model_term(model):
        result = replay(
            bag,
            Path(tmp) / "out",
            command_topic="/command",
            encoder_topic="/encoder",
            joint=joint,
            command_index=0,
            method=method,
        )
    truth = read_truth(result.custom_data)
    assert truth is not None
    hist = result.history
    names = hist.names
    left, right = names.index("c_left"), names.index("c_right")
    hits: dict[str, list[bool]] = {"c_left": [], "c_right": [], "play": []}
    half_widths: list[float] = []
    errors: list[float] = []
    converged = False
    for stamp, est in zip(hist.estimate_t, hist.estimates, strict=True):
        converged = converged or est.state.value == "converged"
        if not converged or not est.available:
            continue
        t_s = (stamp - truth.start_ns) / 1e9
        c_l = float(np.interp(t_s, truth.t_s, truth.c_left))
        c_r = float(np.interp(t_s, truth.t_s, truth.c_right))
        std = est.std()
        play, play_std = est.play()
        hits["c_left"].append(abs(est.parameters[left] - c_l) <= 2 * std[left])
        hits["c_right"].append(abs(est.parameters[right] - c_r) <= 2 * std[right])
        hits["play"].append(abs(play - (c_l + c_r)) <= 2 * play_std)
        half_widths.append(2 * play_std)
        errors.append(abs(play - (c_l + c_r)))
    out = {k: float(np.mean(v)) if v else float("nan") for k, v in hits.items()}
    out["count"] = float(len(hits["play"]))
    out["band"] = float(np.median(half_widths)) if half_widths else float("nan")
    out["error"] = float(np.median(errors)) if errors else float("nan")
    return out


def physics_label(name: str, bandwidth: float) -> str:
    return f"{name} 40 s, {bandwidth:g} Hz servo"


def identify_check(bag: Path) -> dict[str, float]:
    """``genbacklash identify --json`` on ``bag``: its play, ``play_std`` and its parts
    against the quasi-static play of the bag's truth."""
    from genbacklash_ros.bags.bagio import BagReader

    out = cli_json(["identify", str(bag), *PHYSICS_TOPICS, "--json"])
    with BagReader(bag) as reader:
        truth = read_truth(reader.custom_data)
    assert truth is not None
    true_play = float(truth.c_left[0] + truth.c_right[0])

    def number(key: str) -> float:
        value = out.get(key)
        return float(value) if isinstance(value, (int, float)) else float("nan")

    return {
        "error": json_play(out) - true_play,
        "play": json_play(out),
        "true_play": true_play,
        "std": number("play_std"),
        "statistical": number("play_std_statistical"),
        "model": number("play_std_model"),
    }


def run_record(job: tuple[str, int, bool]) -> dict[str, Any]:
    """Write one record's bag and replay it with both identifiers, bands with and without
    the model-error term; for a physics record, ``identify`` too."""
    label, seed, physics = job
    with tempfile.TemporaryDirectory(prefix="gb-coverage-bags-") as tmp:
        bag = Path(tmp) / "bag"
        if physics:
            from genbacklash_ros.physics.bag import write_physics_bag  # needs mujoco
            from genbacklash_ros.physics.variants import variant

            name, bandwidth = next((n, b) for n, b in PHYSICS if physics_label(n, b) == label)
            write_physics_bag(bag, variant(name, bandwidth=bandwidth), seed=seed)
        else:
            SCENARIOS[label](bag, seed)
        out: dict[str, Any] = {"label": label, "seed": seed, "physics": physics}
        for method in METHODS:
            out[method] = coverage(bag, method, "drive_joint", model=True)
            out[method + " before"] = coverage(bag, method, "drive_joint", model=False)
        if physics:
            out["identify"] = identify_check(bag)
    return out


def table_row(
    label: str, method: str, seed: int, c: dict[str, float], b: dict[str, float]
) -> tuple[object, ...]:
    """One record's row of the per-record tables (``c`` after, ``b`` before)."""
    return (
        label,
        method,
        seed,
        f"{c['c_left']:.0%}",
        f"{c['c_right']:.0%}",
        f"{b['play']:.0%} → {c['play']:.0%}",
        int(c["count"]),
        f"{1e3 * c['error']:.2f}",
        f"{1e3 * b['band']:.2f} → {1e3 * c['band']:.2f}",
    )


HEADER = (
    "input",
    "identifier",
    "seed",
    "c_left covered",
    "c_right covered",
    "play covered, before → after",
    "estimates",
    "median abs. play error (mrad)",
    "median 2-sigma half-width, before → after (mrad)",
)


IDENTIFY_HEADER = (
    "input",
    "seed",
    "play (true) (mrad)",
    "play error (mrad)",
    "statistical std (mrad)",
    "model-error std (mrad)",
    "play_std (mrad)",
    "abs. error / play_std",
    "within 2 std: statistical alone → play_std",
    "2 play_std wider than the play",
)


def identify_row(r: dict[str, Any]) -> tuple[object, ...]:
    """One physics record's row of the identify table."""
    i = r["identify"]
    yes = {True: "yes", False: "no"}
    return (
        r["label"],
        r["seed"],
        f"{1e3 * i['true_play']:.1f}",
        f"{1e3 * i['error']:+.2f}",
        f"{1e3 * i['statistical']:.3f}",
        f"{1e3 * i['model']:.2f}",
        f"{1e3 * i['std']:.2f}",
        f"{abs(i['error']) / i['std']:.2f}",
        f"{yes[bool(abs(i['error']) <= 2 * i['statistical'])]} → "
        f"{yes[bool(abs(i['error']) <= 2 * i['std'])]}",
        yes[bool(2 * i["std"] > i["true_play"])],
    )


def identify_summary(results: list[dict[str, Any]]) -> str:
    """Per physics input: the share of seeds whose play is within 2 standard deviations,
    before and after, and the median 2-sigma half-widths."""
    rows = []
    labels = dict.fromkeys(r["label"] for r in results)
    for label in labels:
        ids = [r["identify"] for r in results if r["label"] == label]
        before = np.mean([abs(i["error"]) <= 2 * i["statistical"] for i in ids])
        after = np.mean([abs(i["error"]) <= 2 * i["std"] for i in ids])
        rows.append(
            (
                label,
                len(ids),
                f"{before:.0%} → {after:.0%}",
                f"{2e3 * np.median([i['statistical'] for i in ids]):.3f} → "
                f"{2e3 * np.median([i['std'] for i in ids]):.2f}",
                f"{1e3 * np.median([abs(i['error']) for i in ids]):.2f}",
                f"{1e3 * np.median([i['true_play'] for i in ids]):.1f}",
            )
        )
    return md_table(
        (
            "input",
            "seeds",
            "play within 2 std, before → after",
            "median 2-sigma half-width, before → after (mrad)",
            "median abs. play error (mrad)",
            "true play (mrad)",
        ),
        rows,
    )


def summary_table(results: list[dict[str, Any]]) -> str:
    pooled: dict[tuple[str, str], list[dict[str, float]]] = {}
    before: dict[tuple[str, str], list[dict[str, float]]] = {}
    for r in results:
        for method in METHODS:
            pooled.setdefault((r["label"], method), []).append(r[method])
            before.setdefault((r["label"], method), []).append(r[method + " before"])
    rows = []
    for key, after in pooled.items():
        prior = before[key]
        share = float(np.mean([a["play"] for a in after]))
        rows.append(
            (
                key[0],
                key[1],
                len(after),
                f"{np.mean([p['play'] for p in prior]):.0%} → {share:.0%}",
                f"{np.min([a['play'] for a in after]):.0%}",
                f"{1e3 * np.median([p['band'] for p in prior]):.2f} → "
                f"{1e3 * np.median([a['band'] for a in after]):.2f}",
                f"{1e3 * np.median([a['error'] for a in after]):.2f}",
                "met" if share >= TARGET else "NOT met",
            )
        )
    return md_table(
        (
            "input",
            "identifier",
            "seeds",
            "play covered, pooled, before → after",
            "worst seed (after)",
            "median 2-sigma half-width, before → after (mrad)",
            "median abs. play error (mrad)",
            ">= 90 %",
        ),
        rows,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds of the wear scenarios")
    parser.add_argument("--physics-seeds", type=int, default=3, help="seeds of each physics set")
    parser.add_argument(
        "--physics-first-seed", type=int, default=0, help="first physics seed (3: held out)"
    )
    parser.add_argument("--jobs", type=int, default=1, help="records replayed at once")
    parser.add_argument(
        "--scenarios", nargs="*", choices=list(SCENARIOS), help="a subset of the wear scenarios"
    )
    args = parser.parse_args()
    scenarios = list(SCENARIOS) if args.scenarios is None else args.scenarios
    physics = [physics_label(n, b) for n, b in PHYSICS]
    if args.quick:
        args.seeds, args.physics_seeds = 2, 1
        scenarios, physics = scenarios[:2], physics[:1]
    try:
        import mujoco  # noqa: F401
    except ImportError:
        physics = []
    jobs = [(s, seed, False) for s in scenarios for seed in range(args.seeds)]
    first = args.physics_first_seed
    jobs += [(p, seed, True) for p in physics for seed in range(first, first + args.physics_seeds)]
    started = time.perf_counter()
    machine = machine_description()
    raw = Path(__file__).resolve().parent / "output" / "coverage.jsonl"
    raw.parent.mkdir(parents=True, exist_ok=True)
    results: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool, raw.open("w") as log:
        for result in tqdm(pool.map(run_record, jobs), total=len(jobs), file=sys.stderr):
            results.append(result)
            log.write(json.dumps(result) + "\n")  # each record as it is done
            log.flush()
    operation_results = [r for r in results if not r["physics"]]
    physics_results = [r for r in results if r["physics"]]
    rows = [
        table_row(r["label"], m, r["seed"], r[m], r[m + " before"])
        for r in operation_results
        for m in METHODS
    ]
    physics_rows = [
        table_row(r["label"], m, r["seed"], r[m], r[m + " before"])
        for r in physics_results
        for m in METHODS
    ]
    identify_rows = [identify_row(r) for r in physics_results]
    intro = __doc__.split("Inputs", 1)[0].split(chr(10), 3)[3].strip()
    body = f"""{intro}

Command: `{command_line()}`. {machine} Total {time.perf_counter() - started:.0f} s.

Target: the 2-sigma bands hold the truth >= 90 % of the time after convergence, on the wear
scenarios (operation-shaped data) and on the physics drivetrains, both identifiers.

{summary_table(results)}

Per record, operation-shaped and random-input wear scenarios:

{md_table(HEADER, rows) if rows else "(none)"}

Per record, physics data (MuJoCo, 40 s of operation, no wear; the band against the
quasi-static truth):

{md_table(HEADER, physics_rows) if physics_rows else "(mujoco not installed)"}

Batch: ``genbacklash identify`` on the same physics bags, its play against the quasi-static
play (``play_std`` its reported standard deviation, statistical and model error together;
*before*: the statistical part alone):

{identify_summary(physics_results) if physics_results else "(none)"}

{md_table(IDENTIFY_HEADER, identify_rows) if identify_rows else "(none)"}
"""
    write_section("coverage", body)
    print(body)


if __name__ == "__main__":
    main()
