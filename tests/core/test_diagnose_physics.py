"""The physical effects of diagnose (issue 23): coasting_load, compliant_coupling and
load_torque -- their recursions' limits, and known answers on records built to show each.

The records are drivetrain-shaped (point-to-point moves with dwells, a command held for 10
samples, a quantised reading with a little noise) and short, so each diagnosis takes seconds.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.diagnose import AugmentedModel, diagnose
from genbacklash_core.diagnose.effects import CATALOG
from genbacklash_core.diagnose.effects._physics import command_window
from genbacklash_core.diagnose.physics import PHYSICS_NAMES, LoadPhysics
from genbacklash_core.play import play_operator_loop

N = 3000
HOLD = 10  # samples a command is held (100 Hz commands, 1 kHz readings)
STEP = 2 * np.pi / 4096  # a 4096-count encoder
BACKLASH = GeneralBacklash.ideal(1.0, 0.032, 0.037)


def moves(seed: int, n: int = N) -> np.ndarray:
    """Point-to-point moves between random targets in (-1, 1) rad at 1-3 mrad per sample,
    dwells of 100-400 samples, every command held for :data:`HOLD` samples."""
    rng = np.random.default_rng(seed)
    out: list[float] = []
    position = 0.0
    while len(out) < n:
        target = float(rng.uniform(-1.0, 1.0))
        speed = float(rng.uniform(1e-3, 3e-3))
        steps = max(1, int(abs(target - position) / speed))
        out += list(np.linspace(position, target, steps + 1)[1:])
        out += [target] * int(rng.integers(100, 400))
        position = target
    smooth = np.asarray(out[:n])
    return np.repeat(smooth[::HOLD], HOLD)[:n]


def record(physics: LoadPhysics | None, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(u, y)``: the moves through the backlash with ``physics``, a quantised reading."""
    u = moves(seed)
    model = AugmentedModel(BACKLASH, physics=physics)
    rng = np.random.default_rng([seed, 1])
    y = model.simulate(u, y_start=0.0) + rng.normal(0.0, 2e-4, u.size)
    return u, np.round(y / STEP) * STEP


COASTING = LoadPhysics("coasting_load", retention=0.995, friction=2e-6, window=HOLD)
COMPLIANT = LoadPhysics("compliant_coupling", 0.9, 1e-6, HOLD, stiffness=0.13, damping=0.1)
# the physical effects and those that imitate them (a servo's dead time and lag before the
# play, a lag after it): the whole catalog takes a minute a record, these a few seconds
RIVALS = tuple(
    effect
    for effect in CATALOG
    if effect.name in (*PHYSICS_NAMES, "time_delay", "input_lag", "linear_dynamics")
)
TORQUE = LoadPhysics("load_torque", side=-1, region=(-0.5, 0.5), fall=0.004)


# --------------------------------------------------------------------------- the recursions


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    x0=st.floats(-2.0, 2.0),
    window=st.integers(1, 20),
    friction=st.floats(0.0, 1.0),
)
def test_no_retention_is_the_play_operator(
    seed: int, x0: float, window: int, friction: float
) -> None:
    rng = np.random.default_rng(seed)
    centre = np.cumsum(rng.normal(0.0, 0.1, 200))
    width = rng.uniform(0.0, 0.5, 200)
    lo, hi = centre - width, centre + width
    coast = LoadPhysics("coasting_load", 0.0, friction, window).simulate(lo, hi, x0)
    np.testing.assert_array_equal(coast, play_operator_loop(lo, hi, x0))
    # a load torque over a region the load never reaches changes nothing either
    far = LoadPhysics("load_torque", region=(100.0, 101.0), fall=0.1).simulate(lo, hi, x0)
    np.testing.assert_array_equal(far, play_operator_loop(lo, hi, x0))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    retention=st.floats(0.0, 1.0),
    friction=st.floats(0.0, 0.01),
    side=st.sampled_from([-1, 1]),
)
def test_the_load_stays_between_the_flanks(
    seed: int, retention: float, friction: float, side: int
) -> None:
    # a rigid contact (coasting, a torque) never lets the load leave the play's interval
    rng = np.random.default_rng(seed)
    centre = np.cumsum(rng.normal(0.0, 0.05, 300))
    width = rng.uniform(0.01, 0.3, 300)
    lo, hi = centre - width, centre + width
    for physics in (
        LoadPhysics("coasting_load", retention, friction, 5),
        LoadPhysics("load_torque", side=side, region=(-0.5, 0.5), fall=0.05),
    ):
        x = physics.simulate(lo, hi, float(centre[0]))
        assert np.all(x >= lo - 1e-12) and np.all(x <= hi + 1e-12)


