"""The realistic drivetrain scenario (genbacklash_core.scenarios)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from genbacklash_core import count_reversals
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    OperationSettings,
    operation_record,
    worn,
)


def test_operation_looks_like_the_field() -> None:
    """Commands at 100 Hz held, 1 kHz jittered stamps, 2 % loss, quantised readings, moves
    within the limits, dwells, reversals a few times a second."""
    cfg = OperationSettings(duration=30.0)
    rec = operation_record(cfg, seed=3)
    assert rec.command_t_ns.size == 3000 and rec.sample_t_ns.size == 30_000
    np.testing.assert_array_less(np.diff(rec.sample_t_ns), 1.5e6)  # jitter < period / 3
    assert 0.015 < 1.0 - rec.received.mean() < 0.025
    q = cfg.quantum
    np.testing.assert_allclose(rec.encoder_y / q, np.round(rec.encoder_y / q), atol=1e-9)
    assert np.max(np.abs(rec.encoder_y - rec.x_all[rec.received])) <= q / 2 + 1e-12
    v = np.diff(rec.command_u) * cfg.command_rate
    assert np.max(np.abs(v)) <= cfg.v_max + 1e-9
    assert np.mean(v == 0.0) > 0.2  # dwells
    reversals = count_reversals(rec.command_u) / cfg.total_seconds
    assert 0.8 < reversals < 4.0
    # the held command at each reading
    k = np.searchsorted(rec.command_t_ns, rec.sample_t_ns, side="right") - 1
    np.testing.assert_array_equal(rec.u_all, rec.command_u[k])
    # the load is where the play operator puts it
    np.testing.assert_allclose(rec.x_all, OPERATION_BACKLASH.simulate(rec.u_all, rec.x_all[0]))


def test_series_applies_the_sample_rule() -> None:
    rec = operation_record(OperationSettings(duration=5.0, loss=0.1), seed=1)
    u, y, breaks = rec.series()
    kept = np.flatnonzero(rec.received)
    np.testing.assert_array_equal(breaks[1:], np.diff(kept) != 1)
    assert u.size == y.size == kept.size


def test_wear_and_phases() -> None:
    cfg = OperationSettings(phases=(("operation", 4.0), ("one_way", 6.0)), wear=0.5)
    rec = operation_record(cfg, seed=2)
    assert rec.phase_starts == (("operation", 0.0), ("one_way", 4.0))
    assert rec.c_left[0] == pytest.approx(OPERATION_BACKLASH.c_left, rel=0.01)
    assert rec.c_left[-1] == pytest.approx(1.5 * OPERATION_BACKLASH.c_left, rel=0.01)
    assert rec.truth_end.c_right == pytest.approx(rec.c_right[-1])
    one_way = rec.command_u[400:]
    steps = np.diff(one_way)
    assert np.all(steps >= 0) or np.all(steps <= 0)  # never reverses
    assert worn(OPERATION_BACKLASH, 2.0).c_left == 2 * OPERATION_BACKLASH.c_left


@pytest.mark.parametrize("kind", ["pick_and_place", "sine_sweep"])
def test_other_motions_stay_in_the_travel(kind: str) -> None:
    cfg = OperationSettings(phases=((kind, 20.0),))
    rec = operation_record(cfg, seed=0)
    assert cfg.travel[0] <= rec.command_u.min() and rec.command_u.max() <= cfg.travel[1]
    assert count_reversals(rec.command_u) >= 4


def test_deterministic_per_seed() -> None:
    a = operation_record(OperationSettings(duration=3.0), seed=7)
    b = operation_record(OperationSettings(duration=3.0), seed=7)
    np.testing.assert_array_equal(a.y_all, b.y_all)
    assert not np.array_equal(a.y_all, operation_record(OperationSettings(duration=3.0), 8).y_all)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"travel": (1.0, 0.0)}, "travel"),
        ({"v_max": 0.0}, "v_max"),
        ({"loss": 0.99}, "loss"),
        ({"phases": (("teleport", 1.0),)}, "unknown phase"),
        ({"phases": (("operation", 0.0),)}, "must last"),
        ({"encoder_rate": 10.0}, "encoder_rate"),
        ({"command_jitter": 0.5}, "command_jitter"),
    ],
)
def test_settings_validation(changes: dict[str, object], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        OperationSettings(**changes)  # type: ignore[arg-type]


def test_quantum() -> None:
    assert OperationSettings().quantum == pytest.approx(2 * math.pi / 4096)
    assert OperationSettings(counts_per_rev=0).quantum == 0.0
