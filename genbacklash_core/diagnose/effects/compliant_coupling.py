"""``compliant_coupling``: a spring between the gear and the load, after the play; the load
rings when the play closes.

The model (:mod:`genbacklash_core.diagnose.physics`): the load is pulled towards the play's
interval by a damped spring (natural frequency and damping ratio per sample) and coasts when
the spring is relaxed. A stiff spring with a load that does not coast is the play operator
(eq. 20). Unlike :mod:`.linear_dynamics` (a linear block after the backlash, eq. 30), the
spring acts only while a flank presses it: inside the play the load is free.

Signature: trial springs (natural periods of about 8 .. 120 samples, lightly damped, the
free load coasting a little or far) change the simulated output after each engagement; the
best trial's F-test beyond the model's Jacobian (the current model's, and the same behind the
servo's lag), Bonferroni over the trials, must pass the screening thresholds.
Augmentation: stiffness, damping, the free load's retention and Coulomb deceleration and the
model's parameters by least squares (:func:`~._physics.fit_physics`). A fit damped at
:data:`MAX_RING_DAMPING` or more is no valid fit: what marks a compliant coupling is its ring;
a spring that does not ring is a lag, which a slow servo before the play shows as well (on the
near-ideal physics drivetrain at 20 Hz it was fitted so, and named, before this rule).
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.physics import MAX_STIFFNESS, LoadPhysics, PhysicsKind

from ._base import Detection
from ._physics import command_window, fit_physics, trial_tests

__all__ = ["EFFECT", "CompliantCoupling"]

_STIFFNESSES = (0.05, 0.1, 0.2, 0.4, 0.8)  # trial natural frequencies, rad per sample
_GRID_STIFFNESSES = tuple(float(w) for w in np.geomspace(0.03, 1.2, 14))  # the fit's grid
_DAMPINGS = (0.05, 0.15, 0.4)
# the free load's retention in the trials: a spring that rings while the load swings across
# the play (0.98) changes the output unlike one whose load stops inside it (0.9); with 0.9
# alone the compliant drivetrain behind a 20 Hz servo showed 5 % of its residual (under the
# 10 % rule), with 0.98 69 %
_TRIAL_RETENTIONS = (0.9, 0.98)
MAX_RING_DAMPING = 0.7  # a fitted spring damped more than this does not ring: it is a lag
_RETENTIONS = (0.0, 0.9, 0.98)  # a free load that stops at once .. coasts

_KIND: PhysicsKind = "compliant_coupling"


class CompliantCoupling:
    """Detector and augmentation of a compliant coupling after the play."""

    name: str = _KIND

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no load physics and no linear block."""
        return model.physics is None and not model.cascade

    def detect(self, context: Context) -> Detection:
        """Trial springs; the best one counts (Bonferroni)."""
        window = command_window(context.u)
        trials = [
            LoadPhysics(_KIND, r, 0.0, window, stiffness=w, damping=0.2)
            for w in _STIFFNESSES
            for r in _TRIAL_RETENTIONS
        ]
        best = trial_tests(context, trials)
        fires = best.fires(context)
        stiffness = best.physics.stiffness
        evidence = (
            f"a spring after the play (natural period {2 * math.pi / stiffness:.0f} samples, "
            f"damping ratio 0.2, the free load keeping {best.physics.retention:g} of its "
            f"velocity per sample) {best.numbers()}: "
            + (
                "the load rings on a compliant coupling"
                if fires
                else "no sign of a compliant coupling"
            )
        )
        return Detection(
            self.name,
            fires,
            best.test.share,
            context.settings.min_share,
            evidence,
            {"stiffness": stiffness, "window": float(window)},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Spring, free-load friction and the model refitted by least squares."""
        window = int(detection.hints.get("window", 1.0))

        def make(z: FloatArray) -> LoadPhysics:
            return LoadPhysics(
                _KIND,
                float(z[2]),
                float(z[3]),
                window,
                stiffness=float(z[0]),
                damping=float(z[1]),
            )

        grid = [
            np.array([w, d, r, 0.0])
            for w in _GRID_STIFFNESSES
            for d in _DAMPINGS
            for r in _RETENTIONS
        ]
        fit = fit_physics(
            context, make, grid, (1e-3, 0.0, 0.0, 0.0), (MAX_STIFFNESS, 5.0, 1.0, np.inf)
        )
        physics = None if fit is None else fit.model.physics
        if physics is None or physics.damping >= MAX_RING_DAMPING:
            # A spring that does not ring is a lag, and a lag has its own names: the servo's
            # before the play (input_lag, time_delay) or the load's after it
            # (linear_dynamics). A slow, well-damped servo fits such a spring as well.
            return None
        return fit


EFFECT = CompliantCoupling()