def test_a_coasting_load_keeps_moving_and_a_torque_holds_its_flank() -> None:
    lo = np.concatenate([np.linspace(0.0, 1.0, 50), np.full(100, 1.0)])
    hi = lo + 0.2
    coast = LoadPhysics("coasting_load", retention=1.0, window=1).simulate(lo, hi, 0.0)
    assert coast[-1] == pytest.approx(1.2)  # coasted across the play to the far flank
    down = lo[::-1].copy()
    held = LoadPhysics("load_torque", side=-1, region=(-1.0, 2.0), fall=1.0)
    x = held.simulate(down, down + 0.2, 1.2)
    np.testing.assert_allclose(x, down)  # rides the lower flank down (the play never shows)


def restarted(
    physics: LoadPhysics, lo: np.ndarray, hi: np.ndarray, at: int, reading: float, mark: bool = True
) -> np.ndarray:
    """``physics`` on the bounds ``lo, hi`` restarted at sample ``at`` at ``reading``: the bounds
    pinned to it and, with ``mark``, the anchor marked (as ``ModelSpec.simulate`` restarts)."""
    anchors = np.zeros(lo.size, dtype=bool)
    anchors[at] = True
    pinned_lo, pinned_hi = lo.copy(), hi.copy()
    pinned_lo[at] = pinned_hi[at] = reading
    return physics.simulate(pinned_lo, pinned_hi, 0.0, anchors if mark else None)


def assert_shifted(free: np.ndarray, again: np.ndarray, at: int, shift: float) -> None:
    """``again`` is ``free`` up to sample ``at`` and ``shift`` higher from there on."""
    np.testing.assert_array_equal(again[:at], free[:at])
    np.testing.assert_allclose(again[at:], free[at:] + shift, rtol=0.0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    speed=st.floats(1e-3, 0.05),
    retention=st.floats(0.5, 1.0),
    friction=st.floats(0.0, 1e-3),
    window=st.integers(1, 12),
    at=st.integers(41, 199),
    shift=st.floats(0.0, 1.0),
)
def test_a_restart_moves_the_coasting_load_and_keeps_its_velocity(
    speed: float, retention: float, friction: float, window: int, at: int, shift: float
) -> None:
    # a flank pushes the load up for 40 samples and stops; the load coasts on in a wide
    # play. Restarted at a reading ``shift`` above where it would be, it moves on exactly as
    # before, ``shift`` higher: the anchor moves it and leaves its velocity alone (the former
    # rule treated the pinned bounds as a flank and gave the load the jump's velocity)
    lo = np.concatenate([speed * np.arange(1.0, 41.0), np.full(160, 40.0 * speed)])
    hi = lo + 100.0
    physics = LoadPhysics("coasting_load", retention, friction, window)
    free = physics.simulate(lo, hi, 0.0)
    assert_shifted(free, restarted(physics, lo, hi, at, free[at] + shift), at, shift)


def test_a_coasting_load_restarted_at_a_reading_moves_on_at_its_velocity() -> None:
    # the flank pushes the load up at 0.01 per sample for 50 samples, then stops; the load
    # coasts on (no friction) inside a wide play; a reading at sample 100 puts it at 2.0
    lo = np.concatenate([np.linspace(0.01, 0.5, 50), np.full(100, 0.5)])
    hi = lo + 5.0
    physics = LoadPhysics("coasting_load", retention=1.0, window=1)
    x = restarted(physics, lo, hi, 100, 2.0)
    np.testing.assert_allclose(x[100:], 2.0 + 0.01 * np.arange(50), atol=1e-12)
    # without the anchor mask the pinned bounds are a flank the load stops against: the
    # velocity it leaves with is its jump onto the reading, not the one it had
    as_flank = restarted(physics, lo, hi, 100, 2.0, mark=False)
    assert as_flank[101] - as_flank[100] != pytest.approx(0.01)


