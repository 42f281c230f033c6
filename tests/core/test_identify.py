"""Identification: known answers from the paper's examples, options and the result contract."""

from __future__ import annotations

import json

import numpy as np
import pytest

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    GeneralBacklash,
    IdentificationResult,
    LinearBlock,
    identify_backlash,
    identify_cascade,
    nrmse,
    paper_example,
)
from genbacklash_core.structure import Structure

from ._helpers import TOL_PAPER

SEEDS = [0, 1, 2, 3, 4]


def _identify_example(number: int, seed: int, **options: object) -> IdentificationResult:
    data = paper_example(number).generate(seed)
    if number <= 2:
        return identify_backlash(data.u, data.y, 3, **options)  # type: ignore[arg-type]
    return identify_cascade(data.u, data.y, 3, 2, 2, **options)  # type: ignore[arg-type]


def _max_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    assert estimate.shape == truth.shape
    return float(np.max(np.abs(estimate - truth)))


# --------------------------------------------------------------------------- paper examples


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_paper_example_default(number: int, seed: int) -> None:
    ex = paper_example(number)
    result = _identify_example(number, seed)
    assert result.converged, result.reason
    assert type(result.model) is type(ex.model)
    error = _max_error(result.model.parameters(), ex.model.parameters())
    assert error < TOL_PAPER, (error, result.model)
    assert result.refinement is not None
    assert result.refinement.cost_end <= result.refinement.cost_start
    data = ex.generate(seed)
    # the fit is about the noise level: NRMSE ~ 1/SNR
    assert result.fit.nrmse < 2.0 / ex.snr
    assert result.fit.nrmse == pytest.approx(nrmse(data.y, _simulate(result, data.u, data.y)))


def _simulate(result: IdentificationResult, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    model = result.model
    if isinstance(model, Cascade):
        return model.simulate(u)
    return model.simulate(u, x0=float(y[0]))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_paper_example_plain_iteration(number: int, seed: int) -> None:
    ex = paper_example(number)
    result = _identify_example(number, seed, refine=False)
    assert result.converged, result.reason
    assert result.refinement is None
    values = result.history.values
    np.testing.assert_array_equal(values[0], Structure.of(ex.model).start())
    row = min(10, values.shape[0] - 1)
    error = _max_error(values[row], ex.model.parameters())
    assert error < TOL_PAPER, (row, error)
    # without refinement the model is the last iterate, also the equation-error model
    np.testing.assert_array_equal(result.model.parameters(), values[-1])
    assert result.equation_error_model == result.model


def test_refined_and_plain_share_the_iteration() -> None:
    data = paper_example(1).generate(3)
    plain = identify_backlash(data.u, data.y, 3, refine=False)
    refined = identify_backlash(data.u, data.y, 3)
    np.testing.assert_array_equal(plain.history.values, refined.history.values)
    assert refined.equation_error_model == plain.model
    assert plain.iterations == refined.iterations == plain.history.values.shape[0] - 1


# --------------------------------------------------------------------------- branch sense


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_decreasing_branches_detected(seed: int) -> None:
    ex = paper_example(2)
    data = ex.generate(seed)
    auto = identify_backlash(data.u, data.y, 3)
    assert auto.converged, auto.reason
    assert isinstance(auto.model, GeneralBacklash)
    assert not auto.model.increasing
    assert auto.history.values[0][0] == -1.0  # started from m_1 = -1
    assert _max_error(auto.model.parameters(), ex.model.parameters()) < TOL_PAPER
    explicit = identify_backlash(data.u, data.y, 3, sign=-1)
    assert explicit.converged
    np.testing.assert_array_equal(explicit.model.parameters(), auto.model.parameters())


def test_increasing_sign_explicit_matches_detected() -> None:
    data = paper_example(1).generate(0)
    auto = identify_backlash(data.u, data.y, 3)
    explicit = identify_backlash(data.u, data.y, 3, sign=1)
    assert auto.model.increasing
    np.testing.assert_array_equal(explicit.model.parameters(), auto.model.parameters())


def test_decreasing_cascade_detected() -> None:
    bl = paper_example(2).model
    assert isinstance(bl, GeneralBacklash)
    model = Cascade(bl, LinearBlock((1.0, 0.15), (-0.2, 0.35)))
    rng = np.random.default_rng(11)
    u = rng.uniform(-1.5, 1.5, 1500)
    clean = model.simulate(u)
    y = clean + rng.normal(0, np.std(clean) / 50, u.size)
    result = identify_cascade(u, y, 3, 2, 2)
    assert result.converged, result.reason
    assert not result.model.backlash.increasing  # type: ignore[union-attr]
    assert _max_error(result.model.parameters(), model.parameters()) < TOL_PAPER


@pytest.mark.parametrize("sign", [0, 2, -0.5, "up"])
def test_invalid_sign(sign: object) -> None:
    data = paper_example(1).generate(0)
    with pytest.raises(GenBacklashError, match=r"sign must be \+1, -1 or None"):
        identify_backlash(data.u, data.y, 3, sign=sign)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- other structures


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(
    "truth",
    [
        GeneralBacklash.ideal(0.8, 0.3, 0.5),
        GeneralBacklash((1.0,), 0.15, (1.1,), 0.25),  # lines meet at u = 4.25
        GeneralBacklash.ideal(-0.8, 0.3, 0.5),
    ],
    ids=["ideal", "unequal-slopes", "ideal-decreasing"],
)
def test_degree1(truth: GeneralBacklash, seed: int) -> None:
    rng = np.random.default_rng(seed)
    u = rng.uniform(-2, 2, 600)
    assert truth.branches_separated(-2.0, 2.0)
    clean = truth.simulate(u)
    y = clean + rng.normal(0, np.std(clean) / 50, u.size)
    result = identify_backlash(u, y, 1)
    assert result.converged, result.reason
    assert isinstance(result.model, GeneralBacklash)
    assert result.model.degree == 1
    assert result.history.names == ("m_left_1", "c_left", "m_right_1", "c_right")
    assert _max_error(result.model.parameters(), truth.parameters()) < 0.01


EX3_BACKLASH = GeneralBacklash((0.5, -0.3, 0.3), 0.45, (0.6, 0.4, 0.2), 0.55)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(
    "block",
    [LinearBlock((1.0,), (-0.5,)), LinearBlock((1.0, 0.3, -0.2), (-0.4,)), LinearBlock((1.0,))],
    ids=["na1-nb1", "na3-nb1", "na1-nb0"],
)
def test_cascade_other_orders(block: LinearBlock, seed: int) -> None:
    assert block.stable
    truth = Cascade(EX3_BACKLASH, block)
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, 1500)
    clean = truth.simulate(u)
    y = clean + rng.normal(0, np.std(clean) / 50, u.size)
    result = identify_cascade(u, y, 3, block.na, block.nb)
    assert result.converged, result.reason
    model = result.model
    assert isinstance(model, Cascade)
    assert (model.linear.na, model.linear.nb) == (block.na, block.nb)
    assert model.linear.a[0] == 1.0
    assert model.parameter_names == truth.parameter_names
    assert _max_error(model.parameters(), truth.parameters()) < TOL_PAPER
    # the linear parameters on their own
    np.testing.assert_allclose(model.linear.a, block.a, atol=TOL_PAPER)
    np.testing.assert_allclose(model.linear.b, block.b, atol=TOL_PAPER)


