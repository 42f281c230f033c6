"""The screen stage's sample rule (genbacklash_ros/node/screen.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import Estimate, Structure
from genbacklash_core.samples import lift_bridged, missing_readings
from genbacklash_ros.node.align import AlignedBatch
from genbacklash_ros.node.health import StreamHealth
from genbacklash_ros.node.sample_rule import link_breaks
from genbacklash_ros.node.screen import Screen, early_stamps, linked_breaks

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


def _batch(held: list[int], marks: list[bool] | None = None) -> AlignedBatch:
    t = np.array(held, dtype=np.int64)
    flags = np.zeros(t.size, bool) if marks is None else np.array(marks)
    return AlignedBatch(t, np.zeros(t.size), np.zeros(t.size), t, flags, float(2 * MS), True)


def test_an_early_stamp_breaks_the_chain_but_does_not_restart_the_guard() -> None:
    """A reading stamped 0.1 period after the one before (a publisher catching up) breaks
    the sample rule's chain, but nothing was lost: the guard's free run goes on there. A
    lost reading, a reading taken out before (a mark) and the first sample of a new time
    line restart it."""
    screen = Screen()
    health = StreamHealth()
    est = Estimate.empty(Structure(3))
    first = screen.run(_batch([0, 2 * MS, 2 * MS + MS // 5, 4 * MS, 8 * MS]), health, est)
    assert first.breaks.tolist() == [True, False, True, False, True]
    assert first.restarts.tolist() == [True, False, False, False, True]
    # linked to the batch before: an early first sample goes on, a mark restarts
    second = screen.run(_batch([8 * MS + MS // 5, 10 * MS, 10 * MS + 1], [False, False, True]),
                        health, est)  # fmt: skip
    assert second.breaks.tolist() == [True, False, True]
    assert second.restarts.tolist() == [False, False, True]


def test_early_stamps_are_steps_below_half_a_period() -> None:
    held = np.array([10, 14, 16, 24, 34], dtype=np.int64)
    assert early_stamps(held, 10.0, 0).tolist() == [False, True, True, False, False]
    assert early_stamps(held, 10.0, 7)[0] == np.True_  # 0.3 period after the one before
    assert early_stamps(held, 10.0, None)[0] == np.False_


def test_with_a_servo_modelled_the_commands_restart_only_where_their_path_is_unknown() -> None:
    """The servo output is not bridged (its rows break at every lost reading), but the
    guard's free run on the commands goes on across a lost reading where the commands were
    monotone, as a backlash alone's rows do; a mark restarts both."""
    t = np.array([0, 2 * MS, 6 * MS, 8 * MS, 12 * MS, 14 * MS], dtype=np.int64)
    monotone = np.array([True, True, True, True, False, True])
    marks = np.array([False, False, False, True, False, False])
    batch = AlignedBatch(
        t,
        np.zeros(t.size),
        np.zeros(t.size),
        t,
        marks,
        float(2 * MS),
        True,
        monotone=np.zeros(t.size, dtype=bool),
        commands=np.linspace(0.0, 1.0, t.size),
        command_monotone=monotone,
    )
    screened = Screen(bridge=True).run(batch, StreamHealth(), Estimate.empty(Structure(3)))
    assert screened.restarts.tolist() == [True, False, True, True, True, False]
    assert screened.command_restarts is not None
    assert screened.command_restarts.tolist() == [True, False, False, True, True, False]
    assert screened.commands is not None and screened.commands.tolist() == batch.commands.tolist()
    # no servo modelled: no commands, no second restarts
    plain = Screen(bridge=True).run(
        dataclasses.replace(batch, commands=None, command_monotone=None),
        StreamHealth(),
        Estimate.empty(Structure(3)),
    )
    assert plain.commands is None and plain.command_restarts is None
