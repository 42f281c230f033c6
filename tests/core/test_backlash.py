"""GeneralBacklash: validation, parameter round trips, branch geometry, the ideal backlash."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import GenBacklashError, GeneralBacklash, paper_example
from genbacklash_core.structure import Structure

from ._helpers import backlash_of, eq1_ideal
from .test_inverse import monotone_models

EXAMPLE1 = GeneralBacklash((0.5, -0.3, 0.3), 0.7, (0.6, 0.4, 0.2), 0.8)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"c_left": 0.0}, r"c_left must be > 0"),
        ({"c_left": -0.2}, r"c_left must be > 0"),
        ({"c_right": 0.0}, r"c_right must be > 0"),
        ({"c_right": -1e-9}, r"c_right must be > 0"),
        ({"c_left": math.inf}, r"c_left must be a finite number"),
        ({"c_right": math.nan}, r"c_right must be a finite number"),
        ({"c_left": None}, r"c_left must be a finite number"),
        ({"c_right": "0.5"}, r"c_right must be a finite number"),
        ({"m_left": (0.0, 0.1)}, r"m_left\[0\] and m_right\[0\] must be nonzero"),
        ({"m_right": (0.0, 0.1)}, r"must be nonzero, got 1.0 and 0.0"),
        ({"m_left": (-1.0, 0.1)}, r"same monotonic sense"),
        ({"m_right": (-0.5, 0.0)}, r"different signs"),
        ({"m_left": (1.0,)}, r"same degree: m_left has 1 coefficients, m_right 2"),
        ({"m_right": (1.0, 0.1, 0.2)}, r"same degree: m_left has 2 coefficients, m_right 3"),
        ({"m_left": (1.0, math.nan)}, r"m_left must be finite"),
        ({"m_right": (1.0, -math.inf)}, r"m_right must be finite"),
        ({"m_left": ()}, r"m_left must hold at least one coefficient"),
        ({"m_right": ("a", 1.0)}, r"m_right must be a sequence of numbers"),
    ],
)
def test_invalid_backlash_is_rejected(kwargs: dict[str, object], message: str) -> None:
    args: dict[str, object] = {
        "m_left": (1.0, 0.1),
        "c_left": 0.5,
        "m_right": (1.0, 0.1),
        "c_right": 0.5,
    }
    args.update(kwargs)
    with pytest.raises(GenBacklashError, match=message):
        GeneralBacklash(**args)  # type: ignore[arg-type]


def test_errors_are_value_errors() -> None:
    with pytest.raises(ValueError, match="c_left must be > 0"):
        GeneralBacklash((1.0,), 0.0, (1.0,), 1.0)


def test_valid_backlash_normalises_types() -> None:
    bl = GeneralBacklash([1, 2], 1, np.array([3.0, 4.0]), 0.5)
    assert bl.m_left == (1.0, 2.0)
    assert bl.m_right == (3.0, 4.0)
    assert isinstance(bl.c_left, float)
    assert bl.degree == 2
    assert bl.increasing
    assert bl.sign == 1.0


def test_decreasing_backlash_properties() -> None:
    bl = paper_example(2).model
    assert isinstance(bl, GeneralBacklash)
    assert not bl.increasing
    assert bl.sign == -1.0


def test_numpy_integer_dead_zone_is_accepted() -> None:
    bl = GeneralBacklash((1.0,), np.int64(1), (1.0,), np.int64(2))
    assert (bl.c_left, bl.c_right) == (1.0, 2.0)


# --------------------------------------------------------------------------- parameters


@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_parameters_round_trip_paper_examples(number: int) -> None:
    bl = backlash_of(paper_example(number).model)
    again = GeneralBacklash.from_parameters(bl.parameters(), bl.degree)
    assert again == bl
    np.testing.assert_array_equal(again.parameters(), bl.parameters())


def test_parameters_order_and_names() -> None:
    np.testing.assert_array_equal(EXAMPLE1.parameters(), [0.5, -0.3, 0.3, 0.7, 0.6, 0.4, 0.2, 0.8])
    assert EXAMPLE1.parameter_names == (
        "m_left_1",
        "m_left_2",
        "m_left_3",
        "c_left",
        "m_right_1",
        "m_right_2",
        "m_right_3",
        "c_right",
    )
    assert Structure.of(EXAMPLE1).names() == EXAMPLE1.parameter_names


@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_parameters_round_trip_random(degree: int) -> None:
    rng = np.random.default_rng(degree)
    for _ in range(20):
        sign = rng.choice([-1.0, 1.0])
        m_left = np.concatenate([[sign * rng.uniform(0.1, 2.0)], rng.normal(0, 0.5, degree - 1)])
        m_right = np.concatenate([[sign * rng.uniform(0.1, 2.0)], rng.normal(0, 0.5, degree - 1)])
        bl = GeneralBacklash(
            tuple(m_left), rng.uniform(0.01, 1), tuple(m_right), rng.uniform(0.01, 1)
        )
        assert GeneralBacklash.from_parameters(bl.parameters(), degree) == bl


@pytest.mark.parametrize("values", [[1.0, 0.5, 1.0], np.ones(5), np.ones((2, 2))])
def test_from_parameters_wrong_length(values: object) -> None:
    with pytest.raises(GenBacklashError, match=r"expected 4 parameters for degree 1"):
        GeneralBacklash.from_parameters(values, 1)  # type: ignore[arg-type]


def test_from_parameters_validates() -> None:
    with pytest.raises(GenBacklashError, match="c_right must be > 0"):
        GeneralBacklash.from_parameters([1.0, 0.5, 1.0, -0.5], 1)


def test_theta_eq23_example1() -> None:
    # [m_L1, m_L1 c_L, m_L2, m_L3, m_R1, m_R1 c_R, m_R2, m_R3]
    np.testing.assert_allclose(
        EXAMPLE1.theta(), [0.5, 0.35, -0.3, 0.3, 0.6, 0.48, 0.4, 0.2], rtol=0, atol=1e-15
    )


@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_theta_round_trip(number: int) -> None:
    bl = backlash_of(paper_example(number).model)
    structure = Structure.of(bl)
    theta = bl.theta()
    assert theta.shape == (2 * bl.degree + 2,)
    np.testing.assert_allclose(structure.from_theta(theta), bl.parameters(), rtol=1e-14)


def test_theta_round_trip_degree1() -> None:
    bl = GeneralBacklash.ideal(-0.8, 0.25, 0.4)
    np.testing.assert_allclose(bl.theta(), [-0.8, -0.2, -0.8, -0.32])
    np.testing.assert_allclose(Structure.of(bl).from_theta(bl.theta()), bl.parameters())


def test_from_theta_rejects_vanishing_slope() -> None:
    with pytest.raises(GenBacklashError, match="slope m_1 vanished"):
        Structure(1).from_theta(np.array([0.0, 0.1, 1.0, 0.1]))


# --------------------------------------------------------------------------- branches


def test_branch_values_example1() -> None:
    # L(0) = 0.5*0.7 - 0.3*0.7**2 + 0.3*0.7**3 ; R(0) = 0.6*(-0.8) + 0.4*0.64 + 0.2*(-0.512)
    assert float(EXAMPLE1.left(np.array([0.0]))[0]) == pytest.approx(0.3059, abs=1e-12)
    assert float(EXAMPLE1.right(np.array([0.0]))[0]) == pytest.approx(-0.3264, abs=1e-12)
    # the branches cross the u axis at -c_L and +c_R
    assert float(EXAMPLE1.left(-0.7)) == pytest.approx(0.0, abs=1e-15)
    assert float(EXAMPLE1.right(0.8)) == pytest.approx(0.0, abs=1e-15)
    u = np.linspace(-2, 2, 11)
    left_direct = sum(m * (u + 0.7) ** i for i, m in enumerate((0.5, -0.3, 0.3), 1))
    right_direct = sum(m * (u - 0.8) ** i for i, m in enumerate((0.6, 0.4, 0.2), 1))
    np.testing.assert_allclose(EXAMPLE1.left(u), left_direct, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(EXAMPLE1.right(u), right_direct, rtol=1e-13, atol=1e-14)


def test_branch_difference_polynomial() -> None:
    u = np.linspace(-3, 3, 13)
    np.testing.assert_allclose(
        EXAMPLE1.branch_difference()(u), EXAMPLE1.left(u) - EXAMPLE1.right(u), atol=1e-12
    )


@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_paper_examples_are_separated_on_their_input_range(number: int) -> None:
    ex = paper_example(number)
    assert ex.backlash.branches_separated(-ex.u_max, ex.u_max)
    assert ex.backlash.crossings(-ex.u_max, ex.u_max) == ()


def test_example1_separated_and_ordered_on_minus2_2() -> None:
    assert EXAMPLE1.branches_separated(-2.0, 2.0)
    u = np.linspace(-2, 2, 4001)
    assert np.all(EXAMPLE1.left(u) > EXAMPLE1.right(u))  # increasing: L is the upper branch


def test_example1_crossing_outside_paper_range_is_found() -> None:
    # L - R for Example 1 has a real root near u = -4.0486 (outside |u| < 2)
    # (the start -5 is reported too: the branches are in the wrong order there)
    found = EXAMPLE1.crossings(-5.0, 2.0)
    assert len(found) == 2
    assert found[0] == -5.0
    root = found[1]
    assert -4.06 < root < -4.04
    assert abs(float(EXAMPLE1.left(root) - EXAMPLE1.right(root))) < 1e-9
    assert not EXAMPLE1.branches_separated(-5.0, 2.0)
    # below the root the branches are in the wrong order (L < R)
    assert float(EXAMPLE1.left(-4.5)) < float(EXAMPLE1.right(-4.5))


def test_linear_crossing_found_with_end_point() -> None:
    # L - R = (u + 0.1) - 2 (u - 0.1) = 0.3 - u: meet at 0.3, wrong order on (0.3, 2]
    bl = GeneralBacklash((1.0,), 0.1, (2.0,), 0.1)
    found = bl.crossings(-2.0, 2.0)
    assert found == pytest.approx((0.3, 2.0))
    assert not bl.branches_separated(-2.0, 2.0)
    assert bl.branches_separated(-2.0, 0.29)
    assert bl.crossings(0.5, 1.0) == (0.5, 1.0)  # wrong order on the whole range


def test_decreasing_crossing_uses_branch_sense() -> None:
    # decreasing: valid while L < R; L - R = u - 0.3
    bl = GeneralBacklash((-1.0,), 0.1, (-2.0,), 0.1)
    assert bl.branches_separated(-2.0, 0.29)
    assert bl.crossings(-2.0, 2.0) == pytest.approx((0.3, 2.0))


def test_tangent_branches_touch() -> None:
    # L - R = 0.5 (u - 1.5)^2: the branches touch (double root) at u = 1.5
    bl = GeneralBacklash((1.0, -0.5), 0.5, (1.0, -1.0), 0.5)
    assert float(bl.left(1.5)) == pytest.approx(float(bl.right(1.5)), abs=1e-12)
    found = bl.crossings(-2.0, 2.0)
    assert found
    assert all(abs(c - 1.5) < 1e-6 for c in found)
    assert not bl.branches_separated(-2.0, 2.0)
    assert bl.branches_separated(-2.0, 1.4)


def test_parallel_lines_are_separated_everywhere() -> None:
    # L - R = (u + 0.5) - (u - 0.5) = 1: a constant gap
    bl = GeneralBacklash((1.0, 0.0), 0.5, (1.0, 0.0), 0.5)
    assert bl.branches_separated(-100.0, 100.0)


@pytest.mark.parametrize(("u_min", "u_max"), [(1.0, 1.0), (2.0, -2.0)])
def test_crossings_needs_ordered_range(u_min: float, u_max: float) -> None:
    with pytest.raises(GenBacklashError, match="need u_min < u_max"):
        EXAMPLE1.crossings(u_min, u_max)


# --------------------------------------------------------------------------- ideal backlash


def test_ideal_is_degree_one() -> None:
    bl = GeneralBacklash.ideal(2.0, 0.5, 0.25)
    assert bl.degree == 1
    assert bl.m_left == bl.m_right == (2.0,)
    assert (bl.c_left, bl.c_right) == (0.5, 0.25)


def test_ideal_matches_eq1_hand_computed() -> None:
    # L(u) = 2 (u + 0.5), R(u) = 2 (u - 0.25), x(-1) = 0
    bl = GeneralBacklash.ideal(2.0, 0.5, 0.25)
    u = np.array([0.0, 1.0, 0.5, 0.2, -1.0, -0.4, 0.3, 0.3])
    expected = [0.0, 1.5, 1.5, 1.4, -1.0, -1.0, 0.1, 0.1]
    np.testing.assert_allclose(bl.simulate(u), expected, rtol=0, atol=1e-12)


def test_ideal_decreasing_matches_eq1_hand_computed() -> None:
    # L(u) = -(u + 0.5), R(u) = -(u - 0.5): the output falls when u rises past the gap
    bl = GeneralBacklash.ideal(-1.0, 0.5, 0.5)
    u = np.array([1.0, 0.2, -1.0, 0.0, 2.0])
    expected = [-0.5, -0.5, 0.5, 0.5, -1.5]
    np.testing.assert_allclose(bl.simulate(u), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("m_left", "c_left", "m_right", "c_right", "u_range"),
    [
        (1.0, 0.3, 1.0, 0.2, (-3.0, 3.0)),
        (0.7, 0.1, 1.3, 0.4, (-2.0, 0.95)),  # lines meet at u = 0.983
        (-1.2, 0.2, -0.9, 0.35, (-1.8, 2.0)),  # lines meet at u = -1.85
    ],
)
def test_degree1_matches_eq1_random_input(
    m_left: float, c_left: float, m_right: float, c_right: float, u_range: tuple[float, float]
) -> None:
    rng = np.random.default_rng(7)
    # a clipped random walk: long holds, reversals and both branches
    u = np.clip(np.cumsum(rng.normal(0, 0.3, 600)), *u_range)
    bl = GeneralBacklash((m_left,), c_left, (m_right,), c_right)
    assert bl.branches_separated(*u_range)
    expected = eq1_ideal(m_left, c_left, m_right, c_right, u, 0.0)
    result = bl.simulate(u)
    np.testing.assert_allclose(result, expected, rtol=0, atol=1e-12)
    assert np.ptp(result) > 0.5  # the data did move the output


@settings(max_examples=200, deadline=None)
@given(
    m_left=st.lists(st.floats(-5, 5), min_size=1, max_size=4),
    m_right=st.lists(st.floats(-5, 5), min_size=1, max_size=4),
    c_left=st.floats(0.0, 2.0),
    c_right=st.floats(0.0, 2.0),
    u=st.floats(-1e3, 1e3),
)
def test_branches_at_one_input_are_left_and_right_of_it(
    m_left: list[float], m_right: list[float], c_left: float, c_right: float, u: float
) -> None:
    """The scalar form the stuck-encoder check uses is the array form, to the bit."""
    n = min(len(m_left), len(m_right))
    try:
        model = GeneralBacklash(tuple(m_left[:n]), c_left, tuple(m_right[:n]), c_right)
    except GenBacklashError:  # e.g. a zero leading slope
        return
    left, right = model.branches_at(u)
    assert (left, right) == (float(model.left([u])[0]), float(model.right([u])[0]))


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(monotone_models(), st.lists(st.floats(-1e3, 1e3), max_size=30))
def test_branches_are_left_and_right_to_the_bit(
    model_range: tuple[GeneralBacklash, float, float], u: list[float]
) -> None:
    """``branches`` (the hot loops' form, no input checks) gives exactly what ``left`` and
    ``right`` give."""
    model = model_range[0]
    uu = np.array(u, dtype=np.float64)
    left, right = model.branches(uu)
    assert left.tobytes() == model.left(uu).tobytes()  # to the bit, signed zeros too
    assert right.tobytes() == model.right(uu).tobytes()
