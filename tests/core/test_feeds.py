"""The windowed identifier's feeds (genbacklash_core.online.feeds): rows or samples."""

from __future__ import annotations

import numpy as np

from genbacklash_core import Structure, paper_example
from genbacklash_core.online.feeds import RowFeed, SampleFeed


def _series(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1.0, 1.0, n // 4), 4)  # held commands: dwells of 4 samples
    y = np.tanh(u) + 0.01 * rng.standard_normal(u.size)
    b = rng.random(u.size) < 0.05  # lost readings
    return u, y, b


def _drain(
    feed: RowFeed | SampleFeed, u: np.ndarray, y: np.ndarray, b: np.ndarray, due: int
) -> list[tuple[int, int]]:
    return [(n, feed.progress) for n in feed.take(u, y, b, lambda: due)]


def test_row_feed_takes_the_same_rows_whatever_the_chunking() -> None:
    u, y, b = _series(800)
    whole, chunked, single = RowFeed(400, 8), RowFeed(400, 8), RowFeed(400, 8)
    _drain(whole, u, y, b, 10**9)
    for start in range(0, u.size, 37):
        part = slice(start, start + 37)
        _drain(chunked, u[part], y[part], b[part], 10**9)
    for k in range(u.size):
        single.push(float(u[k]), float(y[k]), k > 0 and not b[k])
    for feed in (chunked, single):
        assert feed.rows == whole.rows and feed.idle == whole.idle
        for mine, theirs in zip(feed.memory.rows(), whole.memory.rows(), strict=True):
            np.testing.assert_array_equal(mine, theirs)
    assert 0 < whole.rows < u.size * 0.3  # a dwell or a break adds no row


def test_row_feed_stops_where_a_fit_is_due() -> None:
    u, y, b = _series(400)
    feed = RowFeed(400, 8)
    steps = _drain(feed, u, y, b, 25)
    assert steps[0][1] == 25  # it stopped at the row that made the fit due
    assert sum(n for n, _ in steps) == u.size


def test_sample_feed_leaves_settled_dwells_out() -> None:
    ex = paper_example(3)
    structure = Structure(3, 2, 2)
    feed = SampleFeed(1000)
    u = np.concatenate([np.linspace(0.0, 1.0, 50), np.full(500, 1.0)])
    y = np.zeros_like(u)
    b = np.zeros(u.size, dtype=bool)
    assert sum(n for n, _ in _drain(feed, u, y, b, 10**9)) == u.size
    assert feed.kept == u.size  # no estimate yet: every sample is stored
    feed.settle(structure, ex.model.parameters())
    assert feed.dwell is not None and 0 < feed.dwell < 400
    counts = [n for n, _ in _drain(feed, np.full(400, 1.0), np.zeros(400), b[:400], 10**9)]
    assert sum(counts) == 400  # every sample counted ...
    assert feed.kept == u.size  # ... none stored: the dwell had settled long before
    assert feed.idle == 400


def test_seed_left_counts_what_new_data_replaced() -> None:
    rows, window = RowFeed(100, 4), SampleFeed(100)
    u = np.linspace(0.0, 1.0, 30)
    _drain(rows, u, u, np.zeros(30, dtype=bool), 10**9)
    _drain(window, u, u, np.zeros(30, dtype=bool), 10**9)
    assert rows.seed_left(50, seed_progress=0) == 50 - rows.rows  # rows since the seed
    assert window.seed_left(100, seed_progress=0) == 70  # the window's room left
