"""The screen stage's sample rule (genbacklash_ros/node/screen.py)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core.samples import lift_bridged, missing_readings
from genbacklash_ros.node.sample_rule import link_breaks
from genbacklash_ros.node.screen import linked_breaks

MS = 1_000_000


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(
    steps=st.lists(st.integers(1, 30 * MS), min_size=1, max_size=40),
    start=st.integers(0, 2**40),
    linked=st.booleans(),
    monotone=st.lists(st.booleans(), min_size=40, max_size=40),
    bridge=st.booleans(),
)
def test_linked_breaks_are_the_sample_rule_and_the_bridging_rule(
    steps: list[int], start: int, linked: bool, monotone: list[bool], bridge: bool
) -> None:
    """One pass gives what link_breaks, then lift_bridged on missing_readings give (stamps
    that float64 holds exactly)."""
    stamps = start + np.cumsum(np.array(steps[1:] if linked else steps, dtype=np.int64))
    held = (
        np.concatenate(([start], stamps))
        if not linked
        else np.concatenate(([start + steps[0]], stamps))
    )
    previous = start if linked else None
    flags = np.array(monotone[: held.size])
    expected = link_breaks(held, float(MS), previous_ns=previous)
    if bridge:
        first = held[0] if previous is None else previous
        missing = missing_readings(np.concatenate(([first], held)), float(MS))[1:]
        expected = lift_bridged(expected, missing, flags)
    got = linked_breaks(held, float(MS), previous, flags if bridge else None)
    assert got.tolist() == expected.tolist()


def test_linked_breaks_count_lost_readings_exactly_on_wall_clock_stamps() -> None:
    """At wall-clock stamps (~1.7e18 ns, 256 ns apart in float64) a gap of 1.500001 periods
    is one lost reading: it breaks, and a monotone command bridges it."""
    t0 = 1_700_000_000_000_000_000
    held = np.array([t0, t0 + 1_500_001], dtype=np.int64)
    assert linked_breaks(held, float(MS), t0 - MS).tolist() == [False, True]
    bridged = linked_breaks(held, float(MS), t0 - MS, np.array([True, True]))
    assert bridged.tolist() == [False, False]
