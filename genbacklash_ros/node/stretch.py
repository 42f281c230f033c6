"""The batch form's quiet stretches: where one ends, and taking it in one step.

:meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.on_batch` runs a block of messages
already read. Most of them make nothing happen but bookkeeping -- in order, on time, finite,
no fault, no feed, no periodic output due, no stuck reading. :class:`QuietStretches` finds
where such a *stretch* from a given message ends, by bisection in what
:class:`~genbacklash_ros.node.batch.BlockView` worked out once for the block against the
stages' current state (:meth:`QuietStretches.find`), and accepts its messages in one step
through the stages' batch methods (:meth:`QuietStretches.take`:
:meth:`~genbacklash_ros.node.align.Aligner.add_readings`,
:meth:`~genbacklash_ros.node.health.StreamHealth.accept_readings`, ...). A stretch also
takes the reading that feeds the identifier (it ends there) and the commands at which only
an estimate comes due; the pipeline makes those steps, and sends each other message that
makes something happen down its per-message path. The outputs are those of the per-message
path to the last bit (tests/ros/node/test_batch.py).

The stretches read the pipeline's stages and never call back into it: the stages that live
as long as the pipeline (the data clock, the stream health, the silences, the ledger) are
given at construction, those a restart replaces (alignment, compensator, estimate in use,
measured tracking) by :meth:`QuietStretches.bind` at each start.
"""

from __future__ import annotations

import bisect

import numpy as np

from genbacklash_ros.node.align import Aligner
from genbacklash_ros.node.batch import BlockView
from genbacklash_ros.node.compensate import CompensateStage
from genbacklash_ros.node.health import (
    LOSS_WINDOW_NS,
    LOSS_WINDOW_READINGS,
    STUCK_INPUT_NS,
    STUCK_NS,
    StreamHealth,
)
from genbacklash_ros.node.identify import EstimateInUse
from genbacklash_ros.node.ledger import Ledger
from genbacklash_ros.node.outputs import BatchCollector
from genbacklash_ros.node.publish import Schedule
from genbacklash_ros.node.silence import SilentStreams
from genbacklash_ros.node.tracking_stage import TrackingStage

__all__ = ["STRETCH_MAX", "QuietStretches", "first_at"]


def _seen(
    view: BlockView, i: int, end: int, c0: int, c1: int, e0: int, e1: int, commands: bool
) -> tuple[int, int, int] | None:
    """What :meth:`~genbacklash_ros.node.silence.SilentStreams.arrived_many` needs of one
    stream over ``i .. end - 1``."""
    own_pos, own_count = (view.cmd_pos, c1 - c0) if commands else (view.enc_pos, e1 - e0)
    other_pos, other_rx, o0, o1 = (
        (view.enc_pos, view.enc_rx, e0, e1) if commands else (view.cmd_pos, view.cmd_rx, c0, c1)
    )
    own_rx = view.cmd_rx if commands else view.enc_rx
    if own_count:
        last_own = (c1 if commands else e1) - 1
        after = bisect.bisect_right(other_pos, own_pos[last_own], o0, o1)
        first = other_rx[after] if after < o1 else -1
        return own_rx[last_own], o1 - after, first
    if o1 > o0:
        return -1, o1 - o0, other_rx[o0]
    return None


def first_at(times: np.ndarray, due: int, start: int, end: int) -> int:
    """The first message of ``start .. end - 1`` whose time is ``due`` or later (``end``:
    none); the times need not be in order. One comparison and ``argmax`` (the first True,
    else 0: that element says which), not ``np.flatnonzero``'s wrappers nor ``any``'s: it
    runs at every stretch."""
    if end <= start:
        return end
    late = times[start:end] >= due
    first = int(late.argmax())
    return start + first if late[first] else end


STRETCH_MAX = 8192  # messages looked at for one stretch at most
_NOT_JUDGED = object()


