"""Identification: known answers from the paper's examples, options and the result contract."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from numpy.polynomial import Polynomial

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
from genbacklash_core.identify import backlash_misfit
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
    assert set(out) == {"model", "backlash", "iterations", "converged", "reason", "fit", "play"}
    assert out["model"] == "backlash"
    assert set(out["backlash"]) == {"m_left", "c_left", "m_right", "c_right"}
    assert set(out["fit"]) == {"nrmse", "misfit"}
    assert out["fit"]["misfit"] == out["fit"]["nrmse"]  # one word for the misfit, old key kept
    model = result.model
    assert isinstance(model, GeneralBacklash)
    assert out["play"] == model.c_left + model.c_right  # the play, rad (issue 22)
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
    expected = {"model", "backlash", "linear", "iterations", "converged", "reason", "fit", "play"}
    assert set(out) == expected
    assert out["model"] == "cascade"
    assert set(out["backlash"]) == {"m_left", "c_left", "m_right", "c_right"}
    assert set(out["linear"]) == {"a", "b"}
    assert set(out["fit"]) == {"nrmse", "misfit"}
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


def _lagged(seed: int, lag: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Example 1's input lagged ``lag`` samples before its backlash (a servo the model
    lacks: the iteration often fails to settle and restarts), 2 % of the rows broken."""
    ex = paper_example(1)
    data = ex.generate(seed, n_samples=n)
    rng = np.random.default_rng(seed)
    u = np.concatenate([np.full(lag, data.u[0]), data.u[: n - lag]])
    y = ex.model.simulate(u, 0.0) + rng.normal(0.0, 0.02, n)
    return data.u, y, rng.random(n) < 0.02


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("degree", [1, 3])
@pytest.mark.parametrize("lag", [0, 3, 8])
def test_backlash_misfit_is_identify_s_fit_to_the_bit(seed: int, degree: int, lag: int) -> None:
    """The servo's score skips the branch-support check: the misfit stays the one
    identify_backlash reads without refinement, on data where it settles and where it
    restarts."""
    u, y, breaks = _lagged(seed, lag, 1500)
    full = identify_backlash(u, y, degree, refine=False, breaks=breaks)
    assert backlash_misfit(u, y, degree, breaks=breaks) == full.fit.nrmse


def test_backlash_misfit_of_a_long_record_and_its_errors() -> None:
    u, y, breaks = _lagged(1, 4, 90_000)  # a prefix warm start first
    full = identify_backlash(u, y, 1, refine=False, breaks=breaks)
    assert backlash_misfit(u, y, 1, breaks=breaks) == full.fit.nrmse
    with pytest.raises(GenBacklashError, match="degree"):
        backlash_misfit(u, y, 0)


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


# --------------------------------------------------------------------------- crossing branches

# Lines that meet inside the input range: L(u) = R(u) at u = (0.15 + 1.1 * 0.25) / 0.1 = 4.25,
# and R lies above L beyond it. On [-6, 6] this is no backlash (the condition below eq. 21).
CROSSING = GeneralBacklash((1.0,), 0.15, (1.1,), 0.25)
# Curved branches whose difference is L(u) - R(u) = 0.05 (u - 4.5) (u - 5.5): apart at both
# ends of [-6, 6], crossed only in the band between: c_R solves the constant term
# 0.05 c_L^2 + c_L + 1.53 c_R = 0.05 * 4.5 * 5.5.
INTERIOR = GeneralBacklash((1.0, 0.05), 0.3, (1.53, 0.0), (1.2375 - 0.0045 - 0.3) / 1.53)
CROSS_REASON = re.compile(r"the branches cross on the input range \(u in \[(\S+), (\S+)\]\)")
CROSS_GRID_STEP = 12.0 / 256  # the check's grid: 257 points across the input range


