"""The restarted validation misfit (genbacklash_core.diagnose.prediction) and the loop's use of
it: load physics ranked among themselves by what they predict between lost readings."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.cascade import Cascade, LinearBlock
from genbacklash_core.diagnose import AugmentedModel, DiagnoseSettings
from genbacklash_core.diagnose.gap import measure_gap, split_record
from genbacklash_core.diagnose.loop import _Candidate, _Run
from genbacklash_core.diagnose.physics import LoadPhysics
from genbacklash_core.diagnose.prediction import restarted_gap
from genbacklash_core.diagnose.spec import ModelSpec, anchors_of

N = 3000


def _record(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, AugmentedModel]:
    """A ringing spring's load, knocked to a random place at each of 60 lost readings: the
    truth restarted there predicts every sample, its free run does not."""
    rng = np.random.default_rng(seed)
    u = np.cumsum(rng.normal(0.0, 0.02, N))
    truth = AugmentedModel(
        GeneralBacklash.ideal(1.0, 0.2, 0.2),
        physics=LoadPhysics("compliant_coupling", 0.99, 0.0, 1, stiffness=0.15, damping=0.05),
    )
    breaks = np.zeros(N, dtype=bool)
    breaks[0] = True
    breaks[rng.choice(np.arange(100, N), 60, replace=False)] = True
    spec = ModelSpec.of(truth)
    theta = spec.vector(truth)
    free = spec.simulate(theta, u, 0.0).y
    knocked = free + rng.normal(0.0, 0.1, N)
    y = spec.simulate(theta, u, 0.0, anchors=anchors_of(breaks), y=knocked).y
    return u, y, breaks, truth


def test_the_truth_restarted_predicts_every_sample_its_free_run_drifts() -> None:
    u, y, breaks, truth = _record(0)
    split = split_record(N, 0.3)
    assert restarted_gap(truth, u, y, split, breaks) < 1e-9
    assert measure_gap(truth, u, y, split).gap > 0.05


def test_a_cascade_cannot_restart() -> None:
    model = AugmentedModel(
        Cascade(GeneralBacklash.ideal(0.5, 0.2, 0.2), LinearBlock(a=(1.0,), b=(-0.5, 0.0)))
    )
    u = np.linspace(0.0, 1.0, 200)
    with pytest.raises(GenBacklashError, match="linear block"):
        restarted_gap(model, u, u, split_record(200, 0.3), np.zeros(200, dtype=bool))


def _candidate(model: AugmentedModel) -> Any:
    return SimpleNamespace(fit=SimpleNamespace(model=model))


@pytest.mark.parametrize("seed", [0, 1])
def test_load_physics_are_ranked_among_their_places_by_the_restarted_misfit(seed: int) -> None:
    u, y, breaks, truth = _record(seed)
    coasting = AugmentedModel(truth.base, physics=LoadPhysics("coasting_load", 0.99, 0.0, 1))
    plain = AugmentedModel(truth.base)
    other = _candidate(AugmentedModel(truth.base, offset=0.01))
    first, spring = _candidate(coasting), _candidate(truth)
    run = _Run(u, y, split_record(N, 0.3), (), DiagnoseSettings(), record_breaks=breaks)
    ranked, predicted = run.physics_by_prediction([first, other, spring], plain)
    assert ranked == [spring, other, first]
    assert predicted is not None and predicted.misfit[id(spring)] < 1e-9
    assert predicted.before == restarted_gap(plain, u, y, split_record(N, 0.3), breaks)
    assert run.physics_by_prediction([spring, other, first], plain)[0] == [spring, other, first]
    unbroken = _Run(u, y, split_record(N, 0.3), (), DiagnoseSettings())
    assert unbroken.physics_by_prediction([first, other, spring], plain) == (
        [first, other, spring],
        None,
    )


def test_a_restarted_misfit_that_tells_no_load_physics_from_the_model_ranks_nothing() -> None:
    """When no load physics predicts the restarted runs better than the model it augments by
    what the loop calls a drop, that misfit does not rank them: the free-run order stays."""
    u, y, breaks, truth = _record(0)
    coasting = AugmentedModel(truth.base, physics=LoadPhysics("coasting_load", 0.99, 0.0, 1))
    first, spring = _candidate(coasting), _candidate(truth)
    run = _Run(u, y, split_record(N, 0.3), (), DiagnoseSettings(), record_breaks=breaks)
    # the truth itself as the model: nothing predicts better than it
    assert run.physics_by_prediction([first, spring], truth) == ([first, spring], None)


def _fitted(effect: str, model: AugmentedModel, bic_change: float) -> Any:
    """A candidate as the loop holds it (its detection's name, its fit, its BIC change)."""
    fit = SimpleNamespace(model=model, bic=bic_change, n_free=ModelSpec.of(model).n_free)
    return _Candidate(SimpleNamespace(effect=effect), fit, bic_change)  # type: ignore[arg-type]


def test_a_near_tie_between_load_physics_is_measured_on_the_restarted_misfit() -> None:
    """The yardstick that ranked two load physics also breaks their near tie.

    The truth (a ringing spring) restarted after each loss predicts every validation sample;
    a softer spring drifts less in the free run (NRMSE 0.34 against 0.37) but predicts the
    restarted runs no better than the plain backlash. With a lower BIC the softer spring
    took the near tie on the free run (the gravity known answer's failure: a load torque
    ranked first by the restarted misfit, then the spring's free run and BIC took it).
    """
    u, y, breaks, truth = _record(0)
    split = split_record(N, 0.3)
    soft = AugmentedModel(
        truth.base,
        physics=LoadPhysics("compliant_coupling", 0.99, 0.0, 1, stiffness=0.1, damping=0.05),
    )
    plain = AugmentedModel(truth.base)
    chosen = _fitted("compliant_coupling", truth, -2000.0)
    rival = _fitted("compliant_coupling", soft, -3000.0)
    run = _Run(u, y, split, (), DiagnoseSettings(), breaks[split.estimation], record_breaks=breaks)
    ranked, gaps, predicted = run.rank_by_gap([rival, chosen], plain)
    report = measure_gap(plain, u, y, split)
    # a near tie on the free run: the rival closes more of the misfit than the truth does
    assert report.gap - gaps[id(rival)].gap > report.gap - gaps[id(chosen)].gap
    assert ranked == [chosen, rival]
    assert not run.ties(report, chosen, rival, gaps, predicted)
    assert run.break_tie(report, [chosen, rival], chosen, gaps, predicted) is None
    # on the free run it is a near tie, and the lower BIC takes it
    assert run.ties(report, chosen, rival, gaps, None)
    swapped = run.break_tie(report, [chosen, rival], chosen, gaps, None)
    assert swapped is not None and swapped[0] is rival


def test_misfits_restart_only_load_physics_without_a_linear_block() -> None:
    u, y, breaks, truth = _record(1)
    split = split_record(N, 0.3)
    run = _Run(u, y, split, (), DiagnoseSettings(), breaks[split.estimation], record_breaks=breaks)
    coasting = AugmentedModel(truth.base, physics=LoadPhysics("coasting_load", 0.99, 0.0, 1))
    plain = AugmentedModel(truth.base)
    (mine, other), what = run.misfits(truth, coasting, restarted=True)
    assert what == "validation misfit restarted after each loss"
    assert mine < 1e-9 < restarted_gap(coasting, u, y, split, breaks) == other
    free = (measure_gap(truth, u, y, split).gap, measure_gap(plain, u, y, split).gap)
    (mine, other), what = run.misfits(truth, plain, restarted=True)  # plain: no load physics
    assert what == "validation misfit"
    assert (mine, other) == free
    assert run.misfits(truth, plain, restarted=False)[0] == list(free)
