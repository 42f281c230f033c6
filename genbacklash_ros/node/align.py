"""The align stage: command and encoder streams in, batches of final samples out.

:class:`Aligner` keeps what the pipeline needs of both streams to form samples (integer
nanoseconds throughout; the rules are in the notes of :mod:`genbacklash_ros.node.pipeline`):

* the time of each message (header stamp or receive time) and its order within its stream
  (a message not after its stream's last time is the caller's to judge: a duplicate, out of
  order, or a clock that jumped back, :meth:`Aligner.reanchor`);
* the commands, held from their time until the next one (zero-order hold), and the pending
  encoder readings with the marks of the sample rule (:mod:`genbacklash_ros.node.sample_rule`:
  a reading that follows one taken out breaks the chain);
* which samples are *final* (their command is known) and, on request, those samples with
  their command (:meth:`Aligner.take`), on the encoder's own times or on a fixed grid.

With ``motor=True`` (the node's ``gear_input = "motor_encoder"``) the gear's input is a motor
encoder's reading, not the command: the input stream is the motor readings
(:meth:`Aligner.add_motor`), each encoder reading is paired with the motor reading of its
stamp (:func:`~genbacklash_ros.node.sample_rule.paired_keep`: one taken no more than half an
encoder period before it; a reading whose motor reading was lost is taken out as a lost
reading is), a sample is final once a motor reading at or after it has come, and commands
only keep their order (:meth:`Aligner.add_command` records the time). The settling rule does
not apply: the motor's position is what the gear gets, however long the servo takes.

It returns :class:`AlignedBatch` values and counts of samples taken out; it calls nothing
downstream. Whether a sample is fed is the screen stage's concern
(:mod:`genbacklash_ros.node.screen`).

Examples
--------
>>> align = Aligner(use_header=True, grid_ns=0, wait_ns=100_000_000)
>>> align.add_command(1_000, 0.5)
>>> for t, y in ((2_000, 0.1), (3_000, 0.2)):
...     align.add_reading(t, y, stuck=False)
>>> batch = align.take(align.horizon(final=True))
>>> batch.us.tolist(), batch.ys.tolist(), batch.before_first_command
([0.5, 0.5], [0.1, 0.2], 0)
"""

from __future__ import annotations

import bisect
import dataclasses
from dataclasses import dataclass

import numpy as np

from genbacklash_core.errors import GenBacklashError
from genbacklash_core.servo import ServoFit, ServoModel, ServoState, estimate_servo
from genbacklash_core.settling import SettleState, carry_marks, settling_keep
from genbacklash_ros.node.sample_rule import (
    EncoderPeriod,
    ServoChoice,
    keep_breaks,
    link_breaks,
    paired_keep,
)

__all__ = ["MAX_COMMANDS", "AlignedBatch", "Aligner"]

MAX_COMMANDS = 4096  # command history kept while no encoder data consume it


