"""The table inverse of a branch (``Branch.invert_fast``, ``invert_many``, the public
``branch_inverse``) against the root solve it replaces (``Branch.invert``): the same command
to within 1e-9 of the command range, on monotone and turning branches, in and out of reach;
and the compensator built on it against the same compensator on the root solve."""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from genbacklash_core import (
    CompensatorOptions,
    GenBacklashError,
    GeneralBacklash,
    InverseBacklash,
    branch_inverse,
    compensate,
    paper_example,
)
from genbacklash_core.inverse import branches as inverse_branches
from genbacklash_core.inverse.branches import Branch, inversion_plan

from .test_inverse import MODELS, _walk, monotone_models

EXACT = 1e-9  # of the command range


@st.composite
def any_models(draw: st.DrawFn) -> tuple[GeneralBacklash, float, float]:
    """Monotone models (test_inverse's) and branches that turn inside the range (degree 2
    and 3 with any middle coefficient): the inverse holds on the monotone piece."""
    if draw(st.booleans()):
        return draw(monotone_models())
    sign = draw(st.sampled_from([1.0, -1.0]))

    def branch() -> tuple[float, ...]:
        m1 = draw(st.floats(0.3, 2.0))
        rest = draw(st.lists(st.floats(-0.6, 0.6), min_size=1, max_size=2))
        return (sign * m1, *(sign * c for c in rest))

    c_left, c_right = draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0))
    low = -c_left - draw(st.floats(0.2, 4.0))
    high = c_right + draw(st.floats(0.2, 4.0))
    try:
        model = GeneralBacklash(branch(), c_left, branch(), c_right)
        inversion_plan(model, low, high)
    except GenBacklashError:
        assume(False)
    return model, low, high


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(any_models(), st.lists(st.floats(-6.0, 6.0), min_size=1, max_size=40), st.floats(-3, 3))
def test_property_table_inverse_is_the_root_solve(
    case: tuple[GeneralBacklash, float, float], targets: list[float], guess: float
) -> None:
    model, low, high = case
    plan = inversion_plan(model, low, high)
    span = high - low
    for branch in (plan.left, plan.right):
        solved = np.array([branch.invert(y, guess) for y in targets])
        fast = np.array([branch.invert_fast(y, guess) for y in targets])
        many = branch.invert_many(np.array(targets))
        assert np.all(np.abs(fast - solved) <= EXACT * span), (fast - solved, targets)
        assert np.all(np.abs(many - solved) <= EXACT * span), (many - solved, targets)
        assert np.all((branch.a <= fast) & (fast <= branch.b))


@pytest.mark.parametrize("name", list(MODELS))
def test_unbounded_pieces_and_targets_beyond_the_table(name: str) -> None:
    """Without output limits the pieces may be unbounded: the table covers part of them and
    the root solve the rest (far targets), with the same answers."""
    model = MODELS[name]
    plan = inversion_plan(model, -math.inf, math.inf)
    targets = np.concatenate((np.linspace(-3.0, 3.0, 301), [-1e6, -200.0, 150.0, 1e9]))
    for branch in (plan.up, plan.down):
        solved = np.array([branch.invert(y, 0.0) for y in targets.tolist()])
        fast = np.array([branch.invert_fast(y, 0.0) for y in targets.tolist()])
        scale = np.maximum(1.0, np.abs(solved))
        assert np.all(np.abs(fast - solved) <= EXACT * scale)
        assert np.all(np.abs(branch.invert_many(targets) - solved) <= EXACT * scale)


def test_a_table_is_built_once_and_only_for_curved_branches() -> None:
    model = paper_example(1).model
    plan = inversion_plan(model, -2.0, 2.0)
    assert plan.up.table is None
    plan.up.invert_fast(0.5, 0.0)
    table = plan.up.table
    assert table is not None and len(table.g_list) > 100
    assert np.all(np.diff(table.g) > 0)  # increasing, as bisection needs
    plan.up.invert_fast(0.6, 0.0)
    assert plan.up.table is table
    straight = inversion_plan(GeneralBacklash.ideal(1.0, 0.3, 0.5), -2.0, 2.0)
    assert straight.up.invert_fast(0.25, 0.0) == straight.up.invert(0.25, 0.0) == 0.75
    assert straight.up.table is None  # the closed form needs none


