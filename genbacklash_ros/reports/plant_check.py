"""Does the plant a report simulates describe the recorded drivetrain?

A replay report predicts the tracking error with and without compensation by driving a
*plant* with the command sequences: the truth a synthetic bag stores, else the final
estimate. Those predictions are only as good as the plant. On a drivetrain the play
operator does not describe (a load that coasts into the play, a spring after it, a flank
held by gravity; GUIDE, issue 23) a plant fitted or stored as a play predicts cuts of
90 % and more where compensating makes tracking worse, while the page measures, beside
it, an uncompensated error the plant does not reproduce.

:func:`check_plant` runs the plant free on the recorded commands, as the node's guard
runs its model (:mod:`genbacklash_core.guard`), and compares its miss of the readings
with the miss of no model at all (the load taken to equal the command):
``ratio = rms(y - P(u)) / rms(y - u)``. The guard's own thresholds judge it: at or above
``rho_full`` (0.75 by default) the node would already fade compensation built on such a
model, so the report does not lead with the plant's predicted cuts and says why.

>>> import numpy as np
>>> from genbacklash_core import GeneralBacklash, simulate_backlash
>>> from genbacklash_core.guard import GuardSettings
>>> model = GeneralBacklash.ideal(1.0, 0.05, 0.05)
>>> u = 0.5 * np.sin(np.linspace(0.0, 12.0, 600))
>>> y = simulate_backlash(model, u, 0.0)
>>> check_plant(model, u, y, GuardSettings(), "truth").describes
True
>>> wrong = GeneralBacklash.ideal(1.0, 0.3, 0.3)
>>> check = check_plant(wrong, u, y, GuardSettings(), "estimate")
>>> check.describes, round(check.ratio, 1)
(False, 4.7)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from genbacklash_core import GenBacklashError, GeneralBacklash, simulate_backlash
from genbacklash_core.guard import GuardSettings

__all__ = ["PlantCheck", "check_plant"]


@dataclass(frozen=True)
class PlantCheck:
    """How well a plant, run free on the recorded commands, reproduces the readings.

    Attributes
    ----------
    plant : str
        ``"truth"`` or ``"estimate"``: which plant was checked.
    model_rms : float
        ``rms(y - P(u))`` over the aligned samples (rad).
    no_model_rms : float
        ``rms(y - u)``: the miss of the load taken to equal the command (rad).
    ratio : float
        ``model_rms / no_model_rms`` (NaN when the readings equal the commands).
    rho_full, rho_off : float
        The guard's thresholds the ratio is judged by (compensation in full at or below
        ``rho_full``, off at or above ``rho_off``).
    """

    plant: str
    model_rms: float
    no_model_rms: float
    ratio: float
    rho_full: float
    rho_off: float

    @property
    def describes(self) -> bool:
        """True when the ratio is below ``rho_full``: the guard would compensate in full
        on this model, and the predictions made with it can be read as the drivetrain's."""
        return not self.ratio >= self.rho_full  # NaN (nothing to miss) describes

    def sentence(self) -> str:
        """One sentence: the plant's miss against the command's, and what the guard makes
        of that ratio."""
        what = "the true drivetrain's play" if self.plant == "truth" else "the final estimate"
        if self.ratio >= self.rho_off:
            verdict = "the node's guard turns compensation off at this ratio"
        elif self.ratio >= self.rho_full:
            verdict = "the node's guard fades compensation at this ratio"
        else:
            verdict = "the node's guard compensates in full at this ratio"
        return (
            f"Run free on the recorded commands, {what} misses the readings by "
            f"{self.model_rms:.3g} rad RMS where the command itself misses them by "
            f"{self.no_model_rms:.3g} rad (ratio {self.ratio:.2f}; {verdict}: full at or "
            f"below {self.rho_full:g}, off at or above {self.rho_off:g})."
        )


def check_plant(
    model: GeneralBacklash | Callable[[np.ndarray, float], np.ndarray],
    u: np.ndarray,
    y: np.ndarray,
    settings: GuardSettings,
    plant: str,
) -> PlantCheck:
    """Judge ``model`` as a plant of the aligned samples ``(u, y)`` (see the module notes).

    Parameters
    ----------
    model : GeneralBacklash or callable
        The plant: a backlash, run by its own simulation (eq. 8), or its free run
        ``model(u, x0) -> x`` from the first reading (e.g. a worn truth).
    u, y : ndarray
        Aligned samples: the command held at each reading, and the reading.
    settings : GuardSettings
        The node's guard settings (their ``rho_full`` and ``rho_off`` judge the ratio).
    plant : str
        ``"truth"`` or ``"estimate"``, for the sentence.

    Returns
    -------
    PlantCheck
        With a ratio of NaN when the plant cannot be run (a branch not finite) or the
        readings equal the commands.
    """
    x0 = float(y[0]) if y.size else 0.0
    nan = math.nan
    if y.size == 0:
        return PlantCheck(plant, nan, nan, nan, settings.rho_full, settings.rho_off)
    none = float(np.sqrt(np.mean((y - u) ** 2)))
    try:
        if isinstance(model, GeneralBacklash):
            x = simulate_backlash(model, u, x0)  # eq. 8
        else:
            x = model(u, x0)
    except GenBacklashError:
        return PlantCheck(plant, nan, none, nan, settings.rho_full, settings.rho_off)
    miss = float(np.sqrt(np.mean((y - x) ** 2)))
    ratio = miss / none if none > 0 else nan
    return PlantCheck(plant, miss, none, ratio, settings.rho_full, settings.rho_off)
