"""``linear_dynamics``: the output lags the backlash - add the linear block of eq. (30).

Signature: the error step response (see :class:`~genbacklash_core.diagnose.context.
StepErrorShape`): a missing lag leaves a residual that answers a step of the model output with
a smooth decay ``-h a^k``, where a dead time leaves a box. The detector fires when the response
is significant and the shapes do not clearly say "dead time" (see :mod:`.time_delay`).
Augmentation: the cascade (eqs. 31-37) with orders ``(r, p)`` in (1, 1), (2, 1), (2, 2), each
started from the current backlash with a few pole guesses (and, on records of up to 8,000
samples, the paper's iteration); the BIC picks. ``(1, 0)`` is left out: it is a one-sample dead
time. A fitted block whose numerator has a zero outside the unit circle is discarded: a
non-minimum-phase zero is how a rational block imitates a dead time (as Padé approximants
do), and the dead time is the other effect. When the model already has a dead time ``d``, the
cascade's own one-sample delay (``a_1 x(t-1)``) and the lag's mean delay take part of it, so
``d - 1 .. d - 3`` are tried as well.
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.cascade import Cascade
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, fit_model
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.spec import ModelSpec

from ._base import (
    Detection,
    format_p,
    fresh_start,
    late_input,
    paper_start,
    screen_starts,
    screened_fir,
)

__all__ = ["EFFECT", "LinearDynamics", "minimum_phase"]

_ORDERS = ((1, 1), (2, 1), (2, 2))
_POLES = (0.5, 0.8)  # first-order pole guesses for the warm starts
_SCREEN_STEPS = 12  # Levenberg-Marquardt steps per start before the best are finished
_FINALISTS = 4
# Records longer than this start from the current model only, and with a dead time try it and
# one sample less: on long, smooth records (a drivetrain in operation, where a sample is 1 ms)
# the warm starts suffice and each extra start costs a second.
_PAPER_START_LIMIT = 8000


def minimum_phase(model: AugmentedModel) -> bool:
    """True when the linear block's numerator ``a_1 + a_2 q^-1 + ..`` has all zeros inside
    the unit circle (always true for a backlash alone).

    >>> from genbacklash_core import Cascade, GeneralBacklash, LinearBlock
    >>> bl = GeneralBacklash.ideal(1.0, 0.2, 0.2)
    >>> minimum_phase(AugmentedModel(Cascade(bl, LinearBlock(a=(1.0, 3.0), b=(-0.5,)))))
    False
    """
    if not isinstance(model.base, Cascade):
        return True
    a = model.base.linear.a
    if len(a) < 2:
        return True
    return bool(np.all(np.abs(np.roots(a)) < 1.0))


def _with_pole(spec: ModelSpec, theta: FloatArray, pole: float) -> FloatArray:
    """``theta`` with the block's poles all at ``pole`` and the backlash scaled to keep the
    static gain: ``1 + b_1 q^-1 + .. = (1 - pole q^-1)^p``, ``m *= (1 - pole)^p``."""
    out = theta.copy()
    structure = spec.structure
    n, nb = structure.degree, structure.nb
    denominator = np.poly(np.full(nb, pole))  # [1, b_1, .., b_p] (eq. 30)
    scale = (1.0 - pole) ** nb
    out[:n] *= scale  # m_left (eq. 11)
    out[n + 1 : 2 * n + 1] *= scale  # m_right (eq. 12)
    first_b = structure.n_backlash + structure.na - 1
    out[first_b : first_b + nb] = denominator[1:]
    return out


class LinearDynamics:
    """Detector and augmentation of linear dynamics after the backlash."""

    name = "linear_dynamics"

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no linear block."""
        return not model.cascade

    def detect(self, context: Context) -> Detection:
        """Is the error step response significant, and does it decay smoothly?"""
        shape = context.step_error
        fir = shape.fir
        fires = screened_fir(context) and shape.verdict != "dead time"
        head = ", ".join(f"{g:+.2f}" for g in shape.taps[:5])
        evidence = (
            f"the residual answers a step of the model output with {head}, ... (error step "
            f"response explains {100 * fir.share:.1f}% of the residual, "
            f"F = {fir.test.statistic:.1f}, {format_p(fir.test.p_value)}); a smooth decay "
            f"(pole {shape.decay_pole:.2f}) fits it {100 * shape.decay_fit:.0f}%, a box "
            f"{100 * shape.box_fit:.0f}%: "
            + {
                "lag": "the output lags the backlash",
                "dead time": "a dead time, not a lag",
                "unclear": "a lag or a dead time - the fits decide",
            }[shape.verdict]
        )
        late, lag, sentence = late_input(context)
        if late and not fires:  # a model that explains nothing has no step response to read
            return Detection(self.name, True, float(lag), 1.0, f"{sentence}: a lag?", {})
        return Detection(
            self.name,
            fires,
            shape.decay_fit,
            shape.box_fit,
            evidence,
            {"pole": shape.decay_pole},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit as a cascade for each candidate order (and dead time); the BIC picks among
        the minimum-phase fits."""
        starts: list[tuple[ModelSpec, FloatArray]] = []
        guess = float(detection.hints.get("pole", 0.0))
        poles = sorted({*_POLES, *([round(guess, 2)] if 0.05 < guess < 0.97 else [])})
        delay = context.spec.delay
        back = (1, 2, 3) if context.u.size <= _PAPER_START_LIMIT else (1,)
        delays = sorted({delay, *(max(0, delay - k) for k in back)}) if delay else [0]
        for orders in _ORDERS:
            for trial_delay in delays:
                spec = context.spec.extended(orders=orders, delay=trial_delay)
                bases = [spec.embed(context.fit.model)]
                fresh = fresh_start(context, spec) if context.degenerate else None
                if fresh is not None:
                    bases.append(fresh[1])
                starts += [(spec, _with_pole(spec, b, pole)) for b in bases for pole in poles]
            if context.u.size > _PAPER_START_LIMIT:
                continue  # the paper's cascade iteration costs seconds on long records
            paper_spec = context.spec.extended(orders=orders, delay=max(0, delay - 1))
            paper = paper_start(context, paper_spec)
            if paper is not None:
                starts.append(paper)
        screened = screen_starts(context, starts, _SCREEN_STEPS)
        chosen = [fit for fit in screened if minimum_phase(fit.model)][:_FINALISTS]
        chosen += [fit for fit in screened[:1] if fit not in chosen]
        finals = [
            fit_model(fit.model, context.u, context.y, breaks=context.breaks) for fit in chosen
        ]
        valid = [fit for fit in finals if minimum_phase(fit.model)]
        return min(valid, key=lambda fit: fit.bic) if valid else None


EFFECT = LinearDynamics()