def test_the_polish_rejects_a_wrong_guess(monkeypatch: pytest.MonkeyPatch) -> None:
    """A table guess off by more than the tolerance goes to the root solve: the tolerance
    bites (a guess off by 1e-6 would otherwise be returned, 1e-6 of the range wrong)."""
    model = paper_example(1).model
    branch = inversion_plan(model, -2.0, 2.0).up
    want = branch.invert(0.4, 0.0)
    branch.invert_fast(0.4, 0.0)  # builds the table
    table = branch.table
    assert table is not None
    monkeypatch.setattr(type(table), "guess", lambda self, target: want + 1e-3)
    calls: list[float] = []
    original = Branch.invert

    def counting(self: Branch, y: float, guess: float) -> float:
        calls.append(guess)
        return original(self, y, guess)

    monkeypatch.setattr(Branch, "invert", counting)
    assert abs(branch.invert_fast(0.4, 0.0) - want) <= 1e-15
    assert calls == [want + 1e-3]  # the solve, from the table's guess


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(monotone_models(), st.integers(0, 2**32 - 1), st.integers(1, 300))
def test_property_compensator_on_the_table_is_the_compensator_on_the_solve(
    case: tuple[GeneralBacklash, float, float], seed: int, n: int
) -> None:
    model, low, high = case
    assume(model.branches_separated(low, high))
    options = CompensatorOptions(u_min=low, u_max=high, smoothing=seed % 3)
    x_d = _walk(seed, n, low, high)
    fast = compensate(model, x_d, options)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Branch, "invert_fast", Branch.invert)
        inverse_branches.inversion_plan.cache_clear()  # plans (and tables) built afresh
        solved = compensate(model, x_d, options)
    inverse_branches.inversion_plan.cache_clear()
    assert np.all(np.abs(fast - solved) <= EXACT * (high - low))


def test_branch_inverse_public_form() -> None:
    model = paper_example(1).model
    options = CompensatorOptions(u_min=-2.0, u_max=2.0)
    x = np.linspace(-1.0, 1.0, 12).reshape(3, 4)
    plan = inversion_plan(model, -2.0, 2.0)
    for push, branch in ((1, plan.up), (-1, plan.down)):
        u = branch_inverse(model, x, push, options)
        assert u.shape == x.shape
        want = np.array([branch.invert(v, 0.0) for v in x.ravel().tolist()]).reshape(x.shape)
        assert np.all(np.abs(u - want) <= EXACT * 4.0)
    lifted = branch_inverse(model, [0.3], +1, options)
    assert float(model.right(lifted)[0]) == pytest.approx(0.3, abs=1e-12)  # eq. (12)
    with pytest.raises(GenBacklashError, match="push must be"):
        branch_inverse(model, [0.3], 0)
    with pytest.raises(GenBacklashError, match="finite"):
        branch_inverse(model, [math.nan], 1)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(
    monotone_models(),
    st.lists(st.tuples(st.floats(-3.0, 3.0), st.integers(1, 6)), min_size=1, max_size=25),
    st.lists(st.integers(0, 60), max_size=4),
    st.sampled_from([0, 3]),
    st.sampled_from([math.inf, 0.05]),
    st.sampled_from([1.0, 0.35]),
)
def test_property_steps_over_dwells_are_the_steps_one_by_one(
    model_range: tuple[GeneralBacklash, float, float],
    dwells: list[tuple[float, int]],
    cuts: list[int],
    smoothing: int,
    max_rate: float,
    confidence: float,
) -> None:
    """``steps`` answers a dwell's repeated target from the step before when that step left
    the state as it was, also across calls: the commands and the state are those of
    ``step`` one by one (smoothing ramps, rate limits and gating included)."""
    model, low, high = model_range
    options = CompensatorOptions(smoothing=smoothing, max_rate=max_rate, valid_range=(low, high))
    targets = [value for value, count in dwells for _ in range(count)]
    one, two = InverseBacklash(model, options), InverseBacklash(model, options)
    expected = [one.step(x, confidence) for x in targets]
    got: list[float] = []
    for a, b in itertools.pairwise([0, *sorted(c for c in cuts if c < len(targets)), len(targets)]):
        got += two.steps(targets[a:b], confidence)
    assert got == expected
    assert two.state == one.state


