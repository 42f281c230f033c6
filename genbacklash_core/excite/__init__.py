"""Commissioning motion: a short trajectory after which the online identifier has converged.

The online identifier (:class:`~genbacklash_core.online.windowed.WindowedIdentifier`, the node's
default method) learns from *rows*: pairs of consecutive encoder readings between which the
command moved (one per command while the joint moves), filed by branch (moves up: the right
branch; moves down: the left branch) and by input region (16 per branch over the range seen,
:class:`~genbacklash_core.online.memory.RowMemory`). It needs rows over each branch's whole range
and reversals that cross the gap. Its first fit, the cold start, needs two reversals; it is
tried after 48 rows and, while it fails, after 98, 198, 385, 572, ... rows. A cold start
on a partial view of the branches can settle on a poor estimate that later fits cannot
leave (they freeze it as ``no_excitation``). A drivetrain in operation may take minutes to
show both branches; :func:`commissioning_trajectory` shows them in a few seconds, for users
who can run a motion at commissioning time:

1. from the start position to the *farther* end of the range;
2. ``sweeps`` end-to-end sweeps (default 2: back to the near end and out again), each timed
   to take about 90 commands (``v_max`` permitting): the second reversal then comes after
   row 98 and both branches are covered over the whole range before row 198, so the first
   cold start that can run sees everything. A joint too slow for that (a sweep of more than
   97 commands) gets more sweeps instead, so that >= 300 commands follow full coverage;
3. optionally ``jog_points`` jogs spread over the range on the last sweep (to the point,
   back one jog of a few gap widths, on): more reversals across the gap, at more places;
4. back to the start position, so that the motion can be repeated.

Every move is a time-optimal trapezoidal (or triangular) velocity profile from rest to rest,
as in :mod:`genbacklash_core.scenarios`; the commands are its samples at ``command_rate``.
Their finite differences respect the limits exactly (planned with a margin for float
rounding): ``max |v| <= v_max``, ``max |a| <= a_max``, every position within
``[low, high]``, at rest at both ends. No command moves more than half a region (1/32 of
the range), so every region gets moves in both directions.

:func:`verify` runs a trajectory through the drivetrain of :mod:`genbacklash_core.scenarios`
(commands held by the servo, a 1 kHz encoder quantised to 4096 counts/rev whose stamps
jitter and whose readings are lost with probability 0.02, the play operator) into a default
:class:`~genbacklash_core.online.windowed.WindowedIdentifier` (degree 3) and reports when it
converged and the free-run NRMSE of its final estimate against the truth.

Measured on the scenario's drivetrain (travel -1.2..1.2 rad, 3 rad/s, 30 rad/s^2, 100 Hz,
start in the middle; models :data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`,
:data:`~genbacklash_core.scenarios.STRAIGHT_BACKLASH`, the same with a wider play
c_L = c_R = 0.1 rad, a narrower one 0.02 rad and an uneven one 0.02/0.08 rad; 40 seeds
each): the default motion lasts 2.84 s (3 reversals); the identifier converged in all 200
runs, at 2.04-2.15 s (median 2.08 s), free-run NRMSE <= 0.0003. Shorter variants did not
hold up: one sweep (1.93 s) never converged (the cold start finds too few reversals at
rows 48 and 98 and waits until row 198, after the motion); leaving out the way back to the
start (2.33 s), an opening jog at the start (2.2-2.5 s) or a staircase of jogs before the
sweeps (2.3-3.6 s) failed in 0.4-23 % of the runs over other limits and start positions: an
early cold start on a few jogs settles on a poor estimate. ``sweeps=3`` (3.75 s) and
``jog_points=4`` (4.08 s) converge as reliably and no earlier.

Over 0.6-4.8 rad of travel, ``v_max`` of 1-20 rad/s, ``a_max`` of 3-100 ``v_max`` per
second, start in the middle, at 1/4 or at an end, and 50-1000 commands/s, the default
converged in every run with a travel of >= 1.2 rad but one case: at 1000 commands/s on
4.8 rad at 1 rad/s and 3 rad/s^2 the identifier ended ``no_excitation`` (frozen by its
coverage test) in 5 of 15 runs, the estimate good. On 0.6 rad (6 gap widths) with the start
in the middle it ended ``converging`` in about half the runs, the estimate good (NRMSE <=
0.001); with ``sweeps=3`` in 1 of 36.

Examples
--------
>>> limits = MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0)
>>> traj = commissioning_trajectory(limits)
>>> round(traj.duration, 2), traj.reversals
(2.84, 3)
>>> bool(traj.peak_velocity <= 3.0 and traj.peak_acceleration <= 30.0)
True
>>> float(traj.u.min()), float(traj.u.max()), float(traj.u[0]), float(traj.u[-1])
(-1.2, 1.2, 0.0, 0.0)
"""

from __future__ import annotations

from .limits import MotionLimits
from .planning import commissioning_trajectory
from .trajectory import Trajectory
from .verification import CommissioningCheck, Verification, check_commissioning, verify

__all__ = [
    "CommissioningCheck",
    "MotionLimits",
    "Trajectory",
    "Verification",
    "check_commissioning",
    "commissioning_trajectory",
    "verify",
]
