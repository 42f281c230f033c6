"""The measured-tracking stage: every reading against the desired position then in force.

:class:`TrackingStage` feeds the :class:`~genbacklash_core.measured.TrackingJudge` of the node:
it remembers the desired position (the command as it came) and the share of the inverse the
compensator applied to it (its weight) of the command in force, pairs each accepted encoder
reading with them, and hands the readings to the judge in batches (at each feed of the
identifier). The per-message path pairs a reading with the last command handled; a stretch
of the batch form pairs each reading with the last command of the stretch that came before
it (by the messages' order), so both forms judge the same pairs.

:func:`record_baseline` runs a stage over a whole record without compensation in it (every
command with weight 0): what the judge measures as its baseline, which ``identify`` and
``replay --checkpoint`` store in the checkpoint
(:class:`~genbacklash_core.measured.OfflineBaseline`). What a node's checkpoint carries of
the judge for the next start -- the baseline, a verdict of harm -- is the stage's to say
(:meth:`TrackingStage.baseline_to_store`, :meth:`TrackingStage.harm_to_store`).

Examples
--------
>>> from genbacklash_core.measured import TrackingJudgeSettings
>>> stage = TrackingStage(TrackingJudgeSettings(min_time=0.001))
>>> stage.command(0.5, 1.0)
>>> stage.reading(1_000_000, 0.45)
>>> stage.flush().on_rms
0.04999999999999999
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from genbacklash_core.measured import (
    HeldHarm,
    OfflineBaseline,
    TrackingJudge,
    TrackingJudgeSettings,
    TrackingVerdict,
)

__all__ = ["STORE_RATIO", "TrackingStage", "record_baseline"]

STORE_RATIO = 0.5
"""A checkpoint stores the tracking baseline only once compensating was measured to keep at
most this share of the tracking error (:meth:`TrackingStage.baseline_to_store`)."""


class TrackingStage:
    """Readings paired with the desired position and the compensation in force.

    Parameters
    ----------
    settings : TrackingJudgeSettings
    """

    def __init__(self, settings: TrackingJudgeSettings) -> None:
        self.judge = TrackingJudge(settings)
        self._r = math.nan  # the desired position of the command in force (NaN: none yet)
        self._w = 0.0  # the weight the compensator gave it
        self._t: list[int] = []
        self._y: list[float] = []
        self._rs: list[float] = []
        self._ws: list[float] = []

    @property
    def verdict(self) -> TrackingVerdict:
        """The judge's latest verdict."""
        return self.judge.verdict

    def command(self, desired: float, weight: float) -> None:
        """A command handled: ``desired`` as it came, compensated with ``weight``."""
        self._r, self._w = float(desired), float(weight)

    def reading(self, stamp: int, load: float) -> None:
        """An accepted encoder reading."""
        self._t.append(int(stamp))
        self._y.append(float(load))
        self._rs.append(self._r)
        self._ws.append(self._w)

    def stretch(
        self,
        cmd_order: list[int],
        desired: list[float],
        weight: float,
        order: list[int],
        stamps: list[int],
        loads: list[float],
    ) -> None:
        """A stretch of the batch form: its commands (all compensated with ``weight``) and
        its readings, each paired with the last command that came before it (``cmd_order``
        and ``order``: the messages' places in the batch)."""
        if stamps:
            if cmd_order:
                # each run of readings between two commands pairs with the first of them
                # (those before the stretch's first command: the command in force before)
                rs = self._rs
                start = bisect.bisect_left(order, cmd_order[0])
                rs.extend([self._r] * start)
                self._ws.extend([self._w] * start)
                self._ws.extend([float(weight)] * (len(order) - start))
                for value, after in zip(desired, (*cmd_order[1:], None), strict=True):
                    stop = len(order) if after is None else bisect.bisect_left(order, after, start)
                    rs.extend([value] * (stop - start))
                    start = stop
            else:
                self._rs.extend([self._r] * len(stamps))
                self._ws.extend([self._w] * len(stamps))
            self._t.extend(stamps)
            self._y.extend(loads)
        if cmd_order:
            self._r, self._w = float(desired[-1]), float(weight)

    def baseline_to_store(self, *, in_loop: bool) -> OfflineBaseline | None:
        """The tracking without compensation a checkpoint stores, for the next start's judge.

        A stored baseline lets the next start compensate after the guard's first verdict
        instead of after ``min_time`` of baseline. That shortcut is taken only where this
        node measured compensation helping on this machine, so with ``compensation_in_loop``
        (``in_loop``):

        * when the judge has measured compensating keep at most :data:`STORE_RATIO` of the
          tracking error over at least ``min_time`` of compensated readings (its state
          ``"on"`` with a clear cut, or a probe after it): the judge's live baseline once it holds
          ``min_time`` seconds of it
          (:meth:`~genbacklash_core.measured.TrackingJudge.live_baseline`: the readings
          while the command went out as it came, weight 0: before the first estimate,
          while the guard or the judge held compensation off, in probes), else
          the baseline this start took from its checkpoint, carried forward unchanged
          (:attr:`~genbacklash_core.measured.TrackingJudge.offline`);
        * else none: compensation not measured yet (``compensate`` false, the guard holding
          it off, a trial), helping only a little, faded or judged harmful; the next start
          measures its baseline first. Measured on physics restarts (BENCHMARKS.md, issue
          23, ckpt-1): a baseline stored whenever one was measured let restarts on
          compliant drivetrains, whose first node never compensated, try compensation on
          the guard's first verdict and track 3 % worse than without it; stored whenever
          compensation was "on" (ratio up to ``ratio_full``), 7.8 % worse on one whose
          first node had cut 6 %. The shortcut is worth about a second of compensation,
          which matters where compensation cuts most of the error.

        Without ``compensation_in_loop`` the node cannot tell which readings went without
        compensation on the machine (it only watches, and its weights are its own, not what
        drove the drivetrain): it stores nothing it measured, and carries forward the
        baseline its start took, if any.
        """
        judge = self.judge
        if not in_loop:
            return judge.offline
        verdict, settings = judge.verdict, judge.settings
        helped = verdict.on_time >= settings.min_time and verdict.ratio <= STORE_RATIO
        if not helped:
            return None
        live = judge.live_baseline()
        return live if live is not None else judge.offline

    def harm_to_store(self, *, in_loop: bool) -> HeldHarm | None:
        """The judge's verdict of harm a checkpoint stores, for the next start to hold.

        With ``compensation_in_loop``, while the judge holds compensation off because it
        measured it tracking worse than without: the next start holds that model off too,
        until a new model or the retry (counted on), instead of trying it again after its
        baseline. Without it the judge never judges harm: none.
        """
        return self.judge.held_harm() if in_loop else None

    def flush(self) -> TrackingVerdict:
        """Judge the readings gathered; the new verdict."""
        if self._t:
            self.judge.readings(self._t, self._y, self._rs, self._ws)
            self._t, self._y, self._rs, self._ws = [], [], [], []
        return self.judge.verdict


