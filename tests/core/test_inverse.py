"""Inverse-backlash compensator: exact inversion, gap behaviour, limits, gating, smoothing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from genbacklash_core import (
    Cascade,
    CompensatorOptions,
    CompensatorState,
    GenBacklashError,
    GeneralBacklash,
    InverseBacklash,
    LinearBlock,
    compensate,
    compensate_step,
    hold_interval,
    paper_example,
    simulate_backlash,
    simulate_backlash_loop,
    simulate_cascade,
)

from ._helpers import backlash_of

TOL = 1e-9
IDEAL = GeneralBacklash.ideal(1.0, 0.3, 0.5)  # gap c_L + c_R = 0.8
IDEAL_DECREASING = GeneralBacklash.ideal(-1.0, 0.3, 0.5)
EXAMPLE1 = paper_example(1).model
EXAMPLE2 = paper_example(2).model  # decreasing branches
MODELS = {
    "ideal": IDEAL,
    "ideal-decreasing": IDEAL_DECREASING,
    "example1": EXAMPLE1,
    "example2-decreasing": EXAMPLE2,
    "example4-backlash": backlash_of(paper_example(4).model),
    "degree1-unequal": GeneralBacklash((0.8,), 0.2, (1.3,), 0.4),
    # not monotone on the whole line: inverted on its monotone part only
    "degree2": GeneralBacklash((1.0, 0.5), 0.5, (1.0, 0.5), 0.5),
}


def _walk(seed: int, n: int, low: float, high: float) -> np.ndarray:
    """A desired path with ramps, reversals, holds (repeated samples) and jumps."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, 0.05 * (high - low), n)
    steps[rng.random(n) < 0.2] = 0.0  # hold
    jumps = rng.random(n) < 0.03
    steps[jumps] = rng.uniform(-0.5, 0.5, jumps.sum()) * (high - low)
    path = np.empty(n)
    x = 0.5 * (low + high)
    for t in range(n):
        x = min(max(x + steps[t], low), high)
        path[t] = x
    return path


def _branch_root(m: tuple[float, ...], y: float, s_low: float, s_high: float) -> float:
    """The one real ``s`` in ``(s_low, s_high)`` with ``sum_k m_k s^k = y`` (numpy's roots).

    An independent inverse of a branch in its shifted variable (``s = u + c_L`` for ``L``,
    ``s = u - c_R`` for ``R``, eqs. 11-12); fails unless exactly one root lies there.
    """
    roots = np.polynomial.polynomial.polyroots([-y, *m])
    real = [float(r.real) for r in roots if abs(r.imag) <= 1e-9 and s_low < r.real < s_high]
    assert len(real) == 1, (m, y, roots)
    return real[0]


def _left_inverse(model: GeneralBacklash, x: float) -> float:
    """``u`` with ``L(u) = x`` for a branch monotone on the whole line (``z_L`` of eq. 9)."""
    return _branch_root(model.m_left, x, -math.inf, math.inf) - model.c_left


def _right_inverse(model: GeneralBacklash, x: float) -> float:
    """``u`` with ``R(u) = x`` for a branch monotone on the whole line (``z_R`` of eq. 10)."""
    return _branch_root(model.m_right, x, -math.inf, math.inf) + model.c_right


# --------------------------------------------------------------------------- exact inverse


@st.composite
def monotone_models(draw: st.DrawFn) -> tuple[GeneralBacklash, float, float]:
    """A model with branches monotone on the whole line, and a range where they stay apart."""
    degree = draw(st.sampled_from([1, 3]))
    sign = draw(st.sampled_from([1.0, -1.0]))

    def branch() -> tuple[float, ...]:
        m1 = draw(st.floats(0.3, 2.0))
        if degree == 1:
            return (sign * m1,)
        m3 = draw(st.floats(0.02, 0.5))
        m2 = draw(st.floats(-0.9, 0.9)) * math.sqrt(3.0 * m1 * m3)  # m2^2 < 3 m1 m3
        return (sign * m1, sign * m2, sign * m3)

    c_left, c_right = draw(st.floats(0.05, 1.0)), draw(st.floats(0.05, 1.0))
    model = GeneralBacklash(branch(), c_left, branch(), c_right)
    low = -c_left - draw(st.floats(0.2, 2.0))
    high = c_right + draw(st.floats(0.2, 2.0))
    return model, low, high


def _reachable(model: GeneralBacklash, low: float, high: float) -> tuple[float, float]:
    """Outputs both branches reach on [low, high] (monotone branches: values at the ends)."""
    ends = np.array([low, high])
    left, right = model.left(ends), model.right(ends)
    return max(left.min(), right.min()), min(left.max(), right.max())


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(monotone_models(), st.integers(0, 2**32 - 1), st.integers(1, 400))
def test_property_inverse_after_forward_is_identity(
    case: tuple[GeneralBacklash, float, float], seed: int, n: int
) -> None:
    model, low, high = case
    assume(model.branches_separated(low, high))
    reach_low, reach_high = _reachable(model, low, high)
    margin = 0.01 * (reach_high - reach_low)
    assume(margin > 0)
    x_d = _walk(seed, n, reach_low + margin, reach_high - margin)
    options = CompensatorOptions(u_min=low, u_max=high)
    u = compensate(model, x_d, options)
    assert np.all((low <= u) & (u <= high))
    x = simulate_backlash(model, u, x0=0.0)  # the default start state is at rest at x = 0
    np.testing.assert_allclose(x, x_d, rtol=0, atol=TOL)
    np.testing.assert_allclose(simulate_backlash_loop(model, u, 0.0), x_d, rtol=0, atol=TOL)


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("x0", [0.0, 0.25, -0.3])
def test_inverse_after_forward_on_known_models(name: str, x0: float) -> None:
    model = MODELS[name]
    state = CompensatorState.initial(model, x0=x0)
    x_d = _walk(7, 600, 0.0, 0.9) if name == "degree2" else _walk(7, 600, -0.9, 0.9)
    u = compensate(model, x_d, state=state)
    np.testing.assert_allclose(simulate_backlash(model, u, x0), x_d, rtol=0, atol=TOL)


