"""Simulation: the fast play-operator forms must equal the paper's per-sample loops."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from genbacklash_core import (
    Cascade,
    CascadeOutput,
    GenBacklashError,
    GeneralBacklash,
    LinearBlock,
    paper_example,
    simulate_backlash,
    simulate_backlash_loop,
    simulate_cascade,
    simulate_cascade_loop,
)
from genbacklash_core.simulate import switching_functions

from ._helpers import backlash_of

TOL = 1e-12

# model and the input amplitude on which its branches are separated
BACKLASH_MODELS = {
    "example1": (paper_example(1).model, 2.0),
    "example2-decreasing": (paper_example(2).model, 2.0),
    "example3-backlash": (backlash_of(paper_example(3).model), 1.0),
    "example4-backlash": (backlash_of(paper_example(4).model), 1.5),
    "ideal-increasing": (GeneralBacklash.ideal(0.8, 0.3, 0.5), 3.0),
    "ideal-decreasing": (GeneralBacklash.ideal(-1.3, 0.2, 0.1), 3.0),
    "degree1-unequal": (GeneralBacklash((1.0,), 0.3, (1.1,), 0.4), 3.0),
}


def _inputs(seed: int, n: int, u_max: float) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0, 0.1 * u_max, n))
    return {
        "uniform": rng.uniform(-u_max, u_max, n),
        "walk": np.clip(walk, -u_max, u_max),
        "sine": u_max * 0.95 * np.sin(np.linspace(0, 12 * np.pi, n)) + rng.normal(0, 0.01, n),
    }


@pytest.mark.parametrize("name", list(BACKLASH_MODELS))
@pytest.mark.parametrize("n", [100, 257, 5000])
@pytest.mark.parametrize("x0", [0.0, 0.3, -2.0])
def test_backlash_fast_equals_loop(name: str, n: int, x0: float) -> None:
    model, u_max = BACKLASH_MODELS[name]
    assert model.branches_separated(-u_max, u_max)
    for kind, u in _inputs(n, n, u_max).items():
        fast = simulate_backlash(model, u, x0)
        loop = simulate_backlash_loop(model, u, x0)
        np.testing.assert_allclose(fast, loop, rtol=0, atol=TOL, err_msg=f"{name} {kind}")
        np.testing.assert_array_equal(model.simulate(u, x0), fast)


@pytest.mark.parametrize("number", [1, 2, 3, 4])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_paper_example_data_equals_loop(number: int, seed: int) -> None:
    ex = paper_example(number)
    data = ex.generate(seed)
    if isinstance(ex.model, Cascade):
        out = simulate_cascade_loop(ex.model, data.u)
        np.testing.assert_allclose(data.y_clean, out.y, rtol=0, atol=TOL)
    else:
        np.testing.assert_allclose(
            data.y_clean, simulate_backlash_loop(ex.model, data.u), rtol=0, atol=TOL
        )
    assert data.noise_std == pytest.approx(np.std(data.y_clean) / ex.snr)


CASCADES = {
    "example3": paper_example(3).model,
    "example4": paper_example(4).model,
    "decreasing-fir": Cascade(paper_example(2).model, LinearBlock((1.0, 0.5, 0.25))),
    "ideal-first-order": Cascade(
        GeneralBacklash.ideal(1.0, 0.2, 0.2), LinearBlock((1.0,), (-0.9,))
    ),
    "degree3-third-order": Cascade(
        paper_example(1).model, LinearBlock((1.0, 0.2), (-0.6, 0.3, -0.05))
    ),
}


@pytest.mark.parametrize("name", list(CASCADES))
@pytest.mark.parametrize("n", [50, 300, 4000])
def test_cascade_fast_equals_loop(name: str, n: int) -> None:
    model = CASCADES[name]
    assert isinstance(model, Cascade)
    for seed, x0 in [(0, 0.0), (1, 0.4)]:
        rng = np.random.default_rng(seed)
        u = rng.uniform(-1.5, 1.5, n)
        fast = simulate_cascade(model, u, x0)
        loop = simulate_cascade_loop(model, u, x0)
        assert isinstance(fast, CascadeOutput)
        np.testing.assert_allclose(fast.x, loop.x, rtol=0, atol=TOL)
        np.testing.assert_allclose(fast.y, loop.y, rtol=0, atol=TOL)
        np.testing.assert_array_equal(model.simulate(u, x0), fast.y)


def test_cascade_starts_from_rest() -> None:
    model = paper_example(3).model
    y = simulate_cascade(model, np.full(10, 0.9), x0=0.0).y
    assert y[0] == 0.0  # y(0) only sees x(-1) = 0
    # rising from rest the output is pushed up by the right (lower) branch: x(0) = R(0.9)
    assert y[1] == pytest.approx(0.6 * 0.35 + 0.4 * 0.35**2 + 0.2 * 0.35**3, rel=1e-14)
    assert y[2] == pytest.approx(1.35 * y[1], rel=1e-14)  # x(1) + 0.15 x(0) + 0.2 y(1), x held


def test_hand_computed_degree3() -> None:
    # Example 1 from rest: rising u is pushed by the lower right branch R, falling u by the
    # upper left branch L, in between the output holds.
    model = paper_example(1).model
    u = np.array([2.0, 1.5, 0.0, -2.0, -1.0])
    r_2 = 0.6 * 1.2 + 0.4 * 1.2**2 + 0.2 * 1.2**3  # R(2) = 1.6416
    l_0 = 0.5 * 0.7 - 0.3 * 0.7**2 + 0.3 * 0.7**3  # L(0) = 0.3059
    l_m2 = 0.5 * -1.3 - 0.3 * 1.3**2 - 0.3 * 1.3**3  # L(-2) = -1.8161
    r_m1 = 0.6 * -1.8 + 0.4 * 1.8**2 - 0.2 * 1.8**3  # R(-1) = -0.9504
    expected = [r_2, r_2, l_0, l_m2, r_m1]
    np.testing.assert_allclose(expected, [1.6416, 1.6416, 0.3059, -1.8161, -0.9504], atol=1e-12)
    np.testing.assert_allclose(simulate_backlash(model, u), expected, rtol=1e-13)
    np.testing.assert_allclose(simulate_backlash_loop(model, u), expected, rtol=1e-13)


def test_switching_functions_decreasing() -> None:
    model = paper_example(2).model  # decreasing: L < R
    u = np.array([-1.0, 0.0, 1.0])
    x_prev = np.zeros(3)
    f1, f2 = switching_functions(model, u, x_prev)
    # L(-1) > 0 engages left; at 0 both branches are away from 0; R(1) < 0 engages right
    np.testing.assert_array_equal(f1, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(f2, [0.0, 0.0, 1.0])


@pytest.mark.parametrize("u", [np.zeros((10, 2)), np.zeros(())])
def test_input_must_be_one_dimensional(u: np.ndarray) -> None:
    model = paper_example(1).model
    with pytest.raises(GenBacklashError, match="the input must be one-dimensional"):
        simulate_backlash(model, u)
    with pytest.raises(GenBacklashError, match="the input must be one-dimensional"):
        simulate_backlash_loop(model, u)


# --------------------------------------------------------------------------- properties

_small = st.floats(min_value=-0.15, max_value=0.15, allow_nan=False)


@st.composite
def separated_models(draw: st.DrawFn) -> tuple[GeneralBacklash, float]:
    degree = draw(st.integers(1, 4))
    sign = draw(st.sampled_from([1.0, -1.0]))
    m_left = [draw(st.floats(0.2, 2.0))] + [draw(_small) for _ in range(degree - 1)]
    m_right = [draw(st.floats(0.2, 2.0))] + [draw(_small) for _ in range(degree - 1)]
    model = GeneralBacklash(
        tuple(sign * m for m in m_left),
        draw(st.floats(0.05, 1.0)),
        tuple(sign * m for m in m_right),
        draw(st.floats(0.05, 1.0)),
    )
    u_max = draw(st.floats(0.3, 3.0))
    return model, u_max


@settings(max_examples=250, deadline=None, derandomize=True, database=None)
@given(
    separated_models(),
    st.integers(0, 2**32 - 1),
    st.integers(1, 800),
    st.floats(-5.0, 5.0),
)
def test_property_output_between_branches(
    case: tuple[GeneralBacklash, float], seed: int, n: int, x0: float
) -> None:
    model, u_max = case
    assume(model.branches_separated(-u_max, u_max))
    rng = np.random.default_rng(seed)
    u = rng.uniform(-u_max, u_max, n)
    left, right = model.left(u), model.right(u)
    lo, hi = np.minimum(left, right), np.maximum(left, right)
    x = simulate_backlash(model, u, x0)
    # the clamp engages at the first sample at the latest, so this holds from t = 0
    assert np.all((lo <= x) & (x <= hi))
    x_loop = simulate_backlash_loop(model, u, x0)
    assert np.all((lo - TOL <= x_loop) & (x_loop <= hi + TOL))
    np.testing.assert_allclose(x, x_loop, rtol=0, atol=TOL)
    # the output only ever holds or sits on a branch
    previous = np.concatenate([[x0], x[:-1]])
    on_branch = np.isclose(x, left, rtol=0, atol=TOL) | np.isclose(x, right, rtol=0, atol=TOL)
    assert np.all(on_branch | (x == previous))