@dataclass(frozen=True, slots=True)
class AlignedBatch:
    """Final samples with their commands, in time order (what the align stage hands on).

    Attributes
    ----------
    times : numpy.ndarray of int64
        The samples' times.
    us, ys : numpy.ndarray of float
        The command holding at each sample (the identifier's input) and the reading.
    held : numpy.ndarray of int64
        The stamps of the encoder readings the samples hold (the sample rule's stamps).
    marks : numpy.ndarray of bool
        Samples that follow one taken out before them (they break the chain).
    period : float or None
        The encoder's nominal period (None while unknown: every sample breaks).
    linked : bool
        The first sample may link to the last sample fed before it (False after a
        re-anchor or after samples were taken out for want of a command).
    before_first_command : int
        Samples taken out because no command had come before them (counted quietly).
    monotone : numpy.ndarray of bool or None
        ``monotone[k]``: the commands in force from the sample before ``k`` (in this batch,
        or the last one taken before it when ``linked``) to sample ``k`` were monotone
        (:func:`~genbacklash_core.samples.monotone_paths`), so lost readings between them
        may be bridged for a backlash alone. None on a grid (not judged).
    resumed : numpy.ndarray of bool or None
        ``resumed[k]``: samples before ``k`` were taken out while the servo settled
        (:mod:`genbacklash_core.settling`), or for want of a motor reading; None when none
        were.
    unpaired : int
        Samples taken out because no motor reading was taken at their stamp (a motor
        encoder as the gear's input; counted quietly).
    commands : numpy.ndarray or None
        With a servo modelled: the commands holding at each sample (``us`` is then the
        modelled servo output), for the guard's second yardstick
        (:class:`~genbacklash_ros.node.judges.CompensationJudges`); None otherwise.
    command_monotone : numpy.ndarray of bool or None
        With a servo modelled: ``monotone`` of the commands (``monotone`` is then all
        False: the servo output is not bridged); None otherwise or on a grid.
    """

    times: np.ndarray
    us: np.ndarray
    ys: np.ndarray
    held: np.ndarray
    marks: np.ndarray
    period: float | None
    linked: bool
    before_first_command: int = 0
    monotone: np.ndarray | None = None
    resumed: np.ndarray | None = None
    unpaired: int = 0
    commands: np.ndarray | None = None
    command_monotone: np.ndarray | None = None

    @property
    def size(self) -> int:
        """Number of samples."""
        return int(self.times.size)


