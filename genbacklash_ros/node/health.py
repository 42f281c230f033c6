"""Whether the command and encoder streams can be trusted: the node's faults.

:class:`StreamHealth` holds what :class:`~genbacklash_ros.node.pipeline.BacklashPipeline` knows
about the health of its input streams -- the active faults and their reports, the encoder's
rate, equal readings, the residual scale of the model's one-step predictions, the resync
after a gap, command saturation, runs of messages from a clock that jumped back -- and the
rules below. Data flow one way: the pipeline hands :class:`StreamHealth` each accepted
message, each batch it screens, each drop and each report, with what it needs of the other
stages' state as arguments; :class:`StreamHealth` never calls back. What it finds comes back
as return values: :class:`Drop` (samples to count as dropped) and :class:`Note` (the text of
a fault that started: the pipeline's latest problem) events, a :class:`ReadingCheck` (a
stuck encoder's readings to take out) and a :class:`Screening` (the samples to keep). All
times are integer nanoseconds of data time unless said otherwise.

Faults
------
Nothing raises and no non-finite number is published, whatever arrives. On top of that the
pipeline watches for signs that the measurements (or their times) cannot be trusted. Each
such sign starts a *fault*: while any fault is active the compensated command is the command
itself (pass-through, still within ``u_min``/``u_max`` and ``max_rate``), and the next
``/diagnostics`` report is WARN (ERROR for a silent or stuck encoder) and says why. A fault
clears ``FAULT_HOLD_NS`` (0.5 s) of data time after its last sign; the estimate never needs
to be reset, so compensation resumes at once with the current estimate.

* **Rejected messages** -- invalid (non-finite values, empty or mismatched JointState arrays,
  a joint that is not there, a wrong type), duplicate or out-of-order messages, and
  identifier errors: dropped and counted as before; each also starts a fault.
* **Encoder silent** -- a command is received more than ``max(SILENCE_MIN_NS,
  SILENCE_PERIODS * period)`` (0.1 s at 1 kHz; 1 s while the period is unknown) after the last
  accepted encoder reading was (receive times: an offset between the streams' stamps does not
  count), or an encoder reading comes that long after the previous one (ERROR, with the number
  and the reason of the encoder messages rejected meanwhile).
* **Clock jumped forward** -- an encoder gap with no command inside it either: both streams
  jumped (reported instead of the silence, WARN). Samples on both sides are kept: the
  command held across the gap is what the drivetrain held.
* **Clock jumped back** -- ``REANCHOR_COUNT`` (3) consecutive messages of one stream, rising
  among themselves but each more than ``REANCHOR_BACK_NS`` (0.1 s) before the stream's last
  time: the pending samples are fed, both streams restart from the new time (the last
  command is held into it) and so do the periodic outputs, instead of dropping every message
  until the clock catches up. Smaller steps back are dropped as out of order until it does.
* **Encoder losing messages** -- over windows of at least ``LOSS_WINDOW_NS`` (0.25 s) and 50
  readings, the encoder's period is learnt while its intervals are regular (90 % within 25 %
  of their median); in an irregular window more than ``MAX_LOSS`` (20 %) of the readings the
  learnt period predicts are missing (gaps longer than the silence limit excluded).
* **Encoder spikes** -- once the estimate of a general backlash has converged (it stays
  trusted while it converges again or lacks excitation, until the identifier restarts or
  diverges), each sample is predicted one step ahead from the previous accepted reading and
  its command (the clamp of eq. 20, which moves the part of the reading inside its band and
  keeps its offset outside it); a reading more than ``SPIKE_SIGMAS`` (8) residual scales
  from its prediction, and *isolated* -- the reading after it does not follow it -- is not
  fed to the identifier (``encoder_spike`` drops), the prediction standing in for it in
  the next prediction. A spike is a reading that jumps and returns; a model that lags the
  drivetrain is not: while the play grows, the estimate lags it and the readings pushed by
  a flank sit a few counts outside the model's band, one after another (the bundled
  operation bag lost 7 readings so). Such readings are fed, and the screen learns where the
  readings put each edge of the band (a running median of the pushed readings' offsets
  from it, weight 0.3 per step, at most ``SHIFT_PLAY_SHARE`` (25 %) of the play; kept
  against the truth when the estimate moves its band) and judges against that band. Nor
  is a reading that continues the last reading's motion (a load that coasts or rings
  inside the play), nor one the reading after it sides with rather than with the
  prediction, nor, right before samples taken out while the servo settled, one that lies
  between the readings before and after it. A reading after such samples is judged by the
  band alone; when the reading after it jumps, the next one follows that, and their motion
  does not lead back to it, it was the isolated one. The last reading of a feed has no
  neighbour yet and is judged without one. A feed is judged in steps of
  ``SCREEN_SAMPLES`` (64) samples, whatever its size; the scale is a running average
  (weight 0.2 per step) of the steps' upper quartile of the absolute prediction errors /
  1.15 (a normal sigma, robust to a quarter of outliers; at least 1e-3 of the readings'
  magnitude). (Judged a feed at a time, a large feed after a dwell met a scale that had
  not followed the errors for hundreds of samples: the bundled operation bag, which has no
  spike, lost 9 readings as spikes with feeds of 64 and 28 with feeds of 128.) The limit
  is at least ``SPIKE_COUNTS`` (2) encoder counts, the count being the smallest change
  between consecutive readings seen: a quantised reading is up to one
  count from what it measures, so an error of one count and a little is no spike, however
  small the scale of the errors while the load rests. When more than ``SPIKE_MAX_SHARE``
  (20 %) of a step would be rejected the model, not the encoder, is taken to be off and
  the step is fed whole.
* **Encoder stuck** -- with a trusted estimate of a general backlash (as for spikes), the
  reading has not changed for ``STUCK_NS`` (50 ms) although the model says the command in
  force ``STUCK_INPUT_NS`` (20 ms) before the reading has moved the load by more than
  ``STUCK_SIGMAS`` (5) residual scales (ERROR); a reading taken as a move starts, before
  the drivetrain answered the new command, is not stuck. Equal
  readings wait (up to ``STILL_HOLD_NS``, 1 s) before they are fed, and those of a stuck
  encoder are not fed at all (``encoder_stuck`` drops) until the reading changes.
* **Command saturated** -- every command for ``SATURATION_NS`` (0.2 s) at or beyond
  ``u_min``/``u_max`` (only with finite limits): the inverse cannot be applied there.

After a gap in the fed samples (silence, lost readings, a stuck encoder), no regression row
may span it: with a trusted estimate of a general backlash, samples are held back
(``encoder_after_gap`` drops) until one is predicted from the last sample before the gap
(the load was pushed onto a branch, which fixes its position whatever happened in the gap),
``RESYNC_NS`` (0.5 s) at most. Spike, stuck and gap checks need a model of the backlash
itself: for a cascade only the other checks run.

The spike and resync rules run in :class:`~genbacklash_ros.node.spike_screen.SpikeScreen`
(:mod:`~genbacklash_ros.node.spike_screen`, with their thresholds), which
:class:`StreamHealth` holds and hands each feed; the events are the types of
:mod:`~genbacklash_ros.node.health_events`. Both are importable from here as before.

Examples
--------
>>> from genbacklash_core import CompensatorOptions, Estimate, Structure
>>> from genbacklash_ros.node.messages import DiagnosticStatus
>>> health = StreamHealth()
>>> no_model = Estimate.empty(Structure(3))
>>> health.check_reading(1_000_000, None, 0.5, None, 1_000_000, [], [], no_model).stuck
False
>>> health.check_command(2_000_000, 9.0, 2_000_000, CompensatorOptions(u_max=1.0))
[]
>>> health.check_command(300_000_000, 9.0, 300_000_000, CompensatorOptions(u_max=1.0))
[Note(text='command saturated at limit u_max = 1 for 0.298 s (last command 9)')]
>>> health.passing_through(400_000_000), health.faults
(True, {'command_saturated': (1, 800000000)})
>>> report = health.report(400_000_000)
>>> report.level == DiagnosticStatus.WARN, report.active
(True, ('command_saturated',))
>>> report.parts[1]
'command saturated at limit u_max = 1 for 0.298 s (last command 9)'
>>> health.passing_through(800_000_000)
False
"""

