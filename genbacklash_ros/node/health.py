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
from dataclasses import dataclass
from typing import NamedTuple, TypeAlias

import numpy as np

from genbacklash_core import CompensatorOptions, Estimate, EstimatorState, GeneralBacklash
from genbacklash_ros.node.messages import DiagnosticStatus

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
SPIKE_SIGMAS = 8.0  # a reading this many residual scales from its prediction is a spike
SPIKE_MAX_SHARE = 0.2  # more of a step than this: the model is off, not the encoder
SCREEN_SAMPLES = 64  # samples the screen judges with one residual scale (it follows each step)
SPIKE_COUNTS = 2.0  # ... and at least this many encoder counts (a quantised reading's error)
RESYNC_NS = 500_000_000  # after a gap, samples wait this long at most for a consistent one
STUCK_NS = 50_000_000  # an unchanged reading this long, while the model says it moves ...
STUCK_SIGMAS = 5.0  # ... by more than this many residual scales, is a stuck encoder
STUCK_PLAY_SHARE = 0.5  # ... and by more than this share of the play c_L + c_R
STILL_HOLD_NS = 1_000_000_000  # equal readings wait this long at most before being fed
# a still reading is judged by the command in force this long before it: a reading taken as
# a move starts (the new command just sent, the load not moved yet) is not a stuck encoder
STUCK_INPUT_NS = 20_000_000
SATURATION_NS = 200_000_000  # commands at or beyond a limit this long: saturated
_SCALE_SMOOTHING = 0.2  # weight of a new step in the residual scale
# the band's edges as the readings show them (see StreamHealth.screen): a step's median offset
# of the readings pushed by an edge is blended in with this weight, from this many readings
_SHIFT_SMOOTHING = 0.3
_SHIFT_MIN_READINGS = 3
SHIFT_PLAY_SHARE = 0.25  # an edge is moved by at most this share of the play c_L + c_R


@dataclass(frozen=True, slots=True)
class Drop:
    """``count`` samples (or messages) dropped for ``key`` (e.g. ``encoder_spike``), the
    latest ``reason`` in words."""

    key: str
    reason: str
    count: int


@dataclass(frozen=True, slots=True)
class Note:
    """A fault started (or went on) with ``text``: the pipeline's latest problem."""

    text: str


HealthEvent: TypeAlias = Drop | Note
"""What a :class:`StreamHealth` check found, in the order it found it."""


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


class Screening(NamedTuple):
    """What :meth:`StreamHealth.screen` made of a batch of samples.

    Attributes
    ----------
    keep : numpy.ndarray of bool or None
        The samples to feed (None: all of them).
    events : list of Drop or Note
        The spikes and the samples held back after a gap, counted as drops.
    """

    keep: np.ndarray | None
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