def record_baseline(
    command_t: Sequence[int] | np.ndarray,
    command_u: Sequence[float] | np.ndarray,
    reading_t: Sequence[int] | np.ndarray,
    reading_y: Sequence[float] | np.ndarray,
    settings: TrackingJudgeSettings | None = None,
) -> OfflineBaseline | None:
    """The baseline the node's judge measures on a record without compensation in it.

    A :class:`TrackingStage` is given the record's commands (``command_t``, ``command_u``:
    stamps in ns and values, sorted) and encoder readings (``reading_t``, ``reading_y``,
    sorted), each reading paired with the last command at or before its stamp (a command
    and a reading of one stamp: the command first), every command with weight 0; the
    judge's baseline after the last reading is the result. None when it holds less than
    ``min_time`` seconds (the judge would not judge on it) or no finite error.

    Only a record in which the commands went to the drivetrain as they are is such a
    record: the caller decides (``identify``, ``replay``: see
    :mod:`genbacklash_ros.cli.start`).

    Examples
    --------
    >>> t = [k * 1_000_000 for k in range(4000)]
    >>> base = record_baseline([0], [0.0], t, [0.01] * 4000)
    >>> round(base.rms, 6), round(base.seconds, 3)
    (0.01, 3.999)
    """
    base = settings if settings is not None else TrackingJudgeSettings()
    stage = TrackingStage(dataclasses.replace(base, in_loop=True))
    ct = np.asarray(command_t, dtype=np.int64)
    et = np.asarray(reading_t, dtype=np.int64)
    if not (ct.size and et.size):
        return None
    # the places of both kinds in one stream ordered by stamp, a command before a reading
    cmd_order = np.arange(ct.size) + np.searchsorted(et, ct, side="left")
    order = np.arange(et.size) + np.searchsorted(ct, et, side="right")
    stage.stretch(
        cmd_order.tolist(),
        np.asarray(command_u, dtype=np.float64).tolist(),
        0.0,
        order.tolist(),
        et.tolist(),
        np.asarray(reading_y, dtype=np.float64).tolist(),
    )
    stage.flush()
    return stage.judge.live_baseline()
