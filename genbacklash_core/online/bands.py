"""When the recursive identifier refits the bands' tracking term.

The bands of the recursive identifier's estimate are its covariance plus how far a drifting
drivetrain has moved past the rows the memory holds
(:func:`~genbacklash_core.online.tracking.dead_zone_drift`, the memory's rows aged from the
iterate's sample, fitted with dead zones that drift). A fit over the memory costs ~1-2 ms,
so :class:`BandSchedule` refits it once per :data:`DRIFT_EVERY` samples at most, at the
iterates' own samples, so that chunking does not matter; between two fits the drift goes on,
counted to the last iterate's sample (:attr:`BandSchedule.ticks`), not the publishing
moment. Nothing for the cascade. (The windowed identifier fits it at each accepted fit,
:meth:`~genbacklash_core.online.feeds.Feed.drift`.)

Examples
--------
>>> bands = BandSchedule()
>>> bands.ticks, bands.next_drift
(0.0, 0)
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import FloatArray

from .covariance import natural_from_theta
from .memory import BinnedRows
from .rows import SampleRing
from .status import IdentifierStatus
from .tracking import BAND_SAMPLES, dead_zone_drift

__all__ = ["DRIFT_EVERY", "BandSchedule"]

DRIFT_EVERY = 250  # samples between two fits of the bands' tracking term (~0.3 ms each)


class BandSchedule:
    """The samples at which the bands' tracking term was and will be fitted (see the module
    notes)."""

    def __init__(self) -> None:
        self.next_drift = 0  # the sample from which the next iterate refits it
        self.drift_at = 0  # the sample it was fitted at
        self.committed_at = 0  # the sample of the last iterate taken

    @property
    def ticks(self) -> float:
        """Samples the drift has gone on since its fit, to the last iterate's sample."""
        return float(self.committed_at - self.drift_at)

    def restart(self) -> None:
        """A new memory: refit at the next iterate."""
        self.next_drift = 0

    def committed(
        self, status: IdentifierStatus, theta: FloatArray, memory: BinnedRows, ring: SampleRing
    ) -> None:
        """An iterate ``theta`` was taken at ``status.samples``: refit the tracking term
        (into ``status.drift``) on the ``memory``'s rows and the latest readings of ``ring``
        (for the model term's free run) when due."""
        self.committed_at = status.samples
        structure = status.structure
        if structure.cascade or status.samples < self.next_drift:
            return
        self.next_drift = status.samples + DRIFT_EVERY
        self.drift_at = status.samples
        rows, stamps = memory.rows()
        p = np.array(natural_from_theta(structure, theta.tolist()))
        cols = (rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3])
        u, y = ring.window(BAND_SAMPLES)
        recent = (u, y, ring.breaks(BAND_SAMPLES))
        status.drift = dead_zone_drift(structure, p, cols, float(status.samples) - stamps, recent)