def test_degree2_cascade_structure() -> None:
    truth = Cascade(
        GeneralBacklash((0.7, 0.1), 0.3, (0.8, -0.1), 0.35), LinearBlock((1.0, 0.15), (-0.2, 0.35))
    )
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 1500)
    clean = truth.simulate(u)
    y = clean + rng.normal(0, np.std(clean) / 50, u.size)
    result = identify_cascade(u, y, 2, 2, 2)
    assert result.converged, result.reason
    assert _max_error(result.model.parameters(), truth.parameters()) < TOL_PAPER


# --------------------------------------------------------------------------- result contract


def test_to_dict_backlash_contract() -> None:
    data = paper_example(1).generate(0)
    result = identify_backlash(data.u, data.y, 3)
    out = result.to_dict()
    assert set(out) == {"model", "backlash", "iterations", "converged", "reason", "fit"}
    assert out["model"] == "backlash"
    assert set(out["backlash"]) == {"m_left", "c_left", "m_right", "c_right"}
    assert set(out["fit"]) == {"nrmse"}
    model = result.model
    assert isinstance(model, GeneralBacklash)
    assert out["backlash"]["m_left"] == list(model.m_left)
    assert out["backlash"]["c_left"] == model.c_left
    assert out["backlash"]["m_right"] == list(model.m_right)
    assert out["backlash"]["c_right"] == model.c_right
    assert out["iterations"] == result.iterations
    assert out["converged"] is True
    assert out["reason"] == result.reason
    assert out["fit"]["nrmse"] == result.fit.nrmse
    assert json.loads(json.dumps(out)) == out  # plain JSON types


def test_to_dict_cascade_contract() -> None:
    data = paper_example(3).generate(0)
    result = identify_cascade(data.u, data.y, 3, 2, 2)
    out = result.to_dict()
    assert set(out) == {"model", "backlash", "linear", "iterations", "converged", "reason", "fit"}
    assert out["model"] == "cascade"
    assert set(out["backlash"]) == {"m_left", "c_left", "m_right", "c_right"}
    assert set(out["linear"]) == {"a", "b"}
    assert set(out["fit"]) == {"nrmse"}
    model = result.model
    assert isinstance(model, Cascade)
    assert out["linear"]["a"] == list(model.linear.a)
    assert out["linear"]["a"][0] == 1.0
    assert out["linear"]["b"] == list(model.linear.b)
    assert isinstance(out["iterations"], int)
    assert isinstance(out["converged"], bool)
    assert isinstance(out["reason"], str)
    assert out["reason"]
    assert json.loads(json.dumps(out)) == out


