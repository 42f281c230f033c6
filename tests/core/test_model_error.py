"""The model-error part of a batch estimate's uncertainty (genbacklash_core.model_error)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from genbacklash_core import GeneralBacklash, identify_backlash, paper_example
from genbacklash_core.model_error import (
    MISFIT_Z,
    Misfit,
    correlated_misfit,
    model_error_covariance,
)
from genbacklash_core.uncertainty import batch_uncertainty, play_std

TRUTH = GeneralBacklash((1.0,), 0.05, (1.0,), 0.07)  # a drivetrain's play: 0.12 rad


def _play_stds(model: GeneralBacklash, u: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The play's statistical and model-error standard deviations of ``model`` on (u, y)."""
    spread = batch_uncertainty(model, u, y)
    return play_std(model, spread.statistical), play_std(model, spread.model)


def _smooth_input(seed: int, n: int = 6000) -> np.ndarray:
    """Moves between random targets at random speeds, with dwells (a drivetrain's command)."""
    rng = np.random.default_rng(seed)
    out: list[float] = []
    position = 0.0
    while len(out) < n:
        target = rng.uniform(-1.0, 1.0)
        steps = int(rng.integers(40, 400))
        out.extend(np.linspace(position, target, steps)[1:].tolist())
        out.extend([target] * int(rng.integers(0, 100)))
        position = target
    return np.asarray(out[:n])


def _lagged(u: np.ndarray, ticks: float) -> np.ndarray:
    """``u`` through a first-order lag of ``ticks`` samples (a servo between command and gear)."""
    a = 1.0 / (1.0 + ticks)
    out = np.empty_like(u)
    state = u[0]
    for k, value in enumerate(u):
        state += a * (value - state)
        out[k] = state
    return out


@pytest.mark.parametrize("seed", range(5))
def test_no_model_error_where_the_model_is_exact(seed: int) -> None:
    """Paper Example 1 (the model is the truth, the noise white): the term is zero."""
    data = paper_example(1).generate(seed=seed)
    model = identify_backlash(data.u, data.y, 3).model
    spread = batch_uncertainty(model, data.u, data.y)
    assert not spread.misfit.significant, spread.misfit
    assert np.all(spread.model == 0.0)
    assert np.array_equal(spread.total, spread.statistical)


def test_no_model_error_with_white_noise_on_a_smooth_input() -> None:
    """A drivetrain-like input, the play operator itself and white noise: no term."""
    u = _smooth_input(3)
    y = TRUTH.simulate(u) + np.random.default_rng(4).normal(0.0, 2e-3, u.size)
    model = identify_backlash(u, y, 1).model
    assert isinstance(model, GeneralBacklash)
    stat, model_std = _play_stds(model, u, y)
    assert model_std == 0.0 < stat


def test_the_term_grows_with_the_misfit() -> None:
    """The same record with a servo lag of 0, 1, 3 and 8 ticks between command and gear:
    the model-error part of the play grows with the lag, the statistical one far less."""
    u = _smooth_input(0)
    noise = np.random.default_rng(1).normal(0.0, 1e-3, u.size)
    model_parts, stat_parts = [], []
    for ticks in (0.0, 1.0, 3.0, 8.0):
        y = TRUTH.simulate(_lagged(u, ticks) if ticks else u) + noise
        model = identify_backlash(u, y, 1).model
        assert isinstance(model, GeneralBacklash)
        stat, model_std = _play_stds(model, u, y)
        stat_parts.append(stat)
        model_parts.append(model_std)
    assert model_parts[0] == 0.0
    assert all(a < b for a, b in itertools.pairwise(model_parts)), model_parts
    assert model_parts[-1] > 20.0 * stat_parts[-1]


def test_a_servo_lag_is_covered_where_the_statistical_band_is_not() -> None:
    """A 5-tick lag biases the play (each dead zone looks wider while moving), on 20 seeded
    records: the statistical 2-sigma band holds the truth on none, statistical + model error
    on >= 90 % (the target; measured: 19 of 20, the bias 1.1-2.3 total standard deviations),
    and the band stays narrower than the play."""
    held, held_statistical = [], []
    for seed in range(20):
        u = _smooth_input(10 + seed)
        rng = np.random.default_rng(20 + seed)
        y = TRUTH.simulate(_lagged(u, 5.0)) + rng.normal(0.0, 1e-3, u.size)
        model = identify_backlash(u, y, 1).model
        assert isinstance(model, GeneralBacklash)
        error = abs(model.c_left + model.c_right - (TRUTH.c_left + TRUTH.c_right))
        stat, model_std = _play_stds(model, u, y)
        total = math.hypot(stat, model_std)
        held.append(error <= 2.0 * total)
        held_statistical.append(error <= 2.0 * stat)
        assert 2.0 * total < TRUTH.c_left + TRUTH.c_right
    assert not any(held_statistical)
    assert np.mean(held) >= 0.9, held


