"""The windowed identifier on a drivetrain in normal operation (issue 12's scenario).

Moves, dwells and jogs, 100 Hz commands held at a 1 kHz quantised encoder with jitter and
2 % lost readings (genbacklash_core.scenarios). The identifier remembers rows by branch and
input region, so dwells do not flush it, a joint moving one way keeps its estimate, and a
lost reading never pairs non-consecutive readings.
"""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import EstimatorState, WindowedIdentifier, nrmse, paper_example
from genbacklash_core.samples import sample_breaks
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    STRAIGHT_BACKLASH,
    OperationRecord,
    OperationSettings,
    operation_record,
)

BATCH = 64  # as the node feeds


def _feed(ident: WindowedIdentifier, rec: OperationRecord) -> float | None:
    """Feed the record in node-sized batches; the data time of the first estimate."""
    u, y, breaks = rec.series()
    first = None
    for s in range(0, u.size, BATCH):
        est = ident.update_many(u[s : s + BATCH], y[s : s + BATCH], breaks[s : s + BATCH])
        if first is None and est.available:
            first = rec.encoder_t_ns[min(s + BATCH, u.size) - 1] / 1e9
    return first


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_identifies_a_drivetrain_in_operation(seed: int) -> None:
    rec = operation_record(OperationSettings(duration=40.0), seed)
    ident = WindowedIdentifier(3)
    first = _feed(ident, rec)
    assert first is not None and first <= 10.0  # an estimate within 10 s of operation
    est = ident.refit()
    assert est.state is EstimatorState.CONVERGED, est.reason
    assert est.model is not None
    fit = nrmse(rec.x_all, est.model.simulate(rec.u_all, rec.x_all[0]))
    assert fit <= 0.02  # issue 12's target (measured ~1e-4)
    assert est.confidence > 0.9


def test_straight_branches_with_a_higher_degree() -> None:
    rec = operation_record(OperationSettings(duration=30.0, model=STRAIGHT_BACKLASH), 4)
    for degree in (1, 2):
        ident = WindowedIdentifier(degree)
        _feed(ident, rec)
        est = ident.refit()
        assert est.model is not None, est.reason
        assert nrmse(rec.x_all, est.model.simulate(rec.u_all, rec.x_all[0])) <= 0.02


def test_one_way_motion_for_minutes_keeps_the_estimate() -> None:
    cfg = OperationSettings(phases=(("operation", 30.0), ("one_way", 120.0)))
    rec = operation_record(cfg, 0)
    u, y, b = rec.series()
    split = int(np.searchsorted(rec.encoder_t_ns, 30e9))
    ident = WindowedIdentifier(3)
    before = ident.update_many(u[:split], y[:split], b[:split])
    after = ident.update_many(u[split:], y[split:], b[split:])
    assert before.state is EstimatorState.CONVERGED
    assert after.state in (EstimatorState.CONVERGED, EstimatorState.NO_EXCITATION)
    assert np.max(np.abs(after.parameters - before.parameters)) < 0.005
    assert 0.5 < after.confidence <= before.confidence


def test_rest_holds_the_estimate_with_a_fading_confidence() -> None:
    rec = operation_record(OperationSettings(duration=20.0), 1)
    ident = WindowedIdentifier(3)
    _feed(ident, rec)
    moving = ident.estimate
    u_rest, y_rest = np.full(300_000, rec.u_all[-1]), np.full(300_000, rec.y_all[-1])
    held = ident.update_many(u_rest, y_rest)
    assert held.state is EstimatorState.NO_EXCITATION
    assert "no information" in held.reason
    np.testing.assert_array_equal(held.parameters, moving.parameters)
    # half-life 600000 samples: after 300000 at rest, 0.5 ** 0.5 of the confidence
    assert held.confidence == pytest.approx(moving.confidence * 0.5**0.5, rel=0.01)


