"""``gap_drift``: the gap grows with time or travel (wear) - let ``c(t) = c + k s(t)``.

Signature: a score test of the drift rate ``k`` at ``k = 0``, along time and along input
travel: the residual follows ``s(t) dy/dc`` (the gap sensitivity, held between engagements,
weighted by how far into the record the sample is). Its coefficient is one Gauss-Newton step,
an estimate of the growth.
Augmentation: refit with a drift along each basis, from 0 and from that step; the BIC picks.
"""

from __future__ import annotations

from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit
from genbacklash_core.diagnose.model import AugmentedModel, DriftBasis
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.diagnose.stats import NestedTest

from ._base import Detection, format_p, score_test, screened

__all__ = ["EFFECT", "GapDrift"]

_BASES: tuple[DriftBasis, ...] = ("time", "travel")


class GapDrift:
    """Detector and augmentation of a drifting gap."""

    name = "gap_drift"

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no drift."""
        return model.drift is None

    def _tests(self, context: Context) -> dict[DriftBasis, tuple[ModelSpec, NestedTest]]:
        out: dict[DriftBasis, tuple[ModelSpec, NestedTest]] = {}
        for basis in _BASES:
            spec = context.spec.extended(drift=basis)
            out[basis] = (spec, score_test(context, spec, spec.embed(context.fit.model)))
        return out

    def detect(self, context: Context) -> Detection:
        """Score test of a gap drift along time and along travel; the stronger one counts."""
        tests = self._tests(context)
        basis = max(tests, key=lambda b: tests[b][1].share)
        spec, test = tests[basis]
        rate = float(test.coefficients[spec.names().index("drift_rate")])
        coordinate = spec.coordinate(context.u)
        span = float(coordinate[-1]) if coordinate is not None else 0.0
        bl = context.fit.model.backlash
        fires = screened(test, context)
        evidence = (
            f"a play (c_L + c_R) changing along {basis} explains {100 * test.share:.1f}% of "
            "the residual "
            f"(score test F = {test.test.statistic:.1f}, {format_p(test.test.p_value)}); one "
            f"Gauss-Newton step puts the change of each dead zone over the estimation record at "
            f"{rate * span:+.3g} (fitted c_L = {bl.c_left:.3g}, c_R = {bl.c_right:.3g})"
        )
        return Detection(
            self.name,
            fires,
            test.share,
            context.settings.min_share,
            evidence,
            {"rate": rate, "basis": float(_BASES.index(basis))},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit with a drift along time and along travel; the BIC picks."""
        starts = []
        for basis in _BASES:
            spec = context.spec.extended(drift=basis)
            theta = spec.embed(context.fit.model)
            starts.append((spec, theta))
            if _BASES[int(detection.hints.get("basis", 0.0))] == basis:
                stepped = theta.copy()
                stepped[spec.names().index("drift_rate")] = float(detection.hints.get("rate", 0.0))
                starts.append((spec, stepped))
        return best_fit(starts, context.u, context.y, breaks=context.breaks)


EFFECT = GapDrift()