from __future__ import annotations

import bisect
import math
from typing import NamedTuple

import numpy as np

from genbacklash_core import CompensatorOptions, Estimate, GeneralBacklash
from genbacklash_ros.node.health_events import Drop as Drop
from genbacklash_ros.node.health_events import HealthEvent as HealthEvent
from genbacklash_ros.node.health_events import Note as Note
from genbacklash_ros.node.messages import DiagnosticStatus
from genbacklash_ros.node.spike_screen import _SCALE_SMOOTHING as _SCALE_SMOOTHING
from genbacklash_ros.node.spike_screen import RESYNC_NS as RESYNC_NS
from genbacklash_ros.node.spike_screen import SHIFT_PLAY_SHARE as SHIFT_PLAY_SHARE
from genbacklash_ros.node.spike_screen import SPIKE_COUNTS as SPIKE_COUNTS
from genbacklash_ros.node.spike_screen import SPIKE_MAX_SHARE as SPIKE_MAX_SHARE
from genbacklash_ros.node.spike_screen import SPIKE_SIGMAS as SPIKE_SIGMAS
from genbacklash_ros.node.spike_screen import Screening as Screening
from genbacklash_ros.node.spike_screen import SpikeScreen, exact_median

__all__ = [
    "FAULT_HOLD_NS",
    "LOSS_WINDOW_NS",
    "LOSS_WINDOW_READINGS",
    "MAX_LOSS",
    "REANCHOR_BACK_NS",
    "REANCHOR_COUNT",
    "RESYNC_NS",
    "SATURATION_NS",
    "SHIFT_PLAY_SHARE",
    "SILENCE_MIN_NS",
    "SILENCE_PERIODS",
    "SILENCE_UNKNOWN_NS",
    "SPIKE_COUNTS",
    "SPIKE_MAX_SHARE",
    "SPIKE_SIGMAS",
    "STILL_HOLD_NS",
    "STUCK_INPUT_NS",
    "STUCK_NS",
    "STUCK_SIGMAS",
    "Drop",
    "HealthEvent",
    "HealthReport",
    "Note",
    "ReadingCheck",
    "Screening",
    "StreamHealth",
]