def test_default_start_is_at_rest_at_zero_in_the_middle_of_the_gap() -> None:
    state = CompensatorState.initial(IDEAL)
    assert state == CompensatorState(x=0.0, u=0.1, u_inverse=0.1)  # middle of [-0.3, 0.5]
    assert compensate(IDEAL, [0.0, 0.0]).tolist() == [0.1, 0.1]


def test_hold_interval_is_where_the_branches_meet_the_output() -> None:
    # eqs. (9)-(10): L(z_L) = R(z_R) = x
    assert hold_interval(IDEAL, 1.0) == pytest.approx((0.7, 1.5), abs=1e-15)
    assert hold_interval(IDEAL_DECREASING, 1.0) == pytest.approx((-1.3, -0.5), abs=1e-15)
    for model in (EXAMPLE1, EXAMPLE2):
        z_left, z_right = hold_interval(model, 0.4)
        assert z_left < z_right
        assert float(model.left(z_left)) == pytest.approx(0.4, abs=1e-14)
        assert float(model.right(z_right)) == pytest.approx(0.4, abs=1e-14)


def test_out_of_reach_uses_the_end_of_the_monotone_part() -> None:
    model = MODELS["degree2"]  # L(u) = s + s^2/2, s = u + 0.5: increasing for u > -1.5
    assert hold_interval(model, -3.0)[0] == pytest.approx(-1.5, abs=1e-12)
    options = CompensatorOptions(u_min=-1.0, u_max=2.0)
    u = compensate(model, [1.0, 100.0, 100.0, -100.0], options)
    assert u.tolist() == [pytest.approx(0.5 + math.sqrt(3.0) - 1.0), 2.0, 2.0, -1.0]


# Branches with two increasing pieces each (B' has two real roots), yet L - R = 2/3 + u^2/2 > 0
# on the whole line: L(u) = B_L(u + 2) with B_L(s) = s - 3s^2/4 + s^3/6, B_L' = (s-1)(s-2)/2,
# increasing for s < 1 and s > 2; R(u) = B_R(u - 2) with B_R(s) = -B_L(-s), increasing for
# s < -2 and s > -1. The zero crossings (anchors) sit at u = -2 (left) and u = +2 (right).
TWO_PIECES = GeneralBacklash((1.0, -0.75, 1.0 / 6.0), 2.0, (1.0, 0.75, 1.0 / 6.0), 2.0)


def test_two_piece_model_is_a_valid_backlash() -> None:
    """Pin the premise of the piece tests: the branches of ``TWO_PIECES`` never meet and each
    has a local maximum and minimum (B_L(1) = 5/12, B_L(2) = 1/3), so ``B_L(s) = 3/8`` has
    three solutions, one on each monotone stretch: ``6 B_L(s) - 9/4 = (s - 3/2)(s^2 - 3s + 3/2)``.
    """
    u = np.linspace(-6.0, 6.0, 241)
    gap = TWO_PIECES.left(u) - TWO_PIECES.right(u)
    np.testing.assert_allclose(gap, 2.0 / 3.0 + 0.5 * u**2, rtol=0, atol=1e-12)
    roots = np.polynomial.polynomial.polyroots([-0.375, *TWO_PIECES.m_left])
    assert np.all(np.abs(roots.imag) < 1e-9)
    expected = [(3.0 - math.sqrt(3.0)) / 2.0, 1.5, (3.0 + math.sqrt(3.0)) / 2.0]
    assert sorted(roots.real.tolist()) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(
    ("x", "z_left", "z_right"),
    [
        (-1.0, "root", 1.0),  # R reaches only (-5/12, inf) on s > -1: its end u = -1 + 2
        (-0.375, "root", "root"),
        (0.0, "root", "root"),
        (0.3, "root", "root"),
        (0.36, "root", "root"),
        (0.375, "root", "root"),
        (0.4, "root", "root"),
        (1.0, -1.0, "root"),  # L reaches only (-inf, 5/12) on s < 1: its end u = 1 - 2
    ],
)
def test_inversion_uses_the_monotone_piece_holding_the_anchor(
    x: float, z_left: float | str, z_right: float | str
) -> None:
    """Pin the piece choice on the whole line: each branch is inverted on its increasing
    piece that holds its zero crossing ``u = -c_L`` (left: ``s < 1``) or ``u = c_R`` (right:
    ``s > -1``), never on the other increasing piece (left ``s > 2``, right ``s < -2``), even
    where that piece also reaches ``x`` (``x = 0.36, 0.375``: three solutions of ``L = x``).
    The expected ends are numpy's roots restricted to the anchor's piece, or that piece's end
    where it does not reach ``x``.
    """
    if z_left == "root":
        z_left = _branch_root(TWO_PIECES.m_left, x, -math.inf, 1.0) - TWO_PIECES.c_left
    if z_right == "root":
        z_right = _branch_root(TWO_PIECES.m_right, x, -1.0, math.inf) + TWO_PIECES.c_right
    assert hold_interval(TWO_PIECES, x) == pytest.approx((z_left, z_right), abs=1e-12)