def _crossing_data(
    model: GeneralBacklash | Cascade, seed: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Inputs on [-6, 6] and the model's output with 1 % noise (seeded)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-6.0, 6.0, n)
    clean = model.simulate(u)
    return u, clean + rng.normal(0.0, np.std(clean) / 100, n)


def _branch_gap(p: np.ndarray, degree: int) -> Polynomial:
    """``L(u) - R(u)`` of a natural parameter vector, built here from eqs. (11)-(12)."""
    m_left, c_left = p[:degree], p[degree]
    m_right, c_right = p[degree + 1 : 2 * degree + 1], p[2 * degree + 1]
    gap = Polynomial([0.0])
    for k in range(degree):
        gap += m_left[k] * Polynomial([c_left, 1.0]) ** (k + 1)
        gap -= m_right[k] * Polynomial([-c_right, 1.0]) ** (k + 1)
    return gap


def _reported_band(reason: str) -> tuple[float, float]:
    match = CROSS_REASON.search(reason)
    assert match is not None, reason
    return float(match[1]), float(match[2])


def test_crossing_models_of_these_tests() -> None:
    """Pin the premise: ``CROSSING`` crosses at u = 4.25 (closed form), ``INTERIOR`` exactly
    on [4.5, 5.5] with both ends of [-6, 6] apart; both are still valid on [-2, 2]."""
    assert CROSSING.crossings(-6.0, 6.0) == pytest.approx((4.25, 6.0), abs=1e-12)
    assert not CROSSING.branches_separated(-6.0, 6.0)
    assert CROSSING.branches_separated(-2.0, 2.0)
    u = np.linspace(-6.0, 6.0, 121)
    gap = INTERIOR.left(u) - INTERIOR.right(u)
    np.testing.assert_allclose(gap, 0.05 * (u - 4.5) * (u - 5.5), rtol=0, atol=1e-12)
    assert INTERIOR.crossings(-6.0, 6.0) == pytest.approx((4.5, 5.5), abs=1e-9)
    assert not INTERIOR.branches_separated(-6.0, 6.0)
    assert INTERIOR.branches_separated(-2.0, 2.0)


def test_iteration_settling_on_crossing_lines_does_not_converge() -> None:
    """Pin the crossing check of the iteration (``Structure.problem`` with the input range).

    Data from ``CROSSING`` on [-6, 6]: the paper's iteration settles on lines that cross
    inside the range. That must end ``converged=False`` with the "cross" reason, whose band
    starts at the crossing of the last iterate (closed form ``(m_L c_L + m_R c_R) /
    (m_R - m_L)``, to the check's grid) and runs to the end of the data. The model returned
    is the last valid iterate, and with the refinement the refined model: both keep their
    branches apart on the whole range.
    """
    u, y = _crossing_data(CROSSING, 0, 600)
    plain = identify_backlash(u, y, 1, refine=False)
    assert plain.converged is False
    assert "the iteration settled on an invalid model: the branches cross" in plain.reason
    m_left, c_left, m_right, c_right = plain.history.values[-1]
    assert m_right > m_left  # R overtakes L: crossed from the crossing to the upper end
    crossing = (m_left * c_left + m_right * c_right) / (m_right - m_left)
    assert u.min() < crossing < u.max()
    low, high = _reported_band(plain.reason)
    assert crossing - 0.01 <= low <= crossing + CROSS_GRID_STEP + 0.01  # printed to 3 digits
    assert high == pytest.approx(u.max(), abs=0.01)
    grid = np.linspace(u.min(), u.max(), 1001)
    for model in (plain.model, plain.equation_error_model):
        assert isinstance(model, GeneralBacklash)
        assert np.all(model.left(grid) > model.right(grid))

    refined = identify_backlash(u, y, 1)
    assert refined.converged is False
    assert CROSS_REASON.search(refined.reason) is not None
    assert refined.refinement is not None
    assert isinstance(refined.model, GeneralBacklash)
    assert np.all(refined.model.left(grid) > refined.model.right(grid))


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_crossing_between_the_range_ends_is_found(seed: int) -> None:
    """Pin that the check looks inside the input range, not only at its ends.

    Data from ``INTERIOR``: the iteration settles near it, on branches apart at both ends of
    the data but crossed between two roots of ``L - R`` (a quadratic, solved here with
    numpy). The result must not be converged and the reported band must lie between those
    roots, to the check's grid.
    """
    u, y = _crossing_data(INTERIOR, seed, 800)
    result = identify_backlash(u, y, 2, refine=False)
    assert result.converged is False
    assert "the iteration settled on an invalid model: the branches cross" in result.reason
    gap = _branch_gap(result.history.values[-1], 2)
    assert gap(u.min()) > 0 and gap(u.max()) > 0  # apart at both ends of the data
    roots = np.sort(gap.roots())
    assert np.all(np.isreal(roots)) and u.min() < roots[0].real < roots[1].real < u.max()
    first, last = roots.real
    low, high = _reported_band(result.reason)
    assert first - 0.01 <= low <= first + CROSS_GRID_STEP + 0.01
    assert last - CROSS_GRID_STEP - 0.01 <= high <= last + 0.01


@pytest.mark.parametrize("cascade", [False, True], ids=["backlash", "cascade"])
def test_start_crossing_on_the_input_range_leaves_nothing_to_refine(cascade: bool) -> None:
    """Pin the refinement's guard against a start whose branches cross on the data's range.

    Started at the crossing truth itself, every iterate crosses, so no candidate is valid to
    refine from: ``converged=False``, no refinement, and the reason says why.
    """
    truth = Cascade(CROSSING, LinearBlock((1.0, 0.3), (-0.5,))) if cascade else CROSSING
    u, y = _crossing_data(truth, 1, 1500 if cascade else 600)
    if cascade:
        result = identify_cascade(u, y, 1, 2, 1, start=truth)  # type: ignore[arg-type]
    else:
        result = identify_backlash(u, y, 1, start=CROSSING)
    assert result.converged is False
    assert result.refinement is None
    assert CROSS_REASON.search(result.reason) is not None
    assert "no start valid on the input range to refine from (branches cross)" in result.reason


def test_cascade_iteration_settling_on_crossing_branches_does_not_converge() -> None:
    """Pin the crossing check in :func:`identify_cascade`.

    A cascade whose backlash is ``CROSSING``: the iteration settles on lines that cross
    inside the input range; the result is not converged, the band starts at the last
    iterate's crossing (closed form), and the model returned keeps its branches apart.
    """
    truth = Cascade(CROSSING, LinearBlock((1.0, 0.3), (-0.5,)))
    u, y = _crossing_data(truth, 0, 1500)
    result = identify_cascade(u, y, 1, 2, 1, refine=False)
    assert result.converged is False
    assert "the iteration settled on an invalid model: the branches cross" in result.reason
    m_left, c_left, m_right, c_right = result.history.values[-1][:4]
    assert m_right > m_left
    crossing = (m_left * c_left + m_right * c_right) / (m_right - m_left)
    assert u.min() < crossing < u.max()
    low, high = _reported_band(result.reason)
    assert crossing - 0.01 <= low <= crossing + CROSS_GRID_STEP + 0.01
    assert high == pytest.approx(u.max(), abs=0.01)
    assert isinstance(result.model, Cascade)
    grid = np.linspace(u.min(), u.max(), 1001)
    assert np.all(result.model.backlash.left(grid) > result.model.backlash.right(grid))