# faults (see the module notes): pass-through while one is active
FAULT_HOLD_NS = 500_000_000  # a fault clears this long after its last sign
SILENCE_MIN_NS = 100_000_000  # encoder silent: no reading for max(this, SILENCE_PERIODS periods)
SILENCE_PERIODS = 20
SILENCE_UNKNOWN_NS = 1_000_000_000  # ... or this while the encoder period is not known yet
LOSS_WINDOW_NS = 250_000_000  # encoder rate checked over windows this long (and 50 readings)
LOSS_WINDOW_READINGS = 50
MAX_LOSS = 0.2  # share of the expected readings missing that is a fault
REANCHOR_COUNT = 3  # consecutive far-back messages of a stream that mean a clock jump back
REANCHOR_BACK_NS = 100_000_000  # ... each this far before the stream's last time
STUCK_NS = 50_000_000  # an unchanged reading this long, while the model says it moves ...
STUCK_SIGMAS = 5.0  # ... by more than this many residual scales, is a stuck encoder
STUCK_PLAY_SHARE = 0.5  # ... and by more than this share of the play c_L + c_R
STILL_HOLD_NS = 1_000_000_000  # equal readings wait this long at most before being fed
# a still reading is judged by the command in force this long before it: a reading taken as
# a move starts (the new command just sent, the load not moved yet) is not a stuck encoder
STUCK_INPUT_NS = 20_000_000
SATURATION_NS = 200_000_000  # commands at or beyond a limit this long: saturated


