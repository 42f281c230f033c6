"""Recursive identification: cold-start convergence, both update paths, drift, holding without
excitation, recovery, seeding. The drivetrain-operation tests (sample rule, memory measured in
information, lost readings) are in ``test_recursive_operation.py``."""

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
    RecursiveIdentifier,
    RecursiveSettings,
    Structure,
    WindowedIdentifier,
    paper_example,
    track,
)
from genbacklash_core.online.rows import memory_regression

from ._helpers import drifting_gap_data, tracking_lag

EX1 = paper_example(1)
EX3_BACKLASH = GeneralBacklash((0.5, -0.3, 0.3), 0.45, (0.6, 0.4, 0.2), 0.55)


def _args(number: int) -> tuple[int, ...]:
    return (3,) if number <= 2 else (3, 2, 2)


def _error(parameters: np.ndarray, truth: np.ndarray) -> float:
    return float(np.max(np.abs(parameters - truth)))


# --------------------------------------------------------------------------- settings


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"forgetting": 1.5}, r"forgetting must lie in \[0.5, 1\]"),
        ({"forgetting": 0.2}, r"forgetting must lie in \[0.5, 1\]"),
        ({"initial_samples": 10}, r"initial_samples must lie in \[20, 1e\+07\]"),
        ({"buffer": 100}, r"buffer must lie in \[300, 1e\+08\]"),
        ({"block": 0}, r"block must lie in \[1, 4096\]"),
        ({"block": 2.0}, "block must be a whole number"),
        ({"covariance_bound": 0.5}, r"covariance_bound must lie in \[1, inf\]"),
        ({"divergence_ratio": 0.9}, r"divergence_ratio must lie in \[1, inf\]"),
        ({"min_conditioning": -0.1}, r"min_conditioning must lie in \[0, 1\]"),
        ({"bins": 0}, r"bins must lie in \[1, 1000\]"),
        ({"idle_samples": 0}, r"idle_samples must lie in \[1, 1e\+10\]"),
        ({"confidence_half_life": 0.5}, r"confidence_half_life must lie in \[1, inf\]"),
        ({"nonfinite": None}, "nonfinite must be 'raise' or 'drop'"),
    ],
)
def test_settings_validation(changes: dict[str, object], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        RecursiveSettings(**changes)  # type: ignore[arg-type]


def test_constructor_validation() -> None:
    with pytest.raises(GenBacklashError, match=r"sign must be \+1, -1 or None"):
        RecursiveIdentifier(3, sign=2)
    with pytest.raises(GenBacklashError, match="na and nb must be >= 0"):
        RecursiveIdentifier(3, -1)
    with pytest.raises(GenBacklashError, match="settings must be RecursiveSettings"):
        RecursiveIdentifier(3, settings=0.99)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- convergence


@pytest.mark.parametrize(
    ("number", "samples", "tolerance"),
    [(1, 1000, 0.03), (2, 1000, 0.03), (3, 2000, 0.03), (4, 2000, 0.03)],
)
def test_converges_from_a_cold_start(number: int, samples: int, tolerance: float) -> None:
    ex = paper_example(number)
    for seed in (0, 1):
        data = ex.generate(seed, n_samples=samples)
        ident = RecursiveIdentifier(*_args(number))
        est = ident.update_many(data.u, data.y)
        assert est.state is EstimatorState.CONVERGED, est.reason
        assert _error(est.parameters, ex.model.parameters()) < tolerance
        assert ident.structure.sign == ex.backlash.sign  # detected at the initial fit
        assert ident.restarts == 0
        assert est.residual < 3.0 * data.noise_std


def test_warming_up_before_the_initial_fit() -> None:
    data = EX1.generate(0, n_samples=299)
    est = RecursiveIdentifier(3).update_many(data.u, data.y)
    assert est.state is EstimatorState.WARMING_UP
    assert est.model is None


def test_keeps_improving_after_the_initial_fit() -> None:
    data = EX1.generate(6, n_samples=4000)
    settings = RecursiveSettings(forgetting=1.0)  # memory never full: the error keeps falling
    trace = track(RecursiveIdentifier(3, settings=settings), data.u, data.y, every=400)
    errors = [_error(e.parameters, EX1.model.parameters()) for e in trace]
    assert errors[-1] < 0.5 * errors[0]
    assert trace[-1].std()[3] < 0.5 * trace[0].std()[3]


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
    rng = np.random.default_rng(21)
    u = rng.uniform(-1.5, 1.5, 2500)
    clean = model.simulate(u)
    y = clean + rng.normal(0.0, float(np.std(clean)) / 50.0, u.size)
    for settings in (RecursiveSettings(), RecursiveSettings(block=1)):
        est = RecursiveIdentifier(*orders, settings=settings).update_many(u, y)
        assert est.state is EstimatorState.CONVERGED, est.reason
        assert _error(est.parameters, model.parameters()) < 0.05
        assert est.names == model.parameter_names


# --------------------------------------------------------------------------- update paths


@pytest.mark.parametrize("number", [1, 2, 3])
def test_block_of_one_equals_per_sample_updates(number: int) -> None:
    data = paper_example(number).generate(2, n_samples=1200)
    settings = RecursiveSettings(block=1, check_every=50)
    one = RecursiveIdentifier(*_args(number), settings=settings)
    for u, y in zip(data.u.tolist(), data.y.tolist(), strict=True):
        last = one.update(u, y)
    many = RecursiveIdentifier(*_args(number), settings=settings)
    est = many.update_many(data.u, data.y)
    np.testing.assert_allclose(est.parameters, last.parameters, rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.covariance, last.covariance, rtol=1e-6, atol=1e-14)
    assert (est.state, est.samples) == (last.state, last.samples)


@pytest.mark.parametrize("number", [1, 3])
def test_chunking_does_not_matter(number: int) -> None:
    """Samples are processed at fixed sample counts (every ``block`` samples), so one at a
    time, in node-sized chunks or all at once give the same estimates."""
    ex = paper_example(number)
    data = ex.generate(3, n_samples=3000)
    one = RecursiveIdentifier(*_args(number))
    for u, y in zip(data.u.tolist(), data.y.tolist(), strict=True):
        last = one.update(u, y)
    chunked = RecursiveIdentifier(*_args(number))
    trace = track(chunked, data.u, data.y, every=37)
    est = RecursiveIdentifier(*_args(number)).update_many(data.u, data.y)
    for other in (trace[-1], est):
        np.testing.assert_allclose(other.parameters, last.parameters, rtol=0, atol=1e-9)
        np.testing.assert_allclose(other.std(), last.std(), rtol=1e-6)
        assert other.state is last.state is EstimatorState.CONVERGED
    assert _error(est.parameters, ex.model.parameters()) < 0.03


def test_refit_takes_the_latest_rows() -> None:
    data = EX1.generate(5, n_samples=1000)
    ident = RecursiveIdentifier(3)
    est = ident.update_many(data.u, data.y)  # 1000 = 300 + 10 * 64 + 60: 60 rows queued
    refit = ident.refit()
    assert refit.samples == est.samples == 1000
    assert not np.array_equal(refit.parameters, est.parameters)
    assert _error(refit.parameters, EX1.model.parameters()) < 0.03


def test_holds_re_read_the_branch_at_their_anchor() -> None:
    """A row inside the gap holds the value the last engaged branch left (eqs. 20-21): with
    its anchor it is one more reading of that branch; after a lost reading it has none."""
    data = EX1.generate(3, n_samples=4000)
    breaks = np.zeros(data.u.size, dtype=bool)
    lost = np.arange(2000, 4000, 53)
    breaks[lost] = True
    ident = RecursiveIdentifier(3, settings=RecursiveSettings(forgetting=1.0))  # keeps all
    ident.update_many(data.u, data.y, breaks)
    rows, stamps = ident.memory.rows()
    held = rows[:, 5] != 0.0
    assert np.count_nonzero(held) > 100
    truth = EX1.model
    u_a, d_a = rows[held, 4], rows[held, 5]
    branch = np.where(d_a < 0.0, truth.left(u_a), truth.right(u_a))
    miss = rows[held, 3] - branch
    assert np.sqrt(np.mean(miss**2)) < 1.3 * data.noise_std  # the reading's noise, no more
    # the anchor is a row since the last lost reading, never one before it
    checked = 0
    for k in np.flatnonzero(held):
        since = lost[lost <= stamps[k]]
        start = since[-1] if since.size else -1
        anchors = np.flatnonzero((stamps > start) & (stamps < stamps[k]))
        assert np.any(rows[anchors, 1] == rows[k, 4]), (stamps[k], start)
        checked += start >= 0
    assert checked > 50
    p = ident.estimate.parameters
    used = memory_regression(Structure(3), p, rows, holds=False)[2]
    # with holds the regression takes more rows than the engaged ones alone
    with_holds = memory_regression(Structure(3), p, rows)[2]
    assert np.count_nonzero(with_holds) > np.count_nonzero(used)


# --------------------------------------------------------------------------- drift


def test_tracks_a_growing_gap() -> None:
    n, ramp = 14_000, (2_000, 12_000)
    u, y, c_left, c_right = drifting_gap_data(1, n, ramp)
    trace = track(RecursiveIdentifier(3), u, y, every=100)
    samples = np.array([e.samples for e in trace])
    values = np.array([e.parameters for e in trace])
    judged = (7_000, 12_000)
    lag_left = tracking_lag(samples, values[:, 3], c_left, judged)
    lag_right = tracking_lag(samples, values[:, 7], c_right, judged)
    # each branch remembers 1 / (1 - forgetting) rows, about one per sample on this input, so
    # the memory spans ~1300 samples; the holds' readings of recent anchors (the play
    # operator holds the value a branch left) bring the lag below half of that
    assert 50 < lag_left < 800 and 50 < lag_right < 800, (lag_left, lag_right)
    assert trace[-1].state is EstimatorState.CONVERGED
    assert abs(trace[-1].parameters[3] - c_left[-1]) < 0.03
    assert abs(trace[-1].parameters[7] - c_right[-1]) < 0.03
    # the drift goes into the gaps, not into the shape of the branches
    slopes = values[samples > 4_000][:, [0, 4]]
    assert np.max(np.abs(slopes - [EX1.backlash.m_left[0], EX1.backlash.m_right[0]])) < 0.04


# --------------------------------------------------------------------------- no excitation


def _segments(seed: int, *parts: tuple[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """Example 1 driven by random, held, dithered or narrow input segments (one simulation)."""
    rng = np.random.default_rng(seed)
    pieces = []
    for kind, length in parts:
        if kind == "random":
            pieces.append(rng.uniform(-2, 2, length))
        elif kind == "hold":
            pieces.append(np.full(length, rng.uniform(-1, 1)))
        elif kind == "dither":
            pieces.append(rng.uniform(-1, 1) + rng.normal(0, 1e-6, length))
        elif kind == "narrow":  # a small oscillation on the upper part of the right branch
            pieces.append(1.2 + 0.3 * np.sin(2 * np.pi * np.arange(length) / 60))
    u = np.concatenate(pieces)
    x = EX1.model.simulate(u)
    return u, x + rng.normal(0.0, float(np.std(x)) / 25.0, u.size)


@pytest.mark.parametrize("kind", ["hold", "dither"])
def test_holds_without_excitation_and_recovers(kind: str) -> None:
    u, y = _segments(4, ("random", 1500), (kind, 3000), ("random", 1500))
    ident = RecursiveIdentifier(3)
    before = ident.update_many(u[:1500], y[:1500])
    assert before.state is EstimatorState.CONVERGED
    during = track(ident, u[1500:4500], y[1500:4500], every=500)
    # the rows queued before the input stopped are taken at the next block boundary (64
    # samples) and move the estimate within its uncertainty (up to 1.2 std over seeds 4-9);
    # after that nothing moves and the memory is not flooded by the rest
    assert np.all(np.abs(during[0].parameters - before.parameters) < 2.0 * before.std())
    for est in during:
        np.testing.assert_array_equal(est.parameters, during[0].parameters)
        np.testing.assert_array_equal(est.covariance, during[0].covariance)  # no wind-up
    assert len(ident.memory) == 1000
    assert during[-1].state is EstimatorState.NO_EXCITATION
    assert "no new information" in during[-1].reason
    assert during[-1].excitation < 0.02
    # the confidence fades with the age of the information, smoothly, never dropped
    assert 0.99 * during[0].confidence < during[-1].confidence < during[0].confidence
    after = ident.update_many(u[4500:], y[4500:])
    assert after.state is EstimatorState.CONVERGED
    assert _error(after.parameters, EX1.model.parameters()) < 0.03
    assert ident.restarts == 0


def test_a_narrow_sweep_does_not_bend_the_branch() -> None:
    """A small oscillation on one part of the range (inside the gap, with the right branch
    touched at its top) refreshes only its own input regions: every other region keeps its
    floor of rows, so the polynomial is not fitted to the narrow part alone."""
    u, y = _segments(5, ("random", 1500), ("narrow", 4000), ("random", 1500))
    ident = RecursiveIdentifier(3)

    def counts() -> list[np.ndarray]:
        rows, _ = ident.memory.rows()
        up = rows[:, 1] > rows[:, 0]
        edges = np.linspace(ident.memory.low, ident.memory.high, ident.settings.bins + 1)
        return [np.histogram(rows[move, 1], edges)[0] for move in (up, ~up)]

    trace = track(ident, u[:1500], y[:1500], every=250)
    before = counts()
    trace += track(ident, u[1500:5500], y[1500:5500], every=250)
    floor = ident.settings.region_floor
    for old, new in zip(before, counts(), strict=True):
        assert np.all(new >= np.minimum(old, floor)), (old, new)
    assert all(e.state is EstimatorState.CONVERGED for e in trace[2:])
    assert max(_error(e.parameters, EX1.model.parameters()) for e in trace[2:]) < 0.03
    est = ident.update_many(u[5500:], y[5500:])
    assert est.state is EstimatorState.CONVERGED
    assert _error(est.parameters, EX1.model.parameters()) < 0.03
    assert ident.restarts == 0


def test_covariance_stays_bounded() -> None:
    u, y = _segments(6, ("random", 1000), ("narrow", 6000))
    ident = RecursiveIdentifier(3)
    start = ident.update_many(u[:1000], y[:1000])
    end = ident.update_many(u[1000:], y[1000:])  # the narrow data refill part of the memory
    bound = RecursiveSettings().covariance_bound
    ratio = end.covariance.diagonal() / start.covariance.diagonal()
    assert np.all(ratio < 2.0 * bound)  # P <= bound * P_init (sigma^2 may change a little)


def test_soak_without_divergence() -> None:
    u, y = _segments(
        7,
        ("random", 3000),
        ("hold", 6000),
        ("random", 4000),
        ("dither", 6000),
        ("narrow", 6000),
        ("random", 4000),
        ("hold", 3000),
        ("random", 3000),
    )
    ident = RecursiveIdentifier(3)
    trace = track(ident, u, y, every=1000)
    assert EstimatorState.DIVERGED not in [e.state for e in trace]
    assert ident.restarts == 0
    assert max(_error(e.parameters, EX1.model.parameters()) for e in trace[1:]) < 0.04
    assert trace[-1].state is EstimatorState.CONVERGED


# --------------------------------------------------------------------------- divergence


def test_recovers_after_a_sensor_fault() -> None:
    data = EX1.generate(3, n_samples=7000)
    rng = np.random.default_rng(7)
    y = data.y.copy()
    y[3000:3300] = rng.normal(0.0, 3.0, 300)  # garbage from the encoder for a while
    ident = RecursiveIdentifier(3)
    trace = track(ident, data.u, y, every=100)
    diverged = [e for e in trace if e.state is EstimatorState.DIVERGED]
    assert diverged, "the burst was not detected"
    assert "diverged" in diverged[0].reason
    assert all(e.confidence == 0.0 for e in diverged)
    # while diverged the last valid estimate is shown
    assert all(_error(e.parameters, EX1.model.parameters()) < 0.03 for e in diverged)
    # the burst's rows were held back, never remembered: once the errors are normal again
    # the identification goes on without a re-initialisation
    _, stamps = ident.memory.rows()
    assert not np.any((stamps >= 3000) & (stamps < 3300))
    assert ident.restarts == 0
    assert trace[-1].state is EstimatorState.CONVERGED
    assert _error(trace[-1].parameters, EX1.model.parameters()) < 0.03


def test_restarts_from_the_rows_held_back_after_a_sudden_change() -> None:
    """The gaps widen by half at once (a loosened coupling): the new rows do not fit the
    memory, are held back, and a batch fit on them replaces it."""
    changed = GeneralBacklash(EX1.backlash.m_left, 1.05, EX1.backlash.m_right, 1.2)
    rng = np.random.default_rng(9)
    u = rng.uniform(-2.0, 2.0, 6000)
    x = np.concatenate([EX1.model.simulate(u[:3000]), changed.simulate(u[3000:])])
    y = x + rng.normal(0.0, float(np.std(x)) / 25.0, u.size)
    ident = RecursiveIdentifier(3)
    trace = track(ident, u, y, every=100)
    assert ident.restarts == 1
    assert trace[-1].state is EstimatorState.CONVERGED
    assert _error(trace[-1].parameters, changed.parameters()) < 0.03


def test_recovers_when_the_estimate_is_pushed_off() -> None:
    data = EX1.generate(8, n_samples=3000)
    ident = RecursiveIdentifier(3)
    ident.update_many(data.u[:1000], data.y[:1000])
    ident._current.theta[1] = -ident._current.theta[1]  # corrupt the state: c_left < 0
    est = ident.update(float(data.u[1000]), float(data.y[1000]))
    assert ident.restarts == 1  # re-initialised at once from the memory
    assert est.state is EstimatorState.CONVERGED
    est = ident.update_many(data.u[1001:], data.y[1001:])
    assert _error(est.parameters, EX1.model.parameters()) < 0.03


# --------------------------------------------------------------------------- bad input


def test_nonfinite_samples() -> None:
    ident = RecursiveIdentifier(3)
    with pytest.raises(NonFiniteInputError, match="sample 0 is not finite"):
        ident.update(0.0, float("nan"))
    with pytest.raises(NonFiniteInputError, match="2 of 3 samples are not finite"):
        ident.update_many([np.nan, 1.0, np.inf], [0.0, 0.5, 1.0])
    dropping = RecursiveIdentifier(3, settings=RecursiveSettings(nonfinite="drop"))
    assert dropping.update_many([0.0, np.nan, 1.0], [0.0, 1.0, 2.0]).samples == 2


# --------------------------------------------------------------------------- seeding (restart)


def _saved(
    number: int = 1, n: int = 6000, seed: int = 3
) -> tuple[Estimate, np.ndarray, np.ndarray]:
    """An identifier's estimate after ``n`` samples (what a checkpoint holds), and the data
    that follow it."""
    ex = paper_example(number)
    data = ex.generate(seed, n_samples=n + 3000)
    ident = RecursiveIdentifier(*_args(number))
    est = ident.update_many(data.u[:n], data.y[:n])
    assert est.state is EstimatorState.CONVERGED
    return est, data.u[n:], data.y[n:]


@pytest.mark.parametrize("number", [1, 3])
def test_seed_continues_as_if_never_stopped(number: int) -> None:
    """A seeded identifier follows the uninterrupted one closely: the information recovered
    from the covariance weighs the new rows as the remembered ones did."""
    ex = paper_example(number)
    data = ex.generate(3, n_samples=9000)
    through = RecursiveIdentifier(*_args(number))
    saved = through.update_many(data.u[:6000], data.y[:6000])
    ident = RecursiveIdentifier(*_args(number))
    first = ident.seed(saved)
    assert np.allclose(first.parameters, saved.parameters, rtol=1e-12, atol=1e-12)
    assert np.allclose(first.covariance, saved.covariance, rtol=1e-6, atol=1e-15)
    assert first.state is EstimatorState.CONVERGED and ident.from_seed
    assert first.confidence == pytest.approx(saved.confidence, rel=1e-3)
    assert first.samples == saved.samples and ident.restarts == 0
    std = saved.std()
    u, y = data.u[6000:], data.y[6000:]
    a = track(through, u, y, every=50)
    b = track(ident, u, y, every=50)
    assert all(e.state is EstimatorState.CONVERGED for e in b)
    assert max(np.max(np.abs(e.parameters - first.parameters) / std) for e in b[:4]) < 3.0
    # the two runs differ by about the uncertainty: the uninterrupted one forgets its oldest
    # rows one by one, the seeded one the seed's information as a whole, as the memory
    # refills (two least-squares fits over partly different rows)
    assert (
        max(np.max(np.abs(e.parameters - f.parameters) / std) for e, f in zip(a, b, strict=True))
        < 2.5
    )
    assert _error(b[-1].parameters, ex.model.parameters()) < 0.03
    assert not ident.from_seed  # the memory has refilled: the seed no longer counts


def test_seeded_cascade_waits_for_its_internal_state() -> None:
    saved, u, y = _saved(3)
    ident = RecursiveIdentifier(3, 2, 2)
    ident.seed(saved)
    for k in range(20):  # sample by sample: the saved estimate holds while x is unknown
        est = ident.update(float(u[k]), float(y[k]))
        assert est.state is EstimatorState.CONVERGED and est.model is not None
    est = ident.update_many(u[20:2000], y[20:2000])
    assert est.state is EstimatorState.CONVERGED
    assert _error(est.parameters, paper_example(3).model.parameters()) < 0.03


def test_seed_from_a_windowed_estimate() -> None:
    data = EX1.generate(4, n_samples=5000)
    saved = WindowedIdentifier(3).update_many(data.u[:3000], data.y[:3000])
    ident = RecursiveIdentifier(3)
    ident.seed(saved)
    est = ident.update_many(data.u[3000:], data.y[3000:])
    assert est.state is EstimatorState.CONVERGED
    assert _error(est.parameters, EX1.model.parameters()) < 0.03


def test_seed_refuses_what_it_cannot_use() -> None:
    est, _, _ = _saved()
    ident = RecursiveIdentifier(3)
    with pytest.raises(
        GenBacklashError, match="degree 3, na 0, nb 0; the identifier degree 3, na 2"
    ):
        RecursiveIdentifier(3, 2, 2).seed(est)
    with pytest.raises(GenBacklashError, match=r"branch sense \+1 is not the identifier's -1"):
        RecursiveIdentifier(3, sign=-1).seed(est)
    with pytest.raises(GenBacklashError, match="holds no valid model"):
        ident.seed(Estimate.empty(Structure(3)))
    singular = Estimate(
        Structure(3), est.parameters, np.zeros((8, 8)), 0.02, 0.5, "converged", 0.9, 10
    )
    with pytest.raises(GenBacklashError, match="covariance is not finite and positive definite"):
        ident.seed(singular)
    assert ident.estimate.state is EstimatorState.WARMING_UP and not ident.from_seed


def test_divergence_after_a_seed_reinitialises_from_the_buffer() -> None:
    saved, u, y = _saved()
    ident = RecursiveIdentifier(3)
    ident.seed(saved)
    ident.update_many(u[:1000], y[:1000])
    ident._current.theta[1] = -ident._current.theta[1]  # corrupt the state: c_left < 0
    est = ident.update(float(u[1000]), float(y[1000]))
    assert ident.restarts == 1 and not ident.from_seed
    assert est.state is EstimatorState.CONVERGED
