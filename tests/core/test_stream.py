"""The recursive identifier's rows as samples come (genbacklash_core.online.stream)."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from genbacklash_core import Structure, paper_example
from genbacklash_core.online.stream import RowStream, window_cascade_rows


def _pieces(
    stream: RowStream,
    structure: Structure,
    theta: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    b: np.ndarray,
    cuts: list[int],
) -> tuple[np.ndarray, np.ndarray]:
    rows, at = [], []
    for lo, hi in pairwise(cuts):
        r, a = stream.take(structure, theta, u[lo:hi], y[lo:hi], b[lo:hi], 1e-4, 0)
        rows.append(r)
        at.append(a + lo)
    return np.concatenate(rows), np.concatenate(at)


def test_rows_and_anchors_do_not_depend_on_the_pieces() -> None:
    ex = paper_example(1)
    data = ex.generate(seed=0, n_samples=600)
    structure = Structure(3)
    theta = structure.theta(ex.model.parameters())
    rng = np.random.default_rng(1)
    u = np.repeat(data.u[:150], 4)  # held commands
    y = np.repeat(data.y[:150], 4)
    b = rng.random(u.size) < 0.03
    one = _pieces(RowStream(structure, 100), structure, theta, u, y, b, [0, u.size])
    cuts = [*range(0, u.size, 5), u.size]  # pieces of five samples: many carry an anchor
    many = _pieces(RowStream(structure, 100), structure, theta, u, y, b, cuts)
    np.testing.assert_array_equal(one[0], many[0])
    np.testing.assert_array_equal(one[1], many[1])
    assert np.any(one[0][:, 5] != 0.0)  # some holds read an anchor
    lost = np.flatnonzero(b)
    assert not np.isin(one[1], lost).any()  # no row pairs across a lost reading


def test_without_an_estimate_rows_are_unanchored_and_the_cascade_takes_none() -> None:
    u = np.linspace(0.0, 1.0, 20)
    b = np.zeros(20, dtype=bool)
    rows, at = RowStream(Structure(3), 50).take(Structure(3), None, u, u, b, 1e-4, 0)
    assert at.size == 19 and not rows[:, 4:].any()
    cascade = Structure(3, 2, 2)
    stream = RowStream(cascade, 50)
    rows, at = stream.take(cascade, None, u, u, b, 1e-4, 0)
    assert at.size == 0 and rows.shape[0] == 0
    assert (stream.low, stream.high, len(stream.recent)) == (0.0, 1.0, 20)


def test_a_window_of_cascade_rows() -> None:
    ex = paper_example(3)
    data = ex.generate(seed=0, n_samples=400)
    structure = Structure(3, 2, 2)
    b = np.zeros(400, dtype=bool)
    rows, at, _ = window_cascade_rows(structure, ex.model.parameters(), data.u, data.y, b, 1e-4)
    assert rows.shape[0] == at.size > 300
    assert at[0] >= 2 and np.all(np.diff(at) > 0)  # once x(t-1), x(t-2) are determined
