"""Commissioning motion (genbacklash_core.excite): limits, coverage, convergence, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.excite import (
    MotionLimits,
    Trajectory,
    check_commissioning,
    commissioning_trajectory,
    verify,
)
from genbacklash_core.online.memory import RowMemory
from genbacklash_core.scenarios import OPERATION_BACKLASH, STRAIGHT_BACKLASH

DEFAULT = MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0)  # the operation scenario's
WIDE = GeneralBacklash((1.0, 0.03, -0.015), 0.1, (1.0, 0.025, -0.012), 0.1)
REL = 1e-9  # the limits hold to this relative tolerance


def _differences(u: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Finite differences written out here, independently of the module: velocity between
    consecutive commands, acceleration at each inner command."""
    return np.diff(u) * rate, (u[2:] - 2.0 * u[1:-1] + u[:-2]) * rate * rate


def _assert_within(traj: Trajectory, limits: MotionLimits, rate: float) -> None:
    u = traj.u
    assert u.min() >= limits.low and u.max() <= limits.high
    velocity, acceleration = _differences(u, rate)
    assert np.max(np.abs(velocity)) <= limits.v_max * (1.0 + REL)
    assert np.max(np.abs(acceleration)) <= limits.a_max * (1.0 + REL)
    # at rest before and after: the first and last step are reachable from rest
    assert abs(u[1] - u[0]) * rate * rate <= limits.a_max * (1.0 + REL)
    assert abs(u[-1] - u[-2]) * rate * rate <= limits.a_max * (1.0 + REL)


def _regions_moved(u: np.ndarray, low: float, high: float, bins: int = 16) -> np.ndarray:
    """Moves per (direction, region) as the identifier files them: by where the input
    arrives, ``[down, up] x bins``."""
    step = np.diff(u)
    moved = step != 0.0
    region = np.clip(np.floor((u[1:] - low) / (high - low) * bins).astype(int), 0, bins - 1)
    counts = np.zeros((2, bins), dtype=int)
    np.add.at(counts, ((step[moved] > 0).astype(int), region[moved]), 1)
    return counts


# --------------------------------------------------------------------------- limits


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(
    low=st.floats(-50.0, 50.0),
    span=st.floats(0.05, 20.0),
    speed=st.floats(0.2, 30.0),  # v_max in spans per second
    agility=st.floats(0.5, 200.0),  # a_max / v_max, 1/s
    rate=st.sampled_from([20.0, 50.0, 100.0, 250.0, 1000.0]),
    start=st.one_of(st.none(), st.floats(0.0, 1.0)),
    jog_points=st.integers(0, 5),
)
def test_limits_hold_and_every_region_is_moved_both_ways(
    low: float,
    span: float,
    speed: float,
    agility: float,
    rate: float,
    start: float | None,
    jog_points: int,
) -> None:
    v_max = speed * span
    limits = MotionLimits(low, low + span, v_max=v_max, a_max=agility * v_max)
    at = None if start is None else limits.low + start * limits.span
    traj = commissioning_trajectory(limits, command_rate=rate, start=at, jog_points=jog_points)
    _assert_within(traj, limits, rate)
    begin = limits.low + 0.5 * limits.span if at is None else at
    assert traj.u[0] == traj.u[-1] == begin
    assert traj.u.min() == limits.low and traj.u.max() == limits.high
    assert traj.reversals >= 3
    counts = _regions_moved(traj.u, limits.low, limits.high)
    assert np.all(counts >= 1), counts


def test_the_default_motion_uses_the_limits_and_lasts_under_three_seconds() -> None:
    traj = commissioning_trajectory(DEFAULT)
    assert traj.duration == pytest.approx(2.84)
    assert traj.reversals == 3
    assert traj.command_rate == 100.0
    assert 0.999 * DEFAULT.v_max < traj.peak_velocity <= DEFAULT.v_max
    assert 0.999 * DEFAULT.a_max < traj.peak_acceleration <= DEFAULT.a_max
    np.testing.assert_allclose(traj.t[:3], [0.0, 0.01, 0.02])
    assert not traj.u.flags.writeable