def test_to_dict_of_failed_run_is_json() -> None:
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, 1000)
    y = np.concatenate([np.zeros(2), u[:-2]])  # a pure delay: no backlash at all
    result = identify_cascade(u, y, 3, 2, 2)
    out = result.to_dict()
    assert out["converged"] is False
    assert out["reason"]
    assert json.loads(json.dumps(out)) == out


@pytest.mark.parametrize("number", [1, 3])
def test_history_shape_and_names(number: int) -> None:
    ex = paper_example(number)
    result = _identify_example(number, 0)
    structure = Structure.of(ex.model)
    history = result.history
    assert history.names == structure.names() == ex.model.parameter_names
    assert history.values.shape == (result.iterations + 1, structure.n_parameters)
    np.testing.assert_array_equal(history.values[0], structure.start())
    np.testing.assert_array_equal(history.series("c_left"), history.values[:, structure.degree])
    with pytest.raises(ValueError, match="not in tuple"):
        history.series("no_such_parameter")


def test_history_validates_shape() -> None:
    from genbacklash_core import IterationHistory

    with pytest.raises(GenBacklashError, match=r"history values must be \(iterations\+1, 2\)"):
        IterationHistory(("a", "b"), np.zeros((3, 3)))


def test_callback_sees_every_iteration() -> None:
    data = paper_example(1).generate(0)
    seen: list[tuple[int, np.ndarray]] = []
    result = identify_backlash(
        data.u, data.y, 3, refine=False, callback=lambda i, p: seen.append((i, p))
    )
    assert [i for i, _ in seen] == list(range(1, result.iterations + 1))
    np.testing.assert_array_equal(np.array([p for _, p in seen]), result.history.values[1:])


def test_max_iterations_limits_the_run() -> None:
    ex = paper_example(3)
    data = ex.generate(0)
    result = identify_cascade(data.u, data.y, 3, 2, 2, max_iterations=3, refine=False)
    assert not result.converged
    assert result.iterations == 3
    assert result.history.values.shape == (4, 11)
    assert result.refinement is None
    assert "no convergence in 3 iterations" in result.reason
    assert np.all(np.isfinite(result.model.parameters()))
    # with the refinement, a converged result must be a good one
    refined = identify_cascade(data.u, data.y, 3, 2, 2, max_iterations=3)
    if refined.converged:
        assert _max_error(refined.model.parameters(), ex.model.parameters()) < TOL_PAPER


@pytest.mark.parametrize("max_iterations", [0, -1])
def test_max_iterations_must_be_positive(max_iterations: int) -> None:
    data = paper_example(1).generate(0)
    with pytest.raises(GenBacklashError, match="max_iterations must be >= 1"):
        identify_backlash(data.u, data.y, 3, max_iterations=max_iterations)


def test_start_model_is_used() -> None:
    ex = paper_example(1)
    data = ex.generate(0)
    result = identify_backlash(data.u, data.y, 3, start=ex.model, refine=False)
    np.testing.assert_array_equal(result.history.values[0], ex.model.parameters())
    assert result.converged
    assert result.iterations <= 4  # starting at the truth, it settles at once
    with pytest.raises(GenBacklashError, match="start has degree 1, expected 3"):
        identify_backlash(data.u, data.y, 3, start=GeneralBacklash.ideal(1.0, 0.1, 0.1))


def test_cascade_start_structure_checked() -> None:
    ex = paper_example(3)
    data = ex.generate(0)
    assert isinstance(ex.model, Cascade)
    wrong = Cascade(ex.model.backlash, LinearBlock((1.0,), (0.1,)))
    with pytest.raises(GenBacklashError, match="start has structure"):
        identify_cascade(data.u, data.y, 3, 2, 2, start=wrong)
    ok = identify_cascade(data.u, data.y, 3, 2, 2, start=ex.model)
    assert ok.converged
    assert _max_error(ok.model.parameters(), ex.model.parameters()) < TOL_PAPER


def test_long_record_uses_a_prefix_warm_start() -> None:
    ex = paper_example(1)
    data = ex.generate(5, n_samples=100_000)
    result = identify_backlash(data.u, data.y, 3)
    assert result.converged, result.reason
    assert "on a prefix" in result.reason
    assert result.history.values.shape == (result.iterations + 1, 8)
    # a hundred times the data: much closer than the paper's tolerance
    assert _max_error(result.model.parameters(), ex.model.parameters()) < 0.005


def test_accepts_python_lists() -> None:
    data = paper_example(1).generate(0)
    from_lists = identify_backlash(data.u.tolist(), data.y.tolist(), 3)
    from_arrays = identify_backlash(data.u, data.y, 3)
    np.testing.assert_array_equal(from_lists.model.parameters(), from_arrays.model.parameters())


def test_nrmse() -> None:
    y = np.array([1.0, 2.0, 3.0])
    assert nrmse(y, y) == 0.0
    assert nrmse(y, np.full(3, 2.0)) == pytest.approx(1.0)
    assert nrmse(np.ones(3), np.ones(3)) == 0.0
    assert nrmse(np.ones(3), np.zeros(3)) == float("inf")
