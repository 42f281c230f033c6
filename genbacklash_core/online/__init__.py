"""Online identification: the two identifiers and the parts they share.

Both identifiers follow one interface (``update(u, y) -> Estimate``, ``update_many``,
``seed``, ``refit``; :mod:`genbacklash_core.estimate`) and differ in how they remember:

* :class:`~genbacklash_core.online.windowed.WindowedIdentifier` re-runs a few warm-started
  iterations of the paper's batch method (eqs. 22-29, 31-37) over a sliding window;
* :class:`~genbacklash_core.online.recursive.RecursiveIdentifier` runs one warm-started
  iteration per block over a binned memory of regression rows.

The modules below them hold one concept each, and what the two share stands once:

========================  ==============================================================
``base``                  the interface both share: construction, sample intake, the
                          seed's start (:class:`~.base.OnlineIdentifier`)
``status``                what an estimate is published from, shared by an identifier's
                          parts (:class:`~.status.IdentifierStatus`)
``settings``              the two frozen settings dataclasses
``inputs``                structure and settings arguments, non-finite samples, the input
                          deadband
``rows``                  the sample rule's regression rows (a window's; as they come),
                          the recent-sample ring, the cascade's lags and settling horizon
``memory``                the row memories (``RowMemory``, ``BinnedRows``)
``advice``                branch coverage and excitation advice
``seed``                  a saved estimate as prior information (``seed``) and how each
                          identifier lets it fade
``engaged``               whether the data engaged each branch at all (before a batch
                          start fits)
``fits``                  the windowed fits and the batch (re-)initialisation both use
``covariance``            the delta method of eq. (34): natural parameters and covariance
``state``                 converged / converging / no_excitation and the confidence
``publish``               the estimate each identifier publishes, and when it rebuilds it
``tracking``              the bands' tracking term for a drifting gap
``feeds``                 the windowed identifier's data: rows (a backlash) or samples
``schedule``              when the windowed identifier fits
``fitter``                the windowed identifier's fits as they follow one another:
                          cold start, warm fits, restarts
``queue``                 the recursive identifier's queue of samples between its events
``blocks``                the recursive identifier's blocks: when it files rows, iterates,
                          holds and re-initialises
``attempts``              the recursive identifier's batch-fit attempts
``ages``                  the age of the recursive identifier's information, per block
``bands``                 when the recursive identifier refits the bands' tracking term
``stream``                the recursive identifier's rows as samples come
``restart``               the recursive identifier's batch start
``iteration``             the recursive identifier's iteration over its memory
``divergence``            the recursive identifier's divergence test (error scales)
``windowed``              :class:`WindowedIdentifier`: a feed, a schedule, a fitter, a
                          publication
``recursive``             :class:`RecursiveIdentifier`: a queue, a block machine, a
                          publication
========================  ==============================================================

``genbacklash_core.windowed``, ``.recursive``, ``.memory`` and ``.tracking`` remain as
compatibility modules re-exporting from here.
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