def test_the_motion_goes_to_the_farther_end_first() -> None:
    up = commissioning_trajectory(DEFAULT, start=-0.5)
    down = commissioning_trajectory(DEFAULT, start=0.5)
    assert up.u[np.argmax(np.abs(up.u - (-0.5)) > 0.1)] > -0.5
    assert down.u[np.argmax(np.abs(down.u - 0.5) > 0.1)] < 0.5
    assert up.u[0] == up.u[-1] == -0.5


def test_positions_far_from_zero_keep_the_limits_despite_rounding() -> None:
    limits = MotionLimits(10_000.0, 10_003.0, v_max=2.0, a_max=40.0)
    traj = commissioning_trajectory(limits, command_rate=1000.0)
    _assert_within(traj, limits, 1000.0)


def test_a_fast_joint_is_slowed_to_sweeps_of_about_ninety_commands() -> None:
    traj = commissioning_trajectory(MotionLimits(-1.2, 1.2, v_max=50.0, a_max=5000.0))
    assert traj.peak_velocity < 3.0
    assert traj.duration == pytest.approx(2.7, abs=0.1)


def test_a_slow_joint_gets_more_sweeps() -> None:
    slow = commissioning_trajectory(MotionLimits(-1.2, 1.2, v_max=2.0, a_max=2.0))
    assert slow.reversals == 4  # 3 sweeps: >= 300 commands after both branches are covered


def test_jog_points_add_reversals_across_the_range() -> None:
    gap = 0.1
    traj = commissioning_trajectory(DEFAULT, gap_hint=gap, jog_points=4)
    assert traj.reversals == 3 + 2 * 4
    _assert_within(traj, DEFAULT, 100.0)
    # each jog turns back by 3 gap widths, at four places spread over the range
    step = np.diff(traj.u)
    moving = np.flatnonzero(step != 0.0)
    turns = moving[np.flatnonzero(np.diff(np.sign(step[moving])) != 0)] + 1
    assert turns.size == traj.reversals
    legs = np.abs(np.diff(traj.u[turns]))
    assert np.count_nonzero(np.isclose(legs, 3 * gap)) == 4
    jogged = traj.u[turns][:-1][np.isclose(legs, 3 * gap)]
    assert np.ptp(jogged) > 0.5 * DEFAULT.span


def test_the_memory_of_the_identifier_sees_every_region_both_ways() -> None:
    traj = commissioning_trajectory(DEFAULT)
    memory = RowMemory(capacity=1500, bins=16)
    u = np.repeat(traj.u, 10)  # 100 Hz commands held for ten 1 kHz readings
    breaks = np.zeros(u.size, dtype=bool)
    breaks[0] = True
    memory.add_series(u, u, breaks)
    cover = memory.coverage()
    assert cover.share("left") == cover.share("right") == 1.0
    assert np.all(cover.up > 0) and np.all(cover.down > 0)


