"""The bands' tracking term (genbacklash_core.online.tracking): a wearing gap in the band."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import RecursiveIdentifier, WindowedIdentifier
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.model_error import correlated_misfit
from genbacklash_core.online.memory import RowMemory
from genbacklash_core.online.tracking import dead_zone_drift, free_run_model
from genbacklash_core.play import play_operator
from genbacklash_core.scenarios import (
    HiddenEffects,
    OperationRecord,
    OperationSettings,
    operation_record,
)
from genbacklash_core.simulate import play_bounds
from genbacklash_core.structure import Structure
from genbacklash_core.uncertainty import free_run_residual

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


def _final_play(make: type, rec: OperationRecord) -> tuple[float, float]:
    """The play and its standard deviation of a ``make(3)`` identifier fed the record in
    chunks of 64 samples, as the node's batch path feeds it."""
    u, y, b = rec.series(bridge=True)
    ident = make(3)
    for s in range(0, u.size, 64):
        est = ident.update_many(u[s : s + 64], y[s : s + 64], b[s : s + 64])
    assert est.available
    return est.play()


@pytest.mark.parametrize("make", [WindowedIdentifier, RecursiveIdentifier])
def test_a_wearing_gap_stays_inside_the_band(make: type) -> None:
    """The operation scenario, both dead zones 20 % wider after 30 s (the bundled bag): the
    estimate trails the wear by several mrad. The statistical band alone (a few tenths of a
    mrad) missed the final play by 20 sigma; with the tracking term it holds it, on 3 seeds."""
    for seed in range(3):
        cfg = OperationSettings(duration=30.0, phases=(("operation", 30.0),), wear=0.2)
        rec = operation_record(cfg, seed)
        play, play_std = _final_play(make, rec)
        true_play = float(rec.c_left[-1] + rec.c_right[-1])
        assert true_play - play > 0.003  # it trails the wear
        assert abs(play - true_play) <= 2.0 * play_std, (seed, play, play_std, true_play)
        assert play_std < 0.02  # and the band still says something (play ~0.11 rad)


