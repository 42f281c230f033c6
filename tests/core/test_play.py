"""The play operator: the fast scan must equal the per-sample loop bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from genbacklash_core import GenBacklashError, play_operator, play_operator_loop
from genbacklash_core.play import _LOOP_BELOW

HYPOTHESIS = settings(max_examples=300, deadline=None, derandomize=True, database=None)


def _bounds(rng: np.random.Generator, n: int, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    centre = np.cumsum(rng.normal(0, scale, n))
    width = rng.exponential(scale, n) * rng.choice([0.0, 1.0, 3.0], n)  # some zero-width
    lo = centre - width / 2
    return lo, lo + width


@pytest.mark.parametrize(
    "n",
    [
        *(0, 1, 2, 17, 1023, 1024, 1025, 4099, 10_001, 65_537, 100_000),
        # straddle the switch from the plain loop to the scan
        *(_LOOP_BELOW - 1, _LOOP_BELOW, _LOOP_BELOW + 1, _LOOP_BELOW + 2),
    ],
)
@pytest.mark.parametrize("x0", [0.0, -7.5, 1e6])
def test_scan_equals_loop(n: int, x0: float) -> None:
    rng = np.random.default_rng(n)
    lo, hi = _bounds(rng, n)
    fast = play_operator(lo, hi, x0)
    slow = play_operator_loop(lo, hi, x0)
    assert fast.shape == slow.shape == (n,)
    assert fast.dtype == np.float64
    assert np.array_equal(fast, slow)


def test_scan_equals_loop_one_million_wide_bounds() -> None:
    rng = np.random.default_rng(42)
    n = 1_000_003  # prime: a ragged last block
    lo, hi = _bounds(rng, n, scale=0.01)
    assert np.array_equal(play_operator(lo, hi, 0.3), play_operator_loop(lo, hi, 0.3))


def test_does_not_modify_inputs() -> None:
    rng = np.random.default_rng(1)
    lo, hi = _bounds(rng, 5000)
    lo_copy, hi_copy = lo.copy(), hi.copy()
    play_operator(lo, hi, 0.0)
    np.testing.assert_array_equal(lo, lo_copy)
    np.testing.assert_array_equal(hi, hi_copy)


def test_hand_computed() -> None:
    lo = [0.0, 1.0, -1.0, -1.0, 2.0]
    hi = [0.5, 2.0, 0.2, 5.0, 2.0]
    expected = [0.5, 1.0, 0.2, 0.2, 2.0]
    assert play_operator(lo, hi, x0=3.0).tolist() == expected
    # the same bounds repeated past the threshold take the scan path
    reps = 100
    assert play_operator(lo * reps, hi * reps, x0=3.0).tolist()[:5] == expected


def test_accepts_lists_and_non_contiguous_views() -> None:
    rng = np.random.default_rng(2)
    lo, hi = _bounds(rng, 2000)
    both = np.stack([lo, hi], axis=1)  # columns are strided views
    assert np.array_equal(play_operator(both[:, 0], both[:, 1]), play_operator_loop(lo, hi))
    assert np.array_equal(play_operator(lo.tolist(), hi.tolist()), play_operator_loop(lo, hi))


@pytest.mark.parametrize(
    ("lo", "hi"),
    [
        (np.zeros(3), np.zeros(4)),
        (np.zeros((300, 2)), np.ones((300, 2))),
        (np.zeros(300), np.ones((1, 300))),
    ],
)
def test_shape_errors(lo: np.ndarray, hi: np.ndarray) -> None:
    with pytest.raises(GenBacklashError, match="lo and hi must be 1-D of one length"):
        play_operator(lo, hi)


# --------------------------------------------------------------------------- properties

_finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
_width = st.floats(min_value=0.0, max_value=1e6, allow_nan=False, allow_infinity=False)


@st.composite
def bounds_and_state(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, float]:
    n = draw(st.one_of(st.integers(0, 40), st.integers(250, 700)))
    lo = draw(hnp.arrays(np.float64, n, elements=_finite))
    width = draw(hnp.arrays(np.float64, n, elements=_width))
    return lo, lo + width, draw(_finite)


@HYPOTHESIS
@given(bounds_and_state())
def test_property_equals_loop(case: tuple[np.ndarray, np.ndarray, float]) -> None:
    lo, hi, x0 = case
    assert np.array_equal(play_operator(lo, hi, x0), play_operator_loop(lo, hi, x0))


@HYPOTHESIS
@given(bounds_and_state())
def test_property_output_within_bounds(case: tuple[np.ndarray, np.ndarray, float]) -> None:
    lo, hi, x0 = case
    x = play_operator(lo, hi, x0)
    assert np.all(lo <= x)
    assert np.all(x <= hi)


@HYPOTHESIS
@given(bounds_and_state())
def test_property_hold(case: tuple[np.ndarray, np.ndarray, float]) -> None:
    lo, hi, x0 = case
    x = play_operator(lo, hi, x0)
    previous = np.concatenate([[x0], x[:-1]])
    inside = (lo <= previous) & (previous <= hi)
    np.testing.assert_array_equal(x[inside], previous[inside])
    # and when it moves, it moves only to the nearer bound
    below = previous < lo
    above = previous > hi
    np.testing.assert_array_equal(x[below], lo[below])
    np.testing.assert_array_equal(x[above], hi[above])
