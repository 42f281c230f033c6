"""``saturation``: the output stops at a limit (a hard stop, a sensor range) - clip it.

Signature: hinge regressions of the residual on ``(y_sim - q)_+`` (upper limit) and
``(q - y_sim)_+`` (lower limit) for knots ``q`` at high (low) quantiles of the simulated output,
beyond the current model's Jacobian. A limit leaves a residual that cancels the model's rise
past the knot: a coefficient near -1 (upper) or +1 (lower). The detector fires when the best
hinge is significant and flattens the output by at least half.
Augmentation: refit with the limit on that side (or both, when both flatten), started at each
knot; the BIC picks.
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.diagnose.stats import NestedTest, nested_f_test

from ._base import Detection, format_p, screened

__all__ = ["EFFECT", "OutputLimit"]

_KNOTS = (0.75, 0.85, 0.92, 0.97)  # quantiles of the simulated output tried as hinge knots
_FLATTENING = 0.5  # the hinge must cancel at least this share of the model's slope


class OutputLimit:
    """Detector and augmentation of an output limit."""

    name = "saturation"

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no limit."""
        return model.saturation is None

    def _hinges(self, context: Context) -> list[tuple[str, float, NestedTest]]:
        y_sim = context.simulation.y
        out = []
        for side in ("high", "low"):
            for level in _KNOTS:
                q = float(np.quantile(y_sim, level if side == "high" else 1.0 - level))
                hinge = np.maximum(y_sim - q, 0.0) if side == "high" else np.maximum(q - y_sim, 0.0)
                if not np.any(hinge > 0):
                    continue
                out.append((side, q, nested_f_test(context.residual, context.jacobian, hinge)))
        return out

    def detect(self, context: Context) -> Detection:
        """The best flattening hinge on either side."""
        hinges = self._hinges(context)
        flattening = {"high": -1.0, "low": 1.0}
        candidates = [
            (side, q, test)
            for side, q, test in hinges
            if flattening[side] * float(test.coefficients[0]) >= _FLATTENING
        ]
        if not candidates:
            return Detection(
                self.name,
                False,
                0.0,
                context.settings.min_share,
                "past its extremes the measured output keeps following the model "
                "(no hinge flattens it by half)",
            )
        side, q, test = max(candidates, key=lambda c: c[2].share)
        both = {s for s, _, t in candidates if screened(t, context)} == {"high", "low"}
        slope = 1.0 + float(test.coefficients[0]) * (-1.0 if side == "low" else 1.0)
        fires = screened(test, context)
        where = "above" if side == "high" else "below"
        evidence = (
            f"{where} a simulated output of {q:.3g} the measured output changes only "
            f"{slope:.2f} per unit of the model's (hinge regression beyond the model's "
            f"Jacobian explains {100 * test.share:.1f}% of the residual, "
            f"F = {test.test.statistic:.1f}, {format_p(test.test.p_value)}): an output limit"
            + (" on both sides" if both else "")
        )
        return Detection(
            self.name,
            fires,
            test.share,
            context.settings.min_share,
            evidence,
            {"high": float(side == "high" or both), "low": float(side == "low" or both), "knot": q},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit with the limit(s), started at each knot on that side."""
        high = bool(detection.hints.get("high", 1.0))
        low = bool(detection.hints.get("low", 0.0))
        spec = context.spec.extended(saturation=(low, high))
        theta = spec.embed(context.fit.model)
        y_sim = context.simulation.y
        starts: list[tuple[ModelSpec, FloatArray]] = []
        for level in _KNOTS:
            start = theta.copy()
            if high:
                start[spec.names().index("saturation_high")] = np.quantile(y_sim, level)
            if low:
                start[spec.names().index("saturation_low")] = np.quantile(y_sim, 1.0 - level)
            starts.append((spec, start))
        return best_fit(starts, context.u, context.y, breaks=context.breaks)


EFFECT = OutputLimit()
