"""Online identification: the two identifiers and the parts they share.

Both identifiers follow one interface (``update(u, y) -> Estimate``, ``update_many``,
``seed``, ``refit``; :mod:`genbacklash_core.estimate`) and differ in how they remember:

* :class:`~genbacklash_core.online.windowed.WindowedIdentifier` re-runs a few warm-started
  iterations of the paper's batch method (eqs. 22-29, 31-37) over a sliding window;
* :class:`~genbacklash_core.online.recursive.RecursiveIdentifier` runs one warm-started
  iteration per block over a binned memory of regression rows.

The modules below them hold one concept each.
"""

from __future__ import annotations

from .advice import BranchCoverage, coverage_of, excitation_advice
from .memory import BinnedRows, RowMemory, pair_series
from .recursive import RecursiveIdentifier, RecursiveSettings
from .rows import memory_regression
from .tracking import DRIFT_Z, DeadZoneDrift, dead_zone_drift
from .windowed import WindowedIdentifier, WindowedSettings

__all__ = [
    "DRIFT_Z",
    "BinnedRows",
    "BranchCoverage",
    "DeadZoneDrift",
    "RecursiveIdentifier",
    "RecursiveSettings",
    "RowMemory",
    "WindowedIdentifier",
    "WindowedSettings",
    "coverage_of",
    "dead_zone_drift",
    "excitation_advice",
    "memory_regression",
    "pair_series",
]
