"""Cascade: construction, parameter vector round trip and simulation."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    GeneralBacklash,
    LinearBlock,
    paper_example,
    simulate_cascade,
)
from genbacklash_core.structure import Structure

EX3 = paper_example(3).model


@pytest.mark.parametrize("number", [3, 4])
def test_from_parameters_round_trip_paper(number: int) -> None:
    model = paper_example(number).model
    assert isinstance(model, Cascade)
    again = Cascade.from_parameters(model.parameters(), 3, 2, 2)
    assert again == model
    np.testing.assert_array_equal(again.parameters(), model.parameters())


@pytest.mark.parametrize(
    ("degree", "a", "b"),
    [
        (1, (1.0,), ()),
        (1, (1.0,), (-0.5,)),
        (2, (1.0, 0.3, -0.2), (-0.4,)),
        (3, (1.0, 0.2), (-0.6, 0.3, -0.05)),
    ],
)
def test_from_parameters_round_trip_orders(
    degree: int, a: tuple[float, ...], b: tuple[float, ...]
) -> None:
    rng = np.random.default_rng(degree)
    m_left = (0.8, *rng.normal(0, 0.1, degree - 1))
    m_right = (0.9, *rng.normal(0, 0.1, degree - 1))
    model = Cascade(GeneralBacklash(m_left, 0.3, m_right, 0.4), LinearBlock(a, b))
    p = model.parameters()
    assert p.shape == (2 * degree + 2 + len(a) - 1 + len(b),)
    again = Cascade.from_parameters(p, degree, len(a), len(b))
    assert again == model
    assert Structure.of(model).names() == model.parameter_names
    assert Structure.of(model).model(p) == model


def test_parameter_names() -> None:
    assert EX3.parameter_names == (
        "m_left_1",
        "m_left_2",
        "m_left_3",
        "c_left",
        "m_right_1",
        "m_right_2",
        "m_right_3",
        "c_right",
        "a_2",
        "b_1",
        "b_2",
    )
    np.testing.assert_allclose(
        EX3.parameters(), [0.5, -0.3, 0.3, 0.45, 0.6, 0.4, 0.2, 0.55, 0.15, -0.2, 0.35]
    )


@pytest.mark.parametrize(("na", "nb"), [(2, 2), (1, 3), (3, 1)])
def test_from_parameters_wrong_length(na: int, nb: int) -> None:
    with pytest.raises(GenBacklashError, match=rf"expected \d+ parameters for degree=3, na={na}"):
        Cascade.from_parameters(np.ones(10), 3, na, nb)


def test_from_parameters_validates_backlash() -> None:
    p = EX3.parameters().copy()
    p[3] = -0.1  # c_left
    with pytest.raises(GenBacklashError, match="c_left must be > 0"):
        Cascade.from_parameters(p, 3, 2, 2)


def test_constructor_checks_types() -> None:
    bl = GeneralBacklash.ideal(1.0, 0.1, 0.1)
    with pytest.raises(GenBacklashError, match="backlash must be a GeneralBacklash"):
        Cascade((1.0,), LinearBlock((1.0,)))  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="linear must be a LinearBlock"):
        Cascade(bl, (1.0, 0.5))  # type: ignore[arg-type]


def test_simulate_method_is_simulate_cascade_y() -> None:
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, 300)
    out = simulate_cascade(EX3, u)
    np.testing.assert_array_equal(EX3.simulate(u), out.y)
    np.testing.assert_array_equal(out.x, EX3.backlash.simulate(u))
