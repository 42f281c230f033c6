"""The servo's settling: which samples pair a reading with a command the gear has reached.

A real drivetrain has a position servo between the command and the gear. A new setpoint is
answered milliseconds later, so a reading taken as a command lands pairs the new command
with a gear that still stands where the old one put it. For the play operator (eq. 8) such a
row reads as extra play: about one command step per side at 100 Hz commands and a 1 kHz
encoder, +40 to +80 % on simulated drivetrains (issue 23). With the compensated command in
the loop it feeds back: the inverse jumps across the play at each reversal, the servo lags
the jump, the rows see still more play, the inverse jumps further.

The rule: a sample within ``settle_ns`` after the command it holds last *changed* (the
first sample with the new value, taken from the samples themselves, not from the command
stamps) is **settling** and is taken out as a lost reading is: for a backlash alone the
samples around it stay a pair where the commands between them were monotone (the play
operator is rate independent, :mod:`genbacklash_core.samples`), so the row from the last
settled sample before a command step to the first settled one after it is kept.

It applies where the data can show a servo at all: when the commands change more slowly
than the encoder samples, at a median of :data:`MIN_READINGS_PER_COMMAND` readings or more
per command value (the paper's input, a new value at every sample, keeps every sample). The
median is of the last :data:`RUN_WINDOW` runs of equal commands. The settling time applied
is at most half the median time a command holds, so a rule set for a slow servo never takes
every sample out; a step larger than the usual ones (a compensated command crossing the
play at a reversal, which a torque-limited servo takes longer to follow) is given longer, in
proportion to the square root of its size against the median step, at most
:data:`MAX_STRETCH` times.

Examples
--------
>>> import numpy as np
>>> t = np.arange(12) * 1_000_000  # 1 kHz readings
>>> u = np.repeat([0.0, 0.1, 0.2, 0.2], 3)  # a command every 3 ms, held at the end
>>> keep, state = settling_keep(t, u, 2_000_000)
>>> keep.astype(int).tolist()  # the stream's first command counts as a change too
[0, 0, 1, 0, 0, 1, 0, 0, 1, 1, 1, 1]
>>> state.runs, state.spans, state.run, state.applies
((3, 3), (3000000, 3000000), 6, True)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ._typing import ArrayLike, BoolArray
from .samples import stamp_steps

__all__ = [
    "MAX_STRETCH",
    "MIN_READINGS_PER_COMMAND",
    "RUN_WINDOW",
    "SettleState",
    "carry_marks",
    "settling_keep",
]

MIN_READINGS_PER_COMMAND = 3
RUN_WINDOW = 63
_INT64_MIN = int(np.iinfo(np.int64).min)
MAX_STRETCH = 4.0  # a large step's settling is at most this many times the usual one


@dataclass(frozen=True)
class SettleState:
    """What the rule carries from one piece of a stream to the next.

    Attributes
    ----------
    last_u : float or None
        The command of the last sample (None: none yet).
    change_ns : int or None
        Time of the first sample holding ``last_u``.
    run : int
        Samples so far in the current run of equal commands.
    runs : tuple of int
        Lengths of the last :data:`RUN_WINDOW` complete runs.
    spans : tuple of int
        Their durations, ns (from a run's first sample to the next run's).
    steps : tuple of float
        The sizes ``|u - u before|`` of the last :data:`RUN_WINDOW` command changes.
    busy_ns : int or None
        Until when the servo is still settling from the changes so far.
    """

    last_u: float | None = None
    change_ns: int | None = None
    run: int = 0
    runs: tuple[int, ...] = ()
    spans: tuple[int, ...] = ()
    steps: tuple[float, ...] = ()
    busy_ns: int | None = None
    # the medians of runs, spans and steps (NaN: none yet), kept with them
    median_run: float = math.nan
    median_span: float = math.nan
    median_step: float = math.nan

    def limit(self, settle_ns: int) -> int:
        """The settling time applied: ``settle_ns``, at most half the median time a command
        holds (so that a rule set for a slow servo never takes every sample out)."""
        if math.isnan(self.median_span):
            return settle_ns
        return min(settle_ns, int(self.median_span) // 2)

    @property
    def applies(self) -> bool:
        """Whether the commands change slowly enough for the rule to apply."""
        return self.median_run >= MIN_READINGS_PER_COMMAND


def settling_keep(
    times_ns: ArrayLike,
    us: ArrayLike,
    settle_ns: int,
    state: SettleState | None = None,
) -> tuple[BoolArray, SettleState]:
    """Which samples to keep under the settling rule (see the module notes), and the state
    after them.

    Parameters
    ----------
    times_ns : array_like of int, shape (N,)
        The samples' times, increasing.
    us : array_like, shape (N,)
        The command each sample holds.
    settle_ns : int
        The servo's settling time; 0 keeps every sample.
    state : SettleState, optional
        From the previous piece of the same stream (default: the stream starts here).
    """
    t = np.asarray(times_ns, dtype=np.int64)
    u = np.asarray(us, dtype=np.float64)
    before = state or SettleState()
    n = u.size
    if n == 0:
        return np.ones(0, dtype=bool), before
    if before.last_u is not None and bool((u == before.last_u).all()):
        # the command held throughout (a dwell): only the run grows
        after = dataclasses.replace(before, run=before.run + n)
        if settle_ns <= 0 or not after.applies or before.busy_ns is None:
            return np.ones(n, dtype=bool), after
        held: BoolArray = t >= before.busy_ns
        return held, after
    previous = np.empty_like(u)
    previous[1:] = u[:-1]
    previous[0] = np.nan if before.last_u is None else before.last_u
    where = (u != previous).nonzero()[0]
    # runs: the carried run ends at the first change; each change starts a new one
    ends = np.concatenate((where, [n]))
    counts = stamp_steps(ends, 0)  # samples before the first change, then in each run
    lengths = counts[1:].tolist()
    complete = [before.run + int(ends[0])] if where.size and before.last_u is not None else []
    complete += lengths[:-1] if where.size else []
    complete = [r for r in complete if r > 0]
    runs = (*before.runs, *complete)[-RUN_WINDOW:]
    run = int(lengths[-1]) if where.size else before.run + n
    starts = t[where]  # the runs' first samples: their spans, the carried run's first
    gaps = stamp_steps(starts, before.change_ns)
    if before.change_ns is None or before.last_u is None:
        gaps = gaps[1:]
    spans = (*before.spans, *gaps.tolist())[-RUN_WINDOW:]
    carried = before.change_ns
    last_change = int(t[where[-1]]) if where.size else int(t[0] if carried is None else carried)
    sizes = np.abs(u[where] - previous[where])
    known = sizes[np.isfinite(sizes)]
    steps = (*before.steps, *known.tolist())[-RUN_WINDOW:]
    fields = (
        float(u[-1]),
        last_change,
        run,
        runs,
        tuple(spans),
        steps,
    )
    medians = (
        _median(runs, before.median_run, bool(complete)),
        _median(spans, before.median_span, len(spans) != len(before.spans) or bool(where.size)),
        _median(steps, before.median_step, bool(known.size)),
    )
    after = SettleState(*fields, before.busy_ns, *medians)
    if settle_ns <= 0 or not after.applies:
        return np.ones(n, dtype=bool), after
    base = after.limit(settle_ns)
    # a step larger than the usual ones takes a torque-limited servo longer: the time to
    # move grows with the square root of the distance (at most MAX_STRETCH times the base),
    # and the servo stays busy until the latest such end, across the changes that follow.
    # (A NaN size, the stream's first change, counts as a usual step; an infinite one is
    # clipped to MAX_STRETCH either way.)
    typical = 0.0 if math.isnan(after.median_step) else after.median_step
    if typical <= 0.0:
        ratio = np.ones(where.size)
    else:
        ratio = sizes / typical
        ratio[np.isnan(ratio)] = 1.0
    stretch = np.minimum(np.maximum(np.sqrt(ratio), 1.0), MAX_STRETCH)
    ends = starts + np.rint(base * stretch).astype(np.int64)  # np.round, decimals 0
    carried_busy = before.busy_ns if before.busy_ns is not None else _INT64_MIN
    busy = np.maximum.accumulate(np.concatenate(([carried_busy], ends)))
    # sample j holds the changes where[m] <= j: busy[m] repeated over each run
    until = np.repeat(busy, counts)
    keep: BoolArray = t >= until
    return keep, SettleState(*fields, int(busy[-1]), *medians)


def _median(values: tuple[float, ...], known: float, changed: bool) -> float:
    """The median of ``values`` (NaN when empty), ``known`` when they did not change."""
    if not changed:
        return known
    if not values:
        return math.nan
    ordered = sorted(values)  # a few dozen numbers: faster than numpy's median
    half = len(ordered) // 2
    if len(ordered) % 2:
        return float(ordered[half])
    return 0.5 * (float(ordered[half - 1]) + float(ordered[half]))


def carry_marks(marks: ArrayLike, keep: ArrayLike) -> BoolArray:
    """The marks of the samples kept: a kept sample is marked when it, or a sample taken
    out since the kept one before it, was (the samples taken out here are then bridged as
    lost readings are, never their marks).

    >>> carry_marks([False, True, False, False, True], [True, False, True, True, False])
    array([False,  True, False])
    """
    m = np.asarray(marks, dtype=bool)
    k = np.asarray(keep, dtype=bool)
    count = m.cumsum()
    at = count[k]
    before = np.concatenate(([0], at[:-1]))
    out: BoolArray = at > before
    return out
