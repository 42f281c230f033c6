"""The windowed identifier's fits as they follow one another (genbacklash_core.online.fitter)."""

from __future__ import annotations

import numpy as np

from genbacklash_core import Estimate, EstimatorState, Structure, paper_example
from genbacklash_core.online.feeds import RowFeed
from genbacklash_core.online.fitter import WindowFitter
from genbacklash_core.online.seed import WindowSeed, seed_prior
from genbacklash_core.online.settings import WindowedSettings
from genbacklash_core.online.status import IdentifierStatus


def _fed(u: np.ndarray, y: np.ndarray) -> RowFeed:
    feed = RowFeed(window=1500, bins=16)
    for _ in feed.take(u, y, np.zeros(u.size, dtype=bool), lambda: 10**9):
        pass
    return feed


def test_a_cold_start_then_warm_fits_that_settle() -> None:
    ex = paper_example(1)
    data = ex.generate(seed=2, n_samples=1200)
    feed = _fed(data.u[:600], data.y[:600])
    status = IdentifierStatus(Structure(3), sign_now=False)
    fitter = WindowFitter(status, WindowedSettings(), feed)
    fitter.fit(recent=0, new_samples=600)
    assert not fitter.needs_cold and status.sign_now
    assert status.reason.startswith("cold start: ")
    for _ in feed.take(data.u[600:], data.y[600:], np.zeros(600, dtype=bool), lambda: 10**9):
        pass
    fitter.fit(recent=300, new_samples=600)
    assert fitter.state is EstimatorState.CONVERGED
    assert fitter.reported is not None
    assert np.max(np.abs(fitter.reported - ex.model.parameters())) < 0.05


def test_a_failed_cold_start_is_counted_and_leaves_no_estimate() -> None:
    u = np.linspace(0.0, 1.0, 60)  # one direction only: the left branch is never seen
    feed = _fed(u, 0.9 * u)
    status = IdentifierStatus(Structure(1), sign_now=False)
    fitter = WindowFitter(status, WindowedSettings(), feed)
    fitter.fit(recent=0, new_samples=60)
    assert fitter.p is None and fitter.failing_cold_starts == 1
    assert status.reason.startswith("cold start failed")
    assert fitter.state is EstimatorState.WARMING_UP  # nothing valid to call diverged


def test_a_planted_seed_fades_as_the_window_refills() -> None:
    truth = paper_example(1).model
    converged = EstimatorState.CONVERGED
    saved = Estimate(
        Structure(3), truth.parameters(), np.eye(8) * 1e-6, 0.02, 0.6, converged, 0.9, 5000
    )
    feed = RowFeed(window=100, bins=4)
    status = IdentifierStatus(Structure(3), sign_now=True)
    fitter = WindowFitter(status, WindowedSettings(window=100), feed)
    prior = seed_prior(Structure(3), False, saved)
    fitter.plant(WindowSeed(prior, 100, feed.progress), np.eye(8) * 1e-6, 0.02)
    assert fitter.seed_weight() == 1.0 and not fitter.needs_cold
    u = np.linspace(-1.0, 1.0, 51)
    for _ in feed.take(u, truth.parameters()[0] * u, np.zeros(51, dtype=bool), lambda: 10**9):
        pass
    assert 0.0 < fitter.seed_weight() < 1.0
