"""Does the compensation help? Measured on the machine: tracking with it against without it.

The :mod:`~genbacklash_core.guard` judges the *model*: where the play operator describes the
settled samples it feeds, compensating with it should help. What it cannot see is what the
play operator leaves out and a closed loop adds: the servo's lag behind each compensated jump,
a transport delay before the drive takes the command, a load that overshoots when the play
closes fast. Those make themselves known in one number only, the tracking error the machine
actually has: the load ``y`` against the desired position ``r`` (the command the node was
given) at every encoder reading, settled or not.

While the compensated command drives the drivetrain (the node's ``compensation_in_loop``),
both are measured, each while it is in force:

* ``e_on = y - r`` at the readings taken while a compensated command was in force (weight
  above 0), and
* ``e_off = y - r`` at the readings taken while the command went out as it came (weight 0:
  before the first estimate, while a fault passes commands through, while the guard or this
  judge holds compensation off, and during a probe).

Their root-mean-square ratio ``q = rms(e_on) / rms(e_off)`` (each exponentially weighted over
``window`` seconds of its *own* time, so the baseline does not fade while compensation runs)
is what compensating keeps of the tracking error, measured, including every effect no model
has. ``q`` below ``ratio_full``: trust 1; above ``ratio_off`` (compensation tracks worse than
nothing): trust 0; linear between. Each needs ``min_time`` seconds of its own readings first
(before that the judge says ``"judging"``). Harm is judged against the baseline, so no
compensation runs before ``min_time`` seconds of it are measured (a fresh start's first
estimate, or a checkpoint's model from the first command, waits with trust 0): a
compensation that could not be judged harmful is never applied. Compensation's first
``min_time`` seconds are then a trial at ``trial`` of its weight, and the trial's weight
grows with the evidence on it: from :data:`RAMP_START` of it to all of it over the
:data:`HARM_SHARE` of ``min_time`` after which clear harm (``q`` above :data:`STRONG_HARM`
times ``ratio_off``) is judged: a compensated jump that rings a compliant load costs little
before a verdict can switch it off (the harm of a jump grows with its size).

A start whose baseline was measured offline (:meth:`TrackingJudge.start_from`, a
:class:`OfflineBaseline`: the tracking without compensation of the record a checkpoint was
identified on) needs no ``min_time`` of baseline first: its trial may begin at once, the weight
growing as above. Such a baseline may be stale or of other work than the machine's now, so it
is replaced by the live one as soon as :data:`OFFLINE_PROBE` of ``min_time`` of that is
measured, unless the live one, still shorter than ``min_time``, agrees with it within
:data:`OFFLINE_AGREE` (it then confirms it: a short probe reads the motion of its own seconds):
after :data:`OFFLINE_CHECK` of ``min_time`` of compensating the judge probes for it
(compensation off), unless readings without compensation gave it before. No verdict rests on an
offline baseline the live probe has not confirmed but the trial's first weights; while the
offline one is in use the verdict's ``baseline`` says ``"offline"``. That trial, judged once
the live probe is done, after :data:`HARM_SHARE` of ``min_time`` of compensating, passes at
once to full weight when it clearly helps (``q`` at most ``ratio_full``; at full weight it is
measured afresh, as any), else it runs its course. The node holds a checkpoint's model until
its guard has judged it on the machine's own samples, so there the live probe always comes
first (:mod:`genbacklash_ros.node.pipeline`; measured in BENCHMARKS.md, issue 23, branch
base-1: a trial from the first command judged on the offline baseline perturbed a load coasting
into the play for the rest of a record, 8.9 % worse than no compensation).

Once every ``probe_every`` seconds of compensating the judge asks for a *probe*:
``min_time`` seconds with compensation off, to measure the baseline again. After a verdict
of harm compensation stays off until a new model is adopted or ``retry`` seconds have passed;
then it is tried (and measured) again. That verdict outlives a restart: a checkpoint carries it
(:meth:`TrackingJudge.held_harm`, a :class:`HeldHarm`) and the next start holds it
(:meth:`TrackingJudge.hold`), the retry counted on.

Without ``compensation_in_loop`` (replay; a node that only watches) compensation changes
nothing the readings show, and the judge only watches: trust 1 always, and when tracking is
clearly better while compensating (``q < ratio_wiring``) it says that the compensated command
seems to drive the drivetrain after all.

Examples
--------
>>> judge = TrackingJudge(TrackingJudgeSettings(min_time=1.0))
>>> t = [k * 1_000_000 for k in range(4000)]  # 4 s at 1 kHz
>>> verdict = judge.readings(t[:2000], [0.05] * 2000, [0.0] * 2000, [0.0] * 2000)
>>> verdict.state  # only the baseline so far
'judging'
>>> verdict = judge.readings(t[2000:], [0.08] * 2000, [0.0] * 2000, [1.0] * 2000)
>>> verdict.state, verdict.trust, round(verdict.ratio, 2)
('off', 0.0, 1.6)
"""

from __future__ import annotations

from .judge import TrackingJudge
from .records import HeldHarm, OfflineBaseline, TrackingVerdict
from .settings import (
    HARM_SHARE,
    OFFLINE_AGREE,
    OFFLINE_CHECK,
    OFFLINE_PROBE,
    RAMP_START,
    RETRY_CHANGE,
    STRONG_HARM,
    TrackingJudgeSettings,
)

__all__ = [
    "HARM_SHARE",
    "OFFLINE_AGREE",
    "OFFLINE_CHECK",
    "OFFLINE_PROBE",
    "RAMP_START",
    "RETRY_CHANGE",
    "STRONG_HARM",
    "HeldHarm",
    "OfflineBaseline",
    "TrackingJudge",
    "TrackingJudgeSettings",
    "TrackingVerdict",
]