class QuietStretches:
    """Finds and takes the quiet stretches of a block of messages (see the module notes).

    Parameters
    ----------
    clock : Schedule
        The pipeline's data clock (read, and copied to look ahead; never moved here).
    health : StreamHealth
        The stream health checks (the quiet tests; a stretch's readings accepted).
    silence : SilentStreams
        The streams' silences (a stretch's arrivals).
    ledger : Ledger
        The counters.

    Attributes
    ----------
    closing : int
        The message of the last stretch found whose reading closes the loss-rate window
        (it ends the stretch; -1: none).

    Notes
    -----
    :meth:`bind` must be called before :meth:`find` and after each (re)start of the
    pipeline's stages.
    """

    __slots__ = (
        "_align",
        "_clock",
        "_comp",
        "_health",
        "_in_loop",
        "_ledger",
        "_silence",
        "_tracking",
        "_use",
        "closing",
    )

    def __init__(
        self, clock: Schedule, health: StreamHealth, silence: SilentStreams, ledger: Ledger
    ) -> None:
        self._clock = clock
        self._health = health
        self._silence = silence
        self._ledger = ledger
        self.closing = -1

    def bind(
        self,
        align: Aligner,
        comp: CompensateStage,
        use: EstimateInUse,
        tracking: TrackingStage,
        *,
        in_loop: bool,
    ) -> None:
        """The stages a (re)start made: alignment, compensator, estimate in use, measured
        tracking; ``in_loop``: the identifier's input is the compensated command."""
        self._align = align
        self._comp = comp
        self._use = use
        self._tracking = tracking
        self._in_loop = in_loop

    def find(self, view: BlockView, i: int, feed_at: int) -> tuple[int, int, list[int]]:
        """Where the quiet stretch from message ``i`` ends (``i``: none here, the message
        takes the per-message path), where it would end by itself (its last message's steps
        made), and the commands in it at which an estimate (or nothing) comes due.

        ``feed_at`` is the pending readings' count at which the identifier is fed (the
        reading that brings them there feeds, and ends the stretch at the latest).
        """
        clock = self._clock
        due = clock.next_due
        now = clock.now
        if due is None or now is None or now >= due or self._align.motor:
            return i, i, []  # (a motor encoder's input: every message by itself)
        self.closing = -1
        end = min(view.n, i + STRETCH_MAX)
        to_feed = max(feed_at - self._align.pending, 1)  # the last of them feeds
        feeds = view.enc_before[i] + to_feed - 1
        if feeds < len(view.enc_pos):  # the reading that feeds ends it at the latest
            end = min(end, view.enc_pos[feeds] + 1)
        natural = end  # where the stretch ends by itself (its last message's steps made)
        k = bisect.bisect_left(view.nonfinite, i)
        if k < len(view.nonfinite):
            end = min(end, view.nonfinite[k])
        marks: list[int] = []  # commands at which an estimate (or nothing) comes due
        if end > i:
            late = first_at(view.times, due, i, end)  # a periodic step is due
            if late < end:
                end = natural = self._periodic_end(view, late, end, marks)
        if end == i:
            return i, natural, marks
        c0, e0 = view.cmd_before[i], view.enc_before[i]
        if view.cmd_before[end] > c0:
            end = self._commands_end(view, i, c0, end)
        if view.enc_before[end] > e0:
            end = self._readings_end(view, e0, c0, end, to_feed)
        return end, natural, marks

    def _periodic_end(self, view: BlockView, p: int, end: int, marks: list[int]) -> int:
        """Where a stretch whose message ``p`` is the first with a periodic step due ends
        (at most ``end``); appends to ``marks`` the commands inside it where steps are due.

        A command's message steps only the estimate (the pipeline's ``_advance`` with
        ``heavy`` False): while no diagnostics report is due either, the stretch goes on through it
        and :meth:`take` and the pipeline make the step there. An encoder reading (it may feed) or
        a report (it counts what came before) ends the stretch: the message is its last,
        whose steps the pipeline makes after all the stretch's bookkeeping, as the
        per-message path makes them. What comes due next is worked out on a copy of the
        schedule, with the steps the stretch would make.
        """
        clock = self._clock.copy()
        times, cmd_before = view.times, view.cmd_before
        while True:
            if cmd_before[p + 1] == cmd_before[p]:  # an encoder reading
                return p + 1
            clock.tick(int(times[p]))
            now = clock.now
            assert now is not None
            due = clock.due(now)
            if due.diagnostics:
                return p + 1
            marks.append(p)
            if due.estimate:
                clock.estimate_done(now)
            clock.settle()
            after = clock.next_due
            assert after is not None
            p += 1
            if after > now:  # else (a feed due) the next message has a step due
                p = first_at(times, after, p, end)
            if p >= end:
                return end

    def _commands_end(self, view: BlockView, i: int, c0: int, end: int) -> int:
        """Where the stretch from ``i`` ends for its commands (ordinals from ``c0``)."""
        c1 = view.cmd_before[end]
        first = view.cmd_pos[c0]
        health = self._health
        if self._in_loop or not self._comp.ready(self._use.current) or not health.commands_quiet():
            return first
        last = self._align.last_cmd_ns
        if last is not None and view.cmd_t[c0] <= last:
            return first
        stop = min(c1, c0 + max(self._align.room, 0))
        options = self._comp.options
        for found, after in (
            (view.cmd_disorder, c0 + 1),  # the first command was checked against the state
            (view.saturated(options.u_min, options.u_max), c0),
        ):
            k = bisect.bisect_left(found, after)
            if k < len(found) and found[k] < stop:
                stop = found[k]
        # late commands: more than the silence limit after the last reading
        silence = health.silence_ns
        known = health.last_encoder_receive
        e0 = view.enc_before[i]
        o = c0
        while o < stop and view.cmd_prev_enc[o] < e0:  # no reading of this stretch before it
            if known is not None and view.cmd_rx[o] - known > silence:
                stop = o
            o += 1
        k = bisect.bisect_left(view.cmd_late, o)
        while k < len(view.cmd_late) and view.cmd_late[k] < stop:
            if view.cmd_gap[view.cmd_late[k]] > silence:
                stop = view.cmd_late[k]
                break
            k += 1
        return view.cmd_pos[stop] if stop < c1 else end

    def _readings_end(self, view: BlockView, e0: int, c0: int, end: int, to_feed: int) -> int:
        """Where the stretch ends for its encoder readings (ordinals from ``e0``; the
        stretch's commands from ordinal ``c0``; ``to_feed`` readings feed the identifier)."""
        e1 = view.enc_before[end]
        first = view.enc_pos[e0]
        align, health = self._align, self._health
        last, previous = align.last_enc_ns, align.last_y
        if last is None or previous is None or not health.readings_quiet():
            return first
        t = view.enc_t
        silence = health.silence_ns
        if t[e0] <= last or t[e0] - last > silence:
            return first
        stop = min(e1, e0 + to_feed)  # the last reading feeds
        k = bisect.bisect_right(view.enc_disorder, e0)
        if k < len(view.enc_disorder) and view.enc_disorder[k] < stop:
            stop = view.enc_disorder[k]
        k = bisect.bisect_right(view.enc_long, e0)
        while k < len(view.enc_long) and view.enc_long[k] < stop:
            if view.enc_step[view.enc_long[k] - 1] > silence:
                stop = view.enc_long[k]
                break
            k += 1
        start, count = health.rate_window
        low = e0 + max(LOSS_WINDOW_READINGS - count - 1, 1 if start is None else 0)
        closing = e1
        if low < stop:  # the readings up to stop are in order: bisect their times
            base = last if start is None else start
            closing = bisect.bisect_left(t, base + LOSS_WINDOW_NS, low, stop)
            if closing < stop:  # it closes the rate window: the stretch's last message
                stop = closing + 1
        if stop > e0:
            stop = self._stuck_end(view, e0, c0, stop)
        if stop == closing + 1:
            self.closing = view.enc_pos[closing]
            return self.closing + 1
        return view.enc_pos[stop] if stop < e1 else end

    def _stuck_end(self, view: BlockView, e0: int, c0: int, stop: int) -> int:
        """Where the readings ``e0 .. stop - 1`` stop being quiet for the stuck-encoder
        check: the first one
        :meth:`~genbacklash_ros.node.health.StreamHealth.check_reading` would find stuck
        (the stretch's commands, from ordinal ``c0``, count from when they come).

        The still run the stretch starts in (or that its first reading starts) is judged
        here, once for each command it holds
        (:meth:`~genbacklash_ros.node.health.StreamHealth.stuck_reason`, the per-message
        test itself); a later run that lasts ``STUCK_NS`` within the stretch
        ends it (its reading goes the per-message way, and the next stretch starts in it).
        """
        t, y = view.enc_t, view.enc_y
        align, health = self._align, self._health
        k = bisect.bisect_right(view.enc_changed, e0)
        run_end = min(view.enc_changed[k] if k < len(view.enc_changed) else stop, stop)
        k = bisect.bisect_left(view.enc_still, run_end)
        if k < len(view.enc_still) and view.enc_still[k] < stop:
            stop = view.enc_still[k]  # a run that began in the stretch lasts STUCK_NS
        run_end = min(run_end, stop)
        if y[e0] == align.last_y:  # the run goes on from before the stretch
            since, begin = health.still_since, e0
            since = align.last_enc_ns if since is None else since
        else:  # the run starts at e0
            since, begin = t[e0], e0 + 1
        assert since is not None
        o = bisect.bisect_left(t, since + STUCK_NS, begin, run_end)
        if o >= run_end:
            return stop
        # candidates o .. run_end - 1: judged at each command they hold (the command in
        # force STUCK_INPUT_NS before the reading, among those that came before it)
        est = self._use.current
        value = y[o]
        known_t, known_u = align.cmd_t, align.cmd_u  # the commands before the stretch
        n_known = len(known_t)  # and the stretch's own from ordinal c0, as they come
        c_end = view.cmd_before[view.enc_pos[run_end - 1]]
        total = n_known + c_end - c0

        def time_of(j: int) -> int:
            return known_t[j] if j < n_known else view.cmd_t[c0 + j - n_known]

        judged: object = _NOT_JUDGED  # the command judged last (a dwell repeats one)
        while o < run_end:
            at = t[o] - STUCK_INPUT_NS
            count = bisect.bisect_right(known_t, at)
            if count == n_known:
                count += bisect.bisect_right(view.cmd_t, at, c0, c_end) - c0
            came = n_known + view.cmd_before[view.enc_pos[o]] - c0
            j = min(count, came) - 1
            held = None if j < 0 else known_u[j] if j < n_known else view.cmd_u[c0 + j - n_known]
            if held != judged:  # else the same reading, estimate and command: the same answer
                if health.stuck_reason(value, held, est):
                    return o
                judged = held
            if count > came:  # held back by a command not come yet: the next reading
                o += 1
            elif j + 1 < total:  # the next command holds from its time + STUCK_INPUT_NS
                o = bisect.bisect_left(t, time_of(j + 1) + STUCK_INPUT_NS, o + 1, run_end)
            else:
                break
        return stop

    def take(self, view: BlockView, i: int, end: int, out: BatchCollector) -> None:
        """Accept the messages ``i .. end - 1`` (all quiet) in one step: the bookkeeping of
        every stage (silences, compensated commands into ``out``, health, alignment,
        counters, measured tracking). The periodic steps at the commands of ``marks`` and
        what the per-message path does at the last message after its bookkeeping (the feed,
        the periodic steps due) are the pipeline's to make, after this."""
        c0, c1 = view.cmd_before[i], view.cmd_before[end]
        e0, e1 = view.enc_before[i], view.enc_before[end]
        align, health, led = self._align, self._health, self._ledger
        self._silence.arrived_many(
            _seen(view, i, end, c0, c1, e0, e1, True), _seen(view, i, end, c0, c1, e0, e1, False)
        )
        stamps: list[int] = []
        values: list[float] = []
        if c1 > c0:
            est = self._use.current
            comp = self._comp
            last_y = align.last_y
            values = view.cmd_u[c0:c1]
            sent = comp.commands(values, est, last_y=last_y)  # no fault active in a stretch
            health.accept_commands()
            stamps = view.cmd_t[c0:c1]
            align.add_commands(stamps, values)
            led.commands += c1 - c0
            led.compensated += c1 - c0
            out.commands(view.cmd_pos[c0:c1], stamps, sent)
        if e1 > e0:
            last = align.last_enc_ns
            assert last is not None
            t, y = view.enc_t, view.enc_y
            gaps = [t[e0] - last, *view.enc_step[e0 : e1 - 1]]
            final = e1 - 1
            if (y[final] != y[final - 1]) if final > e0 else (y[e0] != align.last_y):
                still = None
            else:
                k = bisect.bisect_right(view.enc_changed, final) - 1
                if k >= 0 and view.enc_changed[k] > e0:
                    still = t[view.enc_changed[k]]
                elif y[e0] != align.last_y:
                    still = t[e0]
                else:
                    still = health.still_since
                    still = last if still is None else still
            health.accept_readings(last, gaps, view.enc_rx[final], still)
            align.add_readings(t[e0:e1], y[e0:e1], gaps)
            led.encoders += e1 - e0
        self._tracking.stretch(
            view.cmd_pos[c0:c1],
            values,
            self._comp.last_weight,
            view.enc_pos[e0:e1],
            view.enc_t[e0:e1],
            view.enc_y[e0:e1],
        )