def test_steps_forget_a_settled_step_when_the_model_or_state_changes() -> None:
    """A settled step is answered again only on the state and plan it was worked out on."""
    wide, narrow = GeneralBacklash.ideal(1.0, 0.5, 0.5), GeneralBacklash.ideal(1.0, 0.2, 0.2)
    comp, ref = InverseBacklash(wide), InverseBacklash(wide)
    assert comp.steps([1.0, 1.0]) == [ref.step(1.0), ref.step(1.0)] == [1.5, 1.5]
    comp.set_model(narrow)  # the same state, another plan: the command moves in to 1.2
    ref.set_model(narrow)
    assert comp.steps([1.0]) == [ref.step(1.0)] == [1.2]
    assert comp.steps([1.0]) == [1.2]
    comp.state = ref.state = InverseBacklash(narrow, x0=2.0, u0=2.0).state  # another state
    assert comp.steps([1.0]) == [ref.step(1.0)] == [0.8]


def test_steps_build_the_state_only_when_asked() -> None:
    """``steps`` keeps the state as plain numbers and builds the frozen snapshot only when
    :attr:`~InverseBacklash.state` is read (as ``step`` does): the same commands and state as
    ``step`` one by one, a dwell's repeats across calls and a ``step`` after them included."""
    model = GeneralBacklash.ideal(1.0, 0.5, 0.5)
    options = CompensatorOptions(smoothing=3, max_rate=0.05)
    comp, ref = InverseBacklash(model, options), InverseBacklash(model, options)
    targets = [0.2, 0.9, 0.9, 0.9, -0.4, -0.4, 0.1]
    got = comp.steps(targets[:4]) + comp.steps(targets[4:])
    assert comp._snapshot is None  # not built by the runs
    assert got == [ref.step(x) for x in targets]
    state = comp.state
    assert state == ref.state and comp.state is state  # built once, then kept
    assert comp.steps([0.1, 0.1]) == [ref.step(0.1), ref.step(0.1)]
    assert comp.step(0.1) == ref.step(0.1) and comp.step(0.7) == ref.step(0.7)
    assert comp.state == ref.state


def test_a_branch_with_no_usable_node_gives_an_empty_table() -> None:
    # found by hypothesis (test_fuzz::test_inverse_backlash): a branch whose values all
    # overflow left no node, and the table's rising filter raised an IndexError
    from genbacklash_core.inverse.branches import InverseTable

    class Overflowing:
        a, b, shift, sense = -1.0, 1.0, 0.0, 1.0

        def values_and_slopes(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return np.full(u.shape, np.inf), np.full(u.shape, np.nan)

    table = InverseTable(Overflowing())  # type: ignore[arg-type]
    assert table.g.size == 0
    assert math.isnan(table.guess(0.1))
    assert np.isnan(table.guesses(np.array([0.1]))).all()


def test_a_subnormal_slope_builds_the_table_without_an_overflow_warning() -> None:
    """The fuzz test's example (tests/core/test_fuzz.py::test_compensate_step): a branch whose
    slope is subnormal made 1 / slope overflow while the inverse's table was built (a
    RuntimeWarning, an error under the suite's filter); its step through there is infinite,
    as a zero slope's."""
    from genbacklash_core import GeneralBacklash, compensate_step
    from genbacklash_core.inverse import CompensatorState

    model = GeneralBacklash(m_left=(1.0, 0.0), c_left=1.0, m_right=(5e-324, 1e300), c_right=1.0)
    state = CompensatorState(0.0, 0.0, 1e300, 0, 0.0, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        u, after = compensate_step(model, state, 0.0, None, 0.0)
    assert math.isfinite(u) and math.isfinite(after.x)
