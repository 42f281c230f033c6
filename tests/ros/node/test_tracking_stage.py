"""The measured-tracking stage and the record's baseline measured with it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.measured import OfflineBaseline, TrackingJudgeSettings
from genbacklash_ros.node.checkpoint import Checkpoint, load_checkpoint, save_checkpoint
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.node.tracking_stage import record_baseline

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


def _play_record(seed: int, seconds: float = 8.0) -> tuple[np.ndarray, ...]:
    """100 Hz commands (two sines, seeded phase and noise) through a play of 0.04 rad, held;
    1 kHz readings with 2 % lost: a record the node identifies within 2 s."""
    rng = np.random.default_rng(seed)
    cmd_t = 10 * MS * np.arange(1, round(100 * seconds) + 1)
    tt = cmd_t / 1e9
    cmd_u = 0.4 * np.sin(2 * np.pi * 0.7 * tt + seed) + 0.2 * np.sin(2 * np.pi * 1.9 * tt)
    cmd_u += rng.normal(0.0, 0.01, tt.size)
    x = np.empty_like(cmd_u)
    prev = 0.0
    for i, u in enumerate(cmd_u.tolist()):
        prev = min(max(prev, u - 0.02), u + 0.02)
        x[i] = prev
    enc_t = MS * np.arange(1, round(1000 * seconds))
    enc_t = enc_t[rng.random(enc_t.size) >= 0.02]
    k = np.searchsorted(cmd_t, enc_t, side="right") - 1
    enc_y = np.where(k >= 0, x[np.maximum(k, 0)], 0.0) + rng.normal(0.0, 0.001, enc_t.size)
    return cmd_t, cmd_u, enc_t, enc_y


def _feed(pipe: BacklashPipeline, record: tuple[np.ndarray, ...], seconds: float) -> None:
    """The record's first ``seconds`` through the pipeline, commands before readings."""
    cmd_t, cmd_u, enc_t, enc_y = record
    c = 0
    for t, y in zip(enc_t.tolist(), enc_y.tolist(), strict=True):
        if t > seconds * 1e9:
            break
        while c < cmd_t.size and cmd_t[c] <= t:
            pipe.on_command_value(None, float(cmd_u[c]), int(cmd_t[c]))
            c += 1
        pipe.on_encoder_value(None, y, t)
    pipe.finish(refit=False)


def _params(path: Path, *, in_loop: bool = True) -> NodeParameters:
    return NodeParameters(
        command_type="float64",
        encoder_type="float64",
        compensate=False,
        compensation_in_loop=in_loop,
        checkpoint_file=str(path),
        checkpoint_period=1.0,
    )


def test_the_nodes_checkpoint_keeps_the_baseline_its_judge_measured(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    saved: list[Checkpoint] = []

    def writer(target: Path, checkpoint: Checkpoint) -> None:
        saved.append(checkpoint)
        save_checkpoint(target, checkpoint)

    pipe = BacklashPipeline(_params(path), checkpoint_writer=writer)
    _feed(pipe, _play_record(0), 8.0)
    measured = pipe.measured
    assert measured.off_time >= 3.0 and measured.baseline == "measured"
    # before 3 s of it nothing is stored; after, the judge's numbers
    early = [c for c in saved if c.time_ns < 2_900 * MS]
    assert early and all(c.baseline is None for c in early)
    final = load_checkpoint(path)
    assert final.baseline == OfflineBaseline(measured.off_rms, measured.off_time)
    # a restart from it: the judge starts from that baseline
    again = BacklashPipeline(_params(path))
    assert again.measured.baseline == "offline"
    assert again.measured.off_rms == final.baseline.rms
    # ... and a short run, under 3 s of its own, carries it forward unchanged
    _feed(again, _play_record(1), 1.5)
    assert again.measured.off_time < 3.0
    assert load_checkpoint(path).baseline == final.baseline


def test_a_node_that_measured_no_baseline_stores_none(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    # not in the loop: its weight-0 readings need not have gone without compensation
    _feed(BacklashPipeline(_params(path, in_loop=False)), _play_record(0), 8.0)
    assert load_checkpoint(path).baseline is None
    assert "baseline" not in json.loads(path.read_text())  # the old layout, unchanged
    # in the loop but under 3 s of it
    path.unlink()
    _feed(BacklashPipeline(_params(path)), _play_record(0), 2.5)
    assert load_checkpoint(path).baseline is None


def test_a_watching_node_carries_its_starts_baseline_forward(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    _feed(BacklashPipeline(_params(path)), _play_record(0), 8.0)
    stored = load_checkpoint(path).baseline
    assert stored is not None
    _feed(BacklashPipeline(_params(path, in_loop=False)), _play_record(1), 8.0)
    assert load_checkpoint(path).baseline == stored  # not replaced by what it watched
