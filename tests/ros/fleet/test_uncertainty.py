"""Standard deviations of the batch estimate are calibrated on white noise."""

from __future__ import annotations

import numpy as np

from genbacklash_core import identify_backlash, paper_example
from genbacklash_ros.fleet.uncertainty import gap_std, parameter_covariance, parameter_std


def test_std_matches_the_spread_over_seeds() -> None:
    example = paper_example(1)  # SNR 25, white noise: the covariance's assumption holds
    z, gaps, gap_sd = [], [], []
    for seed in range(12):
        data = example.generate(seed=seed)
        model = identify_backlash(data.u, data.y, 3).model
        _, values, std = parameter_std(model, data.u, data.y)
        z.append((values - example.model.parameters()) / std)
        cov = parameter_covariance(model, data.u, data.y)
        gaps.append(model.c_left + model.c_right)
        gap_sd.append(gap_std(model, cov))
    spread = np.std(np.array(z), axis=0)
    assert np.all((spread > 0.5) & (spread < 2.0)), spread  # ~1 when calibrated
    true_gap = example.model.c_left + example.model.c_right
    z_gap = (np.array(gaps) - true_gap) / np.array(gap_sd)
    assert 0.5 < np.std(z_gap) < 2.0


def test_breaks_restart_the_simulation() -> None:
    example = paper_example(1)
    data = example.generate(seed=3)
    model = identify_backlash(data.u, data.y, 3).model
    breaks = np.zeros(data.u.size, dtype=bool)
    breaks[0] = breaks[400] = True
    with_breaks = parameter_covariance(model, data.u, data.y, breaks)
    without = parameter_covariance(model, data.u, data.y)
    assert np.all(np.isfinite(with_breaks)) and not np.allclose(with_breaks, without)
