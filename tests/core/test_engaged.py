"""Whether the data engaged each branch (genbacklash_core.online.engaged) and the cold start
that does not fit data that never engaged one (genbacklash_core.online.fits.cold_fit)."""

from __future__ import annotations

import numpy as np
import pytest

import genbacklash_core.online.fits as fits
from genbacklash_core import Structure, paper_example
from genbacklash_core.online.engaged import engaged_inputs, unengaged_branch
from genbacklash_core.online.memory import pair_series


def _quantised_sweep(reversal_travel: float, quantum: float = 1e-3) -> tuple[np.ndarray, ...]:
    """Paper example 1 driven up 1.5, then down by ``reversal_travel``, then up again,
    read by a quantised, noise-free encoder."""
    truth = paper_example(1).model
    u = np.concatenate(
        [
            np.linspace(-0.5, 1.0, 300),
            np.linspace(1.0, 1.0 - reversal_travel, 200)[1:],
            np.linspace(1.0 - reversal_travel, 1.2, 200)[1:],
        ]
    )
    y = np.round(truth.simulate(u, x0=truth.right(np.array([-0.5]))[0]) / quantum) * quantum
    return u, y


def test_counts_distinct_inputs_where_the_output_changed_by_direction() -> None:
    u = np.array([0.0, 0.1, 0.2, 0.2, 0.1, 0.0, 0.1])
    y = np.array([0.0, 0.1, 0.2, 0.2, 0.2, 0.1, 0.1])
    # up: 0.1, 0.2 changed (0.0 -> 0.1 at the end held); down: 0.0 changed (0.1 held)
    assert engaged_inputs(u, y, None) == (1, 2)
    breaks = np.zeros(u.size, dtype=bool)
    breaks[5] = True  # the pair (0.1 -> 0.0) crosses a lost reading: no row
    assert engaged_inputs(u, y, breaks) == (0, 2)


def test_a_branch_needs_n_plus_one_distinct_engaged_inputs() -> None:
    s = Structure(1)  # two parameters per branch
    up = np.array([0.0, 0.1, 0.2])
    down = np.array([0.15, 0.05])
    u = np.concatenate([up, down])
    y_one = np.concatenate([up, [0.2, 0.1]])  # down: only 0.05 changed the output
    reason = unengaged_branch(s, u, y_one, None)
    assert reason is not None and "moved down at 1 distinct inputs" in reason
    assert "left branch" in reason and "right" not in reason
    u2 = np.concatenate([u, [-0.05]])
    y_two = np.concatenate([y_one, [0.0]])  # one more changed output on the way down
    assert unengaged_branch(s, u2, y_two, None) is None


def test_white_noise_never_trips_the_check() -> None:
    data = paper_example(1).generate(seed=3, n_samples=200)
    assert unengaged_branch(Structure(3), data.u, data.y, None) is None


def test_a_cascade_is_not_judged() -> None:
    u = np.linspace(0.0, 1.0, 50)
    assert unengaged_branch(Structure(3, 1, 1), u, 0 * u + 1.0, None) is None


def test_cold_fit_does_not_fit_data_whose_reversal_stays_inside_the_play(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the play of example 1 is 0.7 + 0.8: a reversal of 0.3 never reaches the left branch
    u, y = _quantised_sweep(0.3)
    pairs = pair_series(u[:-1], u[1:], y[:-1], y[1:])
    assert engaged_inputs(*pairs)[0] == 0

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("identify_backlash ran on data that never engaged a branch")

    monkeypatch.setattr(fits, "identify_backlash", never)
    found = fits.cold_fit(Structure(3), False, *pairs)
    assert isinstance(found, str)
    assert found.startswith("not enough excitation") and "left branch" in found


def test_cold_fit_still_fits_once_the_reversal_crosses_the_play() -> None:
    u, y = _quantised_sweep(2.5)
    pairs = pair_series(u[:-1], u[1:], y[:-1], y[1:])
    down, up = engaged_inputs(*pairs)
    assert down >= 4 and up >= 4
    assert unengaged_branch(Structure(3), *pairs) is None
    found = fits.cold_fit(Structure(3), False, *pairs)
    assert not isinstance(found, str), found
    truth = paper_example(1).model.parameters()
    assert abs(found[1][3] + found[1][7] - (truth[3] + truth[7])) < 0.05