class ReadingCheck(NamedTuple):
    """What :meth:`StreamHealth.check_reading` found about one encoder reading.

    Attributes
    ----------
    stuck : bool
        The reading belongs to a stuck encoder: not to be fed.
    discard_after : int or None
        The encoder was just found stuck: take out the pending (not yet fed) readings
        stamped after this time (the first of the equal readings is kept) and count them as
        ``encoder_stuck`` drops. None otherwise.
    events : list of Drop or Note
    """

    stuck: bool
    discard_after: int | None
    events: list[HealthEvent]


class HealthReport(NamedTuple):
    """What a ``/diagnostics`` report says about the faults (:meth:`StreamHealth.report`).

    Attributes
    ----------
    passing : bool
        A fault is active: compensation passes the command through.
    level : int
        The highest level of the active faults and of the fault texts (``DiagnosticStatus.OK``
        when there are none).
    parts : list of str
        The sentences for the report's message: the pass-through and its faults, then why
        each fault started since the last report.
    active : tuple of str
        The keys of the active faults (e.g. ``"encoder_silent"``), in the order they started.
    """

    passing: bool
    level: int
    parts: list[str]
    active: tuple[str, ...]


def _held_input(stamp: int, commands: list[int], inputs: list[float]) -> float | None:
    """The command in force ``STUCK_INPUT_NS`` before ``stamp``: it has had that long to move
    the load, so a reading short of where it puts the load is stuck (None when not known)."""
    k = bisect.bisect_right(commands, stamp - STUCK_INPUT_NS) - 1
    return inputs[k] if k >= 0 else None


