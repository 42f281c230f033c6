"""What the three physical effects (:mod:`genbacklash_core.diagnose.physics`) share: the trial
signature test, and the fit of a load physics with the backlash by scipy's least squares.

Signature (as :mod:`.input_lag` reads a servo lag): for a few trial parameter sets the change
``y_sim(physics) - y_sim`` of the model's free-run output is regressed on the residual beyond
the model's own Jacobian (:func:`~genbacklash_core.diagnose.stats.nested_f_test`); the best
trial's F-test, Bonferroni-corrected over the trials, must pass the screening thresholds.

Behind the servo (:func:`servo_base`): a slow servo moves the load more than the load's own
physics do, so the trials and the fit are also made on the current model with a servo's lag
in front of the play (two equal stages, a sample late, fitted first by a few Levenberg-Marquardt
steps; its pole is then fitted with the physics). The fitted model then carries that lag
(``input_lag``) under the physical effect's name; the loop names it only when it passes the
acceptance test against the servo's lag alone (:mod:`genbacklash_core.diagnose.loop`).

Fit: the physics' continuous parameters and the backlash's (branches and dead zones: a
model without the physics biases both; an offset and the rest are held, since each free
parameter costs a simulation per Jacobian) minimise the free-run simulation error on the estimation
data (``scipy.optimize.least_squares``, trust-region reflective with bounds, a finite-difference
Jacobian: a contact is a switch, so the recursion has no useful analytic derivative). It
starts from the best of a small grid of physics parameters and of dead zones (the current
ones, and the current play split evenly and widened: a model without the physics fits dead
zones that are too narrow where the load coasts across the play). Structural choices (the
velocity window, a torque's side and region) are read off the data or searched on a grid.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from weakref import WeakKeyDictionary

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, fit_model
from genbacklash_core.diagnose.model import MAX_LAG_POLE
from genbacklash_core.diagnose.physics import LoadPhysics
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.diagnose.stats import NestedTest, nested_f_test
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import nrmse

from ._base import format_p

__all__ = [
    "PhysicsTrial",
    "command_window",
    "fit_physics",
    "model_play",
    "play_starts",
    "servo_base",
    "trial_tests",
]

MIN_PHYSICS_SHARE = 0.1  # share of the residual a physical signature must explain, at least
_MAX_WINDOW = 50  # samples: longest flank-velocity window read off the command's holds
_PLAY_SCALES = (1.0, 1.5)  # the current play split evenly and widened, as starts
_GRID_KEPT = 3  # physics of the grid tried with the play starts
_FINALISTS = 2  # starts refined by least squares
_MAX_EVALUATIONS = 15  # least-squares iterations per start (each costs 1 + k + 2 runs)
_SERVO_DELAY = 1  # samples of dead time the servo's lag starts behind the model's
_SERVO_POLE = 0.8  # each stage's pole the servo's fit starts from (4.5 samples)
_SERVO_STEPS = 20  # Levenberg-Marquardt steps of the servo's lag before the physics is added
_SERVO_FINALISTS = 1  # starts refined by least squares behind the servo


def command_window(u: FloatArray) -> int:
    """The command's typical hold length in samples: the median run of equal consecutive
    inputs among the runs shorter than :data:`_MAX_WINDOW` (1 for an input that changes every
    sample).

    >>> command_window(np.repeat(np.arange(20.0), 10))
    10
    """
    change = np.flatnonzero(np.diff(u) != 0.0)
    if change.size < 2:
        return 1
    runs = np.diff(change)
    runs = runs[runs < _MAX_WINDOW]
    return int(np.median(runs)) if runs.size else 1


@dataclass(frozen=True, eq=False)
class PhysicsTrial:
    """The best of a detector's trial signatures."""

    physics: LoadPhysics
    test: NestedTest
    p_value: float
    trials: int

    def fires(self, context: Context) -> bool:
        """Significant (Bonferroni over the trials) and large enough: at least
        :data:`MIN_PHYSICS_SHARE` of the residual, above the catalog's ``min_share``. A load's
        physics changes the motion wherever the load moves; a trial that explains a few per
        cent of the residual is a small distortion that a recursion with four free parameters
        can fit anywhere (a compliant coupling was named for 2 % of the residual of an
        operation record with a servo lag and a runout, both already named)."""
        settings = context.settings
        least = max(settings.min_share, MIN_PHYSICS_SHARE)
        return self.p_value < settings.screen_alpha and self.test.share >= least

    def numbers(self) -> str:
        """The test's numbers for a sentence of evidence."""
        return (
            f"explains {100 * self.test.share:.1f}% of the residual beyond the model's own "
            f"parameters (F = {self.test.test.statistic:.1f}, {format_p(self.p_value)} over "
            f"{self.trials} trials)"
        )


