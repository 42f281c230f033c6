"""Batch identification on records of a drivetrain in operation (issue 12, item 2)."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import GeneralBacklash, identify_backlash, nrmse, paper_example
from genbacklash_core.identify import _solve_damped
from genbacklash_core.samples import sample_breaks
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    STRAIGHT_BACKLASH,
    OperationSettings,
    operation_record,
)


@pytest.mark.parametrize(
    ("truth", "degrees"),
    [(STRAIGHT_BACKLASH, (1, 2, 3)), (OPERATION_BACKLASH, (3, 4))],
)
@pytest.mark.parametrize("seed", [0, 1])
def test_converges_for_every_degree_at_or_above_the_true_one(
    truth: GeneralBacklash, degrees: tuple[int, ...], seed: int
) -> None:
    """Held commands and dwells (many repeated rows with neither branch engaged) and lost
    readings: converged, and the free-run NRMSE against the noise-free truth near the
    quantisation floor."""
    rec = operation_record(OperationSettings(duration=30.0, model=truth), seed)
    u, y, breaks = rec.series()
    for degree in degrees:
        result = identify_backlash(u, y, degree, breaks=breaks)
        assert result.converged, result.reason
        assert "singular" not in result.reason
        assert result.model is not None
        simulated = result.model.simulate(rec.u_all, rec.x_all[0])
        assert nrmse(rec.x_all, simulated) < 0.002
        assert result.fit.nrmse < 0.002  # quantisation allows ~0.0007 here


def test_a_singular_regression_takes_a_damped_step() -> None:
    """A branch with slope 0.5 on operation data made iteration 4 singular (a regression
    column collapsed); the damped step keeps the iteration going."""
    model = GeneralBacklash((0.5,), 0.045, (0.5,), 0.05)
    rec = operation_record(OperationSettings(duration=30.0, model=model), 1)
    u, y, breaks = rec.series()
    result = identify_backlash(u, y, 3, breaks=breaks)
    assert result.converged and "singular" not in result.reason, result.reason
    simulated = result.model.simulate(rec.u_all, rec.x_all[0])
    assert nrmse(rec.x_all, simulated) < 0.002


def test_damped_solve_keeps_undetermined_directions() -> None:
    rng = np.random.default_rng(0)
    phi = np.column_stack([rng.normal(size=50), rng.normal(size=50), np.zeros(50)])
    theta_true = np.array([1.0, -2.0, 0.0])
    target = phi @ theta_true
    previous = np.array([0.0, 0.0, 7.0])
    theta = _solve_damped(phi, target, previous)
    assert theta is not None
    np.testing.assert_allclose(theta[:2], theta_true[:2], atol=1e-4)
    assert theta[2] == pytest.approx(7.0)  # no data on it: where it was


@pytest.mark.parametrize("loss", [0.1, 0.3])
def test_lost_readings_with_the_rule_leave_no_bias(loss: float) -> None:
    """Example 1, one command per reading, readings lost at random: with the sample rule the
    estimate is as good as without loss (the equation error and the refinement both)."""
    ex = paper_example(1)
    truth = ex.model.parameters()
    errors, control = [], []
    for seed in range(4):
        d = ex.generate(seed, n_samples=3000)
        keep = np.random.default_rng(seed + 100).random(d.u.size) >= loss
        keep[0] = True
        breaks = sample_breaks(np.flatnonzero(keep) * 1_000_000, 1e6)
        with_rule = identify_backlash(d.u[keep], d.y[keep], 3, breaks=breaks)
        without = identify_backlash(d.u[keep], d.y[keep], 3)
        errors.append(np.max(np.abs(with_rule.model.parameters() - truth)))
        control.append(np.max(np.abs(without.model.parameters() - truth)))
    assert np.mean(errors) < 0.012
    assert np.mean(control) > 3 * np.mean(errors)  # what the rule removes


def test_breaks_and_dropped_nonfinite_samples() -> None:
    ex = paper_example(1)
    d = ex.generate(2, n_samples=1500)
    y = d.y.copy()
    y[100] = np.nan
    breaks = np.zeros(y.size, dtype=bool)
    result = identify_backlash(d.u, y, 3, breaks=breaks, nonfinite="drop")
    assert result.converged
    with pytest.raises(ValueError, match="one flag per sample"):
        identify_backlash(d.u, d.y, 3, breaks=np.zeros(3, dtype=bool))
