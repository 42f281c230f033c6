"""The validation verdict over two held-out blocks (blocked cross-validation).

The loop judges an effect by the validation gap on one held-out block, the last
``validation`` fraction of the record (:func:`~.gap.split_record`). On a record of dwells
and moves that verdict can rest on one or two dwells of that block (on the gravity physics
drivetrain a quarter of the first names changed with the last 40 % held out instead of the
last 30 %; BENCHMARKS, branch diag9-1). A second fold holds out the *first* block of the
same length: each model is refitted on the rest of the record, from its fitted parameters
(as the loop refits a model without an effect, :meth:`~.loop._Run.earns_place`), and
simulated free from the record's first sample over that block. The verdict then pools the
squared errors of both blocks (:class:`Folds`).

A model whose gap drifts along the sample index or the input travel from the first sample
of the series it was fitted on (:class:`~.model.Drift`) is not refitted on the tail: run
back over the head, its drift would start at the wrong origin. A comparison with such a
model is judged on the last block alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError

from .fit import fit_model
from .gap import Split
from .model import AugmentedModel
from .spec import ModelSpec

__all__ = ["FoldErrors", "Folds", "first_block_simulation"]


def first_block_simulation(
    model: AugmentedModel,
    u: FloatArray,
    y: FloatArray,
    split: Split,
    breaks: BoolArray | None = None,
) -> FloatArray | None:
    """``model`` refitted on all but the record's first block (as long as the validation
    segment) and simulated free from the first sample over that block; None when the model
    has a drift (see the module notes) or the refit fails.

    Examples
    --------
    >>> from genbacklash_core import GeneralBacklash
    >>> from genbacklash_core.diagnose.gap import split_record
    >>> from genbacklash_core.diagnose.synthetic import random_walk_input
    >>> u = random_walk_input(1000, np.random.default_rng(0))
    >>> truth = AugmentedModel(GeneralBacklash.ideal(1.0, 0.3, 0.3))
    >>> y = truth.simulate(u) + np.random.default_rng(1).normal(0, 0.01, 1000)
    >>> sim = first_block_simulation(truth, u, y, split_record(1000, 0.3))
    >>> sim.shape, bool(np.sqrt(np.mean((y[:300] - sim) ** 2)) < 0.02)
    ((300,), True)
    """
    if model.drift is not None:
        return None
    n_block = split.n_samples - split.n_estimation
    rest = slice(n_block, split.n_samples)
    try:
        refit = fit_model(model, u[rest], y[rest], breaks=None if breaks is None else breaks[rest])
    except GenBacklashError:
        return None
    spec = ModelSpec.of(refit.model)
    return spec.simulate(spec.vector(refit.model), u[:n_block], float(y[0])).y


@dataclass(frozen=True, eq=False)
class FoldErrors:
    """The held-out readings and one model's simulation of them, fold by fold (the last
    block first)."""

    y: tuple[FloatArray, ...]
    sim: tuple[FloatArray, ...]

    @property
    def squared_errors(self) -> FloatArray:
        """The folds' squared errors, one series (the last block's first)."""
        return np.concatenate([(a - b) ** 2 for a, b in zip(self.y, self.sim, strict=True)])

    def pooled_gap(self) -> float:
        """NRMSE over the folds: the root of their summed squared errors over their summed
        spreads (each block's about its own mean).

        >>> e = FoldErrors((np.array([0.0, 2.0]), np.array([1.0, 3.0])),
        ...                (np.array([0.0, 2.0]), np.array([1.0, 2.0])))
        >>> round(e.pooled_gap(), 6)
        0.5
        """
        spread = sum(float(np.sum((a - np.mean(a)) ** 2)) for a in self.y)
        sse = float(np.sum(self.squared_errors))
        return math.sqrt(sse / spread) if spread > 0.0 else 0.0


@dataclass(frozen=True, eq=False)
class Folds:
    """Both folds of one record: the last block's simulations come with the gap reports,
    the first block's are computed here once per model (cached by the model's ``id``)."""

    u: FloatArray
    y: FloatArray
    split: Split
    breaks: BoolArray | None = None  # of the whole record
    _cache: dict[int, tuple[AugmentedModel, FloatArray | None]] = field(
        default_factory=dict, repr=False
    )

    def first_block(self, model: AugmentedModel) -> FloatArray | None:
        """:func:`first_block_simulation` of ``model``, computed once."""
        hit = self._cache.get(id(model))
        if hit is None or hit[0] is not model:
            hit = (model, first_block_simulation(model, self.u, self.y, self.split, self.breaks))
            self._cache[id(model)] = hit
        return hit[1]

    def errors(
        self,
        models: tuple[AugmentedModel, AugmentedModel],
        last_block: tuple[FloatArray, FloatArray],
    ) -> tuple[FoldErrors, FoldErrors] | None:
        """Two models' folds (``last_block``: their simulations of the validation segment),
        or None when either has no first-block simulation (the last block alone decides)."""
        first = [self.first_block(m) for m in models]
        if first[0] is None or first[1] is None:
            return None
        val = self.split.validation
        head = self.y[: first[0].size]
        ys = (self.y[val], head)
        return (
            FoldErrors(ys, (last_block[0], first[0])),
            FoldErrors(ys, (last_block[1], first[1])),
        )

    def floor_gap(self, floor: float) -> float:
        """A floor measured as a gap on the validation segment (over its output's standard
        deviation) as a gap over both blocks' pooled standard deviation."""
        n_block = self.split.n_samples - self.split.n_estimation
        last = self.y[self.split.validation]
        head = self.y[:n_block]
        rms = floor * float(np.std(last))
        spread = float(np.sum((last - np.mean(last)) ** 2) + np.sum((head - np.mean(head)) ** 2))
        pooled = math.sqrt(spread / (last.size + head.size))
        return rms / pooled if pooled > 0.0 else 0.0
