"""The contract of a catalog effect: a detector and an augmentation.

An effect is an object with a ``name`` (a GUIDE §4 contract name), ``applicable(model)``,
``detect(context) -> Detection`` (a signature statistic against a threshold, with a sentence of
evidence that carries the numbers) and ``augment(context, detection) -> ModelFit | None`` (the
model extended by the effect and refitted on the estimation data). Adding an effect is one
module with such an object, registered in :data:`genbacklash_core.diagnose.effects.CATALOG`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, fit_model
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.spec import ModelSpec, shift_input
from genbacklash_core.diagnose.stats import NestedTest, nested_f_test
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import identify_backlash, identify_cascade

__all__ = [
    "Detection",
    "Effect",
    "format_p",
    "fresh_start",
    "late_input",
    "paper_start",
    "score_test",
    "screened",
    "screened_fir",
]


@dataclass(frozen=True)
class Detection:
    """A detector's verdict on the current model.

    Attributes
    ----------
    effect : str
        The effect's name.
    fires : bool
        True when the signature statistic passes its threshold.
    statistic : float
        The signature statistic.
    threshold : float
        What it was compared with.
    evidence : str
        One sentence with the numbers.
    hints : mapping
        What the detector learnt that the augmentation can start from (e.g. a dead time).
    """

    effect: str
    fires: bool
    statistic: float
    threshold: float
    evidence: str
    hints: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.effect:
            raise GenBacklashError("a detection needs the effect's name")
        if not self.evidence:
            raise GenBacklashError(f"detection of {self.effect} needs a sentence of evidence")


class Effect(Protocol):
    """A catalog entry (see the module docstring)."""

    name: str

    def applicable(self, model: AugmentedModel) -> bool:
        """Whether the effect can still be added to ``model``."""

    def detect(self, context: Context) -> Detection:
        """The signature statistic, its threshold and the evidence."""

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """The model extended by the effect, refitted; None when no valid fit exists."""


def format_p(p: float) -> str:
    """A p-value for a sentence: ``p = 0.003`` or ``p < 1e-12``.

    >>> format_p(0.0031), format_p(0.0)
    ('p = 0.0031', 'p < 1e-12')
    """
    return "p < 1e-12" if p < 1e-12 else f"p = {p:.2g}"


def screened(test: NestedTest, context: Context) -> bool:
    """Whether a signature test passes the screening thresholds (significance and size)."""
    settings = context.settings
    return test.test.p_value < settings.screen_alpha and test.share >= settings.min_share


def screened_fir(context: Context) -> bool:
    """Whether the error step response (the dynamic effects' signature) passes screening."""
    fir = context.step_error.fir
    settings = context.settings
    return fir.test.p_value < settings.screen_alpha and fir.share >= settings.min_share


def late_input(context: Context) -> tuple[bool, int, str]:
    """Evidence that the output follows the input late, for a model that explains nothing.

    When the current model is degenerate (a dead time or lag it lacks hides every input-output
    relation at lag 0, typical with a white input) its simulated output carries no signature,
    but the prewhitened input still correlates with the residual at the lags where the output
    follows it. Returns ``(significant, peak lag, sentence)``.
    """
    ccf = context.analysis.cross_correlation
    causal = ccf.lags >= 1
    values = ccf.values[causal]
    peak = int(np.argmax(np.abs(values)))
    lag = int(ccf.lags[causal][peak])
    p_value = context.analysis.cross_portmanteau.p_value
    significant = (
        context.degenerate
        and p_value < context.settings.screen_alpha
        and abs(values[peak]) > ccf.bound
    )
    sentence = (
        f"the model explains almost none of the output (free-run NRMSE "
        f"{context.fit.nrmse:.2f}) while the prewhitened input correlates with the residual "
        f"most at lag {lag} (r = {values[peak]:+.2f}, 95% bound {ccf.bound:.2f}; portmanteau "
        f"{format_p(p_value)}): the output follows the input late"
    )
    return significant, lag, sentence


def fresh_start(context: Context, spec: ModelSpec) -> tuple[ModelSpec, FloatArray] | None:
    """A start for ``spec`` that does not inherit a degenerate base: straight branches with
    the least-squares slope of the output on the (delayed) input, dead zones 5% of the span."""
    u = shift_input(context.u, spec.delay)
    uc = u - np.mean(u)
    slope = abs(float(uc @ (context.y - np.mean(context.y))) / float(uc @ uc))
    if not (np.isfinite(slope) and slope > 0.0):
        return None
    structure = spec.structure
    n = structure.degree
    current = context.fit.model
    plain = AugmentedModel(
        GeneralBacklash(
            (structure.sign * slope, *([0.0] * (n - 1))),
            0.05 * float(np.ptp(u)),
            (structure.sign * slope, *([0.0] * (n - 1))),
            0.05 * float(np.ptp(u)),
        ),
        spec.delay,
        current.offset,
        current.drift,
        current.saturation,
    )
    return spec, spec.embed(plain)


def screen_starts(
    context: Context,
    starts: list[tuple[ModelSpec, FloatArray]],
    steps: int,
) -> list[ModelFit]:
    """A few Levenberg-Marquardt ``steps`` from each start on the estimation data, best BIC
    first; a start invalid on this record is skipped. The finalists are then fitted fully."""
    fits: list[ModelFit] = []
    for start in starts:
        try:
            fits.append(
                fit_model(start, context.u, context.y, max_iterations=steps, breaks=context.breaks)
            )
        except GenBacklashError:
            continue  # an invalid start on this record
    fits.sort(key=lambda fit: fit.bic)
    return fits


def score_test(context: Context, spec: ModelSpec, theta: FloatArray) -> NestedTest:
    """Score (Lagrange multiplier) test of an extension: does ``dy/dtheta`` of the extended
    model, taken where it equals the current one, explain the residual beyond the current
    model's own Jacobian?  Its coefficients are one Gauss-Newton step into the extension.
    """
    anchors = context.anchors
    out = spec.simulate(theta, context.u, context.y_start, anchors, context.y)
    extended = spec.jacobian(theta, context.u, out, context.y_start, anchors)
    return nested_f_test(context.residual, context.jacobian, extended)


def paper_start(
    context: Context, spec: ModelSpec, offset: float | None = None
) -> tuple[ModelSpec, FloatArray] | None:
    """A start for ``spec`` from the paper's identification (eqs. 22-29 / 31-37).

    The base model of ``spec`` is identified on data with the dead time of ``spec`` and the
    offset (default: the current model's) removed; the other parts come from the current
    model. None when the current model carries a drift or saturation (which the paper's
    iteration cannot see past) or identification fails.
    """
    current = context.fit.model
    if current.drift is not None or current.saturation is not None:
        return None
    structure = spec.structure
    offset = current.offset if offset is None else offset
    u = shift_input(context.u, spec.delay)
    y = context.y - offset
    try:
        if structure.cascade:
            result = identify_cascade(
                u,
                y,
                structure.degree,
                structure.na,
                structure.nb,
                sign=structure.sign,
                breaks=context.breaks,
            )
        else:
            result = identify_backlash(
                u, y, structure.degree, sign=structure.sign, breaks=context.breaks
            )
    except GenBacklashError:
        return None
    model = AugmentedModel(result.model, spec.delay, offset)
    theta = spec.embed(model)
    if not np.all(np.isfinite(theta)):
        return None
    return spec, theta


def log10_p(p: float) -> float:
    """``-log10(p)``, capped at 300 (for ranking statistics)."""
    return 300.0 if p <= 0.0 else min(300.0, -math.log10(p))
