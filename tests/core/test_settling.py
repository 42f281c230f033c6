"""The servo's settling rule (genbacklash_core.settling): which samples pair a reading with a
command the gear has reached (issue 23, deliverable 2)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core.settling import (
    MAX_STRETCH,
    SettleState,
    carry_marks,
    settling_keep,
)

MS = 1_000_000


def _staircase(steps: list[float], per: int) -> tuple[np.ndarray, np.ndarray]:
    """1 kHz readings of commands held for ``per`` readings each."""
    u = np.repeat(np.cumsum(steps), per)
    return np.arange(u.size, dtype=np.int64) * MS, u


def test_samples_within_the_settling_time_after_a_change_are_taken_out() -> None:
    t, u = _staircase([0.01] * 20, 10)  # a move: 100 Hz commands, 10 readings each
    keep, state = settling_keep(t, u, 5 * MS)
    assert keep.reshape(20, 10)[1:, :5].sum() == 0  # the first 5 ms after each step
    assert keep.reshape(20, 10)[1:, 5:].all()
    assert state.applies and state.runs[-1] == 10


def test_the_paper_input_keeps_every_sample() -> None:
    """A new command at every reading: the data cannot show a servo; nothing is taken out."""
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, 500)
    t = np.arange(u.size, dtype=np.int64) * MS
    keep, state = settling_keep(t, u, 5 * MS)
    assert keep.all() and not state.applies


def test_the_rule_never_takes_every_sample_out() -> None:
    """Commands every 4 ms with a 5 ms settling time: half a command period is taken out."""
    t, u = _staircase([0.01] * 50, 4)
    keep, _ = settling_keep(t, u, 5 * MS)
    assert 0.4 < keep.mean() < 0.6


def test_a_large_step_is_given_longer_and_keeps_the_servo_busy_across_the_next() -> None:
    """A compensated command crossing the play (seven usual steps at once) is followed by
    readings the servo has not settled at, after the next (usual) change too."""
    steps = [0.01] * 30 + [0.07] + [0.01] * 5
    t, u = _staircase(steps, 10)
    keep, _ = settling_keep(t, u, 5 * MS)
    jump = 30 * 10
    stretch = min(np.sqrt(7.0), MAX_STRETCH)
    busy = int(np.ceil(5 * stretch))  # ms after the jump
    assert not keep[jump : jump + busy].any()
    assert keep[jump + busy : jump + 10].all()
    assert not keep[jump + 10 : jump + 15].any()  # the next usual step: 5 ms again


def test_pieces_equal_one_call() -> None:
    rng = np.random.default_rng(3)
    steps = rng.choice([0.0, 0.01, -0.01, 0.05], 300).tolist()
    t, u = _staircase(steps, 7)
    whole, _ = settling_keep(t, u, 4 * MS)
    state: SettleState | None = None
    parts = []
    for start in range(0, t.size, 128):
        keep, state = settling_keep(t[start : start + 128], u[start : start + 128], 4 * MS, state)
        parts.append(keep)
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_zero_settling_keeps_everything() -> None:
    t, u = _staircase([0.01] * 20, 10)
    assert settling_keep(t, u, 0)[0].all()


@settings(max_examples=80, deadline=None, derandomize=True)
@given(
    steps=st.lists(st.sampled_from([0.0, 0.005, -0.005, 0.02, -0.05]), min_size=1, max_size=80),
    per=st.integers(1, 12),
    settle=st.integers(0, 12),
)
def test_properties(steps: list[float], per: int, settle: int) -> None:
    t, u = _staircase(steps, per)
    keep, state = settling_keep(t, u, settle * MS)
    assert keep.shape == u.shape
    # a sample kept is at least the base settling time after its command changed, unless the
    # rule does not apply
    if state.applies and settle:
        base = state.limit(settle * MS)
        change = np.r_[True, u[1:] != u[:-1]]
        last = np.maximum.accumulate(np.where(change, np.arange(u.size), 0))
        assert np.all(t[keep] - t[last[keep]] >= base)
    else:
        assert keep.all()


def test_carry_marks_moves_a_mark_to_the_next_kept_sample() -> None:
    marks = np.array([False, False, True, False, False, True])
    keep = np.array([True, False, False, True, True, True])
    assert carry_marks(marks, keep).tolist() == [False, True, False, True]


@pytest.mark.parametrize("settle_ms", [3, 5, 8])
def test_a_servo_lag_no_longer_reads_as_play(settle_ms: int) -> None:
    """A play operator driven through a servo that reaches each new command over ~4 ms
    (first-order, tau 1 ms): identified from every reading the play reads too large (the
    rows at a new command pair it with a gear that has not moved yet); from the settled
    readings it is the play, the error at most half as large."""
    from genbacklash_core import GeneralBacklash, identify_backlash, simulate_backlash
    from genbacklash_core.samples import bridge_lost

    rng = np.random.default_rng(7)
    per, dt = 10, 1e-3
    targets = np.cumsum(rng.choice([-0.02, 0.02], 400) * rng.integers(1, 4, 400))
    u = np.repeat(np.clip(targets, -0.6, 0.6), per)
    motor = np.empty_like(u)
    m = u[0]
    for k, value in enumerate(u):  # the servo: first order, tau 1 ms, at 1 kHz
        m = value + (m - value) * np.exp(-dt / 1e-3)
        motor[k] = m
    true = GeneralBacklash.ideal(1.0, 0.03, 0.03)
    y = simulate_backlash(true, motor)
    t = np.arange(u.size, dtype=np.int64) * MS
    everything = identify_backlash(u, y, 1).model
    keep, _ = settling_keep(t, u, settle_ms * MS)
    index = np.flatnonzero(keep)
    breaks = np.r_[True, np.diff(index) != 1]
    breaks = bridge_lost(breaks, u, index)
    settled = identify_backlash(u[keep], y[keep], 1, breaks=breaks).model
    play = true.c_left + true.c_right
    error_all = everything.c_left + everything.c_right - play
    error_settled = settled.c_left + settled.c_right - play
    assert error_all > 0.03 * play
    assert abs(error_settled) < min(0.02 * play, 0.5 * error_all)
