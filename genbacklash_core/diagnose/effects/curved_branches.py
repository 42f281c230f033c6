"""``curved_branches``: the branches are curves, not lines - raise the polynomial degree.

Signature: a score test of the higher branch coefficients (eqs. 11-12 with ``n + 1``, ``n + 2``
terms), taken at the current model: on the engaged branches the residual follows the next
powers of ``xi_1 = u + c_L`` and ``xi_2 = u - c_R`` (eqs. 16-17).
Augmentation: refit with degree ``n + 1`` and ``n + 2`` (from the current model and from the
paper's iteration) and keep the lower BIC.
"""

from __future__ import annotations

from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit
from genbacklash_core.diagnose.model import AugmentedModel

from ._base import Detection, format_p, paper_start, score_test, screened

__all__ = ["EFFECT", "CurvedBranches"]


class CurvedBranches:
    """Detector and augmentation of curved branches."""

    name = "curved_branches"

    def applicable(self, model: AugmentedModel) -> bool:
        """Always: the degree can be raised up to the settings' limit."""
        return True

    def detect(self, context: Context) -> Detection:
        """Score test of two more branch coefficients per branch."""
        degree = context.spec.structure.degree
        target = min(degree + 2, context.settings.max_degree)
        if target <= degree:
            return Detection(self.name, False, 0.0, 0.0, f"the degree is at the limit ({degree})")
        spec = context.spec.extended(degree=target)
        test = score_test(context, spec, spec.embed(context.fit.model))
        fires = screened(test, context)
        evidence = (
            f"on the engaged branches the residual follows the powers {degree + 1}..{target} "
            f"of the branch variables: they explain {100 * test.share:.1f}% of it "
            f"(score test F = {test.test.statistic:.1f}, {format_p(test.test.p_value)}), so "
            f"the degree-{degree} branches are " + ("too straight" if fires else "curved enough")
        )
        return Detection(
            self.name, fires, test.share, context.settings.min_share, evidence, {"degree": target}
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit with one and with two more coefficients per branch; keep the lower BIC."""
        degree = context.spec.structure.degree
        starts = []
        for new in range(degree + 1, min(degree + 2, context.settings.max_degree) + 1):
            spec = context.spec.extended(degree=new)
            starts.append((spec, spec.embed(context.fit.model)))
            paper = paper_start(context, spec)
            if paper is not None:
                starts.append(paper)
        return best_fit(starts, context.u, context.y, breaks=context.breaks)


EFFECT = CurvedBranches()
