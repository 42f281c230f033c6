"""Standard deviations of a batch estimate: moved to :mod:`genbacklash_core.uncertainty`
(``genbacklash identify`` uses them too); the names stay importable from here."""

from __future__ import annotations

from genbacklash_core.uncertainty import gap_std, parameter_covariance, parameter_std, play_std

__all__ = ["gap_std", "parameter_covariance", "parameter_std", "play_std"]
