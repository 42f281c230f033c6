"""The sample rule (genbacklash_core.samples): which readings are consecutive."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import GeneralBacklash, paper_example
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.play import play_operator
from genbacklash_core.samples import (
    as_breaks,
    breaks_to_rows,
    bridge_lost,
    monotone_paths,
    nominal_period,
    sample_breaks,
    segment_lengths,
)
from genbacklash_core.simulate import play_bounds

PERIOD = 1_000_000


@settings(max_examples=60, derandomize=True, deadline=None)
@given(
    lost=st.lists(st.booleans(), min_size=3, max_size=200),
    jitter=st.floats(0.0, 0.45),
    seed=st.integers(0, 2**16),
)
def test_breaks_exactly_after_lost_readings_whatever_the_jitter(
    lost: list[bool], jitter: float, seed: int
) -> None:
    """A reading breaks the chain exactly when the one before it on the encoder's clock was
    lost; jitter of less than half a period never makes or hides a break."""
    received = ~np.array(lost)
    received[0] = True
    rng = np.random.default_rng(seed)
    ticks = np.arange(received.size)
    stamps = (ticks * PERIOD + rng.uniform(-jitter / 2, jitter / 2, ticks.size) * PERIOD).astype(
        np.int64
    )
    kept = np.flatnonzero(received)
    breaks = sample_breaks(stamps[kept], PERIOD)
    expected = np.concatenate([[True], np.diff(kept) != 1])
    np.testing.assert_array_equal(breaks, expected)


def test_nominal_period_is_robust_to_gaps() -> None:
    t = np.array([0, 10, 20, 30, 70, 80, 90, 200])
    assert nominal_period(t) == 10.0
    np.testing.assert_array_equal(
        sample_breaks(t), [True, False, False, False, True, False, False, True]
    )


def test_rows_for_lagged_regressions() -> None:
    breaks = np.array([True, False, False, True, False, False, False])
    assert breaks_to_rows(breaks, 1).tolist() == [True, True, False, True, True, True]
    assert breaks_to_rows(breaks, 2).tolist() == [True, False, False, True, True]
    assert breaks_to_rows(breaks, 7).tolist() == []
    assert segment_lengths(breaks).tolist() == [3.0, 4.0]


def test_bad_arguments() -> None:
    with pytest.raises(GenBacklashError, match="at least two increasing stamps"):
        nominal_period([5])
    with pytest.raises(GenBacklashError, match="period must be > 0"):
        sample_breaks([0, 1, 2], period_ns=0.0)
    with pytest.raises(GenBacklashError, match="one flag per sample"):
        as_breaks([True, False], 3)
    with pytest.raises(GenBacklashError, match="booleans"):
        as_breaks([0, 2, 1], 3)
    assert as_breaks(None, 3).tolist() == [True, False, False]


def _brute_monotone(v: np.ndarray, i0: int, i1: int) -> bool:
    if i1 < i0:
        return False
    d = np.diff(v[i0 : i1 + 1])
    return bool(np.all(d >= 0) or np.all(d <= 0))


@settings(max_examples=80, derandomize=True, deadline=None)
@given(
    values=st.lists(st.sampled_from([-1.0, 0.0, 0.5, 1.0]), min_size=1, max_size=30),
    pairs=st.lists(st.tuples(st.integers(0, 29), st.integers(0, 29)), min_size=1, max_size=10),
)
def test_monotone_paths_agrees_with_brute_force(
    values: list[float], pairs: list[tuple[int, int]]
) -> None:
    v = np.array(values)
    i0 = np.array([a % v.size for a, _ in pairs])
    i1 = np.array([b % v.size for _, b in pairs])
    expected = [_brute_monotone(v, a, b) for a, b in zip(i0, i1, strict=True)]
    assert monotone_paths(v, i0, i1).tolist() == expected


@settings(max_examples=60, derandomize=True, deadline=None)
@given(
    start=st.floats(-2.0, 2.0),
    x0=st.floats(-2.0, 2.0),
    steps=st.lists(st.floats(0.0, 0.5), min_size=1, max_size=8),
    down=st.booleans(),
)
def test_a_monotone_path_ends_where_one_step_ends(
    start: float, x0: float, steps: list[float], down: bool
) -> None:
    """The property bridging rests on: the play operator (eqs. 20-21) is rate independent,
    so a monotone input path from ``a`` to ``b`` leaves the state one step ``a -> b`` leaves."""
    model = paper_example(1).model
    path = start + np.cumsum([0.0, *steps]) * (-1.0 if down else 1.0)
    along = play_operator(*_bounds(model, path), x0)[-1]
    jump = play_operator(*_bounds(model, path[[0, -1]]), x0)[-1]
    assert float(along) == pytest.approx(float(jump), abs=1e-12)


def _bounds(model: GeneralBacklash, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return play_bounds(model.left(u), model.right(u))


def test_bridge_lost_lifts_only_lost_readings_along_a_monotone_input() -> None:
    held = np.array([0.0, 0.0, 0.1, 0.1, 0.2, 0.3, 0.5, 0.0, 0.0, 0.0, 0.0])
    index = np.array([0, 2, 3, 5, 7, 10])
    breaks = np.array([True, True, True, True, True, True])
    out = bridge_lost(breaks, held, index, max_missing=1)
    # the first sample always breaks; 2 -> 3 broke for another reason (no reading lost: a
    # reading taken out) and stays; 5 -> 7 reverses (0.3, 0.5, 0.0); 7 -> 10 is too long
    assert out.tolist() == [True, False, True, False, True, True]
    assert bridge_lost(breaks, held, index, max_missing=2)[-1] == np.False_
    with pytest.raises(GenBacklashError, match="differ in shape"):
        bridge_lost(breaks, held, index[:-1])
    with pytest.raises(GenBacklashError, match="must lie in"):
        monotone_paths(held, [0], [held.size])


def test_bridged_rows_match_the_rows_without_loss() -> None:
    """On a noise-free held-command record, a bridged pair of readings is exactly a pair of
    consecutive states: every informative row survives 30 % loss."""
    from genbacklash_core.scenarios import OperationSettings, operation_record

    rec = operation_record(OperationSettings(duration=5.0, loss=0.3, noise=0.0), 2)
    u, _, strict = rec.series()
    _, _, bridged = rec.series(bridge=True)
    moving = np.r_[False, np.diff(u) != 0.0]
    assert np.count_nonzero(moving & ~strict) < 0.7 * np.count_nonzero(moving)
    kept = np.flatnonzero(moving & ~bridged)
    assert kept.size >= 0.97 * np.count_nonzero(moving)
    x = rec.x_all[rec.received]
    model = rec.truth
    # the truth maps (u[k-1] -> u[k], x[k-1]) to x[k] on every bridged row
    for k in kept[:200]:
        step = play_operator(*_bounds(model, u[k - 1 : k + 1]), float(x[k - 1]))[-1]
        assert float(step) == pytest.approx(float(x[k]), abs=1e-9)
