"""The wear trend: the fitted line, its scaled uncertainty, Fieller's crossing interval."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.fleet.trends import fit_trend


def test_exact_line() -> None:
    t = np.arange(6.0)
    trend = fit_trend(t, 0.1 + 0.005 * t, np.full(6, 1e-4), limit=0.15)
    assert trend.slope == pytest.approx(0.005)
    assert trend.intercept == pytest.approx(0.1)
    assert trend.crossing == pytest.approx(10.0)
    assert trend.scale < 1e-6  # no scatter at all
    value, _ = trend.gap_at(np.array([10.0]))
    assert value[0] == pytest.approx(0.15)


def test_crossing_interval_covers_the_truth_at_its_level() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(8.0)
    hits = 0
    runs = 400
    for _ in range(runs):
        gap = 0.1 + 0.004 * t + rng.normal(0.0, 1e-3, t.size)
        lo, hi = fit_trend(t, gap, np.full(t.size, 1e-3), limit=0.14).crossing_interval
        assert lo is not None and hi is not None
        hits += lo <= 10.0 <= hi
    assert 0.92 <= hits / runs <= 0.98  # 95 % nominal


def test_scatter_larger_than_the_stds_widens_the_interval() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(10.0)
    gap = 0.1 + 0.004 * t + rng.normal(0.0, 1e-3, t.size)
    tight = fit_trend(t, gap, np.full(t.size, 1e-5), limit=0.14)  # stds 100x too small
    honest = fit_trend(t, gap, np.full(t.size, 1e-3), limit=0.14)
    assert tight.scale > 30
    assert tight.slope_std == pytest.approx(honest.slope_std, rel=0.5)


def test_no_wear_gives_no_crossing() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(8.0)
    trend = fit_trend(t, 0.1 + rng.normal(0, 1e-3, 8), np.full(8, 1e-3), limit=0.14)
    assert trend.crossing is None or trend.crossing > 0
    assert trend.crossing_interval == (None, None)


@pytest.mark.parametrize(
    ("t", "match"),
    [
        (np.array([0.0, 1.0]), "at least 3 bags"),
        (np.array([1.0, 1.0, 1.0]), "2 or more times"),
        (np.array([0.0, np.nan, 2.0]), "finite"),
    ],
)
def test_bad_input(t: np.ndarray, match: str) -> None:
    with pytest.raises(GenBacklashError, match=match):
        fit_trend(t, np.full(t.size, 0.1), np.full(t.size, 1e-3), limit=0.2)
