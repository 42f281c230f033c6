"""Windowed online identification: cold-start convergence, drift, freeze, divergence, contract."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import (
    Cascade,
    Estimate,
    EstimatorState,
    GenBacklashError,
    GeneralBacklash,
    LinearBlock,
    NonFiniteInputError,
    Structure,
    WindowedIdentifier,
    WindowedSettings,
    identify_backlash,
    paper_example,
    track,
)
from genbacklash_core.online.rows import SampleRing

from ._helpers import drifting_gap_data, tracking_lag

EX1 = paper_example(1)


def _args(number: int) -> tuple[int, ...]:
    return (3,) if number <= 2 else (3, 2, 2)


def _error(parameters: np.ndarray, truth: np.ndarray) -> float:
    return float(np.max(np.abs(parameters - truth)))


# --------------------------------------------------------------------------- settings


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"window": 10}, r"window must lie in \[20, inf\]"),
        ({"window": 100.0}, "window must be a whole number"),
        ({"refit_every": 0}, r"refit_every must lie in \[1, 1500\]"),
        ({"refit_every": 3000}, r"refit_every must lie in \[1, 1500\]"),
        ({"refit_fraction": 1.5}, r"refit_fraction must lie in \[0, 1\]"),
        ({"iterations": 0}, r"iterations must lie in \[1, 1000\]"),
        ({"tol": -1e-3}, r"tol must lie in \[0, 1\]"),
        ({"refine": 1}, "refine must be True or False"),
        ({"min_samples": 5}, r"min_samples must lie in \[20, 1500\]"),
        ({"min_excitation": float("nan")}, r"min_excitation must lie in \[0, 1\]"),
        ({"converged_std": 0.0}, r"converged_std must lie in \[1e-12, inf\]"),
        ({"max_failures": 0}, r"max_failures must lie in \[1, 1e\+06\]"),
        ({"nonfinite": "ignore"}, "nonfinite must be 'raise' or 'drop'"),
        ({"input_deadband": "small"}, "input_deadband must be a number"),
    ],
)
def test_settings_validation(changes: dict[str, object], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        WindowedSettings(**changes)  # type: ignore[arg-type]


def test_numpy_numbers_are_settings_too() -> None:
    settings = WindowedSettings(window=np.int64(800), refit_fraction=np.float64(0.2))
    assert settings.window == 800


def test_constructor_validation() -> None:
    with pytest.raises(GenBacklashError, match=r"sign must be \+1, -1 or None"):
        WindowedIdentifier(3, sign=0)
    with pytest.raises(GenBacklashError, match="degree must be >= 1"):
        WindowedIdentifier(0)
    with pytest.raises(GenBacklashError, match="a linear block needs na >= 1"):
        WindowedIdentifier(3, 0, 2)
    with pytest.raises(GenBacklashError, match="settings must be WindowedSettings"):
        WindowedIdentifier(3, settings={"window": 100})  # type: ignore[arg-type]


# --------------------------------------------------------------------------- ring buffer


def test_ring_buffer_holds_the_latest_samples_in_order() -> None:
    ring = SampleRing(5)
    assert ring.window()[0].size == 0
    values = np.arange(13.0)
    ring.extend(values[:3], -values[:3])
    np.testing.assert_array_equal(ring.window()[0], [0.0, 1.0, 2.0])
    for v in values[3:9]:
        ring.push(float(v), -float(v))
    np.testing.assert_array_equal(ring.window()[0], values[4:9])
    np.testing.assert_array_equal(ring.window()[1], -values[4:9])
    np.testing.assert_array_equal(ring.window(2)[0], values[7:9])
    ring.extend(values[9:13], -values[9:13])
    np.testing.assert_array_equal(ring.window()[0], values[8:13])
    ring.extend(np.arange(100.0, 112.0), np.zeros(12))  # longer than the ring
    np.testing.assert_array_equal(ring.window()[0], np.arange(107.0, 112.0))
    assert len(ring) == 5 and ring.count == 25


# --------------------------------------------------------------------------- convergence


@pytest.mark.parametrize(
    ("number", "samples", "tolerance"),
    [(1, 300, 0.05), (2, 300, 0.05), (3, 1000, 0.03), (4, 1000, 0.03)],
)
def test_converges_from_a_cold_start(number: int, samples: int, tolerance: float) -> None:
    ex = paper_example(number)
    for seed in (0, 1):
        data = ex.generate(seed, n_samples=samples)
        ident = WindowedIdentifier(*_args(number))
        est = ident.update_many(data.u, data.y)
        assert est.state in (EstimatorState.CONVERGED, EstimatorState.CONVERGING), est.reason
        assert _error(est.parameters, ex.model.parameters()) < tolerance
        assert ident.structure.sign == ex.backlash.sign  # detected
        assert type(est.model) is type(ex.model)
        assert est.residual < 3.0 * data.noise_std


EX3_BACKLASH = GeneralBacklash((0.5, -0.3, 0.3), 0.45, (0.6, 0.4, 0.2), 0.55)


@pytest.mark.parametrize(
    ("model", "orders"),
    [
        (GeneralBacklash.ideal(0.8, 0.3, 0.5), (1,)),
        (GeneralBacklash.ideal(-0.8, 0.3, 0.5), (1,)),
        (Cascade(EX3_BACKLASH, LinearBlock((1.0,))), (3, 1, 0)),
        (Cascade(EX3_BACKLASH, LinearBlock((1.0, 0.3, -0.2), (-0.4,))), (3, 3, 1)),
    ],
    ids=["ideal", "ideal-decreasing", "na1-nb0", "na3-nb1"],
)
def test_other_structures(model: GeneralBacklash | Cascade, orders: tuple[int, ...]) -> None:
    rng = np.random.default_rng(20)
    u = rng.uniform(-1.5, 1.5, 1500)
    clean = model.simulate(u)
    y = clean + rng.normal(0.0, float(np.std(clean)) / 50.0, u.size)
    est = WindowedIdentifier(*orders).update_many(u, y)
    assert est.state is EstimatorState.CONVERGED, est.reason
    assert _error(est.parameters, model.parameters()) < 0.05
    assert est.names == model.parameter_names


def test_warming_up_until_enough_samples() -> None:
    data = EX1.generate(0, n_samples=30)
    ident = WindowedIdentifier(3)
    est = ident.update_many(data.u, data.y)
    assert est.state is EstimatorState.WARMING_UP
    assert est.model is None and est.confidence == 0.0
    assert ident.min_samples == 48


def test_constant_input_from_the_start_stays_warming_up() -> None:
    ident = WindowedIdentifier(3)
    est = ident.update_many(np.full(500, 0.3), np.full(500, 0.1))
    assert est.state is EstimatorState.WARMING_UP
    assert "input is constant" in est.reason, est.reason


def test_update_and_update_many_agree_exactly() -> None:
    data = paper_example(3).generate(5, n_samples=900)
    one = WindowedIdentifier(3, 2, 2, settings=WindowedSettings(window=400))
    for u, y in zip(data.u.tolist(), data.y.tolist(), strict=True):
        last = one.update(u, y)
    many = WindowedIdentifier(3, 2, 2, settings=WindowedSettings(window=400))
    chunks = np.split(np.arange(900), [7, 250, 251, 600])
    for idx in chunks:
        est = many.update_many(data.u[idx], data.y[idx])
    np.testing.assert_array_equal(last.parameters, est.parameters)
    np.testing.assert_array_equal(last.covariance, est.covariance)
    assert (last.state, last.samples, last.residual) == (est.state, est.samples, est.residual)


def test_confidence_grows_with_data() -> None:
    data = EX1.generate(1, n_samples=3000)
    trace = track(WindowedIdentifier(3), data.u, data.y, every=100)
    assert trace[0].confidence < trace[-1].confidence
    assert trace[-1].confidence > 0.8
    assert np.all(trace[-1].std() < trace[1].std())


def test_large_window_with_refinement_matches_the_batch_fit() -> None:
    data = EX1.generate(3, n_samples=3000)
    settings = WindowedSettings(window=3000, refine=True, iterations=1)
    ident = WindowedIdentifier(3, settings=settings)
    est = ident.update_many(data.u, data.y)
    batch = identify_backlash(data.u, data.y, 3)
    truth = EX1.model.parameters()
    assert _error(est.parameters, truth) < 1.5 * _error(batch.model.parameters(), truth)
    final = ident.refit()  # on all the data now: the batch fit's maximum-likelihood estimate
    assert final.samples == 3000
    np.testing.assert_allclose(final.parameters, batch.model.parameters(), atol=2e-3)


def test_refit_before_any_sample() -> None:
    assert WindowedIdentifier(3).refit().state is EstimatorState.WARMING_UP


def test_refinement_of_the_cascade_runs_on_a_mid_stream_window() -> None:
    ex = paper_example(3)
    data = ex.generate(2, n_samples=2500)
    settings = WindowedSettings(window=1200, refine=True, iterations=1)
    est = WindowedIdentifier(3, 2, 2, settings=settings).update_many(data.u, data.y)
    assert est.state is EstimatorState.CONVERGED, est.reason
    assert _error(est.parameters, ex.model.parameters()) < 0.02


# --------------------------------------------------------------------------- drift


def test_tracks_a_growing_gap() -> None:
    n, ramp = 14_000, (2_000, 12_000)
    u, y, c_left, c_right = drifting_gap_data(0, n, ramp)
    ident = WindowedIdentifier(3, settings=WindowedSettings(window=1000))
    trace = track(ident, u, y, every=100)
    samples = np.array([e.samples for e in trace])
    values = np.array([e.parameters for e in trace])
    judged = (7_000, 12_000)
    lag_left = tracking_lag(samples, values[:, 3], c_left, judged)
    lag_right = tracking_lag(samples, values[:, 7], c_right, judged)
    assert 0 < lag_left < 1000 and 0 < lag_right < 1000, (lag_left, lag_right)
    assert trace[-1].state is EstimatorState.CONVERGED
    assert abs(trace[-1].parameters[3] - c_left[-1]) < 0.03
    assert abs(trace[-1].parameters[7] - c_right[-1]) < 0.03


# --------------------------------------------------------------------------- no excitation


def _held_then_moving(seed: int) -> tuple[np.ndarray, np.ndarray, slice]:
    """1500 random samples, 2000 with the input held, then 1500 random again."""
    rng = np.random.default_rng(seed)
    u = np.concatenate([rng.uniform(-2, 2, 1500), np.full(2000, 0.4), rng.uniform(-2, 2, 1500)])
    x = EX1.model.simulate(u)
    y = x + rng.normal(0.0, float(np.std(x)) / 25.0, u.size)
    return u, y, slice(1500, 3500)


def test_freezes_without_excitation_and_recovers() -> None:
    u, y, held = _held_then_moving(3)
    ident = WindowedIdentifier(3, settings=WindowedSettings(window=1000))
    before = ident.update_many(u[: held.start], y[: held.start])
    assert before.state is EstimatorState.CONVERGED
    during = track(ident, u[held], y[held], every=250)
    assert during[-1].state is EstimatorState.NO_EXCITATION
    assert "no information" in during[-1].reason
    for est in during[1:]:
        np.testing.assert_array_equal(est.parameters, during[0].parameters)  # frozen
    assert during[-1].confidence > 0.5  # the frozen estimate is still good
    after = ident.update_many(u[held.stop :], y[held.stop :])
    assert after.state is EstimatorState.CONVERGED
    assert _error(after.parameters, EX1.model.parameters()) < 0.03


@pytest.mark.parametrize("seed", [1, 2])
def test_a_cascade_at_rest_keeps_its_window(seed: int) -> None:
    """A dwell far longer than the window: its samples past the linear block's settling
    horizon repeat a steady state and are not stored, so the moves before it stay in the
    window; the estimate holds (``no_excitation``, the confidence aged, not dropped) and
    the fits after it still have the moves before it."""
    ex = paper_example(3)
    data = ex.generate(seed=seed, n_samples=3400)
    u = np.concatenate([data.u[:3000], np.full(20_000, data.u[2999]), data.u[3000:]])
    rng = np.random.default_rng(seed)
    y = ex.model.simulate(u) + rng.normal(0.0, data.noise_std, u.size)
    ident = WindowedIdentifier(3, 2, 2)
    before = ident.update_many(u[:3000], y[:3000])
    assert before.state is EstimatorState.CONVERGED
    during = ident.update_many(u[3000:23_000], y[3000:23_000])
    assert during.state is EstimatorState.NO_EXCITATION
    assert "no information" in during.reason
    np.testing.assert_array_equal(during.parameters, before.parameters)
    assert 0.0 < during.confidence < before.confidence
    assert during.samples == 23_000
    window, _ = ident._feed.ring.window(ident._feed.window)
    moves = int(np.count_nonzero(np.diff(window)))
    assert moves > 0.9 * window.size  # the dwell took a few dozen samples of the window
    after = ident.update_many(u[23_000:], y[23_000:])
    assert after.state is EstimatorState.CONVERGED
    assert _error(after.parameters, ex.model.parameters()) < 0.015


def test_keeps_the_rest_of_a_branch_when_the_input_sweeps_only_part_of_it() -> None:
    """Memory by input region: 4000 samples sweeping only the upper part of the right
    branch replace the rows of that region only; the rest of both branches stays, so the
    fits go on without bending the polynomials to the narrow part (a sample window would
    have forgotten everything else and had to freeze)."""
    rng = np.random.default_rng(8)
    t = np.arange(4000)
    narrow = 1.2 + 0.3 * np.sin(2 * np.pi * t / 60)  # the upper part of the right branch only
    u = np.concatenate([rng.uniform(-2, 2, 1500), narrow])
    x = EX1.model.simulate(u)
    y = x + rng.normal(0.0, float(np.std(x)) / 25.0, u.size)
    ident = WindowedIdentifier(3, settings=WindowedSettings(window=1000))
    trace = track(ident, u, y, every=250)
    assert trace[-1].state is EstimatorState.CONVERGED, trace[-1].reason
    assert max(_error(e.parameters, EX1.model.parameters()) for e in trace[2:]) < 0.04
    cover = ident.coverage
    assert cover is not None and cover.share("left") == 1.0 and cover.share("right") == 1.0


# --------------------------------------------------------------------------- divergence


def test_recovers_after_a_sensor_fault() -> None:
    data = EX1.generate(4, n_samples=6000)
    rng = np.random.default_rng(9)
    y = data.y.copy()
    y[2000:2600] = rng.normal(0.0, 2.0, 600)  # a burst of garbage longer than the window
    ident = WindowedIdentifier(3, settings=WindowedSettings(window=500))
    trace = track(ident, data.u, y, every=100)
    states = [e.state for e in trace]
    assert EstimatorState.DIVERGED in states
    diverged = [e for e in trace if e.state is EstimatorState.DIVERGED]
    assert all(e.confidence == 0.0 and e.model is not None for e in diverged)
    assert trace[-1].state is EstimatorState.CONVERGED
    assert _error(trace[-1].parameters, EX1.model.parameters()) < 0.03


# --------------------------------------------------------------------------- bad input


def test_nonfinite_samples() -> None:
    ident = WindowedIdentifier(3)
    with pytest.raises(NonFiniteInputError, match="sample 0 is not finite"):
        ident.update(float("nan"), 0.0)
    with pytest.raises(NonFiniteInputError, match="1 of 3 samples are not finite"):
        ident.update_many([0.0, 1.0, 2.0], [0.0, float("inf"), 1.0])
    assert ident.estimate.samples == 0  # nothing was taken
    dropping = WindowedIdentifier(3, settings=WindowedSettings(nonfinite="drop"))
    assert dropping.update(float("nan"), 1.0).samples == 0
    assert dropping.update_many([0.0, np.nan, 1.0], [0.0, 1.0, 2.0]).samples == 2


def test_bad_series() -> None:
    ident = WindowedIdentifier(3)
    with pytest.raises(GenBacklashError, match="one-dimensional of one length"):
        ident.update_many([0.0, 1.0], [0.0])
    with pytest.raises(GenBacklashError, match="u and y must be numbers"):
        ident.update("left", 0.0)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- seeding (restart)


def _saved(
    number: int = 1, n: int = 5000, seed: int = 3
) -> tuple[Estimate, np.ndarray, np.ndarray]:
    """An identifier's estimate after ``n`` samples (what a checkpoint holds), and the data
    that follow it."""
    ex = paper_example(number)
    data = ex.generate(seed, n_samples=n + 3000)
    ident = WindowedIdentifier(*_args(number))
    est = ident.update_many(data.u[:n], data.y[:n])
    assert est.state is EstimatorState.CONVERGED
    return est, data.u[n:], data.y[n:]


@pytest.mark.parametrize("number", [1, 3])
def test_seed_continues_without_a_transient(number: int) -> None:
    saved, u, y = _saved(number)
    ident = WindowedIdentifier(*_args(number))
    first = ident.seed(saved)
    # the estimate after the restart is the saved one, with its uncertainty and state
    assert np.array_equal(first.parameters, saved.parameters)
    assert np.allclose(first.covariance, saved.covariance)
    assert first.state is EstimatorState.CONVERGED and ident.from_seed
    assert first.confidence == pytest.approx(saved.confidence)
    assert first.samples == saved.samples
    # no cold start: converged throughout, the estimate moving within its noise
    std = saved.std()
    trace = track(ident, u[:2000], y[:2000], every=25)
    assert all(e.state is EstimatorState.CONVERGED for e in trace)
    assert min(e.confidence for e in trace) > 0.9 * first.confidence
    early = trace[:20]  # the first 500 samples: mostly the seed's window still
    assert max(np.max(np.abs(e.parameters - first.parameters) / std) for e in early) < 3.0
    truth = paper_example(number).model.parameters()
    assert _error(trace[-1].parameters, truth) < 0.03
    assert not ident.from_seed  # the window (1500) holds new samples only


def test_seed_beats_a_cold_start() -> None:
    saved, u, y = _saved()
    cold = WindowedIdentifier(3)
    warm = WindowedIdentifier(3)
    warm.seed(saved)
    truth = EX1.model.parameters()
    for k in range(0, 200, 10):
        c = cold.update_many(u[k : k + 10], y[k : k + 10])
        w = warm.update_many(u[k : k + 10], y[k : k + 10])
        assert w.state is EstimatorState.CONVERGED and _error(w.parameters, truth) < 0.02
    assert c.samples == 200 and w.samples == saved.samples + 200
    # the cold identifier warmed up first: no estimate for its first samples
    assert WindowedIdentifier(3).update_many(u[:30], y[:30]).state is EstimatorState.WARMING_UP


def test_seed_tracks_a_drift_after_the_restart() -> None:
    u, y, c_left, _ = drifting_gap_data(5, 12000, (2000, 12000))
    through = WindowedIdentifier(3)
    before = through.update_many(u[:6000], y[:6000])
    restarted = WindowedIdentifier(3)
    restarted.seed(before)
    n = EX1.model.degree
    for k in range(6000, 12000, 500):
        a = through.update_many(u[k : k + 500], y[k : k + 500])
        b = restarted.update_many(u[k : k + 500], y[k : k + 500])
        # while the gap drifts a fit may move more than 3 std: converging, never lost
        assert b.state in (EstimatorState.CONVERGED, EstimatorState.CONVERGING), b.reason
        assert b.confidence >= 0.4
        assert abs(b.parameters[n] - a.parameters[n]) < 0.02  # c_left as without a restart
    assert abs(b.parameters[n] - c_left[-1]) < 0.1


def test_seed_refuses_what_it_cannot_use() -> None:
    est, _, _ = _saved()
    ident = WindowedIdentifier(3)
    with pytest.raises(GenBacklashError, match="degree 3, na 0, nb 0; the identifier degree 2"):
        WindowedIdentifier(2).seed(est)
    with pytest.raises(GenBacklashError, match=r"branch sense \+1 is not the identifier's -1"):
        WindowedIdentifier(3, sign=-1).seed(est)
    with pytest.raises(GenBacklashError, match="holds no valid model"):
        ident.seed(Estimate.empty(Structure(3)))
    with pytest.raises(GenBacklashError, match="not an Estimate"):
        ident.seed("converged")  # type: ignore[arg-type]
    p = EX1.model.parameters()
    no_noise = Estimate(Structure(3), p, np.eye(8) * 1e-6, 0.0, 0.5, "converged", 0.9, 100)
    with pytest.raises(GenBacklashError, match=r"residual 0\.0 is not a positive number"):
        ident.seed(no_noise)
    nan_cov = Estimate(Structure(3), p, np.full((8, 8), np.nan), 0.02, 0.5, "converged", 0.9, 1)
    with pytest.raises(GenBacklashError, match="covariance is not finite and positive definite"):
        ident.seed(nan_cov)
    assert ident.estimate.state is EstimatorState.WARMING_UP and not ident.from_seed


def test_seed_state_follows_the_saved_confidence() -> None:
    p = EX1.model.parameters()
    loose = Estimate(Structure(3), p, np.eye(8) * 1e-2, 0.02, 0.5, "converged", 0.4, 800)
    est = WindowedIdentifier(3).seed(loose)  # relative std 0.1 > converged_std 0.02
    assert est.state is EstimatorState.CONVERGING and est.confidence <= 0.5
    moving = Estimate(Structure(3), p, np.eye(8) * 1e-6, 0.02, 0.5, "converging", 0.5, 800)
    assert WindowedIdentifier(3).seed(moving).state is EstimatorState.CONVERGING
    frozen = Estimate(Structure(3), p, np.eye(8) * 1e-6, 0.02, 0.0, "no_excitation", 0.9, 800)
    assert WindowedIdentifier(3).seed(frozen).state is EstimatorState.CONVERGED
    ident = WindowedIdentifier(3)
    ident.seed(frozen)
    ident.reset()
    assert not ident.from_seed and ident.estimate.state is EstimatorState.WARMING_UP


def test_refit_right_after_a_seed_keeps_the_seed() -> None:
    saved, u, y = _saved()
    ident = WindowedIdentifier(3)
    ident.seed(saved)
    assert np.array_equal(ident.refit().parameters, saved.parameters)  # no samples yet
    ident.update_many(u[:10], y[:10])
    assert np.array_equal(ident.refit().parameters, saved.parameters)  # too few to fit
    ident.update_many(u[10:100], y[10:100])
    est = ident.refit()
    assert est.state is EstimatorState.CONVERGED and est.samples == saved.samples + 100
    assert np.all(np.abs(est.parameters - saved.parameters) <= 3.0 * saved.std())


@pytest.mark.parametrize("resting", [1, 3, 10])
def test_refit_at_the_end_of_a_record_at_rest_keeps_a_converged_estimate(resting: int) -> None:
    """A record that ends a few samples after a scheduled fit, with the input at rest: the
    final refit() judges the excitation over a scheduled fit's span, not over those few
    samples (which would freeze the estimate as no_excitation)."""
    data = paper_example(1).generate(seed=3, n_samples=3000)
    ident = WindowedIdentifier(degree=3)
    ident.update_many(data.u[:2000], data.y[:2000])
    params = ident.estimate.parameters
    end = 2000
    while np.array_equal(ident.estimate.parameters, params):  # up to the next scheduled fit
        ident.update(data.u[end], data.y[end])
        end += 1
    assert ident.estimate.state is EstimatorState.CONVERGED
    ident.update_many(np.full(resting, data.u[end - 1]), np.full(resting, data.y[end - 1]))
    final = ident.refit()
    assert final.state is EstimatorState.CONVERGED, final.reason


def test_seed_with_parameters_whose_products_overflow_is_refused_clearly() -> None:
    # found by hypothesis in CI: m_L1 = 1e300 and c_L = 1e300 made eq. (23)'s m_L1 c_L
    # overflow with a RuntimeWarning instead of a refusal
    p = np.array([1e300, 0.0, 0.0, 1e300, 1.0, 0.0, 0.0, 1.0])
    est = Estimate(Structure(3), p, np.eye(8) * 1e-6, 1.0, 0.0, "warming_up", 0.0, 0)
    with np.errstate(over="raise"), pytest.raises(GenBacklashError, match="too large"):
        WindowedIdentifier(3).seed(est)