def test_white_residuals_are_not_significant_and_smooth_ones_are() -> None:
    rng = np.random.default_rng(5)
    white = rng.normal(0.0, 1.0, 20000)
    assert not correlated_misfit(white).significant
    smooth = white + 0.3 * np.sin(np.arange(20000) / 30.0)
    misfit = correlated_misfit(smooth)
    assert misfit.significant
    assert misfit.rms_model == pytest.approx(0.3 / math.sqrt(2.0), rel=0.2)
    assert misfit.rms_model <= misfit.rms


def test_pairs_across_a_break_or_a_nan_do_not_count() -> None:
    residual = np.array([1.0, 1.0, -1.0, -1.0, np.nan, 2.0, 2.0])
    breaks = np.array([False, False, True, False, False, False, False])
    misfit = correlated_misfit(residual, breaks)
    assert misfit.pairs == 3  # (0, 1), (2, 3), (5, 6)
    assert misfit.lag_one == pytest.approx((1.0 + 1.0 + 4.0) / 3.0)
    assert correlated_misfit(np.array([1.0])).pairs == 0
    assert not correlated_misfit(np.array([1.0])).significant


def test_the_covariance_is_the_worst_bias_of_a_misfit_that_size() -> None:
    """``g^T C_model g = a^2 / 3`` with ``a`` the Cauchy-Schwarz bound of the bias
    ``g^T (J^T J)^-1 J^T d`` over every ``d`` of RMS ``e``; a ``d`` shaped as the worst
    case reaches it."""
    rng = np.random.default_rng(6)
    jac = rng.normal(size=(500, 3))
    e = 0.2
    misfit = Misfit(rms=1.0, lag_one=e * e, noise=1e-4, pairs=499)
    cov = model_error_covariance(jac, misfit)
    g = np.array([0.0, 1.0, 1.0])
    gram_inv = np.linalg.inv(jac.T @ jac)
    worst = jac @ gram_inv @ g
    d = worst / np.sqrt(np.mean(worst**2)) * e  # RMS e, along the least visible direction
    bias = g @ gram_inv @ jac.T @ d
    assert math.sqrt(3.0 * (g @ cov @ g)) == pytest.approx(abs(bias))
    for _ in range(20):  # and no other d of that RMS does more
        other = rng.normal(size=500)
        other *= e / np.sqrt(np.mean(other**2))
        assert abs(g @ gram_inv @ jac.T @ other) <= abs(bias) + 1e-12


def test_an_uninformed_parameter_is_unknown_not_certain() -> None:
    jac = np.zeros((100, 2))
    jac[:, 0] = 1.0
    significant = Misfit(rms=1.0, lag_one=0.5, noise=0.01, pairs=99)
    assert MISFIT_Z * significant.noise < significant.lag_one
    cov = model_error_covariance(jac, significant)
    assert cov[1, 1] == math.inf and cov[0, 0] > 0.0
    quiet = Misfit(rms=1.0, lag_one=0.0, noise=0.01, pairs=99)
    assert np.all(model_error_covariance(jac, quiet) == 0.0)


def test_a_gram_worked_out_by_the_caller_gives_the_same_covariance() -> None:
    """The bands' free-run term hands over the informed columns and ``pinv(J^T J)`` it has
    worked out on the same Jacobian: the covariance is the one worked out here, to the bit
    (an uninformed column included), and a gram from another Jacobian would show."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(500, 4))
    jac[:, 2] = 0.0  # a parameter no reading informs
    jac[:40, 0] = 0.0
    misfit = Misfit(rms=0.02, lag_one=2e-4, noise=1e-6, pairs=499)
    informed = np.any(jac != 0.0, axis=0)
    sub = jac[:, informed]
    gram = (informed, np.linalg.pinv(sub.T @ sub))
    own = model_error_covariance(jac, misfit)
    given = model_error_covariance(jac, misfit, gram=gram)
    assert own.tobytes() == given.tobytes()
    assert own[2, 2] == math.inf and np.isfinite(own[np.ix_(informed, informed)]).all()
    other = jac.copy()
    other[:, 1] *= 2.0
    sub_other = other[:, informed]
    moved = model_error_covariance(
        jac, misfit, gram=(informed, np.linalg.pinv(sub_other.T @ sub_other))
    )
    assert not np.array_equal(moved, own)
