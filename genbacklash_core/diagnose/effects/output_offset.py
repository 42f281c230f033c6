"""``output_offset``: the output's zero is not the backlash's - add a constant to the output.

An offset smaller than a dead zone is absorbed exactly by shifting ``c_L`` and ``c_R`` (for
straight branches ``m (u + c) + o = m (u + c + o/m)``), so there is nothing to name. A larger
one cannot be: a dead-zone constant would have to turn negative, the fit pins it near zero and
the residual keeps a mean.
Signature: the residual mean against its Newey-West standard error, with its size relative
to the residual RMS; or a dead-zone constant pinned at its bound (below 2% of the input span)
while the residual is not white - the fit wanted it negative.
Augmentation: refit with an offset from several starts (the residual mean, the output's centre
against the input's, and the paper's iteration on the output minus that centre), then centre
the gap (for straight branches an offset and the gaps trade exactly; report ``c_L = c_R``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.spec import ModelSpec

from ._base import Detection, format_p, paper_start

__all__ = ["EFFECT", "OutputOffset", "centre_gap"]

_PINNED = 0.02  # a dead-zone constant below this share of the input span sits on its bound


def centre_gap(model: AugmentedModel) -> AugmentedModel:
    """The same input-output behaviour with ``c_L = c_R`` (straight branches only).

    Shifting the backlash output by ``delta`` moves ``c_L`` by ``delta / m_L`` and ``c_R``
    by ``-delta / m_R`` (eqs. 11-12 with ``n = 1``); the offset takes ``-G(1) delta``.

    >>> m = AugmentedModel(GeneralBacklash.ideal(1.0, 0.5, 0.1), offset=1.0)
    >>> c = centre_gap(m)
    >>> c.backlash.c_left, c.backlash.c_right, c.offset
    (0.3, 0.3, 1.2)
    """
    bl = model.backlash
    if bl.degree != 1 or model.offset == 0.0:
        return model
    m_left, m_right = bl.m_left[0], bl.m_right[0]
    delta = (bl.c_right - bl.c_left) / (1.0 / m_left + 1.0 / m_right)
    c_left = bl.c_left + delta / m_left
    c_right = bl.c_right - delta / m_right
    if not (c_left > 0 and c_right > 0):
        return model
    centred = GeneralBacklash(bl.m_left, round(c_left, 15), bl.m_right, round(c_right, 15))
    gain = 1.0
    base: GeneralBacklash | Cascade = centred
    if isinstance(model.base, Cascade):
        gain = model.base.linear.dc_gain
        base = Cascade(centred, model.base.linear)
    if not math.isfinite(gain):
        return model
    return replace(model, base=base, offset=round(model.offset - gain * delta, 15))


class OutputOffset:
    """Detector and augmentation of an output offset."""

    name = "output_offset"

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no offset."""
        return model.offset == 0.0

    def detect(self, context: Context) -> Detection:
        """A residual mean that is significant and large next to the residual RMS."""
        analysis = context.analysis
        share = analysis.mean_value**2 / max(analysis.rms**2, 1e-300)
        bl = context.fit.model.backlash
        span = float(np.ptp(context.u))
        pinned = min(bl.c_left, bl.c_right) < _PINNED * span and not analysis.white(
            context.settings.alpha
        )
        significant = analysis.mean.p_value < context.settings.screen_alpha
        fires = (significant and share >= context.settings.min_share) or pinned
        evidence = (
            f"the residual has mean {analysis.mean_value:+.3g} (t = {analysis.mean.statistic:.1f}"
            f" with a Newey-West variance, {format_p(analysis.mean.p_value)}), "
            f"{100 * share:.1f}% of its mean square; the fitted dead zones are "
            f"c_L = {bl.c_left:.3g}, c_R = {bl.c_right:.3g}"
            + (
                " (one is pinned near zero: the branches cannot absorb the offset)"
                if pinned
                else ""
            )
        )
        return Detection(
            self.name,
            fires,
            share,
            context.settings.min_share,
            evidence,
            {"mean": analysis.mean_value},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit with an offset from several starts; centre the gap."""
        spec = context.spec.extended(offset=True)
        model = context.fit.model
        theta = spec.embed(model)
        index = spec.names().index("offset")
        bl = model.backlash
        slope = 0.5 * (bl.m_left[0] + bl.m_right[0])
        centre = float(np.median(context.y) - slope * np.median(context.u))
        guesses = {model.offset + float(detection.hints.get("mean", 0.0)), centre}
        starts: list[tuple[ModelSpec, FloatArray]] = []
        for guess in guesses:
            start = theta.copy()
            start[index] = guess
            starts.append((spec, start))
            paper = paper_start(context, spec, offset=guess)
            if paper is not None:
                starts.append(paper)
        fit = best_fit(starts, context.u, context.y, breaks=context.breaks)
        if fit is None:
            return None
        return replace(fit, model=centre_gap(fit.model))


EFFECT = OutputOffset()
