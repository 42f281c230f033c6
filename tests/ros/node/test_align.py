"""The aligner's own form of the core's sample rule helpers (genbacklash_ros/node/align.py)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core.samples import monotone_paths
from genbacklash_ros.node.align import _monotone_paths


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(
    values=st.lists(
        st.sampled_from([-1.0, -0.0, 0.0, 0.5, 0.5 + 2**-50, 1e300, -1e300]),
        min_size=1,
        max_size=12,
    ),
    pairs=st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11)), min_size=1, max_size=20),
)
def test_monotone_paths_of_the_pending_commands_are_the_cores(
    values: list[float], pairs: list[tuple[int, int]]
) -> None:
    """Counted in Python over the few pending commands, the answer is the core's, pair for
    pair (held values, signed zeros, neighbouring floats and reversed pairs included)."""
    start = np.array([min(a, len(values) - 1) for a, _ in pairs], dtype=np.int64)
    stop = np.array([min(b, len(values) - 1) for _, b in pairs], dtype=np.int64)
    got = _monotone_paths(values, start, stop)
    assert got.tolist() == monotone_paths(values, start, stop).tolist()