def _lagged_rows(
    rng: np.random.Generator, n: int, lag: float, noise: float
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """``n`` rows of moves at speeds from 0.01 to 0.08 per row, read through a drive that
    trails the command by ``lag`` ticks: each dead zone looks ``lag * |u(t) - u(t-1)|``
    wider (first order; exact for the straight branches of ``STRAIGHT``). Noise of standard
    deviation ``noise`` on the readings; every row engages the branch of its move."""
    u0 = rng.uniform(-1.0, 1.0, n)
    step = rng.uniform(0.01, 0.08, n) * rng.choice([-1.0, 1.0], n)
    u1 = u0 + step
    widened = lag * np.abs(step)
    right = STRAIGHT.m_right[0] * (u1 - STRAIGHT.c_right - widened)  # eq. (12)
    left = STRAIGHT.m_left[0] * (u1 + STRAIGHT.c_left + widened)  # eq. (11)
    y1 = np.where(step > 0, right, left) + rng.normal(0.0, noise, n)
    y0 = np.where(step > 0, y1 - 0.2, y1 + 0.2)
    return (u0, u1, y0, y1), np.arange(n, dtype=np.float64)[::-1]


STRAIGHT = GeneralBacklash([1.0], 0.045, [1.0], 0.05)


@pytest.mark.parametrize("seed", range(3))
def test_a_servo_lag_is_found_and_the_band_reaches_the_drivetrain_at_rest(seed: int) -> None:
    """A drive 0.7 ticks behind the command (a 60 Hz servo at 100 Hz commands is ~0.3-1):
    the dead zones the moving rows show are wider than at rest, and an estimate fitted on
    them sits beside the quasi-static truth. The lag is found, and the band's bias term is
    the distance to the drivetrain at rest (the zero-speed point), not to the rows."""
    rng = np.random.default_rng([seed, 45])
    rows, age = _lagged_rows(rng, 1200, 0.7, 2e-4)
    u0, u1, _, _ = rows
    mean_widening = 0.7 * float(np.mean(np.abs(u1 - u0)))  # what a fit of the rows shows
    truth = STRAIGHT.parameters()
    biased = truth.copy()
    biased[1] += mean_widening  # c_left
    biased[3] += mean_widening  # c_right
    fit = dead_zone_drift(Structure(1), biased, rows, age)
    assert fit is not None
    assert fit.lagging and not fit.drifting
    np.testing.assert_allclose(fit.lag, [0.7, 0.7], atol=6 * float(np.max(fit.lag_std)))
    # the zero-speed point: from the estimate to the drivetrain at rest
    assert fit.rest is not None and fit.rest_covariance is not None
    np.testing.assert_allclose(fit.rest[[1, 3]], -mean_widening, atol=5e-4)
    term = fit.tracking_covariance()
    play_term = float(np.sqrt(term[1, 1] + term[3, 3] + 2 * term[1, 3]))
    true_error = 2 * mean_widening
    assert abs(play_term - true_error) < 0.1 * true_error  # ~ the estimate's play error


def test_rows_without_a_lag_show_none_and_add_nothing() -> None:
    """The same rows at many speeds without a lag, noise only: no lag stands out (5 seeds),
    and the bands stay the statistical ones although the rows could tell a lag (the
    zero-speed point is there, noise of the size of its own standard deviation)."""
    for seed in range(5):
        rows, age = _lagged_rows(np.random.default_rng([seed, 46]), 1200, 0.0, 1e-3)
        fit = dead_zone_drift(Structure(1), STRAIGHT.parameters(), rows, age)
        assert fit is not None and fit.rest_covariance is not None
        assert np.all(fit.lag_std > 0.0)  # the speeds vary: the rows can tell
        assert not fit.lagging and not fit.drifting
        assert fit.rest is not None
        noise = fit.rest_covariance
        play_noise = float(np.sqrt(noise[1, 1] + noise[3, 3] + 2 * noise[1, 3]))
        assert abs(fit.rest[1] + fit.rest[3]) < 4.0 * play_noise
        assert not np.any(fit.tracking_covariance())


def test_rows_at_one_speed_cannot_tell_a_lag() -> None:
    """Every row moving by the same step: a lag is indistinguishable from wider dead zones,
    so none is reported (zeros, no zero-speed point) and the drift's term stands alone
    (here none: the dead zones do not drift)."""
    rows, age = _rows(np.random.default_rng(47), 600, 0.0, 0.0)
    fit = dead_zone_drift(Structure(3), CURVED.parameters(), rows, age)
    assert fit is not None
    assert not np.any(fit.lag) and not np.any(fit.lag_std) and not fit.lagging
    assert fit.rest is None and fit.rest_covariance is None
    assert not np.any(fit.tracking_covariance())


@pytest.mark.parametrize("make", [WindowedIdentifier, RecursiveIdentifier])
def test_a_servo_lag_stays_inside_the_band(make: type) -> None:
    """The operation scenario read through a 60 Hz first-order servo (no wear): the estimate
    sits tens of mrad beside the quasi-static play (every 1 kHz reading is fed, moving),
    which the statistical band (~0.1 mrad, the run without the servo below) does not
    describe. With the lag's bias term the band holds the play at rest, on 3 seeds, and
    is not wider than a few times the error."""
    for seed in range(3):
        cfg = OperationSettings(duration=30.0, phases=(("operation", 30.0),), wear=0.0)
        for servo in (0.0, 1.0 / (2.0 * np.pi * 60.0)):
            rec = operation_record(cfg, seed, hidden=HiddenEffects(input_lag=servo))
            play, play_std = _final_play(make, rec)
            error = abs(play - float(rec.c_left[-1] + rec.c_right[-1]))
            if servo == 0.0:  # the model holds: the statistical band, narrow
                assert error <= 2.0 * play_std < 5e-4, (seed, error, play_std)
            else:
                assert error > 0.01, (seed, error)  # the servo biases the estimate
                assert error <= 2.0 * play_std <= 4.0 * error, (seed, error, play_std)


def test_a_misfit_that_follows_the_motion_adds_a_model_term_that_grows() -> None:
    """Rows read through a drivetrain that the play operator misfits smoothly in time (a
    disturbance ``A sin(t / 40)`` on the readings: a ringing coupling, a load torque) and
    white noise. ``A = 0``: the misfit is white, no model term. Else it stands out and the
    play's model-error term grows with ``A``; neither a drift nor a lag explains it."""
    terms = []
    for amplitude in (0.0, 1e-3, 3e-3, 1e-2):
        rows, age = _lagged_rows(np.random.default_rng(48), 1200, 0.0, 5e-4)
        u0, u1, y0, y1 = rows
        disturbed = (u0, u1, y0, y1 + amplitude * np.sin(age / 40.0))
        fit = dead_zone_drift(Structure(1), STRAIGHT.parameters(), disturbed, age)
        assert fit is not None and fit.misfit is not None and fit.model_covariance is not None
        assert fit.misfit.significant == (amplitude > 0.0)
        model = fit.model_covariance
        terms.append(float(np.sqrt(model[1, 1] + model[3, 3] + 2 * model[1, 3])))
        band = fit.tracking_covariance()
        np.testing.assert_array_less(-1e-18, np.linalg.eigvalsh(band))
        assert np.all(np.diag(band) >= np.diag(model))  # the band holds the model term
    assert terms[0] == 0.0
    assert all(a < b for a, b in itertools.pairwise(terms)), terms


@pytest.mark.parametrize("make", [WindowedIdentifier, RecursiveIdentifier])
def test_the_model_term_moves_the_band_and_nothing_the_compensation_reads(
    make: type, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The operation scenario with a periodic error on the load (a misfit that follows the
    motion): with and without the model-error terms (the one-step rows' and the free run's),
    every estimate's parameters, state and confidence are the same bits (what the
    compensator and the guard read); only the published covariance differs, and it is never
    the smaller."""
    import dataclasses

    from genbacklash_core.online import bands, feeds

    cfg = OperationSettings(duration=20.0, phases=(("operation", 20.0),), wear=0.0)
    hidden = HiddenEffects(period=0.5, harmonics=((0.004, 0.0),))
    u, y, b = operation_record(cfg, 1, hidden=hidden).series(bridge=True)

    def run() -> list[tuple[np.ndarray, str, float, np.ndarray]]:
        ident = make(3)
        out = []
        for s in range(0, u.size, 64):
            est = ident.update_many(u[s : s + 64], y[s : s + 64], b[s : s + 64])
            out.append((est.parameters, est.state.value, est.confidence, est.covariance))
        return out

    with_term = run()

    def without(*args: object) -> object:
        fit = dead_zone_drift(*args)  # type: ignore[arg-type]
        if fit is None:
            return None
        return dataclasses.replace(
            fit, model_covariance=None, free_run_covariance=None, free_run_offset=None
        )

    for module in (feeds, bands):  # the windowed identifier's drift is its feed's, the
        # recursive one's its band schedule's
        monkeypatch.setattr(module, "dead_zone_drift", without)
    without_term = run()
    wider = 0
    for (p, state, conf, cov), (p0, state0, conf0, cov0) in zip(
        with_term, without_term, strict=True
    ):
        np.testing.assert_array_equal(p, p0)
        assert (state, conf) == (state0, conf0)
        if np.all(np.isfinite(cov0)):
            assert np.all(np.diag(cov) >= np.diag(cov0))
            wider += bool(np.any(np.diag(cov) > np.diag(cov0)))
    assert wider > 0  # the misfit was seen: the band did change


ENCODER_STEP = 2.0 * np.pi / 4096  # a 4096-count encoder


def _moves(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Readings at 1 kHz of ``STRAIGHT`` driven through 60 moves of random length and speed
    (0.2-1 mrad a reading, slower than the encoder's step), the play's output rounded to
    the encoder's step: the model is exact, the rounding is not white."""
    rng = np.random.default_rng([seed, 60])
    ends = np.cumsum(rng.uniform(-0.4, 0.4, 60))
    u = np.concatenate(
        [
            np.linspace(a, b, int(abs(b - a) / rng.uniform(2e-4, 1e-3)) + 2)
            for a, b in itertools.pairwise(ends)
        ]
    )
    left, right = Structure(1).branches(STRAIGHT.parameters(), u)
    x = play_operator(*play_bounds(left, right), 0.0)  # eqs. (20)-(21)
    breaks = np.zeros(u.size, dtype=bool)
    breaks[0] = True
    return u, x, breaks


@pytest.mark.parametrize("seed", range(3))
def test_the_free_run_term_leaves_an_exact_model_alone_and_sees_a_load_that_trails(
    seed: int,
) -> None:
    """The free run of the true parameters over quantised readings of an exact play: the
    rounding alone is correlated (it stands out on some seeds), but taken out it is no
    model error, so no term. The same readings through a load that trails the gear (a
    first-order lag after the backlash, the rows' and the play operator's blind spot): a
    significant misfit, a finite term of the size the lag shifts the output by."""
    s, p = Structure(1), STRAIGHT.parameters()
    u, x, breaks = _moves(seed)
    y = ENCODER_STEP * np.round(x / ENCODER_STEP)
    exact = free_run_model(s, p, u, y, breaks)
    assert exact is not None
    assert not exact.misfit.significant and not np.any(exact.covariance)
    assert not np.any(exact.offset)  # the true parameters: the step to the optimum is noise
    residual, _ = free_run_residual(s, p, u, y, breaks)
    assert correlated_misfit(residual, breaks).lag_one > 0.0  # the rounding is not white
    trailing = np.empty_like(x)
    load = x[0]
    for k, value in enumerate(x):  # z(t) = 0.8 z(t-1) + 0.2 x(t): a 4.5 ms load lag
        load = 0.8 * load + 0.2 * value
        trailing[k] = load
    lagged = free_run_model(s, p, u, ENCODER_STEP * np.round(trailing / ENCODER_STEP), breaks)
    assert lagged is not None
    misfit, cov = lagged.misfit, lagged.covariance
    assert misfit.significant
    assert np.all(np.isfinite(cov))
    play_std = float(np.sqrt(cov[1, 1] + cov[3, 3] + 2 * cov[1, 3]))
    shift = float(np.sqrt(np.mean((trailing - x) ** 2)))  # what the lag does to the output
    assert 0.2 * shift < play_std < 10.0 * shift, (play_std, shift)


@pytest.mark.parametrize("seed", range(3))
def test_an_estimate_the_readings_disagree_with_gets_the_distance_in_its_band(seed: int) -> None:
    """An estimate 2 mrad of play wider than the drivetrain (what one-step rows read behind
    a servo that lags the command), run over quantised readings of the exact play: the free
    run's step takes its play back to the truth and stands out, so the band takes the
    distance (``b b^T``); the true parameters get no step (the test above)."""
    s = Structure(1)
    u, x, breaks = _moves(seed)
    y = ENCODER_STEP * np.round(x / ENCODER_STEP)
    wide = STRAIGHT.parameters().copy()
    wide[[1, 3]] += 1e-3  # c_left, c_right: 2 mrad of play too wide
    found = free_run_model(s, wide, u, y, breaks)
    assert found is not None
    step_play = float(found.offset[1] + found.offset[3])
    assert -2.5e-3 < step_play < -1.5e-3, step_play
    assert not np.any(found.covariance)  # no misfit left after the step: no model term


def test_a_free_run_that_misfits_the_readings_by_more_than_a_step_gives_no_offset() -> None:
    """A disturbance of 5 mrad that follows the motion (a ringing coupling), three encoder
    steps, read by an estimate 2 mrad of play too wide: the free run's optimum is then the
    output error's best compromise, not the drivetrain, so its step is no evidence of a
    bias (no offset), and the model-error term bounds the bias instead (a nonzero
    covariance)."""
    s = Structure(1)
    u, x, breaks = _moves(0)
    ring = x + 5e-3 * np.sin(np.arange(x.size) / 40.0)
    y = ENCODER_STEP * np.round(ring / ENCODER_STEP)
    wide = STRAIGHT.parameters().copy()
    wide[[1, 3]] += 1e-3  # 2 mrad of play too wide: the step stands out of its noise
    found = free_run_model(s, wide, u, y, breaks)
    assert found is not None
    assert found.misfit.rms_model > ENCODER_STEP
    assert not np.any(found.offset)
    assert np.all(np.diag(found.covariance) > 0.0)


def test_a_branch_the_readings_do_not_engage_gives_no_free_run_term() -> None:
    """Readings that only ever move up engage one branch: the other's parameters are not
    informed, so there is no term (not an infinite band)."""
    u = np.linspace(0.0, 1.0, 2000)
    y = np.sin(u) - 0.05  # not the model: a misfit there would be significant
    breaks = np.zeros(u.size, dtype=bool)
    breaks[0] = True
    assert free_run_model(Structure(1), STRAIGHT.parameters(), u, y, breaks) is None


def test_the_rows_hide_what_the_free_run_shows_and_only_the_band_takes_it() -> None:
    """Readings of a load that trails the gear (a 4.5 ms first-order lag after the play):
    the rows of those readings (consecutive readings whose input moved) leave a misfit the
    drift and lag fits absorb, so the one-step model term is small; the free run over the
    same readings shows the misfit, and the band takes its term. Without the readings the
    fit is the one-step fit alone (no free-run term), and the estimate the fit reports
    does not depend on them."""
    s, p = Structure(1), STRAIGHT.parameters()
    u, x, breaks = _moves(0)
    trailing = np.empty_like(x)
    load = x[0]
    for k, value in enumerate(x):
        load = 0.8 * load + 0.2 * value
        trailing[k] = load
    y = ENCODER_STEP * np.round(trailing / ENCODER_STEP)
    moved = np.flatnonzero(np.diff(u) != 0.0) + 1
    rows = (u[moved - 1], u[moved], y[moved - 1], y[moved])
    age = (moved[-1] - moved).astype(np.float64)
    alone = dead_zone_drift(s, p, rows, age)
    fit = dead_zone_drift(s, p, rows, age, (u, y, breaks))
    assert alone is not None and fit is not None
    assert alone.free_run is None and alone.free_run_covariance is None
    np.testing.assert_array_equal(alone.correction, fit.correction)
    assert fit.free_run is not None and fit.free_run.significant
    assert fit.free_run_covariance is not None and fit.model_covariance is not None

    def play_var(cov: np.ndarray) -> float:
        return float(cov[1, 1] + cov[3, 3] + 2 * cov[1, 3])

    assert play_var(fit.free_run_covariance) > 4.0 * play_var(fit.model_covariance)
    band = fit.tracking_covariance() - alone.tracking_covariance()
    assert fit.free_run_offset is not None
    offset = np.outer(fit.free_run_offset, fit.free_run_offset)  # rows and readings disagree
    np.testing.assert_allclose(band, fit.free_run_covariance + offset, rtol=1e-12, atol=1e-18)