def test_compensator_inverts_on_the_anchor_pieces() -> None:
    """Pin the commands of the compensator on ``TWO_PIECES``: a push up solves ``R(u) = x_d``
    on ``s > -1``, a push down ``L(u) = x_d`` on ``s < 1`` (known answers from numpy roots),
    a hold keeps the command; the forward model then reproduces the path.
    """
    x_d = [0.2, 0.375, 0.375, 0.36, 0.36, 0.4, 0.0, -0.5]
    u = compensate(TWO_PIECES, x_d)

    def up(x: float) -> float:
        return _branch_root(TWO_PIECES.m_right, x, -1.0, math.inf) + TWO_PIECES.c_right

    def down(x: float) -> float:
        return _branch_root(TWO_PIECES.m_left, x, -math.inf, 1.0) - TWO_PIECES.c_left

    expected = [up(0.2), up(0.375), up(0.375), down(0.36), down(0.36)]
    expected += [up(0.4), down(0.0), down(-0.5)]
    np.testing.assert_allclose(u, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(simulate_backlash(TWO_PIECES, u), x_d, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("x", "z_left", "z_right"),
    [
        (0.375, "root", 1.5),  # R only reaches [-5/12, -1/3] on its piece: its upper end
        (0.35, "root", 1.5),
        (0.0, -1.5, 1.5),  # out of reach of both pieces: L below, R above
        (-0.35, -1.5, "root"),
        (-0.4, -1.5, "root"),
    ],
)
def test_anchor_outside_the_range_uses_the_nearest_piece(
    x: float, z_left: float | str, z_right: float | str
) -> None:
    """Pin the piece nearest the anchor when the anchor lies outside the inversion range.

    On ``[-1.5, 1.5]`` the left branch (anchor ``u = -2``) is increasing on ``[-1.5, -1]``
    (``s`` in ``[0.5, 1]``, distance 0.5) and ``[0, 1.5]`` (distance 2): the first is used.
    The right branch (anchor ``u = 2``) is increasing on ``[-1.5, 0]`` (distance 2) and
    ``[1, 1.5]`` (distance 0.5): the second is used. Targets the piece does not reach give
    its end; the others are numpy's roots on that piece.
    """
    options = CompensatorOptions(valid_range=(-1.5, 1.5))
    if z_left == "root":
        z_left = _branch_root(TWO_PIECES.m_left, x, 0.5, 1.0) - TWO_PIECES.c_left
    if z_right == "root":
        z_right = _branch_root(TWO_PIECES.m_right, x, -1.0, -0.5) + TWO_PIECES.c_right
    assert hold_interval(TWO_PIECES, x, options) == pytest.approx((z_left, z_right), abs=1e-12)


# --------------------------------------------------------------------------- the gap


def test_hold_in_gap_keeps_the_command() -> None:
    state = CompensatorState.initial(IDEAL, x0=0.2, u0=0.1)  # 0.1 in the hold interval
    u = compensate(IDEAL, [0.2] * 5, state=state)
    assert u.tolist() == [0.1] * 5
    # after a push the command stays where the push left it
    u = compensate(IDEAL, [0.5, 0.7, 0.7, 0.7, 0.7])
    np.testing.assert_allclose(u, [1.0, 1.2, 1.2, 1.2, 1.2], rtol=0, atol=1e-15)
    assert len(set(u[1:].tolist())) == 1


@pytest.mark.parametrize("model", [EXAMPLE1, EXAMPLE2], ids=["increasing", "decreasing"])
@pytest.mark.parametrize(
    ("path", "lifted"),
    [([0.1, 0.25, 0.4], True), ([0.3, 0.7, 0.55, 0.4], False)],
    ids=["held-after-push-up", "held-after-push-down"],
)
def test_set_model_while_holding_moves_the_command_to_the_nearest_edge(
    model: GeneralBacklash, path: list[float], lifted: bool
) -> None:
    """Pin the hold-case correction after :meth:`InverseBacklash.set_model`, both branches.

    The load is held at ``x = 0.4`` with the command on the edge of the old hold interval the
    last push left it at. A new model with narrower dead zones (``c_L, c_R = 0.5, 0.6``
    instead of 0.7, 0.8) puts that command outside its hold interval ``[z_L, z_R]`` (eqs.
    9-10): kept, it would move the load. The next hold sample must send the *nearest* edge
    of the new interval - ``z_R`` after a push up and ``z_L`` after a push down for
    increasing branches, the other way round for decreasing ones - so the load stays put.
    Edges are numpy's roots of the new branches.
    """
    narrower = GeneralBacklash(model.m_left, 0.5, model.m_right, 0.6)
    comp = InverseBacklash(model)
    for target in path:
        held = comp.step(target)
    assert comp.state.x == pytest.approx(0.4, abs=1e-12)
    # the old inverse: the lifting branch after a push up, the lowering one after a push down
    old_edge = (
        _right_inverse(model, 0.4) if lifted == model.increasing else _left_inverse(model, 0.4)
    )
    assert held == pytest.approx(old_edge, abs=1e-12)

    z_left, z_right = _left_inverse(narrower, 0.4), _right_inverse(narrower, 0.4)
    low, high = min(z_left, z_right), max(z_left, z_right)
    assert not low <= held <= high  # the old command would move the load under the new model
    nearest = low if abs(held - low) < abs(held - high) else high
    # after a push up the command sits beyond the lifting edge, after a push down below ...
    assert nearest == (high if lifted == model.increasing else low)
    assert nearest == (z_right if lifted == model.increasing else z_left)

    comp.set_model(narrower)
    sent = [comp.step(0.4) for _ in range(3)]
    np.testing.assert_allclose(sent, nearest, rtol=0, atol=1e-12)
    assert comp.state.x == pytest.approx(0.4, abs=1e-12)
    np.testing.assert_allclose(simulate_backlash(narrower, sent, 0.4), 0.4, rtol=0, atol=1e-12)


@pytest.mark.parametrize("model", [IDEAL, IDEAL_DECREASING], ids=["increasing", "decreasing"])
def test_reversal_jumps_across_the_gap(model: GeneralBacklash) -> None:
    up = np.linspace(0.0, 1.0, 11)
    x_d = np.concatenate([up, up[-2::-1]])  # up to 1.0, then back down in steps of 0.1
    u = compensate(model, x_d, state=CompensatorState.initial(model, u0=0.0))
    steps = np.diff(u)
    jump = steps[10]  # the step at the reversal
    assert abs(jump) == pytest.approx(0.3 + 0.5 + 0.1, abs=1e-12)  # c_L + c_R + path step
    assert np.sign(jump) == -np.sign(steps[9])
    np.testing.assert_allclose(np.abs(steps[11:]), 0.1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(simulate_backlash(model, u), x_d, rtol=0, atol=1e-12)


def test_non_finite_target_holds_the_previous_command() -> None:
    x_d = [0.2, 0.5, math.nan, math.inf, -math.inf, 0.5, 0.1]
    u = compensate(EXAMPLE1, x_d)
    assert np.all(np.isfinite(u))
    assert u[2] == u[3] == u[4] == u[1] == u[5]
    x = simulate_backlash(EXAMPLE1, u)
    np.testing.assert_allclose(x[[0, 1, 5, 6]], [0.2, 0.5, 0.5, 0.1], rtol=0, atol=TOL)


def test_state_tracks_the_modelled_output_under_the_sent_command() -> None:
    options = CompensatorOptions(u_min=-1.0, u_max=1.0, max_rate=0.2, smoothing=2)
    comp = InverseBacklash(EXAMPLE1, options)
    x_d = _walk(3, 300, -0.8, 0.8)
    confidence = np.random.default_rng(3).uniform(0.0, 1.0, x_d.size)
    sent, modelled = [], []
    for target, trust in zip(x_d, confidence, strict=True):
        sent.append(comp.step(target, trust))
        modelled.append(comp.state.x)
    # bit for bit what the forward model does with the commands sent
    np.testing.assert_array_equal(simulate_backlash(EXAMPLE1, sent), modelled)


# --------------------------------------------------------------------------- limits


_any_float = st.floats(allow_nan=True, allow_infinity=True)


@st.composite
def any_options(draw: st.DrawFn) -> CompensatorOptions:
    u_min = draw(st.one_of(st.just(-math.inf), st.floats(-5.0, 1.0)))
    u_max = draw(st.one_of(st.just(math.inf), st.floats(1.5, 5.0)))
    gate_low = draw(st.floats(0.0, 1.0))
    return CompensatorOptions(
        u_min=u_min,
        u_max=u_max,
        max_rate=draw(st.one_of(st.just(math.inf), st.floats(1e-3, 2.0))),
        smoothing=draw(st.integers(0, 6)),
        gate_low=gate_low,
        gate_high=draw(st.floats(gate_low, 1.0)),
    )


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(
    st.sampled_from(list(MODELS)),
    any_options(),
    st.lists(
        st.one_of(st.floats(-3.0, 3.0), _any_float, st.sampled_from([1e300, -1e300])),
        min_size=1,
        max_size=60,
    ),
    st.lists(st.one_of(st.floats(0.0, 1.0), _any_float), min_size=1, max_size=60),
)
def test_property_limits_rate_and_finite_always_hold(
    name: str, options: CompensatorOptions, x_d: list[float], confidence: list[float]
) -> None:
    model = MODELS[name]
    n = min(len(x_d), len(confidence))
    state = CompensatorState.initial(model, options=options)
    u = compensate(model, x_d[:n], options, confidence[:n], state=state)
    assert np.all(np.isfinite(u))
    assert np.all((options.u_min <= u) & (u <= options.u_max))
    with np.errstate(over="ignore"):  # commands near +-1.8e308 apart: an infinite step
        steps = np.abs(np.diff(np.concatenate([[state.u], u])))
    assert np.all(steps <= options.max_rate)


def test_a_jump_beyond_the_float_range_is_taken_at_once() -> None:
    """Gap-crossing smoothing ramps a jump from the last command; a jump from +2.7e301 to
    -1.8e308 overflows, and is then taken at once rather than ramping a NaN (hypothesis found
    it with another seed)."""
    options = CompensatorOptions(smoothing=1, gate_low=0.0, gate_high=0.0)
    u = compensate(IDEAL, [2.7390461837125416e301, -1.7976928609576974e308], options, [0.0, 0.0])
    assert np.all(np.isfinite(u))


def test_rate_limit_bounds_the_gap_crossing() -> None:
    options = CompensatorOptions(max_rate=0.1)
    x_d = [0.5] * 5 + [0.4] * 12
    u = compensate(IDEAL, x_d, options, state=CompensatorState.initial(IDEAL, x0=0.5, u0=1.0))
    assert np.all(np.abs(np.diff(u)) <= 0.1)
    assert u[-1] == pytest.approx(0.1)  # L(u) = u + 0.3 = 0.4 reached after ~9 samples
    assert simulate_backlash(IDEAL, u, 0.5)[-1] == pytest.approx(0.4)


# --------------------------------------------------------------------------- gating


def test_confidence_zero_passes_through_and_one_inverts() -> None:
    x_d = _walk(11, 200, -0.8, 0.8)
    np.testing.assert_array_equal(compensate(EXAMPLE1, x_d, confidence=0.0), x_d)
    np.testing.assert_array_equal(compensate(EXAMPLE1, x_d, confidence=math.nan), x_d)
    np.testing.assert_array_equal(
        compensate(EXAMPLE1, x_d, confidence=1.0), compensate(EXAMPLE1, x_d)
    )
    gated = CompensatorOptions(gate_low=0.3, gate_high=0.6)
    np.testing.assert_array_equal(compensate(EXAMPLE1, x_d, gated, confidence=0.3), x_d)
    np.testing.assert_array_equal(
        compensate(EXAMPLE1, x_d, gated, confidence=0.6), compensate(EXAMPLE1, x_d)
    )


def test_gating_fades_monotonically() -> None:
    options = CompensatorOptions(gate_low=0.2, gate_high=0.8)
    confidences = np.linspace(0.0, 1.0, 41)
    assert np.all(np.diff([options.weight(c) for c in confidences]) >= 0.0)
    x_d = _walk(5, 50, -0.8, 0.8)
    state = CompensatorState.initial(EXAMPLE1)
    for target in x_d:
        full, _ = compensate_step(EXAMPLE1, state, target, options, 1.0)
        commands = [compensate_step(EXAMPLE1, state, target, options, c)[0] for c in confidences]
        steps = np.diff(commands) * np.sign(full - target)
        assert np.all(steps >= -1e-15)  # from x_d towards the full inverse, never back
        assert commands[0] == target
        assert commands[-1] == full
        _, state = compensate_step(EXAMPLE1, state, target, options, 1.0)


@pytest.mark.parametrize(
    ("gate_low", "gate_high"), [(0.2, 0.8), (0.0, 1.0), (0.45, 0.55), (0.5, 1.0)]
)
@pytest.mark.parametrize("target", [0.4, -0.4], ids=["push-up", "push-down"])
def test_gating_is_the_linear_fade_between_the_thresholds(
    gate_low: float, gate_high: float, target: float
) -> None:
    """Pin the gating formula at several confidences, not only its monotonicity.

    ``w = clip((c - gate_low) / (gate_high - gate_low), 0, 1)`` and the command
    ``u = x_d + w (u_inverse - x_d)``, with the exact inverse from numpy's roots (``R`` for a
    push up from rest at 0, ``L`` for a push down). The state keeps the ungated inverse and the
    modelled output under the command actually sent.
    """
    options = CompensatorOptions(gate_low=gate_low, gate_high=gate_high)
    span = gate_high - gate_low
    fractions = np.array([-0.5, 0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0, 1.5])
    confidences = np.clip(gate_low + fractions * span, 0.0, 1.0)
    model = backlash_of(EXAMPLE1)
    state = CompensatorState.initial(model)  # at rest at x = 0
    exact = _right_inverse(model, target) if target > 0 else _left_inverse(model, target)
    for confidence in confidences.tolist():
        w = min(max((confidence - gate_low) / span, 0.0), 1.0)
        assert options.weight(confidence) == pytest.approx(w, rel=0, abs=1e-15)
        u, after = compensate_step(model, state, target, options, confidence)
        assert u == pytest.approx(target + w * (exact - target), rel=0, abs=1e-12)
        assert after.u_inverse == pytest.approx(exact, rel=0, abs=1e-12)
        assert after.x == simulate_backlash(model, [u], 0.0)[0]


def test_step_gate_when_thresholds_are_equal() -> None:
    options = CompensatorOptions(gate_low=0.5, gate_high=0.5)
    assert [options.weight(c) for c in (0.0, 0.49, 0.5, 1.0)] == [0.0, 0.0, 1.0, 1.0]


# --------------------------------------------------------------------------- smoothing


@pytest.mark.parametrize("samples", [1, 3, 5])
def test_smoothing_spreads_the_jump_then_catches_up(samples: int) -> None:
    x_d = np.concatenate([np.linspace(0.1, 1.0, 10), np.linspace(0.99, 0.8, 20)])
    start = CompensatorState(x=0.0, u=0.5, u_inverse=0.5, direction=1)  # pushing up already
    instant = compensate(IDEAL, x_d, state=start)
    smooth = compensate(IDEAL, x_d, CompensatorOptions(smoothing=samples), state=start)
    r = 10  # the reversal sample
    np.testing.assert_array_equal(smooth[:r], instant[:r])
    jump = instant[r] - instant[r - 1]  # gap + path step, delivered in `samples` parts
    for j in range(samples):
        expected = instant[r + j] - jump * (samples - 1 - j) / samples
        assert smooth[r + j] == pytest.approx(expected, abs=1e-12)
    np.testing.assert_allclose(smooth[r + samples :], instant[r + samples :], rtol=0, atol=1e-12)
    # the load holds while the gap is crossed, then follows x_d again
    x = simulate_backlash(IDEAL, smooth, 0.0)
    np.testing.assert_allclose(x[r + samples - 1 :], x_d[r + samples - 1 :], rtol=0, atol=1e-12)
    assert np.all(x[r : r + samples - 1] == x[r - 1])


def test_smoothing_restarts_on_a_reversal_mid_ramp() -> None:
    options = CompensatorOptions(smoothing=4)
    x_d = [0.5, 0.6, 0.5, 0.6, 0.6, 0.6, 0.6, 0.6, 0.6]
    u = compensate(IDEAL, x_d, options, state=CompensatorState.initial(IDEAL, 0.4, 0.9))
    assert np.all(np.isfinite(u))
    assert u[-1] == pytest.approx(1.1)  # R(u) = u - 0.5 = 0.6 after the ramps are done
    assert simulate_backlash(IDEAL, u, 0.4)[-1] == pytest.approx(0.6)


def test_reversal_mid_ramp_jumps_from_the_last_smoothed_command() -> None:
    """Pin the command offset at a reversal during a smoothing ramp (ideal backlash).

    ``L(u) = u + 0.3``, ``R(u) = u - 0.5``, smoothing 4. A push down at sample 1 starts a ramp
    across the gap; at sample 3, two samples into it, the path turns up again. The new ramp
    must start from the last smoothed command (0.15, here also the one sent: no gating or
    limits), not from the inverse -0.3 the old ramp was heading for: the jump is
    ``D = R^-1(0.2) - 0.15 = 0.7 - 0.15 = 0.55``, delivered in quarters, so the command goes
    *up* by 0.1375 at once and reaches the exact inverse 0.7 at sample 6. The load holds at
    0.1 throughout (every command lies in its hold interval ``[-0.2, 0.6]``).
    """
    options = CompensatorOptions(smoothing=4)
    start = CompensatorState(x=0.0, u=0.5, u_inverse=0.5, direction=1)  # pushing up at R = 0
    x_d = [0.1, 0.0, 0.0, 0.2, 0.2, 0.2, 0.2, 0.3]
    comp = InverseBacklash(IDEAL, options)
    comp.state = start
    u, offsets = [], []
    for target in x_d:
        u.append(comp.step(target))
        offsets.append(comp.state.offset)
    down_jump = (0.0 - 0.3) - 0.6  # L^-1(0) - last command: -0.9
    up_jump = (0.2 + 0.5) - (-0.3 - down_jump * 2 / 4)  # R^-1(0.2) - 0.15: 0.55
    expected = [
        0.1 + 0.5,  # R^-1(0.1), no reversal
        -0.3 - down_jump * 3 / 4,  # 0.375
        -0.3 - down_jump * 2 / 4,  # 0.15
        0.7 - up_jump * 3 / 4,  # 0.2875: the reversal mid-ramp
        0.7 - up_jump * 2 / 4,
        0.7 - up_jump * 1 / 4,
        0.7,
        0.3 + 0.5,
    ]
    np.testing.assert_allclose(u, expected, rtol=0, atol=1e-12)
    assert u[3] - u[2] == pytest.approx(0.1375, abs=1e-12)  # up, by a quarter of 0.55
    # offset = inverse - command: what is left of the jump (negative crossing down, positive up)
    np.testing.assert_allclose(
        offsets, [0.0, -0.675, -0.45, 0.4125, 0.275, 0.1375, 0.0, 0.0], rtol=0, atol=1e-12
    )
    x = simulate_backlash(IDEAL, u, 0.0)
    np.testing.assert_allclose(x, [0.1] * 6 + [0.2, 0.3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("model", [EXAMPLE1, EXAMPLE2], ids=["increasing", "decreasing"])
def test_reversal_mid_ramp_on_curved_branches(model: GeneralBacklash) -> None:
    """Pin the size and sign of the jump at a reversal mid-ramp for curved branches.

    Path up to 0.2, down to 0.15 (a ramp of 4 samples starts), then up to 0.25 one sample
    later. At that reversal the command moves from the last one sent a quarter of the way to
    the new exact inverse ``v`` (the lifting branch at 0.25, from numpy's roots: ``R`` for
    increasing branches, ``L`` for decreasing ones) - upwards for increasing branches,
    downwards for decreasing ones - then ``v - D (3 - j) / 4`` until it is exact.
    """
    lift = _right_inverse if model.increasing else _left_inverse
    start_u = lift(model, 0.0)
    options = CompensatorOptions(smoothing=4)
    comp = InverseBacklash(model, options)
    comp.state = CompensatorState(x=0.0, u=start_u, u_inverse=start_u, direction=1)
    x_d = [0.1, 0.2, 0.15, 0.15, 0.25, 0.25, 0.25, 0.25, 0.25]
    u = [comp.step(target) for target in x_d]
    x = simulate_backlash(model, u, 0.0)
    assert x[3] == pytest.approx(0.2, abs=1e-12)  # the load held while the ramp ran
    r = 4  # the reversal mid-ramp
    v = lift(model, 0.25)
    jump = v - u[r - 1]
    assert np.sign(u[r] - u[r - 1]) == model.sign == np.sign(jump)
    for j in range(4):
        assert u[r + j] == pytest.approx(v - jump * (3 - j) / 4, abs=1e-12)
    np.testing.assert_allclose(x[r : r + 3], 0.2, rtol=0, atol=1e-12)
    assert x[-1] == pytest.approx(0.25, abs=1e-12)


# --------------------------------------------------------------------------- two forms


def test_pure_and_stateful_forms_agree_with_a_model_change() -> None:
    options = CompensatorOptions(u_min=-1.5, u_max=1.5, max_rate=0.3, smoothing=3, gate_low=0.2)
    x_d = _walk(21, 400, -0.8, 0.8)
    x_d[[50, 51, 200]] = [math.nan, math.inf, math.nan]
    confidence = np.random.default_rng(21).uniform(0.0, 1.0, x_d.size)
    second = GeneralBacklash((0.55, -0.25, 0.3), 0.6, (0.65, 0.35, 0.2), 0.7)
    switch = 230

    comp = InverseBacklash(EXAMPLE1, options)
    stateful = [comp.step(x_d[t], confidence[t]) for t in range(switch)]
    comp.set_model(second)
    stateful += [comp.step(x_d[t], confidence[t]) for t in range(switch, x_d.size)]

    state = CompensatorState.initial(EXAMPLE1, options=options)
    pure = []
    for t in range(x_d.size):
        model = EXAMPLE1 if t < switch else second
        u, state = compensate_step(model, state, x_d[t], options, confidence[t])
        pure.append(u)
    assert pure == stateful
    assert comp.state == state

    # the vector forms are the same loop
    first = compensate(EXAMPLE1, x_d[:switch], options, confidence[:switch])
    np.testing.assert_array_equal(first, stateful[:switch])
    comp.set_model(EXAMPLE1)
    comp.reset()
    np.testing.assert_array_equal(comp.run(x_d[:switch], confidence[:switch]), first)


def test_held_targets_give_the_pure_steps_bit_for_bit() -> None:
    """A held target on a settled state is not recomputed by ``step``: still the pure
    function's commands and states to the bit, the zero's sign, a new confidence, a state
    assigned and a new model each stepping again."""
    options = CompensatorOptions(u_min=-1.5, u_max=1.5, max_rate=0.3, smoothing=3, gate_low=0.2)
    held = np.repeat(_walk(5, 60, -0.8, 0.8), 7)  # dwells of seven equal targets
    x_d = [*held.tolist(), *([0.0] * 10), *([-0.0] * 5), *([0.0] * 3)]
    confidence = [1.0] * len(x_d)
    confidence[100:110] = [0.5] * 5 + [0.0] * 5  # changed mid-dwell: the fade steps again
    confidence[-18:] = [0.0] * 18  # passed through: the command is the target, its zero too
    second = GeneralBacklash((0.55, -0.25, 0.3), 0.6, (0.65, 0.35, 0.2), 0.7)
    switch, saved_at = 230, 300

    comp = InverseBacklash(EXAMPLE1, options)
    state = CompensatorState.initial(EXAMPLE1, options=options)
    saved = state
    sent = []
    for t, (target, trust) in enumerate(zip(x_d, confidence, strict=True)):
        if t == switch:
            comp.set_model(second)
        if t == saved_at:  # back to an earlier state mid-dwell
            comp.state = state = saved
        model = EXAMPLE1 if t < switch else second
        u, state = compensate_step(model, state, target, options, trust)
        got = comp.step(target, trust)
        assert got.hex() == u.hex(), t  # the zero's sign too
        assert comp.state == state, t
        sent.append(got.hex())
        if t == saved_at - 20:
            saved = state
    assert sent[-9:] == ["0x0.0p+0"] * 1 + ["-0x0.0p+0"] * 5 + ["0x0.0p+0"] * 3


def test_steps_unread_then_the_state_and_a_run_continue_as_the_pure_form() -> None:
    """The state a step leaves is built only when read: steps with no read, then the state,
    a run and steps again are the pure function's, a held dwell included."""
    options = CompensatorOptions(max_rate=0.3, smoothing=2)
    x_d = np.repeat(_walk(8, 40, -0.8, 0.8), 4)
    comp = InverseBacklash(EXAMPLE1, options)
    state = CompensatorState.initial(EXAMPLE1, options=options)
    expected, states = [], []
    for target in x_d:
        u, state = compensate_step(EXAMPLE1, state, target, options)
        expected.append(u)
        states.append(state)
    got = [comp.step(target) for target in x_d[:100]]
    assert comp.state == states[99]
    np.testing.assert_array_equal(comp.run(x_d[100:130]), expected[100:130])
    got += expected[100:130]
    got += [comp.step(target) for target in x_d[130:]]
    assert got == expected
    assert comp.state == state
    comp.state = comp.state  # the same snapshot back: nothing changes
    assert comp.step(x_d[-1]) == compensate_step(EXAMPLE1, state, x_d[-1], options)[0]


def test_stateful_reset_and_state_assignment() -> None:
    comp = InverseBacklash(IDEAL, x0=0.2, u0=0.0)
    assert comp.state == CompensatorState(x=0.2, u=0.0, u_inverse=0.0)
    saved = comp.state
    first = [comp.step(v) for v in (0.5, 0.6, 0.3)]
    comp.state = saved
    assert [comp.step(v) for v in (0.5, 0.6, 0.3)] == first
    comp.reset(x0=0.2, u0=0.0)
    assert comp.state == saved
    assert comp.model is IDEAL
    assert comp.options == CompensatorOptions()


def test_set_model_keeps_the_old_model_when_the_new_one_is_rejected() -> None:
    bad = MODELS["degree2"]  # decreasing left of u = -1.5: no increasing part on the range
    with pytest.raises(GenBacklashError, match=r"not increasing anywhere on the inversion"):
        InverseBacklash(bad, CompensatorOptions(valid_range=(-6.0, -4.0)))
    comp2 = InverseBacklash(IDEAL, CompensatorOptions(valid_range=(-6.0, -4.0)))
    with pytest.raises(GenBacklashError, match=r"left branch is not increasing"):
        comp2.set_model(bad)
    assert comp2.model is IDEAL
    assert comp2.step(0.3) == -4.0  # out of reach on the range: its end


# --------------------------------------------------------------------------- cascade


def test_cascade_inverts_only_its_backlash() -> None:
    cascade = paper_example(3).model
    assert isinstance(cascade, Cascade)
    x_d = _walk(4, 300, -0.5, 0.5)
    u = compensate(cascade, x_d)
    np.testing.assert_array_equal(u, compensate(cascade.backlash, x_d))
    np.testing.assert_allclose(simulate_cascade(cascade, u).x, x_d, rtol=0, atol=TOL)
    comp = InverseBacklash(Cascade(IDEAL, LinearBlock(a=(1.0, 0.3), b=(-0.5,))))
    assert [comp.step(v) for v in (0.5, 0.2)] == compensate(IDEAL, [0.5, 0.2]).tolist()


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"u_min": 1.0, "u_max": 1.0}, r"need u_min < u_max, got u_min=1.0 and u_max=1.0"),
        ({"u_min": math.nan}, r"u_min must not be NaN"),
        ({"u_max": "3"}, r"u_max must be a real number"),
        ({"max_rate": 0.0}, r"max_rate must be > 0"),
        ({"max_rate": -1.0}, r"max_rate must be > 0"),
        ({"smoothing": -1}, r"smoothing must be >= 0 samples"),
        ({"smoothing": 1.5}, r"smoothing must be a whole number"),
        ({"gate_low": -0.1}, r"gate_low and gate_high must lie in \[0, 1\]"),
        ({"gate_high": 1.5}, r"must lie in \[0, 1\], got 0.2 and 1.5"),
        ({"gate_low": 0.8, "gate_high": 0.2}, r"need gate_low <= gate_high"),
        ({"valid_range": (1.0, 0.0)}, r"valid_range needs low < high"),
        ({"valid_range": (1.0,)}, r"valid_range must be a pair"),
        ({"valid_range": (0.0, math.nan)}, r"valid_range\[1\] must not be NaN"),
        (
            {"u_min": -1.0, "u_max": 1.0, "valid_range": (2.0, 3.0)},
            r"does not overlap the output limits",
        ),
    ],
)
def test_invalid_options_are_rejected(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        CompensatorOptions(**kwargs)  # type: ignore[arg-type]


def test_valid_range_is_intersected_with_the_limits() -> None:
    options = CompensatorOptions(u_min=-1.0, u_max=1.0, valid_range=(-0.5, 3.0))
    assert options.inversion_range == (-0.5, 1.0)
    # the command stays inside the valid range where the target is out of its reach
    assert compensate(IDEAL, [-5.0], options).tolist() == [-0.5]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"x": math.nan}, r"state x must be finite"),
        ({"u": math.inf}, r"state u must be finite"),
        ({"u_inverse": "a"}, r"u_inverse must be a real number"),
        ({"direction": 2}, r"direction must be -1, 0 or \+1"),
        ({"direction": 0.5}, r"direction must be a whole number"),
        ({"ramp": -1}, r"ramp must be >= 0"),
    ],
)
def test_invalid_state_is_rejected(kwargs: dict[str, object], message: str) -> None:
    args: dict[str, object] = {"x": 0.0, "u": 0.0, "u_inverse": 0.0}
    args.update(kwargs)
    with pytest.raises(GenBacklashError, match=message):
        CompensatorState(**args)  # type: ignore[arg-type]


