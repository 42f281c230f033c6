"""The measured-tracking stage and the record's baseline measured with it."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core.measured import TrackingJudgeSettings
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
