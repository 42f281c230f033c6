"""``time_delay``: a dead time ``d`` between the command and the backlash - shift the input.

Signature: the error step response (see :class:`~genbacklash_core.diagnose.context.
StepErrorShape`). A missing dead time leaves ``e(t) = y_sim(t-d) - y_sim(t)``: the residual
answers a step of the model output with a *box* of ``d`` taps near -1 and zeros after, where a
missing lag leaves a smooth decay. The detector fires when the response is significant and
the shapes do not clearly say "lag"; :mod:`.linear_dynamics` fires unless they clearly say
"dead time". So the two effects that mimic each other are told apart by this evidence, and
where it is unclear (an underdamped lag overshoots, which neither shape follows) both are
fitted and the BIC decides. On 120 generated records with a dead time or a lag (alone, with
curvature or with a limit) a clear verdict was never the wrong one.
Augmentation: search ``d = 1..max_delay`` with short refits and refit the best fully.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np

from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit, fit_model
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.linear import LinearBlock

from ._base import Detection, format_p, fresh_start, late_input, screened_fir

__all__ = ["EFFECT", "TimeDelay"]

_SCAN_STEPS = 6  # Levenberg-Marquardt steps per trial dead time in the search
_FINALISTS = 2  # trial dead times refitted fully


def _one_stage(model: AugmentedModel) -> list[AugmentedModel]:
    """``model`` with its servo's lag in one stage of the same total time constant, when it
    has two (``[]`` otherwise): searched with each dead time, because a second equal stage is
    what stood in for the dead time beyond the servo's (two equal poles are close to one lag
    a sample or more late).

    >>> from genbacklash_core.backlash import GeneralBacklash
    >>> bl = GeneralBacklash.ideal(1.0, 0.1, 0.1)
    >>> [m.input_lag for m in _one_stage(AugmentedModel(bl, input_lag=0.81, input_lag_order=2))]
    [0.9]
    >>> _one_stage(AugmentedModel(bl, input_lag=0.9))
    []
    """
    if model.input_lag == 0.0 or model.input_lag_order == 1:
        return []
    pole = float(model.input_lag ** (1.0 / model.input_lag_order))
    return [replace(model, input_lag=round(pole, 15), input_lag_order=1)]


def _first_order(model: AugmentedModel) -> list[AugmentedModel]:
    """``model`` with the linear block after its play reduced to a first-order lag (``a =
    (1,)``, ``b = (-p,)``: eq. 30 with one pole, ``p`` the block's slowest) of the same static
    gain, the play's slopes rescaled to keep it, when the block has more than one pole or a
    zero (``[]`` otherwise): searched with each dead time, because the block's second pole
    and zero are what stood in for the dead time (as a Pade approximant does), as
    :func:`_one_stage` does for a servo's second stage.

    >>> from genbacklash_core import Cascade, GeneralBacklash, LinearBlock
    >>> bl = GeneralBacklash.ideal(0.1, 0.1, 0.1)
    >>> block = LinearBlock(a=(1.0, 0.5), b=(-1.3, 0.4))  # poles 0.8 and 0.5
    >>> [m.base.linear for m in _first_order(AugmentedModel(Cascade(bl, block)))]
    [LinearBlock(a=(1.0,), b=(-0.8,))]
    >>> reduced = _first_order(AugmentedModel(Cascade(bl, block)))[0].base.backlash
    >>> round(reduced.m_left[0], 6)  # the gain 0.1 x 1.5 / 0.1 kept: 0.3 x 1 / 0.2
    0.3
    >>> _first_order(AugmentedModel(Cascade(bl, LinearBlock(a=(1.0,), b=(-0.8,)))))
    []
    """
    base = model.base
    if not isinstance(base, Cascade):
        return []
    block = base.linear
    if len(block.a) == 1 and len(block.b) <= 1:
        return []
    denominator = np.array([1.0, *block.b])
    poles = np.roots(denominator)
    pole = float(np.max(np.abs(poles))) if poles.size else 0.0
    if not 0.0 < pole < 1.0:
        return []
    # the static gain of eq. (30): sum(a) / (1 + sum(b)), kept by the play's slopes
    scale = float(sum(block.a) / (1.0 + sum(block.b))) * (1.0 - pole)
    play = base.backlash
    rescaled = GeneralBacklash(
        tuple(scale * m for m in play.m_left),
        play.c_left,
        tuple(scale * m for m in play.m_right),
        play.c_right,
    )
    lag = LinearBlock(a=(1.0,), b=(round(-pole, 15),))
    return [replace(model, base=Cascade(rescaled, lag))]


class TimeDelay:
    """Detector and augmentation of a dead time."""

    name = "time_delay"

    def applicable(self, model: AugmentedModel) -> bool:
        """While the model has no dead time, or only the one a servo's lag carries.

        :mod:`.input_lag` searches the servo's dead time with its lag, up to a few samples
        beyond the model's own: a dead time beyond it (a transport delay, a bus) is then
        mimicked by a second lag stage, and is still a dead time to look for. With the
        servo's dead time counted as the model's, a dead time of 4.9 ms behind a servo lag of
        14 ms was never nominated: the lag took two samples and a second stage, and the
        record was named ``input_lag`` alone.
        """
        return model.delay == 0 or model.input_lag != 0.0

    def detect(self, context: Context) -> Detection:
        """Is the error step response significant, and is it a box?"""
        shape = context.step_error
        fir = shape.fir
        fires = screened_fir(context) and shape.verdict != "lag"
        taps = shape.taps
        tail = float(taps[shape.box_delay]) if shape.box_delay < taps.size else 0.0
        evidence = (
            f"the residual answers a step of the model output with {shape.box_height:+.2f} "
            f"for taps 0..{shape.box_delay - 1} and {tail:+.2f} after (error step response "
            f"explains {100 * fir.share:.1f}% of the residual, F = {fir.test.statistic:.1f}, "
            f"{format_p(fir.test.p_value)}); a box fits it {100 * shape.box_fit:.0f}%, a smooth "
            f"decay {100 * shape.decay_fit:.0f}%: "
            + {
                "dead time": f"a dead time of about {shape.box_delay} samples",
                "lag": "a lag, not a dead time",
                "unclear": f"a dead time of about {shape.box_delay} samples or a lag - the "
                "fits decide",
            }[shape.verdict]
        )
        late, lag, sentence = late_input(context)
        if late and not fires:  # a model that explains nothing has no step response to read
            return Detection(
                self.name, True, float(lag), 1.0, f"{sentence}: a dead time?", {"delay": lag}
            )
        return Detection(
            self.name,
            fires,
            shape.box_fit,
            shape.decay_fit,
            evidence,
            {"delay": float(shape.box_delay)},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Search the dead time with short refits, then refit the best candidates fully."""
        trials: list[ModelFit] = []
        models = [context.fit.model, *_one_stage(model := context.fit.model), *_first_order(model)]
        for delay, model in itertools.product(range(1, context.settings.max_delay + 1), models):
            spec = ModelSpec.of(model).extended(delay=delay)
            starts = [(spec, spec.embed(model))]
            fresh = fresh_start(context, spec) if context.degenerate else None
            if fresh is not None:
                starts.append(fresh)
            trial = best_fit(
                starts,
                context.u,
                context.y,
                max_iterations=_SCAN_STEPS,
                breaks=context.breaks,
            )
            if trial is not None:
                trials.append(trial)
        trials.sort(key=lambda fit: fit.sse)
        finals = [
            fit_model(trial.model, context.u, context.y, breaks=context.breaks)
            for trial in trials[:_FINALISTS]
        ]
        return min(finals, key=lambda fit: fit.bic) if finals else None


EFFECT = TimeDelay()
