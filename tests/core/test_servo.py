"""The servo model (a dead time and a first-order lag before the play) and its estimate."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.identify import identify_backlash
from genbacklash_core.play import play_operator
from genbacklash_core.servo import ServoModel, _Outputs, estimate_servo, servo_changes

MS = 1_000_000


def _reference(model: ServoModel, t: np.ndarray, u: np.ndarray, dt_ns: int = 1000) -> np.ndarray:
    """The lag integrated on a fine grid (exact per step: the target is held on the grid)."""
    change_t, change_v = servo_changes(t, u)
    grid = np.arange(int(t[0]) - dt_ns, int(t[-1]) + 1, dt_ns)
    k = np.searchsorted(change_t + model.dead_ns, grid, side="right") - 1
    target = change_v[np.maximum(k, 0)]
    x = np.empty(grid.size)
    x[0] = change_v[0]
    a = math.exp(-dt_ns / (model.time_constant * 1e9)) if model.time_constant else 0.0
    for i in range(1, grid.size):
        x[i] = target[i - 1] + (x[i - 1] - target[i - 1]) * a
    out: np.ndarray = np.interp(t, grid, x)
    return out


def _commands(seed: int, n: int = 4000, hold: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """1 kHz samples holding 100 Hz commands: smooth moves between random targets."""
    rng = np.random.default_rng(seed)
    steps = n // hold + 1
    targets = np.cumsum(rng.uniform(-1, 1, steps // 40 + 2))[np.arange(steps) // 40]
    path = np.convolve(targets, np.ones(8) / 8, mode="same") * 0.3
    u = np.repeat(path, hold)[:n]
    t = np.arange(n, dtype=np.int64) * MS + rng.integers(-50_000, 50_000, n)
    return np.sort(t), u


def test_a_step_through_dead_time_and_lag_is_exact() -> None:
    t = np.arange(20, dtype=np.int64) * MS
    u = np.where(np.arange(20) >= 5, 2.0, 0.0)  # a step of 2 at 5 ms
    x, _ = ServoModel(0.002, 0.004).output(t, u)
    want = np.where(t >= 7 * MS, 2.0 * (1 - np.exp(-(t - 7 * MS) / 4e6)), 0.0)
    np.testing.assert_allclose(x, want, rtol=0, atol=1e-15)


def test_no_servo_is_the_command() -> None:
    t, u = _commands(0, 500)
    x, _ = ServoModel().output(t, u)
    np.testing.assert_array_equal(x, u)
    assert ServoModel().is_identity


@pytest.mark.parametrize("dead, tau", [(0.0, 0.003), (0.0025, 0.0), (0.004, 0.007)])
def test_the_output_is_the_lag_integrated_on_a_fine_grid(dead: float, tau: float) -> None:
    t, u = _commands(1, 800)
    model = ServoModel(dead, tau)
    x, _ = model.output(t, u)
    np.testing.assert_allclose(x, _reference(model, t, u), atol=2e-3 * np.ptp(u))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    dead=st.floats(0.0, 0.02),
    tau=st.floats(0.0, 0.05),
    cuts=st.lists(st.integers(1, 399), max_size=6),
)
def test_a_stream_in_pieces_gives_the_same_output_to_the_bit(
    seed: int, dead: float, tau: float, cuts: list[int]
) -> None:
    t, u = _commands(seed, 400)
    model = ServoModel(dead, tau)
    whole, _ = model.output(t, u)
    state = None
    parts = []
    for piece in np.split(np.arange(t.size), sorted(set(cuts))):
        x, state = model.output(t[piece], u[piece], state)
        parts.append(x)
    np.testing.assert_array_equal(np.concatenate(parts), whole)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    servos=st.lists(
        st.tuples(
            st.one_of(st.just(0.0), st.floats(0.0, 0.6)),  # 0.6 s: events beyond the record
            st.one_of(st.just(0.0), st.just(5e-10), st.floats(0.0, 0.05)),
        ),
        min_size=1,
        max_size=6,
    ),
)
def test_the_estimate_s_candidate_outputs_are_output_s_to_the_bit(
    seed: int, servos: list[tuple[float, float]]
) -> None:
    """estimate_servo runs the lag's recursion once per time constant (_Outputs): every
    candidate's input is still what ServoModel.output gives, bit for bit."""
    t, u = _commands(seed, 400)
    outputs = _Outputs(t, u)
    for dead, tau in servos + [(dead + 0.001, tau) for dead, tau in servos]:
        model = ServoModel(dead, tau)
        np.testing.assert_array_equal(outputs(model), model.output(t, u)[0])
    empty = _Outputs(np.zeros(0, dtype=np.int64), np.zeros(0))
    assert empty(ServoModel(0.001, 0.002)).size == 0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), dead=st.floats(0.0, 0.02), tau=st.floats(0.0, 0.05))
def test_the_output_stays_within_the_commands_and_moves_toward_them(
    seed: int, dead: float, tau: float
) -> None:
    t, u = _commands(seed, 400)
    x, _ = ServoModel(dead, tau).output(t, u)
    assert x.min() >= u.min() - 1e-12 and x.max() <= u.max() + 1e-12
    # the output only ever moves toward the target in force (S1 is a convex combination)
    change_t, change_v = servo_changes(t, u)
    k = np.searchsorted(change_t + round(dead * 1e9), t, side="right") - 1
    target = change_v[np.maximum(k, 0)]
    step = np.diff(x)
    toward = target[1:] - x[:-1]
    same_target = k[1:] == k[:-1]
    assert np.all(step[same_target] * toward[same_target] >= -1e-12)


@pytest.mark.parametrize("bad", [-0.001, math.nan, math.inf, "0.1", True])
def test_a_bad_servo_is_refused_with_the_reason(bad: object) -> None:
    with pytest.raises(GenBacklashError, match="servo dead_time"):
        ServoModel(bad, 0.0)  # type: ignore[arg-type]


@pytest.mark.parametrize("dead, tau", [(0.0, 0.0), (0.003, 0.0), (0.002, 0.006), (0.0, 0.009)])
def test_the_servo_and_the_play_are_recovered_exactly_without_noise(
    dead: float, tau: float
) -> None:
    """Known answer: held commands through the servo, then a play operator. Exact to a
    tenth of the sample period (the stamps' jitter is 0.05 ms: with no lag a shift of the
    dead time below it moves no sample across a step)."""
    t, u = _commands(3, 6000)
    x, _ = ServoModel(dead, tau).output(t, u)
    c_left, c_right = 0.03, 0.04
    y = play_operator(x - c_right, x + c_left, x[0])  # eq. 8 with unit slopes
    fit = estimate_servo(t, u, y)
    assert fit.model.dead_time == pytest.approx(dead, abs=1e-4)
    assert fit.model.time_constant == pytest.approx(tau, abs=1e-4)
    assert fit.misfit <= fit.none_misfit
    xs, _ = fit.model.output(t, u)
    model = identify_backlash(xs, y, 1).model
    assert isinstance(model, GeneralBacklash)
    assert model.c_left + model.c_right == pytest.approx(c_left + c_right, rel=0.01)


def test_too_few_samples_say_why() -> None:
    t = np.arange(5, dtype=np.int64) * MS
    with pytest.raises(GenBacklashError, match="servo could not be estimated"):
        estimate_servo(t, np.zeros(5), np.zeros(5))
