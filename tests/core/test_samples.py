"""The sample rule (genbacklash_core.samples): which readings are consecutive."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core.errors import GenBacklashError
from genbacklash_core.samples import (
    as_breaks,
    breaks_to_rows,
    nominal_period,
    sample_breaks,
    segment_lengths,
)

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
