"""Output-error refinement: it lowers the simulation cost, its Jacobian is right, it helps."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import (
    Cascade,
    GeneralBacklash,
    LinearBlock,
    identify_backlash,
    paper_example,
    refine_output_error,
    simulate_backlash,
    simulate_cascade,
)
from genbacklash_core.refine import (
    _engaged,
    _jacobian,
    restart_points,
    simulate_parameters,
    simulation_jacobian,
)
from genbacklash_core.structure import Structure


def _cost(model: GeneralBacklash | Cascade, u: np.ndarray, y: np.ndarray, x0: float) -> float:
    if isinstance(model, Cascade):
        r = y - simulate_cascade(model, u, x0).y
    else:
        r = y - simulate_backlash(model, u, x0)
    return float(r @ r)


# --------------------------------------------------------------------------- cost


@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_refinement_lowers_the_cost_from_the_iteration(number: int) -> None:
    ex = paper_example(number)
    data = ex.generate(4)
    start = ex.model  # refine from the truth: the noise leaves room to lower the cost
    out = refine_output_error(start, data.u, data.y)
    x0 = 0.0 if isinstance(start, Cascade) else float(data.y[0])
    assert out.cost_start == pytest.approx(_cost(start, data.u, data.y, x0), rel=1e-12)
    assert out.cost_end == pytest.approx(_cost(out.model, data.u, data.y, x0), rel=1e-12)
    assert out.cost_end <= out.cost_start
    assert out.converged
    assert out.reason


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refinement_after_identification_never_raises_the_cost(seed: int) -> None:
    data = paper_example(1).generate(seed)
    result = identify_backlash(data.u, data.y, 3)
    assert result.refinement is not None
    x0 = float(data.y[0])
    assert result.refinement.cost_end <= result.refinement.cost_start
    assert result.refinement.cost_start == pytest.approx(
        _cost(result.equation_error_model, data.u, data.y, x0), rel=1e-12
    )
    assert result.refinement.cost_end == pytest.approx(
        _cost(result.model, data.u, data.y, x0), rel=1e-12
    )


def test_rough_start_cost_falls_a_lot() -> None:
    data = paper_example(2).generate(0)
    rough = GeneralBacklash((-0.4, 0.2, -0.2), 0.6, (-0.5, -0.3, -0.25), 0.9)
    out = refine_output_error(rough, data.u, data.y)
    assert out.cost_end < 0.2 * out.cost_start
    assert not out.model.increasing  # type: ignore[union-attr]


def test_step_limit_reports_not_converged() -> None:
    data = paper_example(1).generate(0)
    rough = GeneralBacklash((0.45, -0.25, 0.3), 0.6, (0.55, 0.4, 0.2), 0.7)
    out = refine_output_error(rough, data.u, data.y, max_iterations=1)
    assert out.iterations == 1
    assert not out.converged
    assert "stopped after 1 steps" in out.reason
    assert out.cost_end < out.cost_start


def test_explicit_x0_is_used() -> None:
    ex = paper_example(1)
    data = ex.generate(0)
    default = refine_output_error(ex.model, data.u, data.y)
    explicit = refine_output_error(ex.model, data.u, data.y, x0=float(data.y[0]))
    assert default.cost_start == explicit.cost_start
    other = refine_output_error(ex.model, data.u, data.y, x0=5.0)
    assert other.cost_start == pytest.approx(_cost(ex.model, data.u, data.y, 5.0), rel=1e-12)


# --------------------------------------------------------------------------- Jacobian


def test_simulate_parameters_matches_the_models() -> None:
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, 700)
    for number in (1, 2, 3, 4):
        model = paper_example(number).model
        structure = Structure.of(model)
        x, y = simulate_parameters(structure, model.parameters(), u, 0.2)
        if isinstance(model, Cascade):
            out = simulate_cascade(model, u, 0.2)
            np.testing.assert_allclose(x, out.x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(y, out.y, rtol=0, atol=1e-12)
        else:
            np.testing.assert_allclose(x, simulate_backlash(model, u, 0.2), rtol=0, atol=1e-12)
            np.testing.assert_array_equal(x, y)


def _finite_difference(
    structure: Structure, p: np.ndarray, u: np.ndarray, x0: float, h: float = 1e-6
) -> np.ndarray:
    columns = []
    for i in range(p.size):
        step = np.zeros_like(p)
        step[i] = h
        plus = simulate_parameters(structure, p + step, u, x0)[1]
        minus = simulate_parameters(structure, p - step, u, x0)[1]
        columns.append((plus - minus) / (2 * h))
    return np.column_stack(columns)


MODELS = {
    "example1": paper_example(1).model,
    "example2-decreasing": paper_example(2).model,
    "example3-cascade": paper_example(3).model,
    "example4-cascade": paper_example(4).model,
    "degree1-cascade-na3-nb1": Cascade(
        GeneralBacklash((0.9,), 0.2, (1.1,), 0.3), LinearBlock((1.0, 0.3, -0.2), (-0.4,))
    ),
    "degree2": GeneralBacklash((0.8, 0.1), 0.3, (0.9, -0.1), 0.25),
}


@pytest.mark.parametrize("name", list(MODELS))
def test_jacobian_matches_central_differences(name: str) -> None:
    model = MODELS[name]
    structure = Structure.of(model)
    rng = np.random.default_rng(len(name))
    # a generic point: the true model, slightly moved, and inputs that keep the branches apart
    p = model.parameters() + rng.normal(0.0, 0.01, structure.n_parameters)
    assert structure.problem(p) is None
    u = rng.uniform(-1.0, 1.0, 400)
    x0 = 0.1
    x, y = simulate_parameters(structure, p, u, x0)
    jac = _jacobian(structure, p, u, x, y, x0)
    assert jac.shape == (u.size, structure.n_parameters)
    fd = _finite_difference(structure, p, u, x0)
    relative = np.linalg.norm(jac - fd, axis=0) / np.maximum(np.linalg.norm(fd, axis=0), 1e-300)
    # The simulation is piecewise smooth; with these seeded data no switching decision sits
    # within the difference step of a kink, so every column must agree (they do to ~1e-10).
    assert np.all(relative < 1e-4), relative
    assert np.median(relative) < 1e-7, relative
    assert np.all(np.linalg.norm(fd, axis=0) > 0)  # every parameter matters on these data


def test_jacobian_zero_before_first_engagement() -> None:
    model = GeneralBacklash.ideal(1.0, 0.5, 0.5)
    structure = Structure.of(model)
    u = np.array([0.0, 0.1, -0.1, 1.0, 0.9, -1.0])  # x0 = 0 is held until u = 1
    x, y = simulate_parameters(structure, model.parameters(), u, 0.0)
    jac = _jacobian(structure, model.parameters(), u, x, y, 0.0)
    np.testing.assert_array_equal(jac[:3], 0.0)
    # u = 1 engages R: dR/dm_R1 = u - c_R, dR/dc_R = -m_R1; u = 0.9 holds it
    np.testing.assert_allclose(jac[3], [0.0, 0.0, 0.5, -1.0])
    np.testing.assert_allclose(jac[4], jac[3])
    # u = -1 engages L: dL/dm_L1 = u + c_L, dL/dc_L = m_L1
    np.testing.assert_allclose(jac[5], [-0.5, 1.0, 0.0, 0.0])


def test_jacobian_on_the_simulations_branches_is_the_jacobian_to_the_bit() -> None:
    """The refinement and the free run hand the Jacobian the branches the simulation ran on
    (not evaluated again): the same Jacobian, bit for bit, with restarts at breaks too; and
    the columns are zero exactly up to the first engagement (a prefix, zeroed by a slice)."""
    model = MODELS["degree2"]
    structure = Structure.of(model)
    rng = np.random.default_rng(7)
    p = model.parameters() + rng.normal(0.0, 0.01, structure.n_parameters)
    # a long hold before the first engagement, then back and forth with a few breaks
    u = np.concatenate([np.full(300, 0.01), 0.8 * np.sin(np.linspace(0.0, 12 * np.pi, 3000))])
    y = simulate_parameters(structure, p, u, 0.0)[0] + rng.normal(0.0, 1e-3, u.size)
    breaks = np.zeros(u.size, dtype=bool)
    breaks[[10, 700, 1900]] = True
    anchors = restart_points(breaks)
    branches = structure.branches(p, u)
    x, y_sim = simulate_parameters(structure, p, u, 0.0, anchors, y, branches=branches)
    x_own, y_own = simulate_parameters(structure, p, u, 0.0, anchors, y)
    assert x.tobytes() == x_own.tobytes() and y_sim.tobytes() == y_own.tobytes()
    fresh = _jacobian(structure, p, u, x, y_sim, 0.0, anchors)
    given = _jacobian(structure, p, u, x, y_sim, 0.0, anchors, branches)
    assert fresh.tobytes() == given.tobytes()
    y_j, jac = simulation_jacobian(structure, p, u, y, 0.0, breaks)
    assert y_j.tobytes() == y_sim.tobytes() and jac.tobytes() == fresh.tobytes()
    f1, f2 = _engaged(structure, p, u, x, 0.0, anchors)
    first = int(np.flatnonzero(f1 | f2 | anchors)[0])
    assert first > 0  # the hold: no sensitivity before the first engagement
    np.testing.assert_array_equal(jac[:first], 0.0)
    assert np.all(np.any(jac[first:] != 0.0, axis=0))


# --------------------------------------------------------------------------- statistics


def test_refined_estimate_not_worse_than_plain_iteration_at_snr25() -> None:
    ex = paper_example(1)
    assert ex.snr == 25.0
    truth = ex.model.parameters()
    refined_errors, plain_errors = [], []
    for seed in range(10):
        data = ex.generate(seed, snr=25.0)
        refined = identify_backlash(data.u, data.y, 3)
        plain = identify_backlash(data.u, data.y, 3, refine=False)
        assert refined.converged and plain.converged
        refined_errors.append(np.mean((refined.model.parameters() - truth) ** 2))
        plain_errors.append(np.mean((plain.model.parameters() - truth) ** 2))
    assert np.mean(refined_errors) <= 1.1 * np.mean(plain_errors), (
        np.mean(refined_errors),
        np.mean(plain_errors),
    )