def trial_tests(context: Context, trials: Sequence[LoadPhysics]) -> PhysicsTrial:
    """How much of the residual the change of the simulated output under each trial physics
    explains beyond the model's Jacobian -- the current model's, and the same model behind
    the servo's lag (:func:`servo_base`: a slow servo hides the load's physics from a model
    that lacks it); the best trial, Bonferroni over all."""
    bases = [_Base(context.spec, context.theta, context.simulation.y, context.jacobian)]
    servo = servo_base(context)
    if servo is not None:
        bases.append(servo)
    best: tuple[LoadPhysics, NestedTest] | None = None
    for base in bases:
        residual = context.y - base.y_sim
        for physics in trials:
            spec = base.spec.extended(physics=physics)
            moved = spec.simulate(
                base.theta, context.u, context.y_start, context.anchors, context.y
            )
            test = nested_f_test(residual, base.jacobian, moved.y - base.y_sim)
            if best is None or test.share > best[1].share:
                best = (physics, test)
    if best is None:
        raise ValueError("trial_tests needs at least one trial")
    physics, test = best
    count = len(trials) * len(bases)
    return PhysicsTrial(physics, test, min(1.0, count * test.test.p_value), count)


def play_starts(context: Context, theta: FloatArray | None = None) -> list[FloatArray]:
    """The parameter vector (default: the current one), and copies with its play (``c_L +
    c_R``) split evenly and scaled by :data:`_PLAY_SCALES` (straight or curved branches
    alike: only the dead-zone constants change)."""
    theta = context.theta if theta is None else theta
    n = context.spec.structure.degree
    play = float(theta[n] + theta[2 * n + 1])
    starts = [theta.copy()]
    for scale in _PLAY_SCALES:
        start = theta.copy()
        start[n] = start[2 * n + 1] = 0.5 * scale * max(play, 0.0)
        if start[n] > 0.0:
            starts.append(start)
    return starts


@dataclass(frozen=True, eq=False)
class _Base:
    """A model the physics is fitted on: its spec, parameters, free-run output on the
    estimation data and Jacobian."""

    spec: ModelSpec
    theta: FloatArray
    y_sim: FloatArray
    jacobian: FloatArray


_SERVO_CACHE: WeakKeyDictionary[Context, _Base | None] = WeakKeyDictionary()


def servo_base(context: Context) -> _Base | None:
    """The current model with the servo's lag in front of the play (two equal stages one
    sample late: a critically damped position loop, as :mod:`.input_lag` models it), its
    pole and the branches fitted by a few Levenberg-Marquardt steps; None when the model has a lag
    or a linear block already, or no valid fit exists. Fitted once per context.

    A slow servo moves the load more than the load's own physics do: a physical effect
    tried and fitted on the command alone explains less than the servo's lag, which was
    named in its place (coasting and compliant drivetrains at 20 Hz, issue 23). Behind the
    servo, the physics is tried and fitted on the gear's input as the servo delivers it.
    """
    if context in _SERVO_CACHE:
        return _SERVO_CACHE[context]
    base = _servo_fit(context)
    _SERVO_CACHE[context] = base
    return base


def _servo_fit(context: Context) -> _Base | None:
    spec = context.spec
    if spec.input_lag or spec.structure.cascade:
        return None
    delay = min(spec.delay + _SERVO_DELAY, context.settings.max_delay)
    servo = spec.extended(input_lag=True, input_lag_order=2, delay=delay)
    theta = servo.embed(context.fit.model)
    theta[servo.names().index("input_lag_pole")] = _SERVO_POLE
    try:
        fit = fit_model(
            (servo, theta),
            context.u,
            context.y,
            max_iterations=_SERVO_STEPS,
            breaks=context.breaks,
        )
    except GenBacklashError:
        return None
    if fit.model.input_lag == 0.0:
        return None
    fitted = ModelSpec.of(fit.model)
    vector = fitted.vector(fit.model)
    out = fitted.simulate(vector, context.u, context.y_start, context.anchors, context.y)
    jacobian = fitted.jacobian(vector, context.u, out, context.y_start, context.anchors)
    return _Base(fitted, vector, out.y, jacobian)


def _sse(context: Context, spec: ModelSpec, theta: FloatArray) -> float:
    out = spec.simulate(theta, context.u, context.y_start, context.anchors, context.y)
    residual = context.y - out.y
    return float(residual @ residual)