def test_bad_calls_are_rejected() -> None:
    state = CompensatorState.initial(IDEAL)
    with pytest.raises(GenBacklashError, match=r"model must be a GeneralBacklash or a Cascade"):
        compensate("model", [0.0])  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match=r"options must be CompensatorOptions"):
        compensate(IDEAL, [0.0], {"u_min": 0.0})  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match=r"x_d must be one-dimensional"):
        compensate(IDEAL, [[0.0, 1.0]])
    with pytest.raises(GenBacklashError, match=r"confidence of shape \(3,\) does not fit"):
        compensate(IDEAL, [0.0, 1.0], confidence=[1.0, 1.0, 1.0])
    with pytest.raises(GenBacklashError, match=r"state must be a CompensatorState"):
        compensate_step(IDEAL, None, 0.0)  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match=r"x_d must be a number"):
        compensate_step(IDEAL, state, "up")  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match=r"u0 must be finite and within \[-1.0, 1.0\]"):
        CompensatorState.initial(IDEAL, u0=2.0, options=CompensatorOptions(u_min=-1, u_max=1))
    with pytest.raises(GenBacklashError, match=r"x0 must be finite"):
        InverseBacklash(IDEAL, x0=math.inf)
    with pytest.raises(GenBacklashError, match=r"state must be a CompensatorState"):
        InverseBacklash(IDEAL).state = 1.0  # type: ignore[assignment]