def _monotone_paths(values: list[float], start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """:func:`~genbacklash_core.samples.monotone_paths` of a short list of commands (the
    pending ones: a few per batch), its rises and falls counted in Python."""
    ups, downs = [0], [0]
    rises = falls = 0
    previous = values[0]
    for value in values[1:]:
        if value > previous:  # as step > 0 of the difference (the same for any floats)
            rises += 1
        elif value < previous:
            falls += 1
        ups.append(rises)
        downs.append(falls)
        previous = value
    up, down = np.array(ups), np.array(downs)
    out: np.ndarray = (stop >= start) & ((up[stop] == up[start]) | (down[stop] == down[start]))
    return out


class Aligner:
    """The command and encoder streams, aligned into samples (see the module notes).

    Parameters
    ----------
    use_header : bool
        A message's time is its header stamp (when it has a nonzero one), else its receive
        time.
    grid_ns : int
        Sample on the grid ``k * grid_ns`` (0: one sample per encoder reading).
    wait_ns : int
        Encoder time after which a sample's command is taken as held.
    settle_ns : int
        The servo's settling time (:mod:`genbacklash_core.settling`): samples taken sooner
        after their command changed are taken out as lost readings are (0: none). Not on a
        grid, nor with a ``servo`` or ``motor``.
    servo : ServoModel or "auto" or None
        The servo between the command and the gear (:mod:`genbacklash_core.servo`): the
        samples' input becomes its modelled output, as
        :func:`~genbacklash_ros.node.sample_rule.select_rows` makes it for the batch path
        (no settling rule, no bridging). ``"auto"``: the samples of the first
        ``servo_window_ns`` are held back, the servo estimated from them
        (:func:`~genbacklash_core.servo.estimate_servo`), then they and all later ones are
        handed on with its output. Not on a grid, nor with ``motor``.
    servo_window_ns : int
        The data time ``"auto"`` collects before it estimates.
    motor : bool
        The gear's input is a motor encoder's reading (see the module notes; not on a grid).
    """

    def __init__(
        self,
        *,
        use_header: bool,
        grid_ns: int,
        wait_ns: int,
        settle_ns: int = 0,
        servo: ServoChoice = None,
        servo_window_ns: int = 5_000_000_000,
        motor: bool = False,
    ) -> None:
        self._use_header = use_header
        self._grid_ns = grid_ns
        self._wait = wait_ns
        self._motor = motor
        self._servo: ServoChoice = None if grid_ns or motor else servo
        self._servo_window = servo_window_ns
        self._servo_state: ServoState | None = None
        self._servo_held: list[AlignedBatch] = []  # "auto": batches before the estimate
        self.servo_fit: ServoFit | None = None
        self.servo_note = ""  # why "auto" fell back to no servo ("" when it did not)
        self._settle_ns = 0 if grid_ns or motor or self._servo is not None else settle_ns
        self._settle = SettleState()
        self._settle_tail = False  # the last batch ended with samples taken out settling
        # streams: accepted times and values of the identifier's input (the commands, or
        # with ``motor`` the motor readings)
        self.cmd_t: list[int] = []
        self.cmd_u: list[float] = []
        self._enc_t: list[int] = []
        self._enc_y: list[float] = []
        # pending readings that follow one taken out; whether the next accepted reading does
        self._enc_mark: list[bool] = []
        self._mark_next = False
        self._period = EncoderPeriod()
        self._linked = False  # the next batch may link to the sample fed before it
        self.last_cmd_ns: int | None = None
        self.last_motor_ns: int | None = None  # with ``motor``: the input stream's last time
        self.last_enc_ns: int | None = None
        self.last_y: float | None = None
        self._next_grid_k: int | None = None
        self._last_time: int | None = None  # the time of the last sample taken

    # ------------------------------------------------------------------ messages

    def time_of(self, header_ns: int | None, receive_ns: int) -> int:
        """The time of a message (see the pipeline's notes)."""
        return header_ns if self._use_header and header_ns else int(receive_ns)

    def times_of(self, header_ns: np.ndarray, receive_ns: np.ndarray) -> np.ndarray:
        """:meth:`time_of` of many messages (int64 arrays; a header stamp of 0: none)."""
        if not self._use_header:
            return receive_ns
        return np.where(header_ns != 0, header_ns, receive_ns)

    @property
    def pending(self) -> int:
        """Encoder readings not yet taken."""
        return len(self._enc_t)

    @property
    def motor(self) -> bool:
        """The gear's input is a motor encoder's reading."""
        return self._motor

    def add_command(self, stamp: int, value: float) -> None:
        """An accepted command at ``stamp``; ``value`` is what the identifier takes (with
        ``motor`` only the time is kept: the motor readings are the input)."""
        self.last_cmd_ns = stamp
        if self._motor:
            return
        self._add_input(stamp, value)

    def add_motor(self, stamp: int, value: float) -> None:
        """An accepted motor reading at ``stamp`` (with ``motor``: the identifier's input)."""
        self.last_motor_ns = stamp
        self._add_input(stamp, value)

    def _add_input(self, stamp: int, value: float) -> None:
        self.cmd_t.append(stamp)
        self.cmd_u.append(value)
        if len(self.cmd_t) > MAX_COMMANDS:
            self._trim_commands()

    def add_reading(self, stamp: int, value: float, *, stuck: bool) -> None:
        """An accepted encoder reading at ``stamp`` (a stuck encoder's is not kept: the next
        kept reading breaks the chain)."""
        last = self.last_enc_ns
        if last is not None:
            self._period.add(stamp - last)
        self.last_enc_ns = stamp
        self.last_y = value
        if stuck:
            self._mark_next = True
        else:
            self._enc_t.append(stamp)
            self._enc_y.append(value)
            self._enc_mark.append(self._mark_next)
            self._mark_next = False

    def add_commands(self, stamps: list[int], values: list[float]) -> None:
        """Accepted commands in order, as :meth:`add_command` for each (the caller keeps the
        history within ``MAX_COMMANDS``: :attr:`room`)."""
        if stamps:
            self.cmd_t.extend(stamps)
            self.cmd_u.extend(values)
            self.last_cmd_ns = stamps[-1]

    @property
    def room(self) -> int:
        """Commands :meth:`add_commands` may add before the history needs trimming."""
        return MAX_COMMANDS - len(self.cmd_t)

    def add_readings(self, stamps: list[int], values: list[float], steps: list[int]) -> None:
        """Accepted encoder readings in order, none stuck, each after the one before (the
        first after :attr:`last_enc_ns`, ``steps`` the differences): as :meth:`add_reading`
        for each."""
        if not stamps:
            return
        if self.last_enc_ns is not None:
            self._period.add_many(steps)
        else:
            self._period.add_many(steps[1:])
        self.last_enc_ns = stamps[-1]
        self.last_y = values[-1]
        self._enc_t.extend(stamps)
        self._enc_y.extend(values)
        self._enc_mark.append(self._mark_next)
        self._enc_mark.extend([False] * (len(stamps) - 1))
        self._mark_next = False

    def reading_taken_out(self) -> None:
        """A reading was rejected (invalid, not finite): the next one breaks the chain."""
        self._mark_next = True

    def discard_after(self, since: int) -> int:
        """Drop the pending readings after ``since`` (a stuck encoder's, the first equal
        reading kept); how many there were."""
        cut = bisect.bisect_right(self._enc_t, since)
        held = len(self._enc_t) - cut
        if held:
            del self._enc_t[cut:], self._enc_y[cut:], self._enc_mark[cut:]
            self._mark_next = True  # the next reading kept follows those taken out
        return held

    def reanchor(self, stamp: int) -> None:
        """Restart both streams at ``stamp`` after a clock jump back (take the pending
        samples first): the last command is held into the new time line."""
        self._enc_t.clear()
        self._enc_y.clear()
        self._enc_mark.clear()
        self._mark_next = False
        self._linked = False  # a new time line: its first sample breaks
        self._next_grid_k = None
        self._last_time = None
        self._servo_state = None  # the servo's output restarts at rest on the new line
        if self._servo_held:  # "auto" estimates from one time line: the old one is dropped
            self._servo_held = []
        if self.cmd_u:
            self.cmd_t, self.cmd_u = [stamp - 1], [self.cmd_u[-1]]
        else:
            self.cmd_t, self.cmd_u = [], []
        self.last_cmd_ns = stamp - 1 if self.cmd_u else None
        if self._motor:  # the last motor reading is held (the pairing rule judges it)
            self.last_motor_ns = self.last_cmd_ns
        self.last_enc_ns = None

    # ------------------------------------------------------------------ samples

    def horizon(self, final: bool) -> int | None:
        """Latest sample time whose command is known (None: nothing final yet); with
        ``final`` every pending sample (their commands taken as held)."""
        last_enc = self.last_enc_ns
        if last_enc is None:
            return None
        if final:
            return last_enc
        horizon = last_enc - self._wait
        last_input = self.last_motor_ns if self._motor else self.last_cmd_ns
        if last_input is not None and last_input > horizon:
            horizon = last_input
        return horizon

    @property
    def servo(self) -> ServoModel | None:
        """The servo model the samples' input comes from (None: none, or not yet estimated)."""
        return self._servo if isinstance(self._servo, ServoModel) else None

    @property
    def servo_pending(self) -> bool:
        """``"auto"`` still collects the samples it estimates the servo from."""
        return self._servo == "auto"

    def take(self, horizon: int | None, *, final: bool = False) -> AlignedBatch | None:
        """The final samples up to ``horizon``, with their commands (None: none); ``final``:
        the stream ends (``"auto"`` estimates from what it holds)."""
        batch = self._take(horizon)
        if self._servo is None:
            return batch
        if isinstance(self._servo, ServoModel):
            return None if batch is None else self._servo_output(batch)
        if batch is not None:
            self._servo_held.append(batch)
        return self._servo_estimate(final)

    def _servo_output(self, batch: AlignedBatch) -> AlignedBatch:
        """``batch`` with the modelled servo output as its input (no bridging)."""
        model = self._servo
        assert isinstance(model, ServoModel)
        if batch.size == 0:
            return batch
        xs, self._servo_state = model.output(batch.times, batch.us, self._servo_state)
        no = np.zeros(batch.size, dtype=bool)
        return dataclasses.replace(
            batch,
            us=xs,
            monotone=no,
            resumed=None,
            commands=batch.us,
            command_monotone=batch.monotone,
        )

    def _servo_estimate(self, final: bool) -> AlignedBatch | None:
        """``"auto"``: once the held samples span the window (or at the end), estimate the
        servo from them and hand them all on as one batch with its output."""
        held = [b for b in self._servo_held if b.size]
        early = sum(b.before_first_command for b in self._servo_held)
        span = int(held[-1].times[-1] - held[0].times[0]) if held else 0
        if not final and span < self._servo_window:
            if early:  # counted as they come; the held samples wait
                for i, b in enumerate(self._servo_held):
                    self._servo_held[i] = dataclasses.replace(b, before_first_command=0)
                return self._empty(None, early)
            return None
        self._servo_held = []
        if not held:
            return self._empty(None, early) if early else None
        times = np.concatenate([b.times for b in held])
        us = np.concatenate([b.us for b in held])
        marks = np.concatenate([b.marks for b in held])
        marks[0] |= not held[0].linked
        for i in range(1, len(held)):  # a batch that does not link to the one before breaks
            if not held[i].linked:
                marks[sum(b.size for b in held[:i])] = True
        period = held[-1].period
        monotone = (
            np.concatenate([b.monotone for b in held])
            if all(b.monotone is not None for b in held)
            else None
        )
        breaks, _ = keep_breaks(link_breaks(times, period, marks=marks), np.ones(times.size, bool))
        try:
            self.servo_fit = estimate_servo(times, us, np.concatenate([b.ys for b in held]), breaks)
            self._servo = self.servo_fit.model
        except GenBacklashError as err:
            self._servo = ServoModel(0.0, 0.0)
            self.servo_note = f"servo not estimated ({err}); taken as none"
        batch = AlignedBatch(
            times,
            us,
            np.concatenate([b.ys for b in held]),
            np.concatenate([b.held for b in held]),
            marks,
            period,
            held[0].linked,
            early,
            monotone,
        )
        return self._servo_output(batch)

    def _take(self, horizon: int | None) -> AlignedBatch | None:
        """:meth:`take` before the servo stage."""
        if horizon is None or not self._enc_t:
            return None
        if self._grid_ns:
            times, ys, held, marks = self._grid_samples(horizon)
        else:
            count = bisect.bisect_right(self._enc_t, horizon)
            if count == 0:
                return None
            times = held = np.array(self._enc_t[:count], dtype=np.int64)
            ys = np.array(self._enc_y[:count])
            marks = np.array(self._enc_mark[:count], dtype=bool)
            del self._enc_t[:count], self._enc_y[:count], self._enc_mark[:count]
        if times.size == 0:
            return None
        period = float(self._grid_ns) if self._grid_ns else self._period.value
        if not self.cmd_t:
            self._linked = False
            return self._empty(period, int(times.size))
        k = np.searchsorted(np.array(self.cmd_t, dtype=np.int64), times, side="right") - 1
        early = int(np.count_nonzero(k < 0))  # a prefix: times increase
        linked = self._linked
        if early:
            k, ys, times, held, marks = (
                k[early:],
                ys[early:],
                times[early:],
                held[early:],
                marks[early:],
            )
            if k.size == 0:
                self._linked = False
                return self._empty(period, early)
            marks = marks.copy()
            marks[0] = True  # the samples before it were taken out
        commands = np.array(self.cmd_u)
        us = commands[k]
        resumed = None
        unpaired = 0
        keep: np.ndarray | None = None  # the samples kept; the others are taken out
        if self._motor:  # each reading with the motor reading of its stamp, or taken out
            input_t = np.array(self.cmd_t, dtype=np.int64)[k]
            keep = paired_keep(times, input_t, period)
            unpaired = int(np.count_nonzero(~keep))
        elif self._settle_ns:  # not while the servo settles
            keep, self._settle = settling_keep(times, us, self._settle_ns, self._settle)
        if keep is not None:
            tail = self._settle_tail
            self._settle_tail = not keep[-1] or (tail and not keep.any())
            if not keep.all() or tail:  # taken out as lost readings: bridged where monotone
                resumed = carry_marks(~keep, keep)
                if tail and resumed.size:
                    resumed[0] = True
                marks = carry_marks(marks, keep)
                k, us, ys, times, held = (k[keep], us[keep], ys[keep], times[keep], held[keep])
                if k.size == 0:
                    if not unpaired:
                        return None
                    return AlignedBatch(
                        times, us, ys, held, marks, period, linked, early, None, None, unpaired
                    )
        monotone = None if self._grid_ns else self._monotone(k, linked)
        held_from = int(k[-1])  # the command holding at the last sample, and later ones
        if held_from:
            del self.cmd_t[:held_from], self.cmd_u[:held_from]
        self._linked = True
        self._last_time = int(times[-1])
        return AlignedBatch(
            times, us, ys, held, marks, period, linked, early, monotone, resumed, unpaired
        )

    def _monotone(self, k: np.ndarray, linked: bool) -> np.ndarray:
        """Per sample, whether the commands in force since the sample before were monotone
        (the first sample: since the last sample of the batch before, when linked)."""
        before = np.empty_like(k)
        before[1:] = k[:-1]
        last = self._last_time
        first_known = False
        if linked and last is not None and self.cmd_t and self.cmd_t[0] <= last:
            first_known = True
            before[0] = bisect.bisect_right(self.cmd_t, last) - 1
        else:
            before[0] = k[0]
        out = _monotone_paths(self.cmd_u, before, k)
        if not first_known:
            out[0] = False
        return out

    def _empty(self, period: float | None, early: int) -> AlignedBatch:
        none = np.zeros(0, dtype=np.int64)
        return AlignedBatch(
            none, np.zeros(0), np.zeros(0), none, np.zeros(0, dtype=bool), period, False, early
        )

    def _grid_samples(self, horizon: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Grid times up to ``horizon`` (and the latest encoder time) with the held encoder:
        ``(times, readings, stamps of the readings held, their marks)``."""
        period = self._grid_ns
        enc_t = self._enc_t
        if self._next_grid_k is None:
            self._next_grid_k = -(-enc_t[0] // period)  # first grid point at/after the data
        first = self._next_grid_k
        last = min(horizon, enc_t[-1]) // period
        if last < first:
            none = np.zeros(0, dtype=np.int64)
            return none, np.zeros(0), none, np.zeros(0, dtype=bool)
        times = np.arange(first, last + 1, dtype=np.int64) * period
        stamps = np.array(enc_t, dtype=np.int64)
        j = np.searchsorted(stamps, times, side="right") - 1
        ys = np.array(self._enc_y)[j]
        marks = np.array(self._enc_mark, dtype=bool)[j]
        self._next_grid_k = last + 1
        keep = int(j[-1])  # the encoder reading holding at the last grid point, and later
        if keep:
            del self._enc_t[:keep], self._enc_y[:keep], self._enc_mark[:keep]
        self._enc_mark[0] = False  # held already: its mark has broken the chain there
        return times, ys, stamps[j], marks

    def _trim_commands(self) -> None:
        """Bound the command history when no encoder data consume it.

        Keeps the commands a pending encoder reading may need, and those of the last
        ``wait_ns`` (a reading later than that would be more than the wait late).
        """
        oldest = self.cmd_t[-1] - self._wait
        if self._enc_t:
            oldest = min(oldest, self._enc_t[0])
        cut = bisect.bisect_right(self.cmd_t, oldest) - 1  # keep the one holding at oldest
        if cut > 0:
            del self.cmd_t[:cut], self.cmd_u[:cut]
