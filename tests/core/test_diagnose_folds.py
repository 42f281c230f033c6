"""The validation verdict over two held-out blocks (``DiagnoseSettings.folds``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.diagnose import AugmentedModel, DiagnoseSettings, measure_gap, split_record
from genbacklash_core.diagnose.folds import FoldErrors, Folds, first_block_simulation
from genbacklash_core.diagnose.loop import _judge
from genbacklash_core.diagnose.model import Drift
from genbacklash_core.diagnose.synthetic import random_walk_input

RNG_SEED = 20261128


def _record(n: int = 1500) -> tuple[np.ndarray, np.ndarray, AugmentedModel]:
    u = random_walk_input(n, np.random.default_rng(RNG_SEED))
    truth = AugmentedModel(GeneralBacklash.ideal(1.0, 0.3, 0.3))
    y = truth.simulate(u) + np.random.default_rng(RNG_SEED + 1).normal(0.0, 0.02, n)
    return u, y, truth


@pytest.mark.parametrize("folds", [0, 3, True, 2.0])
def test_folds_must_be_one_or_two(folds: object) -> None:
    with pytest.raises(GenBacklashError, match="folds must be 1 or 2"):
        DiagnoseSettings(folds=folds)  # type: ignore[arg-type]


def test_a_drifting_model_is_judged_on_the_last_block_alone() -> None:
    u, y, truth = _record()
    split = split_record(u.size, 0.3)
    drifting = AugmentedModel(GeneralBacklash.ideal(1.0, 0.3, 0.3), drift=Drift(1e-5))
    assert first_block_simulation(drifting, u, y, split) is None
    sim = first_block_simulation(truth, u, y, split)
    assert sim is not None and sim.size == 450
    # the truth refitted on the last 70 % predicts the first 30 % to the noise
    assert math.sqrt(float(np.mean((y[:450] - sim) ** 2))) < 0.03


def test_the_verdict_pools_both_blocks() -> None:
    u, y, truth = _record()
    split = split_record(u.size, 0.3)
    folds = Folds(u, y, split)
    wide = AugmentedModel(GeneralBacklash.ideal(1.0, 0.5, 0.1))  # a wrong play, not refitted
    good, bad = measure_gap(truth, u, y, split), measure_gap(wide, u, y, split)
    val = split.validation
    settings = DiagnoseSettings()
    ok, verdict = _judge(y[val], bad, good, -100.0, settings, folds=folds)
    assert ok and "over both held-out blocks" in verdict
    # the pooled misfits the verdict quotes are those of both blocks' errors
    pooled = folds.errors((wide, truth), (bad.y_sim[val], good.y_sim[val]))
    assert pooled is not None
    before, after = (e.pooled_gap() for e in pooled)
    assert f"{before:.4f} -> {after:.4f}" in verdict
    assert not _judge(y[val], good, bad, -100.0, settings, folds=folds)[0]
    # a model without a first-block simulation: the last block alone, as with one fold
    drifting = AugmentedModel(truth.backlash, drift=Drift(0.0))
    alone = measure_gap(drifting, u, y, split)
    ok, verdict = _judge(y[val], bad, alone, -100.0, settings, folds=folds)
    assert ok and "over both held-out blocks" not in verdict


def test_pooled_gap_weights_each_block_by_its_spread() -> None:
    rng = np.random.default_rng(RNG_SEED + 2)
    last, head = rng.normal(0.0, 1.0, 300), rng.normal(0.0, 3.0, 200)
    errors = FoldErrors((last, head), (last + 0.1, head - 0.2))
    spread = np.sum((last - last.mean()) ** 2) + np.sum((head - head.mean()) ** 2)
    expected = math.sqrt((300 * 0.01 + 200 * 0.04) / spread)
    assert errors.pooled_gap() == pytest.approx(expected, rel=1e-12)
    assert errors.squared_errors.size == 500


def test_the_floor_over_both_blocks_keeps_its_rms() -> None:
    u, y, _ = _record()
    split = split_record(u.size, 0.3)
    folds = Folds(u, y, split)
    rms = 0.001
    floor = rms / float(np.std(y[split.validation]))
    both = np.concatenate([y[split.validation], y[:450]])
    pooled_std = math.sqrt(
        (
            np.sum((y[split.validation] - y[split.validation].mean()) ** 2)
            + np.sum((y[:450] - y[:450].mean()) ** 2)
        )
        / both.size
    )
    assert folds.floor_gap(floor) == pytest.approx(rms / pooled_std, rel=1e-12)