def fit_physics(
    context: Context,
    make: Callable[[FloatArray], LoadPhysics],
    grid: Sequence[FloatArray],
    lower: Sequence[float],
    upper: Sequence[float],
) -> ModelFit | None:
    """Fit a load physics with the model's parameters (see the module notes), on the
    command as it is and behind the servo's lag (:func:`servo_base`).

    Parameters
    ----------
    context : Context
        The current model on the estimation data.
    make : callable
        The physics for a vector of its continuous parameters.
    grid : sequence of ndarray
        Trial vectors of those parameters; the best few, with the play starts, start the fits.
    lower, upper : sequence of float
        Bounds of those parameters.

    Returns
    -------
    ModelFit or None
        The lowest-BIC valid fit; None when every fit leaves the valid set.
    """
    bases = [(context.spec, context.theta)]
    servo = servo_base(context)
    if servo is not None:
        bases.append((servo.spec, servo.theta))
    best: ModelFit | None = None
    for (base, theta), finalists in zip(bases, (_FINALISTS, _SERVO_FINALISTS), strict=False):
        fit = _fit_on(context, make, grid, (lower, upper), (base, theta), finalists)
        if fit is not None and (best is None or fit.bic < best.bic):
            best = fit
    return best


def _fit_on(
    context: Context,
    make: Callable[[FloatArray], LoadPhysics],
    grid: Sequence[FloatArray],
    bounds: tuple[Sequence[float], Sequence[float]],
    start_model: tuple[ModelSpec, FloatArray],
    finalists: int,
) -> ModelFit | None:
    """:func:`fit_physics` on one base model (with or without the servo's lag)."""
    from scipy.optimize import least_squares  # here: a slow import most runs never need

    lower, upper = bounds
    base, current = start_model
    k = len(lower)
    u_range = (float(np.min(context.u)), float(np.max(context.u)))
    # the grid on the base's parameters, then the best few physics with the play starts
    ranked = sorted(
        grid, key=lambda phys: _sse(context, base.extended(physics=make(phys)), current)
    )
    screened: list[tuple[float, FloatArray]] = []
    for phys in ranked[:_GRID_KEPT]:
        for theta in play_starts(context, current):
            if base.problem(theta, u_range) is not None:
                continue
            spec = base.extended(physics=make(phys))
            screened.append((_sse(context, spec, theta), np.concatenate([phys, theta])))
    screened.sort(key=lambda item: item[0])
    n = base.structure.degree
    # branches and dead zones, and the servo's pole when the base has one
    zones = list(range(k, k + base.structure.n_backlash))
    free_low = np.full(len(zones), -np.inf)
    free_high = np.full(len(zones), np.inf)
    free_low[[n, 2 * n + 1]] = 0.0  # c_left, c_right >= 0
    if base.input_lag:
        zones.append(k + base.names().index("input_lag_pole"))
        free_low = np.append(free_low, 0.0)
        free_high = np.append(free_high, MAX_LAG_POLE)
    low = np.concatenate([np.asarray(lower, dtype=np.float64), free_low])
    high = np.concatenate([np.asarray(upper, dtype=np.float64), free_high])

    def full(z: FloatArray, start: FloatArray) -> FloatArray:
        out = start.copy()
        out[:k] = z[:k]
        out[zones] = z[k:]
        return out

    best: ModelFit | None = None
    for _, start in screened[:finalists]:

        def residual(z: FloatArray, start: FloatArray = start) -> FloatArray:
            whole = full(z, start)
            spec = base.extended(physics=make(whole[:k]))
            out = spec.simulate(whole[k:], context.u, context.y_start, context.anchors, context.y)
            return np.asarray(out.y - context.y, dtype=np.float64)

        packed = np.concatenate([start[:k], start[zones]])
        margin = 1e-9 * np.maximum(1.0, np.abs(packed))
        z0 = np.clip(packed, low + margin, high - margin)
        # a trial step into a region where the simulation runs away has a residual whose
        # squares overflow: an infinite cost, which the trust region rejects and shrinks
        # from (it was a RuntimeWarning, an error under the test suite, when a spring was
        # fitted behind a servo lag on a record with a dead time beyond the servo's)
        with np.errstate(over="ignore"):
            result = least_squares(
                residual,
                z0,
                bounds=(low, high),
                x_scale="jac",
                diff_step=1e-4,
                max_nfev=_MAX_EVALUATIONS,
            )
        z = full(np.asarray(result.x, dtype=np.float64), start)
        theta = z[k:]
        if base.problem(theta, u_range) is not None:
            continue
        spec = base.extended(physics=make(z[:k]))
        y_sim = spec.simulate(theta, context.u, context.y_start, context.anchors, context.y).y
        error = context.y - y_sim
        try:
            model = spec.model(theta)
        except GenBacklashError:
            continue  # a servo's pole at 0 with a fraction, say
        fit = ModelFit(
            model,
            float(error @ error),
            context.u.size,
            nrmse(context.y, y_sim),
            int(result.nfev),
            bool(result.success),
            str(result.message),
        )
        if best is None or fit.bic < best.bic:
            best = fit
    return best


def model_play(context: Context) -> float:
    """The model's play ``c_L + c_R`` (kept above zero: the physics scale with it)."""
    n = context.spec.structure.degree
    return max(float(context.theta[n] + context.theta[2 * n + 1]), 1e-9)
