"""What the three physical effects (:mod:`genbacklash_core.diagnose.physics`) share: the trial
signature test, and the fit of a load physics with the backlash by scipy's least squares.

Signature (as :mod:`.input_lag` reads a servo lag): for a few trial parameter sets the change
``y_sim(physics) - y_sim`` of the model's free-run output is regressed on the residual beyond
the model's own Jacobian (:func:`~genbacklash_core.diagnose.stats.nested_f_test`); the best
trial's F-test, Bonferroni-corrected over the trials, must pass the screening thresholds.

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

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit
from genbacklash_core.diagnose.physics import LoadPhysics
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.diagnose.stats import NestedTest, nested_f_test
from genbacklash_core.identify import nrmse

from ._base import format_p

__all__ = [
    "PhysicsTrial",
    "command_window",
    "fit_physics",
    "model_play",
    "play_starts",
    "trial_tests",
]

MIN_PHYSICS_SHARE = 0.1  # share of the residual a physical signature must explain, at least
_MAX_WINDOW = 50  # samples: longest flank-velocity window read off the command's holds
_PLAY_SCALES = (1.0, 1.5)  # the current play split evenly and widened, as starts
_GRID_KEPT = 3  # physics of the grid tried with the play starts
_FINALISTS = 2  # starts refined by least squares
_MAX_EVALUATIONS = 15  # least-squares iterations per start (each costs 1 + k + 2 runs)


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
    explains beyond the current model's Jacobian; the best trial, Bonferroni over all."""
    best: tuple[LoadPhysics, NestedTest] | None = None
    for physics in trials:
        spec = context.spec.extended(physics=physics)
        moved = spec.simulate(context.theta, context.u, context.y_start, context.anchors, context.y)
        test = nested_f_test(context.residual, context.jacobian, moved.y - context.simulation.y)
        if best is None or test.share > best[1].share:
            best = (physics, test)
    if best is None:
        raise ValueError("trial_tests needs at least one trial")
    physics, test = best
    return PhysicsTrial(physics, test, min(1.0, len(trials) * test.test.p_value), len(trials))


def play_starts(context: Context) -> list[FloatArray]:
    """The current parameter vector, and copies with the current play (``c_L + c_R``) split
    evenly and scaled by :data:`_PLAY_SCALES` (straight or curved branches alike: only the
    dead-zone constants change)."""
    theta = context.theta
    n = context.spec.structure.degree
    play = float(theta[n] + theta[2 * n + 1])
    starts = [theta.copy()]
    for scale in _PLAY_SCALES:
        start = theta.copy()
        start[n] = start[2 * n + 1] = 0.5 * scale * max(play, 0.0)
        if start[n] > 0.0:
            starts.append(start)
    return starts


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
    """Fit a load physics with the model's parameters (see the module notes).

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
    from scipy.optimize import least_squares  # here: a slow import most runs never need

    k = len(lower)
    base = context.spec
    u_range = (float(np.min(context.u)), float(np.max(context.u)))
    # the grid on the current parameters, then the best few physics with the play starts
    ranked = sorted(
        grid, key=lambda phys: _sse(context, base.extended(physics=make(phys)), context.theta)
    )
    screened: list[tuple[float, FloatArray]] = []
    for phys in ranked[:_GRID_KEPT]:
        for theta in play_starts(context):
            if base.problem(theta, u_range) is not None:
                continue
            spec = base.extended(physics=make(phys))
            screened.append((_sse(context, spec, theta), np.concatenate([phys, theta])))
    screened.sort(key=lambda item: item[0])
    n = base.structure.degree
    zones = list(range(k, k + base.structure.n_backlash))  # branches and dead zones
    free_low = np.full(len(zones), -np.inf)
    free_low[[n, 2 * n + 1]] = 0.0  # c_left, c_right >= 0
    low = np.concatenate([np.asarray(lower, dtype=np.float64), free_low])
    high = np.concatenate([np.asarray(upper, dtype=np.float64), np.full(len(zones), np.inf)])

    def full(z: FloatArray, start: FloatArray) -> FloatArray:
        out = start.copy()
        out[:k] = z[:k]
        out[zones] = z[k:]
        return out

    best: ModelFit | None = None
    for _, start in screened[:_FINALISTS]:

        def residual(z: FloatArray, start: FloatArray = start) -> FloatArray:
            whole = full(z, start)
            spec = base.extended(physics=make(whole[:k]))
            out = spec.simulate(whole[k:], context.u, context.y_start, context.anchors, context.y)
            return np.asarray(out.y - context.y, dtype=np.float64)

        packed = np.concatenate([start[:k], start[zones]])
        margin = 1e-9 * np.maximum(1.0, np.abs(packed))
        z0 = np.clip(packed, low + margin, high - margin)
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
        fit = ModelFit(
            spec.model(theta),
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
