"""One row rule for batch and online: the rows of eq. (24) both paths fit on."""

from __future__ import annotations

import numpy as np

from genbacklash_core import GeneralBacklash
from genbacklash_core.identify import backlash_rows
from genbacklash_core.online.rows import window_rows
from genbacklash_core.structure import Structure

TRUTH = GeneralBacklash((1.0, 0.0, 0.05), 0.03, (1.0, 0.0, -0.05), 0.04)


def _held_commands(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ramp up and back held in steps of 10 samples (commands slower than the encoder),
    white noise, 3 % of the readings lost."""
    rng = np.random.default_rng(seed)
    steps = np.concatenate([np.linspace(-1.0, 1.0, 40), np.linspace(1.0, -1.0, 40)])
    u = np.repeat(steps, 10)
    y = TRUTH.simulate(u, x0=float(TRUTH.right([-1.0])[0])) + rng.normal(0.0, 1e-3, u.size)
    breaks = rng.random(u.size) < 0.03
    return u, y, breaks


def test_the_window_takes_the_batch_rows_whose_input_moved() -> None:
    u, y, breaks = _held_commands(0)
    structure = Structure(3, sign=1.0)
    p = TRUTH.parameters()
    deadband = 1e-4 * float(np.ptp(u))
    phi, target, engaged = backlash_rows(structure, p, u, y, breaks)
    window = window_rows(structure, p, u, y, deadband, breaks=breaks)
    moved = np.abs(np.diff(u)) > deadband
    assert np.array_equal(window.informative, engaged & moved)
    kept = moved[engaged]  # the batch rows, in order, that the window keeps
    assert np.array_equal(window.phi, phi[kept])
    assert np.array_equal(window.target, target[kept])
    # batch keeps the engaged rows of a held command too: most of them here
    held = engaged & ~moved
    assert held.sum() > engaged.sum() // 2
    assert not (engaged & breaks[1:]).any()  # never a row across a lost reading