class StreamHealth:
    """The faults of a pipeline's command and encoder streams and what detects them.

    Notes
    -----
    Not thread-safe, like the pipeline. The pipeline calls :meth:`check_command` and
    :meth:`check_reading` for each accepted message, :meth:`jumped_back` for each message not
    after its stream's last one (then :meth:`reanchored` once it has re-anchored alignment),
    :meth:`screen` and :meth:`feed_horizon` when it feeds, :meth:`encoder_rejected` and
    :meth:`fault` when it drops a message, and :meth:`passing_through` and :meth:`report`
    when it compensates and reports. Each returns what it found; none calls back.
    """

    __slots__ = (
        "_cmd_back",
        "_enc_back",
        "_enc_period",
        "_enc_reject_reason",
        "_enc_rejects",
        "_events",
        "_fault_texts",
        "_gaps",
        "_gaps_from",
        "_last_enc_rx",
        "_sat_since",
        "_silence",
        "_spikes",
        "_still_since",
        "_stuck",
        "_stuck_branches",
        "_stuck_why",
        "faults",
    )

    faults: dict[str, tuple[int, int]]
    """Active faults: key -> (level, data time the pass-through lasts until). Read only."""

    def __init__(self) -> None:
        self._events: list[HealthEvent] = []  # what the current call found (returned)
        self.reset()

    @property
    def model_fits(self) -> bool:
        """The compensation guard's judgement, set by the pipeline at each feed: the model
        describes the drivetrain (a reading far from a prediction of a model that does not
        is no evidence of a spike). True after :meth:`reset`."""
        return self._spikes.model_fits

    @model_fits.setter
    def model_fits(self, fits: bool) -> None:
        self._spikes.model_fits = fits

    def reset(self) -> None:
        """Forget the faults and what detects them (construction, restart)."""
        self.faults = {}
        self._fault_texts: dict[str, tuple[int, str]] = {}  # since the last report
        self._enc_rejects = 0  # encoder messages rejected since the last accepted one
        self._last_enc_rx: int | None = None  # receive time of the last accepted reading
        self._enc_reject_reason = ""
        self._cmd_back: list[int] = []  # times of consecutive far-back messages
        self._enc_back: list[int] = []
        self._enc_period: float | None = None  # learnt while the encoder is regular
        self._silence = SILENCE_UNKNOWN_NS
        self._gaps: list[int] = []  # encoder intervals of the current rate window
        self._gaps_from: int | None = None
        self._still_since: int | None = None  # time of the first of equal readings
        self._stuck = False
        self._stuck_why = ""
        # the branches at the last command judged: (model, command, L(u), R(u)); a dwell
        # asks for the same command at every still reading
        self._stuck_branches: tuple[GeneralBacklash, float, float, float] | None = None
        self._sat_since: int | None = None  # time of the first of saturated commands
        self._spikes = SpikeScreen()  # the spike screen (and its residual scale)

    # ------------------------------------------------------------------ faults

    def _found(self) -> list[HealthEvent]:
        """The events of the current call (and a fresh list for the next one)."""
        events, self._events = self._events, []
        return events

    def _drop(self, key: str, reason: str, count: int) -> None:
        self._events.append(Drop(key, reason, count))

    def fault(self, key: str, level: int, text: str, at: int | None) -> list[HealthEvent]:
        """Start (or prolong) fault ``key``: pass-through until ``FAULT_HOLD_NS`` after ``at``
        (the data clock; None before the first message); ``text`` goes into the next
        report ("" when the report says why by itself). Returns its :class:`Note`."""
        self._start(key, level, text, at)
        return self._found()

    def _start(self, key: str, level: int, text: str, at: int | None) -> None:
        until = (0 if at is None else at) + FAULT_HOLD_NS
        old = self.faults.get(key)
        if old is not None:
            level, until = max(level, old[0]), max(until, old[1])
        self.faults[key] = (level, until)
        if text:
            self._fault_texts[key] = (level, text)
            self._events.append(Note(text))

    def _clear_fault(self, key: str) -> None:
        self.faults.pop(key, None)
        self._fault_texts.pop(key, None)

    def passing_through(self, now: int) -> bool:
        """True while a fault is active at data time ``now`` (forgets those that cleared)."""
        faults = self.faults
        for key in [k for k, (_, until) in faults.items() if until <= now]:
            del faults[key]
        return bool(faults)

    def report(self, now: int) -> HealthReport:
        """The faults for a report at data time ``now`` (forgets those that cleared, and the
        texts: each is reported once)."""
        faults = self.faults
        passing = self.passing_through(now)
        level = DiagnosticStatus.OK
        parts: list[str] = []
        if passing:
            level = max(level, *(lvl for lvl, _ in faults.values()))
            names = ", ".join(key.replace("_", " ") for key in faults)
            parts.append(f"compensation passes the command through ({names})")
        for lvl, text in self._fault_texts.values():
            level = max(level, lvl)
            parts.append(text)
        self._fault_texts.clear()
        return HealthReport(passing, level, parts, tuple(faults))

    def encoder_rejected(self, count: int, reason: str) -> None:
        """``count`` encoder messages rejected (invalid, duplicate, out of order) for
        ``reason``: told with the silence they may explain."""
        self._enc_rejects += count
        self._enc_reject_reason = reason

    # ------------------------------------------------------------------ per message

    def check_command(
        self, stamp: int, value: float, receive_ns: int, options: CompensatorOptions
    ) -> list[HealthEvent]:
        """An accepted command at ``stamp`` (received at ``receive_ns``): encoder silence (on
        the receive clock: immune to an offset between the streams' stamps) and command
        saturation against the limits of ``options``. Returns the faults' notes."""
        if self._cmd_back:
            self._cmd_back.clear()
        last_rx = self._last_enc_rx
        if last_rx is not None and receive_ns - last_rx > self._silence:
            silent = receive_ns - last_rx
            self._start("encoder_silent", DiagnosticStatus.ERROR, self._silent_text(silent), stamp)
        if value >= options.u_max or value <= options.u_min:
            since = self._sat_since
            if since is None:
                self._sat_since = stamp
            elif stamp - since >= SATURATION_NS:
                name, limit = (
                    ("u_max", options.u_max) if value >= options.u_max else ("u_min", options.u_min)
                )
                self._start(
                    "command_saturated",
                    DiagnosticStatus.WARN,
                    f"command saturated at limit {name} = {limit:g} for "
                    f"{(stamp - since) / 1e9:.3f} s (last command {value:.6g})",
                    stamp,
                )
        elif self._sat_since is not None:
            self._sat_since = None
        return self._found()

    def check_reading(
        self,
        stamp: int,
        last: int | None,
        value: float,
        previous: float | None,
        receive_ns: int,
        commands: list[int],
        inputs: list[float],
        estimate: Estimate,
    ) -> ReadingCheck:
        """An accepted encoder reading: encoder gaps (silence, clock jump forward), message
        loss and a stuck encoder.

        Parameters
        ----------
        stamp : int
            The reading's time.
        last : int or None
            The stream's last accepted time (None for the first reading of a time line).
        value : float
            The reading.
        previous : float or None
            The stream's last accepted reading.
        receive_ns : int
            When the reading was received (the transport's clock).
        commands, inputs : list
            The pipeline's pending commands: their times and identifier inputs (read only).
        estimate : Estimate
            The estimate in use (judges whether unchanged readings are stuck).

        Returns
        -------
        ReadingCheck
        """
        if self._enc_back:
            self._enc_back.clear()
        if last is not None:
            gap = stamp - last
            if gap > self._silence:
                self._encoder_gap(stamp, last, commands)
            else:
                self._gaps.append(gap)
            start = self._gaps_from
            if start is None:
                self._gaps_from = last
            elif stamp - start >= LOSS_WINDOW_NS and len(self._gaps) >= LOSS_WINDOW_READINGS:
                self._check_rate(stamp)
        self._enc_rejects = 0
        self._last_enc_rx = receive_ns
        if last is None or value != previous:
            self._still_since, self._stuck = None, False
            return ReadingCheck(False, None, self._found())
        return self._watch_stuck(stamp, last, value, commands, inputs, estimate)

    # ------------------------------------------------------------------ batch form

    @property
    def silence_ns(self) -> int:
        """The encoder gap that counts as a silence now (ns)."""
        return self._silence

    @property
    def last_encoder_receive(self) -> int | None:
        """The receive time of the last accepted encoder reading (None: none yet)."""
        return self._last_enc_rx

    @property
    def rate_window(self) -> tuple[int | None, int]:
        """Where the current rate window started (None: at the next reading) and how many
        gaps it holds: a reading closes it ``LOSS_WINDOW_NS`` after its start once it holds
        ``LOSS_WINDOW_READINGS`` gaps."""
        return self._gaps_from, len(self._gaps)

    @property
    def still_since(self) -> int | None:
        """The time of the reading before the current run of equal readings (None: the
        last reading changed)."""
        return self._still_since

    def commands_quiet(self) -> bool:
        """Commands checked now find nothing by themselves but a late command or a
        saturated one: no fault is active and no run of commands from the past is going."""
        return not self.faults and not self._cmd_back

    def readings_quiet(self) -> bool:
        """Readings checked now are judged by their gap, rate window and stillness only: the
        encoder is not stuck and no run of readings from the past is going."""
        return not self._stuck and not self._enc_back

    def stuck_reason(self, value: float, held: float | None, est: Estimate) -> str:
        """Why an unchanged reading ``value`` is stuck ("" when the model allows it), ``held``
        being the command in force ``STUCK_INPUT_NS`` before the reading: the test
        :meth:`check_reading` makes of a reading ``STUCK_NS`` into a still run."""
        return self._stuck_reason(value, held, est)

    def accept_commands(self) -> None:
        """Commands that :meth:`check_command` would pass without finding anything (none
        saturated, none late), accepted."""
        if self._cmd_back:
            self._cmd_back.clear()
        self._sat_since = None

    def accept_readings(
        self, last: int, gaps: list[int], receive_ns: int, still_since: int | None
    ) -> None:
        """Readings that :meth:`check_reading` would pass without finding anything (no gap
        beyond the silence, no rate window closed but by the last one: then
        :meth:`close_rate_window` follows, none stuck), accepted after the stream's
        last time ``last``: their ``gaps`` to the reading before each, the last one's
        receive time and the start of the still run it ends in (None: it changed)."""
        if not gaps:
            return
        if self._enc_back:
            self._enc_back.clear()
        if self._gaps_from is None:
            self._gaps_from = last
        self._gaps.extend(gaps)
        self._enc_rejects = 0
        self._last_enc_rx = receive_ns
        self._still_since = still_since
        if still_since is None:
            self._stuck = False

    def close_rate_window(self, stamp: int) -> list[HealthEvent]:
        """The reading at ``stamp``, accepted by :meth:`accept_readings` as the last of its
        readings, closes the rate window (:attr:`rate_window`): what :meth:`check_reading`
        does then (learn the period, or find lost readings), and what it found."""
        self._check_rate(stamp)
        return self._found()

    def jumped_back(self, stream: str, stamp: int, last: int) -> int | None:
        """Whether a message of ``stream`` (``"command"`` or ``"encoder"``) at ``stamp``, not
        after ``last``, completes a run that shows its clock jumped back: about how far back
        it jumped when it does (the pipeline then re-anchors, see the module notes), else
        None (the message is dropped as out of order)."""
        run = self._cmd_back if stream == "command" else self._enc_back
        if last - stamp < REANCHOR_BACK_NS:
            run.clear()
            return None
        if run and stamp <= run[-1]:
            run.clear()
        run.append(stamp)
        if len(run) < REANCHOR_COUNT:
            return None
        # the first of the run came about one message interval after the last accepted one
        return last - run[0] + (stamp - run[0]) // (len(run) - 1)

    def reanchored(self, stream: str, stamp: int, last: int, back: int) -> list[HealthEvent]:
        """Alignment and the data clock restarted at ``stamp`` after a clock jump back (by
        about ``back``) seen on ``stream`` after its last time ``last``: restart what watches
        the streams, hold the active faults from ``stamp`` and report the jump."""
        self._cmd_back.clear()
        self._enc_back.clear()
        self.faults = {k: (lvl, stamp + FAULT_HOLD_NS) for k, (lvl, _) in self.faults.items()}
        self._gaps, self._gaps_from = [], None
        self._still_since, self._stuck, self._sat_since = None, False, None
        self._spikes.forget_fed_time()
        return self.fault(
            "clock_jump_back",
            DiagnosticStatus.WARN,
            f"clock jumped back {back / 1e9:.3f} s ({stream} time {stamp} ns after {last} ns): "
            "alignment re-anchored",
            stamp,
        )

    # ------------------------------------------------------------------ per feed

    def feed_horizon(self, horizon: int, now: int) -> int:
        """The latest sample time to feed at data time ``now`` instead of ``horizon``: equal
        readings wait (the encoder may be stuck), ``STILL_HOLD_NS`` at most."""
        still = self._still_since
        if still is not None and now - still < STILL_HOLD_NS:
            return min(horizon, still)
        return horizon

    def screen(
        self,
        times: np.ndarray,
        us: np.ndarray,
        ys: np.ndarray,
        est: Estimate,
        resumed: np.ndarray | None = None,
    ) -> Screening:
        """Which of the samples (``times``, inputs ``us``, readings ``ys``) to feed: not the
        spikes nor those held back after a gap, judged with ``est``, the estimate in use
        (:meth:`SpikeScreen.screen <genbacklash_ros.node.spike_screen.SpikeScreen.screen>`
        under the encoder's silence limit)."""
        return self._spikes.screen(times, us, ys, est, resumed, silence_ns=self._silence)

    # ------------------------------------------------------------------ detection

    def _silent_text(self, silent_ns: int) -> str:
        text = f"encoder silent for {silent_ns / 1e9:.3f} s"
        if self._enc_rejects:
            text += (
                f" ({self._enc_rejects} encoder messages rejected meanwhile, last: "
                f"{self._enc_reject_reason})"
            )
        return text

    def _encoder_gap(self, stamp: int, last: int, commands: list[int]) -> None:
        """An encoder gap longer than the silence limit: lost readings or a clock jump
        (``commands``: the pending commands' times)."""
        gap = stamp - last
        margin = min(self._silence, gap // 4)
        first = bisect.bisect_right(commands, last + margin)
        inside = bisect.bisect_left(commands, stamp - margin) > first
        if commands and not inside:  # neither stream has anything in the gap
            self._clear_fault("encoder_silent")
            self._start(
                "clock_jump_forward",
                DiagnosticStatus.WARN,
                f"clock jumped forward {gap / 1e9:.3f} s (no command nor encoder reading in "
                "between)",
                stamp,
            )
        else:
            self._start("encoder_silent", DiagnosticStatus.ERROR, self._silent_text(gap), stamp)

    def _check_rate(self, stamp: int) -> None:
        """Close a rate window: learn the period when regular, else look for lost readings."""
        gaps = np.array(self._gaps, dtype=np.float64)
        self._gaps = []
        self._gaps_from = stamp
        median = exact_median(gaps)
        regular = np.count_nonzero(np.abs(gaps - median) <= 0.25 * median)
        if regular / gaps.size >= 0.9:
            self._enc_period = median
            self._silence = max(SILENCE_MIN_NS, round(SILENCE_PERIODS * median))
            return
        period = self._enc_period
        if period is None:
            return
        span = float(gaps.sum())
        loss = 1.0 - gaps.size * period / span
        if loss > MAX_LOSS:
            self._start(
                "encoder_loss",
                DiagnosticStatus.WARN,
                f"encoder lost {loss:.0%} of its readings over {span / 1e9:.2f} s (one expected "
                f"every {period / 1e6:.3g} ms)",
                stamp,
            )

    def _watch_stuck(
        self,
        stamp: int,
        last: int,
        value: float,
        commands: list[int],
        inputs: list[float],
        estimate: Estimate,
    ) -> ReadingCheck:
        """Whether the reading ``value`` at ``stamp``, equal to the one at ``last``, belongs
        to a stuck encoder (not to be fed)."""
        since = self._still_since
        if since is None:
            self._still_since = last
            return ReadingCheck(False, None, self._found())
        if stamp - since < STUCK_NS:
            return ReadingCheck(False, None, self._found())
        discard: int | None = None
        if not self._stuck:
            why = self._stuck_reason(value, _held_input(stamp, commands, inputs), estimate)
            if not why:
                return ReadingCheck(False, None, self._found())
            self._stuck, self._stuck_why = True, why
            discard = since  # the pending readings after the first equal one go too
        self._drop("encoder_stuck", "encoder reading unchanged", 1)
        self._start(
            "encoder_stuck",
            DiagnosticStatus.ERROR,
            f"encoder stuck at {value:.6g} for {(stamp - since) / 1e9:.3f} s{self._stuck_why}",
            stamp,
        )
        return ReadingCheck(True, discard, self._found())

    def _stuck_reason(self, value: float, held: float | None, est: Estimate) -> str:
        """Why an unchanged reading ``value`` is stuck ("" when the model allows it), ``held``
        being the command in force ``STUCK_INPUT_NS`` before the reading, ``est`` the
        estimate in use."""
        model = est.model
        spikes = self._spikes
        scale = spikes.scale
        trusted = spikes.trusted(est)
        if not trusted or scale is None or not isinstance(model, GeneralBacklash):
            return ""
        if held is None:
            return ""
        u = held
        memo = self._stuck_branches
        if memo is not None and memo[0] is model and memo[1] == u:
            left, right = memo[2], memo[3]
        else:
            left, right = model.branches_at(u)
            self._stuck_branches = (model, u, left, right)
        move = max(min(left, right) - value, value - max(left, right))
        # a servo's static error or its settling puts a held load a little off the model's
        # band: only a move of a good part of the play is a stuck encoder
        floor = STUCK_PLAY_SHARE * (model.c_left + model.c_right)
        if not (math.isfinite(move) and move > max(STUCK_SIGMAS * scale, 1e-3 * abs(value), floor)):
            return ""
        return f" although the model moves the load by {move:.3g} at the command {u:.6g}"
