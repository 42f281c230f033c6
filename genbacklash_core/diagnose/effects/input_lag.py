"""``input_lag``: the servo lags the command before the gear - a lag (one first-order stage or
two equal ones) and a dead time before the backlash.

The motor does not follow the command at once: the backlash sees ``v(t) = a v(t-1) + (1 - a)
u(t - d)`` instead of ``u(t - d)``. Unlike :mod:`.linear_dynamics` (a lag *after* the
backlash, eq. 30), the output stops the moment the lagged motor turns back, and it holds
exactly while the motor crosses the play; a lag after the backlash keeps the output moving
after the backlash output stopped. Both leave an error step response that decays, so both
are tried and the BIC on the estimation data decides.

A servo is a lag *and* a dead time (the drive's own loop, the sample-and-hold of a held
command, the encoder's latency): a critically damped position servo's two equal poles are
close to one lag one sample late. So the servo's lag is searched with the dead time before it
(up to :data:`_SERVO_DELAYS` samples beyond the model's), and one step adds both; and the
lag is one first-order stage or two equal ones (``input_lag_order`` 2: a position loop tuned
critically damped, as the physics drivetrains' servos are). A lag of one stage without its
dead time fits such a servo worse than a lag after the play or a spring does, which then got
named in its place (the near-ideal physics drivetrain at 20-100 Hz, issue 23).

The dead time need not be whole samples: a held command lands between the encoder's readings,
and the zero-order-hold discretisation of a lag has a numerator ``b_1 + b_2 q^-1`` -- a
fraction ``f = b_2 / (b_1 + b_2)`` of a sample of dead time, linearly interpolated (the
model's ``input_lag_fraction``). Once the lag is fitted at whole samples, a few fractions
around its dead time are tried; one is kept only when it lowers the BIC by the margin. With
whole samples only, a lag *after* the play (``linear_dynamics``, whose zeros absorb the
fraction) fitted the near-ideal drivetrain's servo closer on the validation data and was
named in its place on 6 of 9 records (issue 23).

Signature: for trial poles ``a`` and dead times the change ``y_sim(a, d) - y_sim`` of the
model's free-run output, regressed on the residual beyond the model's Jacobian (a
trial-direction test: the score test at ``a = 0`` sees only the first-order part ``u(t-1) -
u(t)``, which a held command makes spiky). The best trial's F-test, Bonferroni-corrected over
the trials, must pass the screening thresholds.
Augmentation: short refits from the best trial poles at each dead time searched, the best
refitted fully; the BIC picks. A fit whose lag vanishes (:func:`vanished`) is named
``time_delay`` by the loop: what it adds is a dead time.
"""

from __future__ import annotations

import math

from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.diagnose.stats import NestedTest, nested_f_test

from ._base import Detection, format_p, screen_starts

__all__ = ["EFFECT", "InputLag", "adds_dead_time", "vanished"]

_POLES = (0.5, 0.7, 0.8, 0.9, 0.95, 0.98)  # trial poles (time constants 1.4 .. 50 samples)
_SERVO_DELAYS = 3  # dead time searched with the lag, samples beyond the model's own
_ORDERS = (1, 2)  # a first-order lag; a critically damped servo's two equal poles
_SCREEN_STEPS = 8  # Levenberg-Marquardt steps per start before the best are finished
_FINALISTS = 2
_FRACTIONS = (0.25, 0.5, 0.75)  # fractions of a sample of dead time tried after the fit
_VANISHED = 1e-3  # a lag that leaves less of a step than this one sample on is no lag


def _specs(context: Context) -> dict[tuple[int, int], ModelSpec]:
    """The model's spec with an input lag of each order, at its own dead time and up to
    :data:`_SERVO_DELAYS` samples more (within ``max_delay``), by (order, dead time)."""
    own = context.spec.delay
    longest = max(own, min(own + _SERVO_DELAYS, context.settings.max_delay))
    return {
        (order, delay): context.spec.extended(input_lag=True, delay=delay, input_lag_order=order)
        for order in _ORDERS
        for delay in range(own, longest + 1)
    }


def _pole(pole: float, order: int) -> float:
    """A first-order pole's equivalent in ``order`` equal stages (the same total time
    constant, each stage ``1/order`` of it)."""
    return float(pole**order)


def _trial(context: Context, spec: ModelSpec, pole: float) -> NestedTest:
    """How much of the residual the change of the simulated output with pole ``a`` (and the
    spec's dead time) explains beyond the model's Jacobian."""
    theta = spec.embed(context.fit.model)
    theta[spec.names().index("input_lag_pole")] = pole
    anchors = context.anchors
    moved = spec.simulate(theta, context.u, context.y_start, anchors, context.y).y
    return nested_f_test(context.residual, context.jacobian, moved - context.simulation.y)


