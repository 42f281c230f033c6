"""The bands' tracking term (genbacklash_core.online.tracking): a wearing gap in the band."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import RecursiveIdentifier, WindowedIdentifier
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.online.memory import RowMemory
from genbacklash_core.online.tracking import dead_zone_drift
from genbacklash_core.scenarios import OperationSettings, operation_record
from genbacklash_core.structure import Structure

CURVED = GeneralBacklash([1.0, 0.03, -0.015], 0.045, [1.0, 0.025, -0.012], 0.05)


def _rows(
    rng: np.random.Generator, n: int, rate_left: float, rate_right: float
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """``n`` rows of moves from the engaged branch, oldest first, while the dead zones grow
    at the given rates per row; and each row's age (rows taken since)."""
    u0 = rng.uniform(-1.0, 1.0, n)
    u1 = u0 + rng.choice([-0.05, 0.05], n)
    age = np.arange(n, dtype=np.float64)[::-1]
    y1 = np.empty(n)
    for k in range(n):
        drivetrain = GeneralBacklash(
            CURVED.m_left,
            CURVED.c_left - rate_left * age[k],
            CURVED.m_right,
            CURVED.c_right - rate_right * age[k],
        )
        branch = drivetrain.right if u1[k] > u0[k] else drivetrain.left
        y1[k] = float(branch(np.array([u1[k]]))[0])
    # the previous state on the branch the move engages, so every row engages it
    y0 = np.where(u1 > u0, y1 - 0.06, y1 + 0.06)
    return (u0, u1, y0, y1), age


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    st.floats(-2e-5, 2e-5),
    st.floats(-2e-5, 2e-5),
    st.integers(0, 2**31 - 1),
)
def test_known_drift_is_recovered(rate_left: float, rate_right: float, seed: int) -> None:
    """Noise-free rows of dead zones growing linearly: the joint fit finds the rates and how
    far the drivetrain is now past an estimate (here the truth as it was 100 rows ago)."""
    rows, age = _rows(np.random.default_rng(seed), 600, rate_left, rate_right)
    then = CURVED.parameters().copy()
    n = CURVED.degree
    then[n] -= 100 * rate_left  # c_left, 100 rows ago
    then[-1] -= 100 * rate_right
    fit = dead_zone_drift(Structure(3), then, rows, age)
    assert fit is not None
    # first order in the drift: exact for a straight branch, ~1e-4 relative for these curves
    np.testing.assert_allclose(fit.rate, [rate_left, rate_right], rtol=2e-3, atol=1e-12)
    want = np.zeros(then.size)
    want[n], want[-1] = 100 * rate_left, 100 * rate_right
    np.testing.assert_allclose(fit.correction, want, atol=2e-3 * np.max(np.abs(want)) + 1e-12)
    tracking = fit.tracking_covariance()
    assert np.all(np.linalg.eigvalsh(tracking) >= -1e-18)  # b b^T: positive semi-definite


def test_a_drivetrain_that_does_not_change_adds_nothing() -> None:
    """Noise only: no rate stands out, the bands stay the statistical ones (5 seeds)."""
    for seed in range(5):
        rng = np.random.default_rng([seed, 44])
        rows, age = _rows(rng, 800, 0.0, 0.0)
        u0, u1, y0, y1 = rows
        noisy = (u0, u1, y0, y1 + rng.normal(0.0, 1e-3, y1.size))
        fit = dead_zone_drift(Structure(3), CURVED.parameters(), noisy, age)
        assert fit is not None and not fit.drifting
        assert not np.any(fit.tracking_covariance())


def test_rows_that_cannot_tell_give_none() -> None:
    rng = np.random.default_rng(1)
    (u0, u1, y0, y1), age = _rows(rng, 100, 0.0, 0.0)
    up = u1 > u0
    only_up = (u0[up], u1[up], y0[up], y1[up])
    assert dead_zone_drift(Structure(3), CURVED.parameters(), only_up, age[up]) is None
    empty = (np.empty(0),) * 4
    assert dead_zone_drift(Structure(3), CURVED.parameters(), empty, np.empty(0)) is None
    cascade = Structure(3, 1, 1)
    assert dead_zone_drift(cascade, np.zeros(cascade.n_parameters), (u0, u1, y0, y1), age) is None


def test_memory_stamps_count_the_rows_taken() -> None:
    mem = RowMemory(capacity=4, bins=1)
    u = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.4])
    mem.add_series(u, u, np.zeros(u.size, dtype=bool))
    assert mem.taken == 6
    order, up = mem.stamps()
    assert order.tolist() == [2, 3, 4, 5] and up.tolist() == [True, True, True, False]


@pytest.mark.parametrize("make", [WindowedIdentifier, RecursiveIdentifier])
def test_a_wearing_gap_stays_inside_the_band(make: type) -> None:
    """The operation scenario, both dead zones 20 % wider after 30 s (the bundled bag): the
    estimate trails the wear by several mrad. The statistical band alone (a few tenths of a
    mrad) missed the final play by 20 sigma; with the tracking term it holds it, on 3 seeds."""
    for seed in range(3):
        cfg = OperationSettings(duration=30.0, phases=(("operation", 30.0),), wear=0.2)
        rec = operation_record(cfg, seed)
        u, y, b = rec.series(bridge=True)
        ident = make(3)
        for s in range(0, u.size, 64):
            est = ident.update_many(u[s : s + 64], y[s : s + 64], b[s : s + 64])
        assert est.available
        play, play_std = est.play()
        true_play = float(rec.c_left[-1] + rec.c_right[-1])
        assert true_play - play > 0.003  # it trails the wear
        assert abs(play - true_play) <= 2.0 * play_std, (seed, play, play_std, true_play)
        assert play_std < 0.02  # and the band still says something (play ~0.11 rad)