def _median(values: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D array, to the bit (the middle value, or the mean of
    the two middle ones), from one partition and without its generic machinery."""
    n = values.size
    half = n // 2
    if n % 2:
        return float(np.partition(values, half)[half])
    ordered = np.partition(values, (half - 1, half))
    return (float(ordered[half - 1]) + float(ordered[half])) / 2.0


def _one_step_errors(
    y_prev: float,
    band_prev: tuple[float, float],
    ys: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    resumed: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The one-step errors of eq. (20)'s clamp: each reading ``ys`` (band ``low .. high``)
    predicted from the one before it (the first from ``y_prev``, its band ``band_prev``),
    the clamp moving the part of it inside its band and keeping the offset outside it (a
    band that lags the drivetrain by an offset lags it by as much one reading later). A
    ``resumed`` reading (after samples taken out while the servo settled: the commands
    between may have reversed) is judged by the band alone, ``|y - clamp(y, low, high)|``.

    Returns the errors and which readings the clamp put on the band's lower and upper edge
    (the load pushed by a flank)."""
    n = ys.size
    previous, low_prev, high_prev = np.empty(n), np.empty(n), np.empty(n)
    if n:  # each shifted by one, the one before first
        previous[0], previous[1:] = y_prev, ys[:-1]
        low_prev[0], low_prev[1:] = band_prev[0], low[:-1]
        high_prev[0], high_prev[1:] = band_prev[1], high[:-1]
    with np.errstate(all="ignore"):
        inside = np.minimum(np.maximum(previous, low_prev), high_prev)
        carry = previous - inside
        if resumed is not None:
            inside[resumed] = ys[resumed]
            carry[resumed] = 0.0
        errors: np.ndarray = np.abs(ys - (np.minimum(np.maximum(inside, low), high) + carry))
        on_low: np.ndarray = inside <= low
        on_high: np.ndarray = inside >= high
    return errors, on_low, on_high


def _step(value: float, low: float, high: float, low_next: float, high_next: float) -> float:
    """The clamp of eq. (20) one reading on from ``value`` (band ``low .. high``) into the
    band ``low_next .. high_next``: the part inside the band moves, the offset outside it
    stays (a band that lags the drivetrain by an offset lags it as much one reading later)."""
    inside = min(max(value, low), high)
    return min(max(inside, low_next), high_next) + (value - inside)


def _isolated(
    y: float,
    predicted: float,
    low: float,
    high: float,
    y_next: float,
    low_next: float,
    high_next: float,
    limit: float,
) -> bool:
    """Whether the reading ``y`` (band ``low .. high``), far from its prediction
    ``predicted``, is isolated: the reading after it (``y_next``, band ``low_next ..
    high_next``) does not follow it within ``limit``, and lies nearer where the prediction
    leads than where ``y`` leads (a spike jumps and returns; a load that moved where the
    model did not say stays there)."""
    from_y = abs(y_next - _step(y, low, high, low_next, high_next))
    from_predicted = abs(y_next - _step(predicted, low, high, low_next, high_next))
    return from_y > limit and from_predicted < from_y


def _travelling(readings: tuple[float, float, float]) -> bool:
    """Whether three readings in a row travel one way (strictly): a load that moves, at a
    pace of its own. After samples taken out while the servo settled, the first reading
    (judged by the band alone) is where the load was when the readings resumed: inside the
    play, where the model holds a load (eq. 20, ``x(t) = x(t-1)`` between the branches), one
    falls across the gap under gravity or coasts; on a flank, a load behind a servo that lags
    the command catches up with the band (the physics drivetrains: +9, +3, +1.5 mrad a
    reading). Either way the pace changes between the readings, and the readings after the
    first do not lead back to it on a straight line: that is the load's, not a spike's.

    The price: a spike displaced against the motion at such a reading also travels one way
    with the readings after it, and is fed; one displaced along the motion by more than a
    reading's step turns back, and is still caught (as is any spike on a resting load)."""
    a, b, c = readings
    return a < b < c or a > b > c


def _trailing(y: float, predicted: float, y_next: float, y_after: float) -> bool:
    """Whether a reading judged by the band alone (the first after samples taken out while
    the servo settled), off its band by ``y - predicted``, is a load trailing the band: it
    and the two readings after it travel one way (:func:`_travelling`), towards the side the
    band is on. A servo that lags the command leaves the load behind a moving flank when the
    readings resume and it closes on it reading by reading (the physics gravity records:
    3.8 mrad behind, then 0.7, then on it). A spike returns at once instead, and a spike
    ahead of the flank turns back: both are still caught. The price: a spike behind a
    moving flank at such a reading is fed."""
    travelling = _travelling((y, y_next, y_after))
    return travelling and (y - predicted) * (y_next - y) < 0.0


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
        "_converged",
        "_enc_back",
        "_enc_period",
        "_enc_reject_reason",
        "_enc_rejects",
        "_events",
        "_fault_texts",
        "_fed_band",
        "_fed_t",
        "_fed_y",
        "_gaps",
        "_gaps_from",
        "_last_enc_rx",
        "_quantum",
        "_resync_since",
        "_sat_since",
        "_scale",
        "_shift",
        "_shift_model",
        "_silence",
        "_still_since",
        "_stuck",
        "_stuck_branches",
        "_stuck_why",
        "faults",
        "model_fits",
    )

    faults: dict[str, tuple[int, int]]
    """Active faults: key -> (level, data time the pass-through lasts until). Read only."""

    def __init__(self) -> None:
        self._events: list[HealthEvent] = []  # what the current call found (returned)
        self.reset()

    def reset(self) -> None:
        """Forget the faults and what detects them (construction, restart)."""
        # the compensation guard's judgement: the model describes the drivetrain (a reading
        # far from a prediction of a model that does not is no evidence of a spike)
        self.model_fits = True
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
        self._fed_t: int | None = None  # the last sample fed (spike prediction)
        self._fed_y: float | None = None
        self._fed_band: tuple[float, float] | None = None  # its band's edges (unshifted)
        self._scale: float | None = None  # robust scale of the one-step prediction errors
        # where the readings put the band's lower and upper edge, against the estimate's
        # band (the edges of the model self._shift_model; see screen)
        self._shift = (0.0, 0.0)
        self._shift_model: GeneralBacklash | None = None
        self._quantum = math.inf  # the smallest change between consecutive readings fed
        self._resync_since: int | None = None  # time of the first sample after a gap
        self._converged = False  # the estimate has converged since the identifier started

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
        self._fed_t = None
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
        spikes nor those held back after a gap (see the module notes), judged with ``est``,
        the estimate in use; tracks the scale of the one-step prediction errors.

        The samples are judged in steps of ``SCREEN_SAMPLES``, the scale following each
        step: a feed is judged the same whatever its size (a large one after a dwell, or
        feeds of another size, meet the limits a steady stream of small ones would). The
        usual steps (each reading predicted from the one before it, none too far) are
        judged at once, in numpy steps over the whole feed.

        ``resumed`` marks samples after ones taken out while the servo settled
        (:mod:`genbacklash_core.settling`): they are judged against the model's band alone.

        Returns the mask of the samples to keep (None to keep them all) and the drops. The
        screen stage breaks the chain of consecutive samples at the next kept sample after
        each one taken out (:func:`~genbacklash_ros.node.sample_rule.keep_breaks`)."""
        model = est.model
        if not isinstance(model, GeneralBacklash):
            self._fed_t, self._fed_y, self._fed_band = int(times[-1]), float(ys[-1]), None
            return Screening(None, [])
        self._track_quantum(ys)
        left, right = model.branches(us)
        low, high = np.minimum(left, right), np.maximum(left, right)
        self._follow_model(model, float(us[0]))
        t_prev, y_prev = self._fed_t, self._fed_y
        # a gap before a sample (or no sample before it): not predicted from the one before
        fresh = np.empty(times.size, dtype=bool)
        np.greater(times[1:] - times[:-1], self._silence, out=fresh[1:])
        fresh[0] = t_prev is None or y_prev is None or int(times[0]) - t_prev > self._silence
        n, step = int(ys.size), SCREEN_SAMPLES
        start = 0
        if self._resync_since is None and y_prev is not None and not fresh.any():
            # the usual case, a step at once: each reading predicted from the one before it
            trusted = self._trusted(est)
            previous, band = y_prev, self._band_before()
            while start < n:
                part = slice(start, start + step)
                lows, highs = self._shifted(low[part], high[part])
                errs, on_low, on_high = _one_step_errors(
                    previous,
                    band,
                    ys[part],
                    lows,
                    highs,
                    None if resumed is None else resumed[part],
                )
                if (errs > self._limit(trusted)).any():
                    break  # a spike: this step and those after it sample by sample
                self._track_scale(errs, ys[part])
                y_part = ys[part]
                self._track_shift(
                    y_part[on_low] - low[part][on_low], y_part[on_high] - high[part][on_high], model
                )
                previous, band = float(y_part[-1]), (float(lows[-1]), float(highs[-1]))
                start += step
            if start >= n:
                self._fed_t, self._fed_y = int(times[-1]), float(ys[-1])
                self._fed_band = (float(low[-1]), float(high[-1]))
                return Screening(None, [])
            if start:
                self._fed_t, self._fed_y = int(times[start - 1]), float(ys[start - 1])
                self._fed_band = (float(low[start - 1]), float(high[start - 1]))
        keeps: list[np.ndarray | None] = [None] if start else []
        events: list[HealthEvent] = []
        for first in range(start, n, step):
            part = slice(first, first + step)
            j = first + step  # the reading after the step, its neighbour
            after = None
            if j < n and not fresh[j]:
                after = (
                    float(ys[j]),
                    float(low[j]),
                    float(high[j]),
                    resumed is None or not bool(resumed[j]),
                )
            found = self._screen_step(
                times[part],
                ys[part],
                low[part],
                high[part],
                fresh[part],
                est,
                model,
                None if resumed is None else resumed[part],
                after,
            )
            keeps.append(found.keep)
            events += found.events
        if all(keep is None for keep in keeps):
            return Screening(None, events)
        sizes = [start] if start else []
        sizes += [min(step, n - first) for first in range(start, n, step)]
        keep = np.concatenate(
            [
                np.ones(size, dtype=bool) if part is None else part
                for size, part in zip(sizes, keeps, strict=True)
            ]
        )
        return Screening(keep, events)

    def _limit(self, trusted: bool) -> float:
        """The spike limit now (infinite while the estimate may not judge, or while the
        compensation guard judges that the model does not describe the drivetrain:
        :attr:`model_fits`).

        A reading exactly ``SPIKE_COUNTS`` counts from a prediction that is itself a
        reading is within the limit: the counts floor carries a millionth of a count more,
        so that the rounding of two quantised readings' difference does not decide (the
        physics gravity record, seed 15: a load moving 2 counts inside the play, dropped at
        ``3.0679616e-3 > 3.0679615e-3``)."""
        scale = self._scale
        if trusted and self.model_fits and scale is not None:
            return max(SPIKE_SIGMAS * scale, (SPIKE_COUNTS + 1e-6) * self._quantum)
        return math.inf

    def _screen_step(
        self,
        times: np.ndarray,
        ys: np.ndarray,
        low: np.ndarray,
        high: np.ndarray,
        fresh: np.ndarray,
        est: Estimate,
        model: GeneralBacklash,
        resumed: np.ndarray | None = None,
        after: tuple[float, float, float, bool] | None = None,
    ) -> Screening:
        """:meth:`screen` of one step: the samples (``times``, readings ``ys``, the band
        ``low .. high`` of their commands under ``model``, the estimate's, ``fresh``: after
        a gap, ``resumed``: after the servo settled), sample by sample; ``after``: the
        reading after the step, its band and whether it follows on (not ``resumed``; None:
        none yet, or after a gap).

        A reading far from its prediction is a spike only when it is isolated: the reading
        after it does not follow it (:func:`_follows`). When it does, the readings moved
        where the model did not say (a band that lags the drivetrain's wear, a slip): both
        are fed, and a reading just before them judged by the band alone (``resumed``) that
        neither follows is the isolated one. A reading right before samples taken out while
        the servo settled has only the value of the reading after them to go by: a reading
        that lies between the readings before and after it did not jump."""
        y_prev, band_prev = self._fed_y, self._band_before()
        trusted = self._trusted(est)
        limit = self._limit(trusted)
        resync = self._resync_since
        edges = (low, high)
        low, high = self._shifted(low, high)
        self._fed_t, self._fed_y = int(times[-1]), float(ys[-1])
        self._fed_band = (float(edges[0][-1]), float(edges[1][-1]))
        if resync is None and y_prev is not None and not fresh.any():
            errs, on_low, on_high = _one_step_errors(y_prev, band_prev, ys, low, high, resumed)
            if not (errs > limit).any():
                self._track_scale(errs, ys)
                self._track_shift(
                    ys[on_low] - edges[0][on_low], ys[on_high] - edges[1][on_high], model
                )
                return Screening(None, [])
        pushed: tuple[list[float], list[float]] = ([], [])  # offsets from the edges
        errors: list[float] = []
        bad: list[int] = []  # spikes
        held: list[int] = []  # after a gap, until a sample follows from the one before it
        worst = (0.0, 0.0, 0.0)
        x, (x_low, x_high), x_at = y_prev, band_prev, -1  # the last reading fed (or its stand-in)
        move: float | None = None  # how far the readings moved at the last one fed
        again = [False] * ys.size if resumed is None else resumed.tolist()
        # each reading's neighbour: the next one of the step, or ``after`` (None: none)
        later: list[tuple[float, float, float, bool] | None] = [
            None if new else (y, lo, hi, not res)
            for y, lo, hi, new, res in zip(
                ys[1:].tolist(),
                low[1:].tolist(),
                high[1:].tolist(),
                fresh[1:].tolist(),
                again[1:],
                strict=True,
            )
        ]
        if after is not None:
            shifted = self._shifted(np.array([after[1]]), np.array([after[2]]))
            after = (after[0], float(shifted[0][0]), float(shifted[1][0]), after[3])
        later.append(after)
        by_band: int | None = None  # the last reading judged by the band alone and fed
        for i, (t, y, lo, hi, new, res) in enumerate(
            zip(
                times.tolist(),
                ys.tolist(),
                low.tolist(),
                high.tolist(),
                fresh.tolist(),
                again,
                strict=True,
            )
        ):
            if x is None or (new and not trusted):
                x, x_low, x_high, x_at, move = y, lo, hi, i, None
                continue
            if res:  # the band alone judges it (see _one_step_errors)
                inside, carry = y, 0.0
            else:
                inside = min(max(x, x_low), x_high)
                carry = x - inside
            if new:
                resync = t
            predicted = min(max(inside, lo), hi) + carry  # the clamp of eq. (20)
            error = y - predicted
            if resync is not None:
                if abs(error) <= limit or t - resync >= RESYNC_NS:
                    resync = None  # consistent with the sample before the gap
                    x, x_low, x_high, x_at, move = y, lo, hi, i, None
                else:
                    held.append(i)
                continue
            # a reading judged by the band alone (no reading before it) gets one count more:
            # where the load rests against a flank when the readings resume depends on how
            # far the servo trails the command then, which the learned shift only averages
            # (the physics gravity record, seed 6: 2 counts behind, on the flank at the next)
            far = limit + self._quantum if res else limit
            if abs(error) > far:
                # a load still moving as it moved one reading before (coasting, ringing)
                # is no spike; nor is a reading the one after it sides with
                if move is None or res or abs(y - x - move) > limit:
                    neighbour = later[i]
                    if neighbour is None:
                        isolated = True
                    elif not neighbour[3]:  # after a settling gap: between its neighbours?
                        isolated = not min(x, neighbour[0]) <= y <= max(x, neighbour[0])
                    else:
                        isolated = _isolated(y, predicted, lo, hi, *neighbour[:3], limit)
                        beyond = later[i + 1] if i + 1 < len(later) else None
                        if isolated and res and beyond is not None and beyond[3]:
                            isolated = not _trailing(y, predicted, neighbour[0], beyond[0])
                    if isolated:
                        bad.append(i)
                        x, x_low, x_high, x_at = predicted, lo, hi, i  # stands in for it
                        move = None
                        if abs(error) > abs(worst[1]):
                            worst = (y, error, predicted)
                        continue
                    # a reading just before it judged by the band alone (the commands
                    # before it unknown) that neither follows, nor their motion leads back
                    # to, is the isolated one
                    # (judged by the band alone: one count more, as above; and not when
                    # the three travel one way, at a pace the model does not predict: the
                    # physics drivetrains, see _travelling)
                    if (
                        neighbour is not None
                        and neighbour[3]
                        and by_band == i - 1
                        and abs(x - (2.0 * y - neighbour[0])) > limit + self._quantum
                        and not _travelling((x, y, neighbour[0]))
                    ):
                        bad.append(by_band)
                        back = 2.0 * y - neighbour[0]  # where the readings after it lead
                        if abs(x - back) > abs(worst[1]):
                            worst = (x, x - back, back)
            else:
                errors.append(abs(error))
            by_band = i if res and abs(error) <= far else None
            if inside <= lo:
                pushed[0].append(y - float(edges[0][i]))
            elif inside >= hi:
                pushed[1].append(y - float(edges[1][i]))
            move = y - x if x_at == i - 1 and not res else None
            x, x_low, x_high, x_at = y, lo, hi, i
        self._resync_since = resync
        self._track_scale(np.array(errors), ys)
        self._track_shift(np.array(pushed[0]), np.array(pushed[1]), model)
        if len(bad) > SPIKE_MAX_SHARE * ys.size:
            bad = []  # the model is off rather than the encoder: feed them
        elif bad:
            y, error, predicted = worst
            self._drop(
                "encoder_spike",
                f"encoder reading {y:.6g} is {error:+.3g} from the model's prediction "
                f"{predicted:.6g} (limit {limit:.3g})",
                len(bad),
            )
        if held:
            self._drop("encoder_after_gap", "sample after a gap not yet consistent", len(held))
        if not bad and not held:
            return Screening(None, self._found())
        if x is not None:
            self._fed_y = x
            if x_at >= 0:
                self._fed_band = (float(edges[0][x_at]), float(edges[1][x_at]))
        keep = np.ones(ys.size, dtype=bool)
        keep[bad] = False
        keep[held] = False
        return Screening(keep, self._found())

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
        median = _median(gaps)
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

    def _trusted(self, est: Estimate) -> bool:
        """Whether ``est`` may judge the readings (spikes, stuck, gaps): the identifier has
        converged since it last (re)started, and a residual scale is known."""
        state = est.state
        if state is EstimatorState.CONVERGED:
            self._converged = True
        elif state in (EstimatorState.WARMING_UP, EstimatorState.DIVERGED):
            self._converged = False
            self._shift = (0.0, 0.0)
        return self._converged and self._scale is not None

    def _stuck_reason(self, value: float, held: float | None, est: Estimate) -> str:
        """Why an unchanged reading ``value`` is stuck ("" when the model allows it), ``held``
        being the command in force ``STUCK_INPUT_NS`` before the reading, ``est`` the
        estimate in use."""
        model = est.model
        scale = self._scale
        trusted = self._trusted(est)
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

    def _band_before(self) -> tuple[float, float]:
        """The band (shifted) of the last reading fed; unbounded when not known."""
        band = self._fed_band
        if band is None:
            return (-math.inf, math.inf)
        low, high = self._shifted(np.array([band[0]]), np.array([band[1]]))
        return (float(low[0]), float(high[0]))

    def _shifted(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The band ``low .. high`` with its edges where the readings put them."""
        shift_low, shift_high = self._shift
        if shift_low == 0.0 and shift_high == 0.0:
            return low, high
        return low + shift_low, np.maximum(high + shift_high, low + shift_low)

    def _follow_model(self, model: GeneralBacklash, u: float) -> None:
        """Keep the edges where the readings put them when the estimate moves its band:
        the shifts change by what the new model moves each edge at the command ``u``."""
        old = self._shift_model
        if old is model:
            return
        self._shift_model = model
        if old is None or self._shift == (0.0, 0.0):
            return
        left0, right0 = old.branches_at(u)
        left1, right1 = model.branches_at(u)
        moved = (
            self._shift[0] + min(left0, right0) - min(left1, right1),
            self._shift[1] + max(left0, right0) - max(left1, right1),
        )
        self._shift = self._bounded(moved, model)

    def _track_shift(
        self, off_low: np.ndarray, off_high: np.ndarray, model: GeneralBacklash
    ) -> None:
        """Blend a step's offsets of the readings pushed by the band's lower and upper edge
        (``y - edge``, the estimate's edges) into the edges' shifts: their median, from
        ``_SHIFT_MIN_READINGS`` readings on, while the estimate may judge."""
        if not self._converged:
            return
        shift = list(self._shift)
        for side, offsets in enumerate((off_low, off_high)):
            if offsets.size < _SHIFT_MIN_READINGS:  # too few, finite or not
                continue
            offsets = offsets[np.isfinite(offsets)]
            if offsets.size >= _SHIFT_MIN_READINGS:
                shift[side] += _SHIFT_SMOOTHING * (_median(offsets) - shift[side])
        self._shift = self._bounded((shift[0], shift[1]), model)

    @staticmethod
    def _bounded(shift: tuple[float, float], model: GeneralBacklash) -> tuple[float, float]:
        """``shift`` within ``SHIFT_PLAY_SHARE`` of the play of ``model`` (0 where not finite)."""
        bound = SHIFT_PLAY_SHARE * abs(model.c_left + model.c_right)
        if not math.isfinite(bound):
            return (0.0, 0.0)
        low, high = shift
        low = min(max(low, -bound), bound) if math.isfinite(low) else 0.0
        high = min(max(high, -bound), bound) if math.isfinite(high) else 0.0
        return (low, high)

    def _track_quantum(self, ys: np.ndarray) -> None:
        """Lower the encoder count to the smallest change between consecutive readings of
        ``ys`` (an encoder without quantisation soon makes it negligible)."""
        if ys.size > 1:
            with np.errstate(all="ignore"):
                steps = np.abs(ys[1:] - ys[:-1])
                # NaN and equal readings out (none left: inf, the count unchanged)
                moved = steps[steps > 0.0]
                smallest = float(moved.min()) if moved.size else math.inf
            self._quantum = min(self._quantum, smallest)

    def _track_scale(self, errors: np.ndarray, ys: np.ndarray) -> None:
        """Blend a step's absolute prediction errors into the residual scale (their upper
        quartile / 1.15, a normal sigma; at least 1e-3 of the readings' magnitude)."""
        errors = errors[np.isfinite(errors)]  # an overflowing branch gives NaN or inf
        if errors.size == 0:
            return
        k = (errors.size - 1) * 3 // 4
        floor = 1e-3 * float(np.maximum.reduce(np.abs(ys)))  # np.max without its wrapper
        errors.partition(k)  # in place: ``errors`` is this step's own copy
        batch = max(float(errors[k]) / 1.15, floor, 1e-300)
        if batch < math.inf:
            scale = self._scale
            self._scale = batch if scale is None else scale + _SCALE_SMOOTHING * (batch - scale)
