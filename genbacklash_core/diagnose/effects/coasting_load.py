"""``coasting_load``: a load with little friction coasts on into the play when the motor slows
or stops, instead of stopping with the flank that pushed it.

The model (:mod:`genbacklash_core.diagnose.physics`): free of both flanks the load keeps a
velocity that its friction shrinks each sample (a retention for viscous friction, a constant
deceleration for Coulomb's) until it stops inside the play or meets the other flank; in
contact it moves with the flank. The play operator (eq. 20) is its limit with no retention.

Signature: trial retentions (time constants 10 .. 1000 samples, no Coulomb friction) change
the simulated output where the flank decelerates; the best trial's F-test beyond the model's
Jacobian, Bonferroni over the trials, must pass the screening thresholds.
Augmentation: retention, Coulomb deceleration and the model's parameters by least squares
(:func:`~._physics.fit_physics`), the flank-velocity window read off the command's holds.
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.physics import LoadPhysics, PhysicsKind

from ._base import Detection
from ._physics import command_window, fit_physics, model_play, trial_tests

__all__ = ["EFFECT", "CoastingLoad"]

_RETENTIONS = (0.9, 0.98, 0.995, 0.999)
_FRICTIONS = (0.0, 1e-4, 1e-3)  # Coulomb deceleration per sample^2, as shares of the play

_KIND: PhysicsKind = "coasting_load"


class CoastingLoad:
    """Detector and augmentation of a load that coasts into the play."""

    name: str = _KIND

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no load physics and no linear block (whose state would
        blur the contact)."""
        return model.physics is None and not model.cascade

    def detect(self, context: Context) -> Detection:
        """Trial retentions; the best one counts (Bonferroni)."""
        window = command_window(context.u)
        trials = [LoadPhysics(_KIND, retention=r, window=window) for r in _RETENTIONS]
        best = trial_tests(context, trials)
        fires = best.fires(context)
        retention = best.physics.retention
        evidence = (
            f"letting the load coast when the flank slows (it keeps {retention:g} of its "
            f"velocity per sample, a time constant of {1.0 / (1.0 - retention):.0f} samples) "
            f"{best.numbers()}: "
            + ("the load coasts into the play" if fires else "no sign of a coasting load")
        )
        return Detection(
            self.name,
            fires,
            best.test.share,
            context.settings.min_share,
            evidence,
            {"retention": retention, "window": float(window)},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Retention, Coulomb deceleration and the model refitted by least squares."""
        window = int(detection.hints.get("window", 1.0))
        play = model_play(context)

        def make(z: FloatArray) -> LoadPhysics:
            return LoadPhysics(_KIND, float(z[0]), float(z[1]), window)

        grid = [np.array([r, f * play]) for r in _RETENTIONS for f in _FRICTIONS]
        fit = fit_physics(context, make, grid, (0.0, 0.0), (1.0, np.inf))
        return fit


EFFECT = CoastingLoad()