def test_tracks_wear_within_30_seconds() -> None:
    """Gap +50 % over 10 minutes of operation: the estimate follows within 30 s."""
    rec = operation_record(OperationSettings(duration=600.0, wear=0.5), 0)
    u, y, b = rec.series()
    t = rec.encoder_t_ns / 1e9
    truth = rec.c_left[rec.received]
    ident = WindowedIdentifier(3)
    lags = []
    for s in range(0, u.size, 2000):
        est = ident.update_many(u[s : s + 2000], y[s : s + 2000], b[s : s + 2000])
        now = t[min(s + 2000, u.size) - 1]
        if now > 300.0:  # judged in the second half
            k = min(int(np.searchsorted(truth, est.parameters[3])), t.size - 1)
            lags.append(now - t[k])
    assert 0.0 < float(np.median(lags)) <= 30.0


@pytest.mark.parametrize("loss", [0.1, 0.3])
def test_lost_readings_do_not_bias_the_estimate(loss: float) -> None:
    """Example 1, one command per reading: rows only from consecutive readings, so the final
    error at 10 % and 30 % loss stays within 1.2x the error without loss (over seeds)."""
    ex = paper_example(1)
    truth = ex.model.parameters()

    def error(rate: float, seed: int) -> float:
        d = ex.generate(seed, n_samples=6000)
        keep = np.random.default_rng([seed, 5]).random(d.u.size) >= rate
        keep[0] = True
        breaks = sample_breaks(np.flatnonzero(keep) * 1_000_000, 1e6)
        ident = WindowedIdentifier(3)
        for s in range(0, int(keep.sum()), BATCH):
            ident.update_many(
                d.u[keep][s : s + BATCH], d.y[keep][s : s + BATCH], breaks[s : s + BATCH]
            )
        return float(np.max(np.abs(ident.refit().parameters - truth)))

    seeds = range(6)
    base = np.mean([error(0.0, s) for s in seeds])
    lossy = np.mean([error(loss, s) for s in seeds])
    assert lossy <= 1.2 * base, (lossy, base)


def test_without_the_rule_loss_would_bias_it() -> None:
    """The control: the same lossy stream fed as if consecutive shrinks the gaps."""
    ex = paper_example(1)
    d = ex.generate(0, n_samples=6000)
    keep = np.random.default_rng([0, 5]).random(d.u.size) >= 0.3
    ident = WindowedIdentifier(3)
    est = ident.update_many(d.u[keep], d.y[keep])
    assert est.parameters[3] < 0.95 * ex.model.c_left  # the left gap read too small


def test_update_and_update_many_agree_in_memory_mode() -> None:
    """One sample at a time (with follows=False at the breaks) is the batched path."""
    rec = operation_record(OperationSettings(duration=6.0, loss=0.05), 2)
    u, y, breaks = rec.series()
    one = WindowedIdentifier(3)
    for uk, yk, bk in zip(u.tolist(), y.tolist(), breaks.tolist(), strict=True):
        last = one.update(uk, yk, follows=not bk)
    many = WindowedIdentifier(3)
    for s in range(0, u.size, 333):
        est = many.update_many(u[s : s + 333], y[s : s + 333], breaks[s : s + 333])
    np.testing.assert_array_equal(last.parameters, est.parameters)
    assert (last.state, last.samples, last.confidence) == (est.state, est.samples, est.confidence)


def test_a_bad_early_start_is_replaced_from_the_memory() -> None:
    """180 s at 30 % loss, seed 3: the first cold start (1.9 s, few rows) gave a wild left
    branch, and every later fit from it met a singular regression. That was reported as no
    excitation and frozen for good; with the memory holding every region seen, it now
    restarts from it."""
    rec = operation_record(OperationSettings(duration=180.0, loss=0.3), 3)
    ident = WindowedIdentifier(3)
    _feed(ident, rec)
    est = ident.refit()
    assert est.state is EstimatorState.CONVERGED, est.reason
    assert np.max(np.abs(est.parameters - OPERATION_BACKLASH.parameters())) < 0.005
