"""The measured-tracking stage and the record's baseline measured with it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.measured import HeldHarm, OfflineBaseline, TrackingJudgeSettings
from genbacklash_ros.node.checkpoint import load_checkpoint, save_checkpoint
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.node.tracking_stage import TrackingStage, record_baseline

MS = 1_000_000


def _record(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """100 Hz commands, 1 kHz readings with 2 % lost (seeded), a lagging load."""
    rng = np.random.default_rng(seed)
    cmd_t = 10 * MS * np.arange(1, 801)
    cmd_u = np.cumsum(rng.normal(0.0, 0.01, cmd_t.size))
    enc_t = MS * np.arange(1, 8000)
    enc_t = enc_t[rng.random(enc_t.size) >= 0.02]
    k = np.searchsorted(cmd_t, enc_t, side="right") - 1
    held = np.where(k >= 0, cmd_u[np.maximum(k, 0)], 0.0)
    enc_y = held - 0.02 * np.sign(np.gradient(held)) + rng.normal(0.0, 0.001, enc_t.size)
    return cmd_t, cmd_u, enc_t, enc_y


def test_the_records_baseline_is_what_the_nodes_judge_measures() -> None:
    cmd_t, cmd_u, enc_t, enc_y = _record(0)
    pipe = BacklashPipeline(
        NodeParameters(
            command_type="float64",
            encoder_type="float64",
            compensate=False,
            compensation_in_loop=True,
        )
    )
    c = 0
    for t, y in zip(enc_t.tolist(), enc_y.tolist(), strict=True):
        while c < cmd_t.size and cmd_t[c] <= t:
            pipe.on_command_value(None, float(cmd_u[c]), int(cmd_t[c]))
            c += 1
        pipe.on_encoder_value(None, y, t)
    pipe.finish(refit=False)
    measured = pipe.measured
    base = record_baseline(cmd_t, cmd_u, enc_t, enc_y)
    assert base is not None
    assert base.rms == pytest.approx(measured.off_rms, rel=1e-12)
    assert base.seconds == pytest.approx(measured.off_time, rel=1e-12)


def test_a_record_shorter_than_min_time_gives_no_baseline() -> None:
    cmd_t, cmd_u, enc_t, enc_y = _record(1)
    short = enc_t < 2_000 * MS
    assert record_baseline(cmd_t, cmd_u, enc_t[short], enc_y[short]) is None
    longer = TrackingJudgeSettings(min_time=1.0)
    assert record_baseline(cmd_t, cmd_u, enc_t[short], enc_y[short], longer) is not None
    assert record_baseline([], [], enc_t, enc_y) is None


# --------------------------------------------------------------------------- checkpoints


def _motion(seed: int, seconds: float) -> np.ndarray:
    """100 Hz commands: two sines (seeded phase) and noise."""
    rng = np.random.default_rng(seed)
    tt = np.arange(1, round(100 * seconds) + 1) / 100
    u = 0.4 * np.sin(2 * np.pi * 0.7 * tt + seed) + 0.2 * np.sin(2 * np.pi * 1.9 * tt)
    return u + rng.normal(0.0, 0.01, tt.size)


def _loop(pipe: BacklashPipeline, seed: int, seconds: float, gain: float = 1.0) -> int:
    """The pipeline in the loop of a play of 0.04 rad: each command's answer is what the
    play takes; 10 readings (1 kHz) of the load after each command; then finish. ``gain``:
    what the drive makes of the compensation (-1: a drive that turns it round, so that
    compensating tracks worse). Returns how many commands went out compensated."""
    rng = np.random.default_rng(seed + 1000)
    x = 0.0
    compensated = 0
    for k, value in enumerate(_motion(seed, seconds).tolist()):
        stamp = 10 * MS * (k + 1)
        got = pipe.on_command_value(None, value, stamp)
        sent = value if got is None else got[1]
        compensated += sent != value
        drive = value + gain * (sent - value)
        x = min(max(x, drive - 0.02), drive + 0.02)
        for j, noise in enumerate(rng.normal(0.0, 0.001, 10).tolist(), start=1):
            pipe.on_encoder_value(None, x + noise, stamp + j * MS)
    pipe.finish(refit=False)
    return compensated


def _params(path: Path, *, in_loop: bool = True, compensate: bool = True) -> NodeParameters:
    return NodeParameters(
        command_type="float64",
        encoder_type="float64",
        compensate=compensate,
        compensation_in_loop=in_loop,
        checkpoint_file=str(path),
    )


def test_the_nodes_checkpoint_keeps_the_baseline_its_judge_measured(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    pipe = BacklashPipeline(_params(path))
    _loop(pipe, 0, 14.0)
    measured = pipe.measured
    assert measured.state == "on" and measured.baseline == "measured"  # it helps, measured
    final = load_checkpoint(path)
    assert final.baseline == OfflineBaseline(measured.off_rms, measured.off_time)
    # a restart from it: the judge starts from that baseline
    again = BacklashPipeline(_params(path))
    assert again.measured.baseline == "offline"
    assert final.baseline is not None and again.measured.off_rms == final.baseline.rms
    # ... compensates after the guard's first verdict, under 3 s of its own baseline, and
    # carries the one it started from forward
    _loop(again, 1, 10.0)
    assert again.measured.state == "on"
    # the live probe agreed with it: still judged against the stored one
    assert again.measured.baseline == "offline" and "agrees" in again.measured.reason
    assert again.measured.live_time < 3.0
    assert load_checkpoint(path).baseline == final.baseline


def test_a_node_that_measured_no_help_stores_no_baseline(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    # not in the loop: its weight-0 readings need not have gone without compensation
    _loop(BacklashPipeline(_params(path, in_loop=False)), 0, 14.0)
    assert load_checkpoint(path).baseline is None
    assert "baseline" not in json.loads(path.read_text())  # the old layout, unchanged
    # in the loop with a full baseline, but compensation never measured helping
    path.unlink()
    pipe = BacklashPipeline(_params(path, compensate=False))
    _loop(pipe, 0, 14.0)
    assert pipe.measured.off_time >= 3.0 and load_checkpoint(path).baseline is None


def test_a_watching_node_carries_its_starts_baseline_forward(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    _loop(BacklashPipeline(_params(path)), 0, 14.0)
    stored = load_checkpoint(path).baseline
    assert stored is not None
    _loop(BacklashPipeline(_params(path, in_loop=False)), 1, 10.0)
    assert load_checkpoint(path).baseline == stored  # not replaced by what it watched


@pytest.mark.parametrize(("kept", "stored"), [(0.25, True), (0.75, False)])
def test_a_baseline_is_stored_only_where_compensation_clearly_helped(
    kept: float, stored: bool
) -> None:
    # the judge fed directly: 4 s without compensation, then 8 s keeping `kept` of the error
    stage = TrackingStage(NodeParameters(compensation_in_loop=True).judge_settings())
    judge = stage.judge
    rng = np.random.default_rng(0)
    last = 0
    for seconds, rms, weight in ((4.0, 0.04, 0.0), (8.0, 0.04 * kept, 1.0)):
        for _ in range(round(10 * seconds)):  # 100 readings at 1 kHz a feed
            t = last + MS * np.arange(1, 101)
            last = int(t[-1])
            judge.readings(t, rng.normal(0.0, rms, 100), np.zeros(100), np.full(100, weight))
    assert judge.verdict.state == "on"  # both: compensation kept on, ratio below 0.9
    assert judge.verdict.ratio == pytest.approx(kept, rel=0.15)
    expected = judge.live_baseline() if stored else None
    assert stage.baseline_to_store(in_loop=True) == expected and (expected is not None) == stored
    # a node that only watches stores nothing it measured: its start's baseline (none here)
    assert stage.baseline_to_store(in_loop=False) is None
    assert stage.harm_to_store(in_loop=False) is None


def _play_of(pipe: BacklashPipeline) -> float:
    model = pipe.estimate.model
    assert model is not None
    return float(model.c_left + model.c_right)  # type: ignore[union-attr]


def test_the_nodes_checkpoint_keeps_its_verdict_of_harm(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    pipe = BacklashPipeline(_params(path))
    _loop(pipe, 0, 14.0, gain=-1.0)  # compensation turned round: it tracks worse
    assert pipe.measured.state == "off"
    saved = load_checkpoint(path)
    assert saved.harm is not None and saved.baseline is None
    assert saved.harm.ratio >= 1.0 and 0.0 < saved.harm.held < 14.0
    assert saved.harm == pipe._tracking.judge.held_harm()
    # not in the loop: the judge never judges harm, and nothing is stored
    path.unlink()
    _loop(BacklashPipeline(_params(path, in_loop=False)), 0, 14.0, gain=-1.0)
    assert load_checkpoint(path).harm is None


def test_a_restart_holds_the_model_its_checkpoint_says_tracked_worse(tmp_path: Path) -> None:
    # a checkpoint of a model that helps on this loop, told it was measured tracking worse
    path = tmp_path / "c.json"
    first = BacklashPipeline(_params(path))
    _loop(first, 0, 14.0)
    play = _play_of(first)
    saved = dataclasses.replace(load_checkpoint(path), baseline=None, harm=HeldHarm(play, 1.3, 1.0))
    held, bare = tmp_path / "held.json", tmp_path / "bare.json"
    save_checkpoint(held, saved)
    save_checkpoint(bare, dataclasses.replace(saved, harm=None))
    restart = BacklashPipeline(_params(held))
    assert restart.measured.state == "off" and "before this start" in restart.measured.reason
    # the model stays off while the estimate stays within RETRY_CHANGE of its play
    assert _loop(restart, 1, 10.0) == 0
    assert abs(_play_of(restart) / play - 1.0) < 0.1
    assert restart.measured.state == "off"
    kept = load_checkpoint(held).harm
    assert kept is not None and kept.play == play and kept.held > 9.0  # carried on
    # without the verdict the same restart tries the model after its 3 s baseline
    assert _loop(BacklashPipeline(_params(bare)), 1, 10.0) > 0


def test_compensation_back_after_the_guard_held_it_off_is_tried_again(tmp_path: Path) -> None:
    """The judge measures compensation afresh, with a trial, when the model's guard lets it
    back after an "off" (a seeded start on gravity 60 Hz went back to full weight at once
    10 s after its trial and tracked 33 % worse for 2 s: BENCHMARKS.md, issue 23)."""
    pipe = BacklashPipeline(_params(tmp_path / "c.json"))
    _loop(pipe, 0, 14.0)
    assert pipe.measured.state == "on" and pipe.measured.trust == 1.0
    verdict = pipe.guard
    pipe._judges.apply()  # the guard still on: nothing changes
    assert pipe.measured.state == "on"
    pipe._judges.guard.verdict = dataclasses.replace(verdict, trust=0.0, state="off")
    pipe._judges.apply()
    assert pipe.measured.state == "on"  # the judge's own verdict, the guard's trust apart
    pipe._judges.guard.verdict = verdict
    pipe._judges.apply()
    measured = pipe.measured
    assert measured.state == "judging" and "trial" in measured.reason
    assert measured.trust < 0.1 and measured.off_time > 3.0  # the baseline is kept
