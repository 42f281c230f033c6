"""What runs per bag of a fleet archive: plan it, then identify, diagnose, optionally replay.

Two steps, each a plain function a Dask worker runs (picklable inputs, no database):

* :func:`inspect_bag`: the bag's content hash, its drivetrain (robot, joints) and time by the
  rule of :mod:`genbacklash_ros.fleet.archive` -- a :class:`BagPlan`. Cheap: the driver then
  skips the joints whose result is already in the database (same hash, same settings).
* :func:`analyse_bag`: per joint, the aligned samples
  (:func:`~genbacklash_ros.bags.bagio.read_aligned`), the batch identification
  (:func:`~genbacklash_core.identify_backlash` or ``identify_cascade``, with the sample
  rule's breaks) with standard deviations
  (:mod:`genbacklash_ros.fleet.uncertainty`), the discrepancy workflow
  (:func:`~genbacklash_core.diagnose.diagnose`) and, with ``replay``, the online replay through
  the node's pipeline (:func:`~genbacklash_ros.bags.replay.replay`, into a temporary bag). It
  never raises for a bad bag: every joint gets a :class:`BagResult` whose ``status`` says how
  it went and ``reason`` why.

Statuses: ``ok`` (identified, converged, free-run NRMSE at most ``max_nrmse``), ``poor_fit``
(converged, but the free-run NRMSE is above ``max_nrmse``: a wrong local solution or a
drivetrain the model does not describe; the estimate is kept, trends leave it out),
``not_converged`` (identified, the iteration did
not converge; the estimate is kept), ``no_motion`` (not enough excitation: the joint did not
move through its play), ``unreadable`` (the bag, a topic or its messages cannot be read),
``failed`` (anything else; the reason names the exception).

A recording cut part-way (a recorder killed mid-write) or corrupt after some point is not
thrown away: its readable part is analysed, as ``genbacklash replay`` keeps it, and the row
is flagged -- ``truncated`` True, ``recorded_s`` the recording's length by its
``metadata.yaml`` (None for a bare ``.mcap``, whose copy was cut off with it), and the reason
starts with ``truncated: read X of Y s`` and where the damage is.
"""

from __future__ import annotations

from .analysis import analyse_bag, truncation_note
from .plan import BagPlan, check_archive, inspect_bag
from .result import STATUSES, BagResult
from .settings import FleetSettings, JointRequest

__all__ = [
    "STATUSES",
    "BagPlan",
    "BagResult",
    "FleetSettings",
    "JointRequest",
    "analyse_bag",
    "check_archive",
    "inspect_bag",
    "truncation_note",
]