@settings(max_examples=40, deadline=None)
@given(
    speed=st.floats(1e-3, 0.05),
    stiffness=st.floats(0.05, 1.0),
    damping=st.floats(0.0, 0.7),
    retention=st.floats(0.5, 1.0),
    friction=st.floats(0.0, 1e-3),
    later=st.integers(1, 60),
    shift=st.floats(0.0, 1.0),
)
def test_a_restart_moves_the_springs_load_and_keeps_its_velocity(
    speed: float,
    stiffness: float,
    damping: float,
    retention: float,
    friction: float,
    later: int,
    shift: float,
) -> None:
    # the spring drags the load up behind a flank for 40 samples; the flank stops and the
    # load, once it is past it, coasts on in a wide play. Restarted there at a reading
    # ``shift`` above where it would be, it moves on exactly as before, ``shift`` higher
    # (the former rule read the pinned bounds as a flank: the spring pulled the load
    # towards the reading and gave it the pull's velocity)
    lo = np.concatenate([speed * np.arange(1.0, 41.0), np.full(260, 40.0 * speed)])
    hi = lo + 100.0
    physics = LoadPhysics("compliant_coupling", retention, friction, HOLD, stiffness, damping)
    free = physics.simulate(lo, hi, 0.0)
    behind = np.flatnonzero(free < lo)  # deflected: the spring still pulls
    at = max(41, int(behind[-1]) + 2 if behind.size else 0) + later
    assume(at < lo.size)
    assert_shifted(free, restarted(physics, lo, hi, at, free[at] + shift), at, shift)


def test_a_springs_load_restarted_at_a_reading_moves_on_at_its_velocity() -> None:
    # the spring drags the load up at 0.01 per sample, then the flank stops and the load
    # coasts on (no friction) inside a wide play; a reading at sample 200 puts it at 5.0
    lo = np.concatenate([np.linspace(0.01, 0.5, 50), np.full(250, 0.5)])
    hi = lo + 10.0
    physics = LoadPhysics("compliant_coupling", retention=1.0, stiffness=0.5, damping=0.5)
    free = physics.simulate(lo, hi, 0.0)
    velocity = free[199] - free[198]
    assert velocity > 0.0
    x = restarted(physics, lo, hi, 200, 5.0)
    np.testing.assert_allclose(x[200:], 5.0 + velocity * np.arange(100), atol=1e-12)
    # without the anchor mask the pinned bounds are a flank the spring pulls the load to:
    # it does not land on the reading, and leaves with the pull's velocity
    as_flank = restarted(physics, lo, hi, 200, 5.0, mark=False)
    assert as_flank[200] != pytest.approx(5.0)
    assert as_flank[202] - as_flank[201] != pytest.approx(velocity)


def test_a_torques_load_restarted_at_a_reading_takes_it() -> None:
    # the load torque has no velocity to keep: eq. (20)'s clamp onto the pinned bounds is its
    # restart, with or without the anchor mask
    lo = np.linspace(0.0, 1.0, 100)
    physics = LoadPhysics("load_torque", side=1, region=(-5.0, 5.0), fall=0.01)
    x = restarted(physics, lo, lo + 0.07, 60, 0.65)
    assert x[60] == 0.65
    np.testing.assert_array_equal(x, restarted(physics, lo, lo + 0.07, 60, 0.65, mark=False))


def test_load_physics_is_validated() -> None:
    with pytest.raises(GenBacklashError, match="unknown load physics"):
        LoadPhysics("gravity")  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="retention"):
        LoadPhysics("coasting_load", retention=1.5)
    with pytest.raises(GenBacklashError, match="stiffness"):
        LoadPhysics("compliant_coupling", stiffness=2.5)
    with pytest.raises(GenBacklashError, match="region"):
        LoadPhysics("load_torque", region=(1.0, 0.0))
    model = AugmentedModel(BACKLASH, physics=COMPLIANT)
    assert model.effects == ("compliant_coupling",)
    assert AugmentedModel.from_dict(model.to_dict()) == model


def test_the_command_window_is_its_hold_length() -> None:
    assert command_window(moves(0)) == HOLD
    assert command_window(np.arange(100.0)) == 1


# --------------------------------------------------------------------------- known answers


@pytest.mark.parametrize(
    ("physics", "seed"), [(COASTING, 1), (COMPLIANT, 6), (TORQUE, 3)], ids=PHYSICS_NAMES
)
def test_each_physical_effect_is_named_first_on_a_record_that_shows_it(
    physics: LoadPhysics, seed: int
) -> None:
    u, y = record(physics, seed)
    result = diagnose(u, y, catalog=RIVALS)
    assert result.steps, result.reason
    assert result.steps[0].effect == physics.kind, [s.evidence for s in result.steps]
    first = result.steps[0]
    assert first.gap_after < 0.6 * first.gap_before
    assert "%" in first.evidence  # the evidence carries its numbers


