"""``bench/run_all.py`` assembles every section: a full run must not drop one.

Every benchmark script in ``bench/`` is run by it (under its own name or, with arguments, under
a section name of :data:`RUNS`), and the sections no script writes (the live demo's) are carried
over from the ``BENCHMARKS.md`` being replaced.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture(scope="module")
def run_all() -> Iterator[ModuleType]:
    sys.path.insert(0, str(BENCH))
    try:
        yield importlib.import_module("run_all")
    finally:
        sys.path.remove(str(BENCH))


def test_every_benchmark_script_is_run(run_all: ModuleType) -> None:
    scripts = {p.stem for p in BENCH.glob("*.py") if not p.stem.startswith("_")} - {"run_all"}
    run = {run_all.RUNS.get(name, (name, []))[0] for name in run_all.BENCHMARKS}
    assert scripts - run == set(), "scripts whose sections a full run would drop"
    assert run - scripts == set()
    for name in ("physics_accuracy", "physics_loop", "physics_diagnose", "csv_vs_bag"):
        assert name in run_all.BENCHMARKS
    assert {"coverage", "spike_screen", "spike_screen_physics"} <= set(run_all.BENCHMARKS)


def test_hand_kept_sections_are_carried_over(run_all: ModuleType) -> None:
    text = (BENCH.parent / "BENCHMARKS.md").read_text(encoding="utf-8")
    kept = run_all.hand_kept(text)
    assert set(kept) <= set(run_all.BENCHMARKS)
    (demo,) = kept["take_cost"]
    assert demo.startswith("## Live demo") and "\n## " not in demo
    assert run_all.hand_kept("# t\n\n## A\na\n") == {}


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_physics_loop_refuses_a_late_stamp_time_that_is_no_time(
    value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--late-stamps -1`` ran every record as if no stamp were late; now it is refused
    before anything runs, with the reason."""
    sys.path.insert(0, str(BENCH))
    try:
        physics_loop = importlib.import_module("physics_loop")
        with pytest.raises(SystemExit) as stop:
            physics_loop._arguments(["--late-stamps", value])
    finally:
        sys.path.remove(str(BENCH))
    assert stop.value.code == 2
    assert "--late-stamps must be a time in ms >= 0" in capsys.readouterr().err


def test_physics_start_finds_the_latest_switch_over_that_still_meets_the_target() -> None:
    """``bench/physics_start.py``'s arithmetic: an error of 1 before the switch-over and 0
    after cuts ``1 - sqrt(T / D)`` over a record of D seconds, so a 50 % target allows a
    switch-over up to D / 4 and no later; and two runs first differ where they first differ."""
    sys.path.insert(0, str(BENCH))
    try:
        physics_start = importlib.import_module("physics_start")
    finally:
        sys.path.remove(str(BENCH))
    seconds = np.arange(4000) * 0.01  # 40 s at 100 Hz
    none, true = np.ones(seconds.size), np.zeros(seconds.size)
    assert physics_start.latest_start(seconds, none, true, 50.0) == pytest.approx(10.0)
    assert physics_start.latest_start(seconds, none, true, 49.0) == pytest.approx(10.4)
    assert np.isnan(physics_start.latest_start(seconds, none, none, 1.0))
    a = np.arange(10.0)
    b = a.copy()
    assert physics_start.first_difference(a, b) is None
    b[7] += 1e-15
    assert physics_start.first_difference(a, b) == 7


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--variants", "nearideal"], "argument --variants: invalid choice: 'nearideal'"),
        (["--duration", "0"], "argument --duration: must be a number > 0, got '0'"),
        (["--duration", "inf"], "argument --duration: must be a number > 0, got 'inf'"),
        (["--bandwidths", "60", "-20"], "argument --bandwidths: must be a number > 0"),
        (["--bandwidths", "nan"], "argument --bandwidths: must be a number > 0"),
    ],
)
@pytest.mark.parametrize(
    "bench",
    ["physics_accuracy", "physics_diagnose", "physics_loop", "physics_null", "physics_start"],
)
def test_the_physics_benches_refuse_a_grid_that_is_no_grid(
    bench: str, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A misspelt variant ran as far as building it and then stopped with a traceback, and a
    duration of 0 failed deep in the scenario; now each is refused with one line before
    anything runs."""
    sys.path.insert(0, str(BENCH))
    try:
        module = importlib.import_module(bench)
        with pytest.raises(SystemExit) as stop:
            module._arguments(argv)
    finally:
        sys.path.remove(str(BENCH))
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
