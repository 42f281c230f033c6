"""``load_torque``: a torque on the load (gravity, a process force) holds it on one flank over
part of the travel, whichever way the gear turns.

The model (:mod:`genbacklash_core.diagnose.physics`): where the load position lies in a
region ``(z_1, z_2)`` the load falls towards one flank (the lower bound of the play's interval
or the upper), by at most a fall rate per sample; elsewhere the play operator (eq. 20) holds.
Where the torque beats the load's friction the play stops showing on reversals: the load
follows the same branch both ways.

Signature: trial regions (the middle half, the middle 80% and all of the travel, each side)
and fall rates (a few to a hundred samples across the play) change the simulated output on
the reversals inside them; the best trial's F-test beyond the
model's Jacobian, Bonferroni over the trials, must pass the screening thresholds.
Augmentation: side and region on a grid of travel quantiles; the fall rate, both ends of the
region and the model's parameters by least squares (:func:`~._physics.fit_physics`).
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit
from genbacklash_core.diagnose.model import AugmentedModel
from genbacklash_core.diagnose.physics import LoadPhysics, PhysicsKind

from ._base import Detection
from ._physics import fit_physics, model_play, trial_tests

__all__ = ["EFFECT", "LoadTorque"]

_TRIAL_REGIONS = ((0.25, 0.75), (0.1, 0.9), (0.0, 1.0))  # quantiles of the simulated load
_GRID = (0.0, 0.2, 0.5, 0.8, 1.0)  # region ends tried by the fit (quantiles)
# Fall per sample, as shares of the play: a torque that barely beats the friction takes tens
# of samples to carry the load across the play (the gravity drivetrain: m g l 0.12 N m against
# 0.1 N m of friction, 1e-3 kg m^2, ~80 ms across 70 mrad at 1 kHz), a strong one a few.
_TRIAL_FALLS = (0.01, 0.03, 0.3)
_FALLS = (0.01, 0.03, 0.1)


def _side_name(side: int) -> str:
    return "the lower flank" if side < 0 else "the upper flank"


_KIND: PhysicsKind = "load_torque"


class LoadTorque:
    """Detector and augmentation of a load torque that holds one flank."""

    name: str = _KIND

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no load physics and no linear block."""
        return model.physics is None and not model.cascade

    def detect(self, context: Context) -> Detection:
        """Trial regions and sides; the best one counts (Bonferroni)."""
        load = context.simulation.load
        play = model_play(context)
        trials = [
            LoadPhysics(
                _KIND,
                side=side,
                region=(float(np.quantile(load, a)), float(np.quantile(load, b))),
                fall=fall * play,
            )
            for side in (-1, 1)
            for a, b in _TRIAL_REGIONS
            for fall in _TRIAL_FALLS
        ]
        best = trial_tests(context, trials)
        fires = best.fires(context)
        z1, z2 = best.physics.region
        evidence = (
            f"holding the load on {_side_name(best.physics.side)} where it lies in "
            f"[{z1:.3g}, {z2:.3g}] {best.numbers()}: "
            + (
                "a load torque holds one flank"
                if fires
                else "no sign of a torque holding one flank"
            )
        )
        return Detection(
            self.name,
            fires,
            best.test.share,
            context.settings.min_share,
            evidence,
            {"side": float(best.physics.side)},
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Side and region on a grid, then the fall, the region and the model by least
        squares; the BIC picks the side."""
        load = context.simulation.load
        levels = [float(np.quantile(load, q)) for q in _GRID]
        play = model_play(context)
        best: ModelFit | None = None
        for side in (-1, 1):

            def make(z: FloatArray, side: int = side) -> LoadPhysics:
                low, high = float(z[1]), float(z[2])
                return LoadPhysics(
                    _KIND,
                    side=side,
                    region=(min(low, high), max(low, high)),
                    fall=float(z[0]),
                )

            grid = [
                np.array([f * play, a, b])
                for f in _FALLS
                for i, a in enumerate(levels)
                for b in levels[i + 1 :]
            ]
            fit = fit_physics(
                context, make, grid, (1e-6 * play, -np.inf, -np.inf), (np.inf, np.inf, np.inf)
            )
            if fit is not None and (best is None or fit.bic < best.bic):
                best = fit
        return best


EFFECT = LoadTorque()
