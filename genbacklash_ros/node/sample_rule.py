"""The sample rule where the node and the batch path form their samples.

The rule itself is :func:`genbacklash_core.samples.sample_breaks`: a sample *follows* the one
before it when the difference of the encoder stamps they hold, in units of the encoder's
nominal period, rounds to exactly one. A lost reading, a gap or a clock that jumped back
breaks the chain, and so does every sample taken out between two that are fed. This module
applies that rule, in one place, to what :class:`~genbacklash_ros.node.pipeline.BacklashPipeline`
feeds its identifier and to what :func:`~genbacklash_ros.bags.bagio.align` gives batch
``identify`` and ``diagnose`` on bags (and :func:`~genbacklash_ros.bags.csvio.read_series_csv`
on a CSV with a ``t`` column):

* :func:`link_breaks` -- the breaks of samples holding the encoder readings stamped
  ``stamps``, linked to the sample fed before them (``previous_ns``), with ``marks`` for
  readings that follow one taken out (a rejected message, a stuck encoder's readings);
* :func:`keep_breaks` -- the breaks of the samples left after some are taken out (spikes,
  samples before the first command): a kept sample breaks when any sample before it, since
  the previous kept one, was taken out;
* :func:`select_rows` -- the batch path's whole rule in one function: given every reading
  with the command it holds, which readings are rows and where the chain breaks (the
  servo's settling rule, lost readings bridged along monotone commands for a backlash alone,
  marks). A bag (:func:`~genbacklash_ros.bags.bagio.align`) and a CSV of the same readings
  (:func:`~genbacklash_ros.bags.csvio.read_series_csv`) both go through it, so they give the
  same rows;
* :func:`paired_keep` -- with a motor encoder as the gear's input (the node's ``gear_input``),
  which readings have the motor reading of their stamp: one taken no more than half an
  encoder period before them (the drive samples both encoders together; a reading whose
  motor reading was lost holds an older one and is taken out as a lost reading is);
* :class:`EncoderPeriod` -- the nominal period the node learns from the stream: the median
  of the last :data:`PERIOD_WINDOW` positive stamp differences. The batch path takes the
  median over the whole record (:func:`~genbacklash_core.samples.nominal_period`), the same
  estimator. A median is immune to jitter and to a minority of lost readings; when more than
  half of the readings are lost the period reads as a multiple of the true one and single
  losses are no longer seen (the node's ``encoder_loss`` fault is up long before that).

Examples
--------
>>> link_breaks([10, 20, 40, 50], 10.0).tolist()
[True, False, True, False]
>>> link_breaks([60, 70], 10.0, previous_ns=50).tolist()
[False, False]
>>> keep_breaks(np.array([True, False, False, False]), np.array([True, True, False, True]))
(array([ True, False,  True]), False)
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Literal, TypeAlias

import numpy as np
import numpy.typing as npt

from genbacklash_core.samples import (
    lift_bridged,
    missing_readings,
    monotone_paths,
    nominal_period,
    sample_breaks,
)
from genbacklash_core.servo import ServoFit, ServoModel, estimate_servo
from genbacklash_core.settling import carry_marks, settling_keep

__all__ = [
    "PERIOD_WINDOW",
    "EncoderPeriod",
    "Rows",
    "ServoChoice",
    "keep_breaks",
    "link_breaks",
    "paired_keep",
    "record_period",
    "select_rows",
    "time_breaks",
]

BoolArray = npt.NDArray[np.bool_]

PERIOD_WINDOW = 255  # stamp differences behind the node's period estimate (0.26 s at 1 kHz)

#: The servo between the command and the gear (:mod:`genbacklash_core.servo`): None (the
#: gear's input is the command), a model, or ``"auto"`` (estimated from the rows).
ServoChoice: TypeAlias = ServoModel | Literal["auto"] | None


def link_breaks(
    stamps: npt.ArrayLike,
    period_ns: float | None,
    *,
    previous_ns: int | None = None,
    marks: npt.ArrayLike | None = None,
) -> BoolArray:
    """``breaks[k]``: sample ``k`` does not follow the sample before it.

    Parameters
    ----------
    stamps : array_like of int, shape (N,)
        The stamps of the encoder readings the samples hold (integer ns).
    period_ns : float or None
        The encoder's nominal period; None while it is not known (no sample is then
        vouched for: all break).
    previous_ns : int, optional
        The stamp of the sample fed just before ``stamps[0]`` (None: none, or unknown:
        ``stamps[0]`` breaks).
    marks : array_like of bool, shape (N,), optional
        Readings that follow one taken out: they break whatever their stamps say.
    """
    t = np.asarray(stamps, dtype=np.int64)
    if t.size == 0:
        return np.zeros(0, dtype=bool)
    if period_ns is None:
        out = np.ones(t.size, dtype=bool)
    elif previous_ns is None:
        out = sample_breaks(t - t[0], period_ns)  # relative: exact in float64
    else:
        linked = np.concatenate(([previous_ns], t)) - previous_ns
        out = sample_breaks(linked, period_ns)[1:]
    if marks is not None:
        out |= np.asarray(marks, dtype=bool)
    return out


def keep_breaks(breaks: BoolArray, keep: BoolArray) -> tuple[BoolArray, bool]:
    """The breaks of the samples ``keep`` leaves, and whether the last sample was taken out.

    A kept sample breaks where it broke already or where a sample before it (since the
    previous kept one, or from the start of ``breaks``) was taken out: no row pairs two
    samples with a removed one between them. When the last sample is taken out the next
    sample fed after these breaks too (the caller's concern: the second value).
    """
    index = np.flatnonzero(keep)
    out = np.asarray(breaks, dtype=bool)[index]
    if index.size:
        out |= np.diff(index, prepend=-1) > 1
    tail = bool(keep.size) and not bool(keep[-1])
    return out, tail


def paired_keep(
    stamps: npt.ArrayLike, input_stamps: npt.ArrayLike, period_ns: float | None
) -> BoolArray:
    """``keep[k]``: the motor reading held by the encoder reading stamped ``stamps[k]`` (the
    latest at or before it, stamped ``input_stamps[k]``) is its own: taken no more than half
    the encoder's nominal period before it (exactly at it while the period is unknown).

    >>> paired_keep([10, 20, 30], [10, 19, 20], 10.0).tolist()
    [True, True, False]
    """
    t = np.asarray(stamps, dtype=np.int64)
    age = t - np.asarray(input_stamps, dtype=np.int64)
    limit = 0.0 if period_ns is None else 0.5 * period_ns
    out: BoolArray = age <= limit
    return out


def record_period(stamps: npt.ArrayLike) -> float | None:
    """The nominal period of a whole record (the batch path's estimate): the median of its
    positive stamp differences (:func:`~genbacklash_core.samples.nominal_period`); None with
    fewer than two increasing stamps.

    >>> record_period([0, 10, 20, 40, 50]), record_period([5])
    (10.0, None)
    """
    t = np.asarray(stamps)
    if t.ndim != 1 or t.size < 2:
        return None
    if np.issubdtype(t.dtype, np.integer):
        t = t - t[0]  # integer ns since the epoch do not fit a float64 exactly
    rel = np.asarray(t, dtype=np.float64)
    if not np.any(np.diff(rel) > 0):
        return None
    return nominal_period(rel)


def time_breaks(t: npt.ArrayLike) -> BoolArray | None:
    """The breaks of a record stamped ``t`` (any one unit: seconds, integer ns), the period
    being :func:`record_period`; None when ``t`` holds fewer than two increasing stamps
    (nothing to tell). Missing (NaN) or non-increasing stamps break.

    >>> time_breaks([0.0, 0.001, 0.002, 0.004, 0.005]).tolist()
    [True, False, False, True, False]
    """
    tt = np.asarray(t, dtype=np.float64)
    period = record_period(tt)
    if period is None:
        return None
    return sample_breaks(tt - tt[np.isfinite(tt)][0], period)


@dataclass(frozen=True, eq=False)
class Rows:
    """The samples :func:`select_rows` keeps: stamps ``t`` (int64 ns), the command held ``u``,
    the reading ``y``, the sample rule's ``breaks``, ``skipped``: readings before the first
    command (they hold none), ``index``: where each row was among the readings given, and
    ``unpaired``: readings taken out for want of their motor reading (:func:`paired_keep`).
    With a servo, ``u`` is the modelled servo output (:mod:`genbacklash_core.servo`),
    ``servo`` the model used and ``servo_fit`` how it was estimated (``"auto"``)."""

    t: npt.NDArray[np.int64]
    u: npt.NDArray[np.float64]
    y: npt.NDArray[np.float64]
    breaks: BoolArray
    skipped: int
    index: npt.NDArray[np.intp]
    servo: ServoModel | None = None
    servo_fit: ServoFit | None = None
    unpaired: int = 0


def select_rows(
    stamps: npt.ArrayLike,
    held: npt.ArrayLike,
    commands: npt.ArrayLike,
    values: npt.ArrayLike,
    *,
    marks: npt.ArrayLike | None = None,
    bridge: bool = False,
    settle_ns: int = 0,
    servo: ServoChoice = None,
    input_stamps: npt.ArrayLike | None = None,
) -> Rows:
    """Which readings are identification samples, and where their chain breaks.

    The one place the batch path's row rules live (a bag's readings and a CSV of the same
    readings both come here; the node applies the same rules piece by piece in
    :class:`~genbacklash_ros.node.align.CommandHistory`):

    0. with ``input_stamps`` (a motor encoder as the gear's input: ``commands`` are its
       readings) a reading whose motor reading is not its own (:func:`paired_keep`, the
       period that of every reading) is taken out as a lost one; the settling rule then
       does not apply (the motor's position is what the gear gets);
    1. the servo's settling rule (:mod:`genbacklash_core.settling`, ``settle_ns``; for a
       backlash alone, ``bridge``): a reading taken as a new command lands is taken out as a
       lost one, its mark carried to the next reading kept;
    2. the readings before the first command (``held < 0``) are skipped;
    3. a sample breaks where its stamp is not one nominal period (the median difference,
       :func:`record_period`) after the one before, and where ``marks`` say a reading was
       taken out before it; with ``bridge`` a break that only lost readings made (at most
       :data:`~genbacklash_core.samples.MAX_BRIDGED`, none rejected) is lifted where the
       commands in force over the gap were monotone.

    With a ``servo`` (:mod:`genbacklash_core.servo`) the gear's input is the servo's
    modelled output, evaluated at every reading from the commands the readings hold: the
    row's ``u``. The model then describes the readings taken while the servo moves, so the
    settling rule is not applied, and no break is bridged (the commands' monotony says
    nothing of the lagged output between two readings). ``"auto"`` estimates the servo
    from these rows first (:func:`~genbacklash_core.servo.estimate_servo`).

    Parameters
    ----------
    stamps : array_like of int, shape (N,)
        The readings' stamps, increasing (ns).
    held : array_like of int, shape (N,)
        Per reading, the index in ``commands`` of the command it holds (-1: none yet).
    commands : array_like, shape (M,)
        The commands in the order they took effect (the monotone test runs over them).
    values : array_like, shape (N,)
        The readings.
    marks : array_like of bool, shape (N,), optional
        Readings that follow one taken out (a rejected message, a dropped CSV row).
    bridge : bool
        A backlash alone: lift breaks lost readings made along monotone commands.
    settle_ns : int
        The servo's settling time (applies with ``bridge`` only and without ``servo``; 0:
        off).
    servo : ServoModel or "auto" or None
        The servo between the command and the gear (None: none, the command is the input;
        not with ``input_stamps``: a motor encoder's readings are the gear's input).
    input_stamps : array_like of int, shape (M,), optional
        The stamps of ``commands`` when they are a motor encoder's readings (see above).

    >>> rows = select_rows([5, 10, 15, 25], [-1, 0, 0, 1], [1.0, 2.0], [0.1, 0.2, 0.3, 0.4])
    >>> rows.u.tolist(), rows.y.tolist(), rows.skipped, rows.breaks.tolist()
    ([1.0, 1.0, 2.0], [0.2, 0.3, 0.4], 1, [True, False, True])
    """
    et = np.asarray(stamps, dtype=np.int64)
    k = np.asarray(held, dtype=np.int64)
    cmd_u = np.asarray(commands, dtype=np.float64)
    ys = np.asarray(values, dtype=np.float64)
    index = np.arange(et.size)
    period_all = None
    unpaired = 0
    if servo is not None and input_stamps is None:
        return _servo_rows(et, k, cmd_u, ys, marks, servo)
    if input_stamps is not None:  # a motor encoder: each reading with the motor's of its stamp
        period_all = record_period(et)
        on = k >= 0
        paired = np.ones(et.size, dtype=bool)
        in_t = np.asarray(input_stamps, dtype=np.int64)
        paired[on] = paired_keep(et[on], in_t[k[on]], period_all)
        if not paired.all():
            unpaired = int(np.count_nonzero(~paired))
            if marks is not None:
                marks = carry_marks(marks, paired)
            et, ys, k, index = et[paired], ys[paired], k[paired], index[paired]
    elif settle_ns and bridge:  # the node's settling rule (a backlash alone): as lost readings
        on = k >= 0
        settled, _ = settling_keep(et[on], cmd_u[k[on]], settle_ns)
        if not settled.all():
            taken = np.ones(et.size, dtype=bool)
            taken[np.flatnonzero(on)[~settled]] = False
            if marks is not None:
                marks = carry_marks(marks, taken)
            et, ys, k, index = et[taken], ys[taken], k[taken], index[taken]
    keep = k >= 0
    period = record_period(et) if period_all is None else period_all
    linked = link_breaks(et, period)
    if bridge and period is not None and et.size > 1:
        monotone = np.zeros(et.size, dtype=bool)
        both = keep[1:] & keep[:-1]  # a reading before the first command holds none
        monotone[1:][both] = monotone_paths(cmd_u, k[:-1][both], k[1:][both])
        linked = lift_bridged(linked, missing_readings(et, period), monotone)
    if marks is not None:
        linked |= np.asarray(marks, dtype=bool)
    breaks, _ = keep_breaks(linked, keep)
    skipped = int(np.count_nonzero(~keep))
    return Rows(et[keep], cmd_u[k[keep]], ys[keep], breaks, skipped, index[keep], unpaired=unpaired)


def _servo_rows(
    et: npt.NDArray[np.int64],
    k: npt.NDArray[np.int64],
    cmd_u: npt.NDArray[np.float64],
    ys: npt.NDArray[np.float64],
    marks: npt.ArrayLike | None,
    servo: ServoModel | Literal["auto"],
) -> Rows:
    """:func:`select_rows` with a servo: every reading after the first command is a row,
    its input the modelled servo output; breaks from the stamps and marks alone."""
    keep = k >= 0
    period = record_period(et)
    linked = link_breaks(et, period)
    if marks is not None:
        linked |= np.asarray(marks, dtype=bool)
    breaks, _ = keep_breaks(linked, keep)
    t, held, y = et[keep], cmd_u[k[keep]], ys[keep]
    fit = None
    if servo == "auto":
        fit = estimate_servo(t, held, y, breaks)
        model = fit.model
    else:
        model = servo
    x, _ = model.output(t, held)
    index = np.flatnonzero(keep)
    return Rows(t, x, y, breaks, int(np.count_nonzero(~keep)), index, model, fit)


class EncoderPeriod:
    """The encoder's nominal period learnt from its stream (the node's estimate).

    The median of the last ``window`` positive differences of accepted encoder stamps.

    >>> period = EncoderPeriod()
    >>> for step in (1000, 1010, 2000, 990):
    ...     period.add(step)
    >>> period.value
    1005.0
    """

    __slots__ = ("_cached", "_steps")

    def __init__(self, window: int = PERIOD_WINDOW) -> None:
        self._steps: deque[int] = deque(maxlen=window)
        self._cached: float | None = None

    def add(self, step_ns: int) -> None:
        """One difference of consecutive accepted stamps (ignored unless positive)."""
        if step_ns > 0:
            self._steps.append(step_ns)
            self._cached = None

    def add_many(self, steps_ns: list[int]) -> None:
        """Differences in order, as :meth:`add` for each."""
        # a stretch's readings are in order: every difference positive, none to sift out
        positive = steps_ns if steps_ns and min(steps_ns) > 0 else [s for s in steps_ns if s > 0]
        if positive:
            self._steps.extend(positive)
            self._cached = None

    def reset(self) -> None:
        """Forget the differences (a restart)."""
        self._steps.clear()
        self._cached = None

    @property
    def value(self) -> float | None:
        """The period in ns (None before the first difference)."""
        steps = self._steps
        if self._cached is None and steps:
            ordered = sorted(steps)  # the median as numpy's: the middle one, or the mean of two
            half = len(ordered) // 2
            if len(ordered) % 2:
                self._cached = float(ordered[half])
            else:
                self._cached = (float(ordered[half - 1]) + float(ordered[half])) / 2.0
        return self._cached
