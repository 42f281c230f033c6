"""Drivetrains in normal operation: records that look like the field, with their truth.

The paper's input (a new uniform value every sample) is the easy case. A drivetrain doing its
job moves smoothly between targets, dwells, jogs back and forth a few times a second, gets
position commands at 100 Hz that the servo holds, and is read by a quantised encoder at
1 kHz whose readings jitter and are sometimes lost. :func:`operation_record` simulates that,
pure numpy, and keeps the noise-free truth so that estimates can be judged against it.

Motions (``phases``, each ``(kind, seconds)``, run one after the other):

* ``"operation"``: point-to-point moves to random targets in the travel with trapezoidal
  velocity (random fraction of ``v_max``, ``a_max``), dwells of 0.1-0.5 s, and small jogs
  that reverse the last move (half the moves);
* ``"one_way"``: a slow traverse in one direction only, with speed changes and stops (one
  branch engaged for minutes, the other never);
* ``"pick_and_place"``: the same two targets (a few millimetres of scatter) again and again,
  with dwells at both: only the part of each branch between them is ever seen;
* ``"sine_sweep"``: a slow sine over most of the travel whose frequency sweeps from 0.05 to
  0.5 Hz.

Time line: commands at ``command_rate`` (100 Hz) with up to ``command_jitter`` of delay,
held by the drivetrain (zero-order hold) until the next; encoder readings at
``encoder_rate`` (1 kHz), each taken at its nominal instant plus Gaussian ``stamp_jitter``
(clipped to a third of the period) and stamped with the instant it was taken; the reading is
the load position at that instant (the backlash is rate-independent, so the play operator on
the held command at the sampling instants is exact), plus optional white ``noise``,
quantised to ``counts_per_rev``. Each reading is lost with probability ``loss``. With
``wear``, both dead zones ``c_L``, ``c_R`` grow linearly by that fraction over the record.

Examples
--------
>>> rec = operation_record(OperationSettings(duration=2.0), seed=1)
>>> rec.command_t_ns.size, rec.sample_t_ns.size
(200, 2000)
>>> bool(0.95 < rec.received.mean() < 1.0)
True
>>> u, y, breaks = rec.series()
>>> u.size == y.size == breaks.size == int(rec.received.sum())
True
"""

from __future__ import annotations

from .clocks import readings, timeline
from .drivetrain import arm_records, drive, operation_record
from .motions import operation_commands, trapezoid
from .record import OperationRecord
from .settings import (
    OPERATION_BACKLASH,
    PHASE_KINDS,
    STRAIGHT_BACKLASH,
    HiddenEffects,
    OperationSettings,
)
from .wear import simulate_worn, worn

__all__ = [
    "OPERATION_BACKLASH",
    "PHASE_KINDS",
    "STRAIGHT_BACKLASH",
    "HiddenEffects",
    "OperationRecord",
    "OperationSettings",
    "arm_records",
    "drive",
    "operation_commands",
    "operation_record",
    "readings",
    "simulate_worn",
    "timeline",
    "trapezoid",
    "worn",
]