class InputLag:
    """Detector and augmentation of the servo's lag before the backlash."""

    name = "input_lag"

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no input lag and no linear block: once a linear block
        follows the backlash its orders absorb a lag before it wherever a branch is engaged,
        and the two differ only while the play is crossed (a servo lag found first may still
        be followed by a load lag)."""
        return model.input_lag == 0.0 and not model.cascade

    def detect(self, context: Context) -> Detection:
        """Trial-direction tests of a few poles and dead times; the best one counts
        (Bonferroni)."""
        specs = _specs(context)
        tests = {
            (order, delay, pole): _trial(context, spec, _pole(pole, order))
            for (order, delay), spec in specs.items()
            for pole in _POLES
        }
        order, delay, pole = max(tests, key=lambda key: tests[key].share)
        test = tests[(order, delay, pole)]
        p_value = min(1.0, len(tests) * test.test.p_value)
        settings = context.settings
        fires = p_value < settings.screen_alpha and test.share >= settings.min_share
        coefficient = float(test.coefficients[0])
        evidence = (
            f"lagging the input by a servo lag (time constant {-1.0 / math.log(pole):.1f} "
            f"samples in {order} equal stage{'s' if order > 1 else ''}, dead time {delay} "
            "samples) changes the "
            f"simulated output in a way that explains {100 * test.share:.1f}% of the residual "
            f"beyond the model's own parameters (F = {test.test.statistic:.1f}, "
            f"{format_p(p_value)} over {len(tests)} trial poles, orders and dead times; it wants "
            f"{coefficient:.2f} of that change): "
            + ("the motor lags the command" if fires else "no sign of a servo lag")
        )
        return Detection(
            self.name,
            fires,
            test.share,
            settings.min_share,
            evidence,
            {"pole": pole, "delay": float(delay)},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit with the input lag from the best trial poles at each dead time searched (a
        short refit each: the trial test, linear in the change, does not tell one sample of
        dead time from a slightly slower lag); the BIC picks."""
        guess = float(detection.hints.get("pole", 0.9))
        poles = sorted({guess, *(p for p in _POLES if abs(p - guess) <= 0.15)})
        starts = []
        for (order, _), spec in _specs(context).items():
            base = spec.embed(context.fit.model)
            index = spec.names().index("input_lag_pole")
            for pole in poles:
                start = base.copy()
                start[index] = _pole(pole, order)
                starts.append((spec, start))
        screened = screen_starts(context, starts, _SCREEN_STEPS)
        finals = [
            fit
            for order in _ORDERS
            if (
                fit := best_fit(
                    [f.model for f in screened if f.model.input_lag_order == order][:_FINALISTS],
                    context.u,
                    context.y,
                    breaks=context.breaks,
                )
            )
            is not None
        ]
        if not finals:
            return None
        # the second stage is a structural choice with no parameter of its own: like an
        # effect, it must lower the BIC by the margin over the one-stage lag (a first-order
        # lag with a runout the model still lacks was fitted as two stages, and the runout
        # named next then left a misfit twice the floor)
        simple = finals[0]
        best = min(finals, key=lambda fit: fit.bic)
        if best is not simple and simple.model.input_lag_order == 1:
            if not best.bic < simple.bic - context.settings.bic_margin:
                best = simple
        return _fractional(context, best)


def vanished(model: AugmentedModel) -> bool:
    """True when ``model``'s servo lag is no lag: less than :data:`_VANISHED` of a step is
    left one sample on (its pole fitted to zero), so what ``input_lag``'s fit adds is a dead
    time and perhaps a fraction of a sample -- ``time_delay``'s to name.

    >>> from genbacklash_core import GeneralBacklash
    >>> play = GeneralBacklash.ideal(1.0, 0.1, 0.1)
    >>> vanished(AugmentedModel(play, delay=3, input_lag=3e-9, input_lag_fraction=0.25))
    True
    >>> vanished(AugmentedModel(play, delay=1, input_lag=0.5, input_lag_order=2))
    False
    """
    return 0.0 < model.input_lag**model.input_lag_order < _VANISHED


def adds_dead_time(before: AugmentedModel, after: AugmentedModel) -> bool:
    """True when ``after`` adds a servo's lag that ``before`` lacks *and* a dead time beyond
    ``before``'s (whole samples or a fraction of one): one ``input_lag`` step then adds two
    effects of the catalog at once, the lag and ``time_delay``'s dead time.

    >>> from genbacklash_core import GeneralBacklash
    >>> play = GeneralBacklash.ideal(1.0, 0.1, 0.1)
    >>> adds_dead_time(AugmentedModel(play), AugmentedModel(play, delay=3, input_lag=0.8))
    True
    >>> adds_dead_time(AugmentedModel(play), AugmentedModel(play, input_lag=0.8))
    False
    >>> lagged = AugmentedModel(play, input_lag=0.8, input_lag_order=2, input_lag_fraction=0.75)
    >>> adds_dead_time(AugmentedModel(play), lagged)
    True
    >>> adds_dead_time(AugmentedModel(play, delay=3), AugmentedModel(play, delay=3, input_lag=0.8))
    False
    """
    if before.input_lag != 0.0 or after.input_lag == 0.0:
        return False
    dead = after.delay + after.input_lag_fraction
    return dead > before.delay + before.input_lag_fraction


def _fractional(context: Context, fit: ModelFit) -> ModelFit:
    """``fit`` with a fraction of a sample of dead time before its lag, when one lowers the
    BIC by the margin (a structural choice, searched: ``d - 1 + f`` and ``d + f`` for the
    fitted dead time ``d`` and each of :data:`_FRACTIONS`, a short refit each, the best
    finished)."""
    model = fit.model
    spec = ModelSpec.of(model)
    own = context.spec.delay
    delays = [d for d in (model.delay - 1, model.delay) if own <= d < context.settings.max_delay]
    starts = []
    for delay in delays:
        for fraction in _FRACTIONS:
            extended = spec.extended(delay=delay, input_lag_fraction=fraction)
            starts.append((extended, extended.embed(model)))
    screened = screen_starts(context, starts, _SCREEN_STEPS)
    if not screened:
        return fit
    best = best_fit([screened[0].model], context.u, context.y, breaks=context.breaks)
    if best is not None and best.bic < fit.bic - context.settings.bic_margin:
        return best
    return fit


EFFECT = InputLag()