def test_trajectory_rejects_motions_beyond_the_limits() -> None:
    limits = MotionLimits(0.0, 1.0, v_max=1.0, a_max=100.0)
    with pytest.raises(GenBacklashError, match="moves at 5 units/s; v_max is 1"):
        Trajectory(limits, 10.0, np.array([0.0, 0.5, 0.5]))
    stiff = MotionLimits(0.0, 1.0, v_max=1.0, a_max=5.0)
    with pytest.raises(GenBacklashError, match=r"accelerates at 10 units/s\^2; a_max is 5"):
        Trajectory(stiff, 10.0, np.array([0.0, 0.0, 0.1, 0.1]))
    with pytest.raises(GenBacklashError, match=r"outside the range \[0, 1\]"):
        Trajectory(limits, 10.0, np.array([0.0, -0.01]))
    with pytest.raises(GenBacklashError, match="NaN or infinite"):
        Trajectory(limits, 10.0, np.array([0.0, math.nan]))
    with pytest.raises(GenBacklashError, match=">= 2 commands"):
        Trajectory(limits, 10.0, np.array([0.0]))
    with pytest.raises(GenBacklashError, match="command_rate must be > 0"):
        Trajectory(limits, 0.0, np.array([0.0, 0.0]))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((1.0, 1.0, 1.0, 1.0), "low < high"),
        ((0.0, math.inf, 1.0, 1.0), "high must be finite"),
        ((0.0, 1.0, 0.0, 1.0), "v_max must be > 0"),
        ((0.0, 1.0, 1.0, -2.0), "a_max must be > 0"),
        ((0.0, 1.0, True, 1.0), "v_max must be a number"),
        ((0.0, "1", 1.0, 1.0), "high must be a number"),
    ],
)
def test_limits_are_validated(args: tuple[object, ...], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        MotionLimits(*args)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"gap_hint": 0.3}, r"too small for a gap of 0.3: it should hold at least 12 gap"),
        ({"gap_hint": -0.1}, "gap_hint must be > 0"),
        ({"start": 2.0}, r"start 2 lies outside the range \[-1.2, 1.2\]"),
        ({"sweeps": 0}, "sweeps must be a whole number >= 1"),
        ({"sweeps": 1.5}, "sweeps must be a whole number"),
        ({"jog_points": -1}, "jog_points must be a whole number >= 0"),
        ({"command_rate": 0.0}, "command_rate must be > 0"),
        ({"command_rate": math.nan}, "command_rate must be finite"),
    ],
)
def test_options_are_validated(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        commissioning_trajectory(DEFAULT, **kwargs)  # type: ignore[arg-type]


def test_unreasonable_limits_are_refused_with_the_reason() -> None:
    with pytest.raises(GenBacklashError, match=r"would take about .* raise v_max"):
        commissioning_trajectory(MotionLimits(0.0, 100.0, v_max=1e-3, a_max=1.0))
    with pytest.raises(GenBacklashError, match="float rounding alone"):
        commissioning_trajectory(MotionLimits(1e9, 1e9 + 1.0, v_max=1.0, a_max=1e-3))
    with pytest.raises(GenBacklashError, match="limits must be MotionLimits"):
        commissioning_trajectory((-1.0, 1.0, 1.0, 1.0))  # type: ignore[arg-type]


# --------------------------------------------------------------------------- convergence


@pytest.mark.parametrize("model", [OPERATION_BACKLASH, STRAIGHT_BACKLASH], ids=["op", "straight"])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_identifier_converges_within_the_motion(model: GeneralBacklash, seed: int) -> None:
    traj = commissioning_trajectory(DEFAULT)
    converged_at, error = verify(traj, model, seed)
    assert converged_at is not None
    assert converged_at < traj.duration
    assert error <= 0.02


def test_a_wider_play_converges_too_and_the_check_reports_the_estimate() -> None:
    traj = commissioning_trajectory(DEFAULT, gap_hint=0.2)  # 12 gap widths: just enough
    check = check_commissioning(traj, WIDE, seed=3)
    assert check.converged and check.state.value == "converged"
    assert check.model is not None
    assert abs(check.model.c_left - 0.1) < 0.01 and abs(check.model.c_right - 0.1) < 0.01
    assert check.nrmse <= 0.02
    assert check.rows > 0.9 * 10 * traj.u.size


def test_one_sweep_is_too_short_for_the_cold_start() -> None:
    traj = commissioning_trajectory(DEFAULT, sweeps=1)
    converged_at, error = verify(traj, OPERATION_BACKLASH, 0)
    assert converged_at is None and math.isinf(error)


def test_the_shape_can_be_checked_on_a_drivetrain_of_another_travel() -> None:
    traj = commissioning_trajectory(MotionLimits(0.0, 30.0, v_max=40.0, a_max=400.0))
    converged_at, error = verify(traj, OPERATION_BACKLASH, 0, travel=(-1.2, 1.2))
    assert converged_at is not None and error <= 0.02
    with pytest.raises(GenBacklashError, match="branches cross"):
        verify(traj, OPERATION_BACKLASH, 0)  # the model is no backlash over 0..30


def test_check_options_are_validated() -> None:
    traj = commissioning_trajectory(DEFAULT)
    with pytest.raises(GenBacklashError, match="trajectory must be a Trajectory"):
        check_commissioning(traj.u)  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="model must be a GeneralBacklash"):
        check_commissioning(traj, "model")  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="loss must lie in"):
        check_commissioning(traj, loss=1.0)
    with pytest.raises(GenBacklashError, match="encoder_rate must be at least"):
        check_commissioning(traj, encoder_rate=50.0)
    with pytest.raises(GenBacklashError, match="travel must be"):
        check_commissioning(traj, travel=(1.0, -1.0))
    with pytest.raises(GenBacklashError, match="seed must be"):
        check_commissioning(traj, seed=-1)
