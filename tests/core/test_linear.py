"""LinearBlock (eq. 30): validation, stability, dc gain and simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from genbacklash_core import GenBacklashError, LinearBlock, simulate_linear

PAPER_BLOCK = LinearBlock(a=(1.0, 0.15), b=(-0.2, 0.35))  # Examples 3 and 4


@pytest.mark.parametrize("a", [(2.0,), (0.0, 1.0), (-1.0,), (1.0 + 1e-12, 0.3)])
def test_a1_must_be_one(a: tuple[float, ...]) -> None:
    with pytest.raises(GenBacklashError, match=r"a_1 must be 1 \(key-term normalisation"):
        LinearBlock(a=a)


def test_a_must_not_be_empty() -> None:
    with pytest.raises(GenBacklashError, match=r"a needs at least a_1"):
        LinearBlock(a=())


@pytest.mark.parametrize(
    ("a", "b"), [((1.0, math.nan), ()), ((1.0,), (math.inf,)), ((1.0, 0.1), (0.2, -math.inf))]
)
def test_coefficients_must_be_finite(a: tuple[float, ...], b: tuple[float, ...]) -> None:
    with pytest.raises(GenBacklashError, match="coefficients must be finite"):
        LinearBlock(a=a, b=b)


def test_block_properties() -> None:
    block = LinearBlock(a=[1, 0.15], b=np.array([-0.2, 0.35]))
    assert block.a == (1.0, 0.15)
    assert block.b == (-0.2, 0.35)
    assert (block.na, block.nb) == (2, 2)
    assert block.parameter_names == ("a_2", "b_1", "b_2")
    np.testing.assert_array_equal(block.parameters(), [0.15, -0.2, 0.35])
    np.testing.assert_array_equal(block.numerator, [0.0, 1.0, 0.15])
    np.testing.assert_array_equal(block.denominator, [1.0, -0.2, 0.35])
    fir = LinearBlock(a=(1.0,))
    assert (fir.na, fir.nb, fir.parameter_names) == (1, 0, ())
    assert fir.parameters().shape == (0,)


@pytest.mark.parametrize(
    ("b", "stable"),
    [
        ((), True),
        ((-0.2, 0.35), True),  # the paper's block: |poles| = sqrt(0.35)
        ((-0.5,), True),
        ((-1.8, 0.81), True),  # double pole at 0.9
        ((0.0, 0.0, 0.5), True),  # |poles| = 0.5 ** (1/3)
        ((-1.0,), False),  # pole at 1: integrator
        ((1.0,), False),  # pole at -1
        ((-1.5,), False),
        ((0.0, 1.0), False),  # poles at +-i, on the unit circle
        ((-2.0, 1.0), False),  # double pole at 1
        ((0.2, -1.1), False),  # a real pole outside
    ],
)
def test_stability(b: tuple[float, ...], stable: bool) -> None:
    assert LinearBlock(a=(1.0,), b=b).stable is stable


@pytest.mark.parametrize(
    ("a", "b", "gain"),
    [
        ((1.0, 0.15), (-0.2, 0.35), 1.0),  # 1.15 / (1 - 0.2 + 0.35)
        ((1.0,), (), 1.0),
        ((1.0, 0.5), (-0.5,), 3.0),  # 1.5 / 0.5
        ((1.0, -0.4), (0.6,), 0.375),  # 0.6 / 1.6
        ((1.0,), (-1.0,), math.inf),
    ],
)
def test_dc_gain(a: tuple[float, ...], b: tuple[float, ...], gain: float) -> None:
    assert LinearBlock(a=a, b=b).dc_gain == pytest.approx(gain, rel=1e-14)


def test_dc_gain_is_the_step_response_limit() -> None:
    y = simulate_linear(PAPER_BLOCK, np.ones(400))
    assert y[-1] == pytest.approx(PAPER_BLOCK.dc_gain, rel=1e-12)


def test_simulate_linear_impulse_hand_computed() -> None:
    # y(t) = x(t-1) + 0.15 x(t-2) + 0.2 y(t-1) - 0.35 y(t-2), impulse at t = 0, from rest
    y = simulate_linear(PAPER_BLOCK, [1.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(y, [0.0, 1.0, 0.35, -0.28, -0.1785], rtol=0, atol=1e-15)


def test_simulate_linear_first_order_hand_computed() -> None:
    # y(t) = x(t-1) - 0.5 x(t-2) + 0.5 y(t-1)
    block = LinearBlock(a=(1.0, -0.5), b=(-0.5,))
    y = block.simulate([2.0, 1.0, -1.0, 0.0])
    # y0 = 0; y1 = 2; y2 = 1 - 1 + 1 = 1; y3 = -1 - 0.5 + 0.5 = -1
    np.testing.assert_allclose(y, [0.0, 2.0, 1.0, -1.0], rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    ("a", "b"),
    [((1.0, 0.15), (-0.2, 0.35)), ((1.0,), (-0.5,)), ((1.0, 0.3, -0.2), (-0.4,)), ((1.0, 0.7), ())],
)
def test_simulate_linear_matches_difference_equation(
    a: tuple[float, ...], b: tuple[float, ...]
) -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=300)
    y_ref = np.zeros_like(x)
    for t in range(x.size):
        acc = sum(ai * x[t - i] for i, ai in enumerate(a, 1) if t - i >= 0)
        acc -= sum(bj * y_ref[t - j] for j, bj in enumerate(b, 1) if t - j >= 0)
        y_ref[t] = acc
    np.testing.assert_allclose(simulate_linear(LinearBlock(a, b), x), y_ref, rtol=1e-12, atol=1e-12)