@pytest.mark.parametrize("seed", [4, 5])
def test_clean_backlash_names_no_physical_effect(seed: int) -> None:
    u, y = record(None, seed)
    result = diagnose(u, y, catalog=RIVALS)
    assert not set(result.effects) & set(PHYSICS_NAMES), [s.evidence for s in result.steps]
    detections = {d.effect: d for d in result.rounds[0].detections}
    if not detections:  # the ideal backlash already sits at the floor: nothing was asked
        assert "times the floor" in result.reason
    for name in PHYSICS_NAMES:
        assert name not in detections or not detections[name].fires, detections[name].evidence


def test_the_catalog_holds_the_physical_names() -> None:
    names = [effect.name for effect in CATALOG]
    assert names[-3:] == list(PHYSICS_NAMES)


def test_a_misfit_no_effect_explains_is_said_with_its_number() -> None:
    # the coasting record with a catalog that lacks its effect: nothing named, and the output
    # says how far above the floor the misfit stays instead of naming nothing silently
    u, y = record(COASTING, 1)
    result = diagnose(u, y, catalog=())
    assert result.steps == ()
    times = result.unexplained
    assert times is not None and times > 3.0
    text = result.unexplained_text()
    assert text.startswith("unexplained: the final misfit") and f"{times:.0f} times" in text
    assert result.to_dict()["unexplained"]["times_floor"] == pytest.approx(times)


# --------------------------------------------------------------------------- behind a servo


def servo_record(
    physics: LoadPhysics | None, seed: int, pole: float = 0.88
) -> tuple[np.ndarray, np.ndarray]:
    """``(u, y)`` as :func:`record`, the load behind a slow servo: two equal stages of pole
    ``pole`` (8 samples each: a critically damped 20 Hz position loop at 1 kHz) one sample
    late, then the play and ``physics``."""
    u = moves(seed)
    model = AugmentedModel(BACKLASH, delay=1, input_lag=pole, input_lag_order=2, physics=physics)
    rng = np.random.default_rng([seed, 2])
    y = model.simulate(u, y_start=0.0) + rng.normal(0.0, 2e-4, u.size)
    return u, np.round(y / STEP) * STEP


def test_a_physical_effect_behind_a_slow_servo_is_named_and_carries_the_servo() -> None:
    # a slow servo moves the load more than its spring does: fitted on the command alone the
    # spring explains less than the servo's lag, which was named in its place (issue 23,
    # the compliant drivetrain at 20 Hz); fitted behind the servo's lag, it is named first
    u, y = servo_record(COMPLIANT, 6)
    result = diagnose(u, y, catalog=RIVALS)
    assert result.steps, result.reason
    first = result.steps[0]
    assert first.effect == "compliant_coupling", [s.evidence for s in result.steps]
    assert first.model.input_lag > 0.0 and first.model.input_lag_order == 2
    assert first.gap_after < 0.5 * first.gap_before


def test_a_slow_servo_alone_gets_no_physical_name() -> None:
    # the physics fitted behind the servo's lag nests that lag: it must explain more than the
    # lag alone to be named
    u, y = servo_record(None, 4)
    result = diagnose(u, y, catalog=RIVALS)
    assert result.effects and result.effects[0] in ("input_lag", "time_delay"), result.reason
    assert not set(result.effects) & set(PHYSICS_NAMES), [s.evidence for s in result.steps]


def test_the_servo_lag_finds_a_fraction_of_a_sample_of_dead_time() -> None:
    # a servo whose dead time is 1.5 samples (a held command sampled between two readings):
    # whole samples fit it worse than the fraction does, and the BIC keeps the fraction
    u = moves(7)
    truth = AugmentedModel(
        BACKLASH, delay=1, input_lag=0.7, input_lag_order=2, input_lag_fraction=0.5
    )
    rng = np.random.default_rng([7, 3])
    y = np.round((truth.simulate(u, y_start=0.0) + rng.normal(0.0, 2e-4, u.size)) / STEP) * STEP
    lag = tuple(effect for effect in CATALOG if effect.name == "input_lag")
    result = diagnose(u, y, catalog=lag)
    assert result.effects == ("input_lag",), result.reason
    model = result.model
    assert model.input_lag_fraction > 0.0
    assert model.delay + model.input_lag_fraction == pytest.approx(1.5, abs=0.3)
    assert model.input_lag_order == 2
