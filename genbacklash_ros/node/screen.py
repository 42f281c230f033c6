"""The screen stage: aligned samples in, the samples to identify from and their breaks out.

:class:`Screen` takes an :class:`~genbacklash_ros.node.align.AlignedBatch`, asks the stream
health (:meth:`~genbacklash_ros.node.health.StreamHealth.screen`) which samples are spikes
or held back after a gap, and applies the sample rule
(:mod:`genbacklash_ros.node.sample_rule`): sample ``k`` breaks the chain of consecutive
samples when the stamps it and the sample before it hold are not one period apart, when a
reading was taken out in between, or when it is the first after a re-anchor. The chain
links from one batch to the next through the stamp of the last sample kept.

The result, a :class:`Screened` batch, is what the identify stage takes; the drops found go
with it. Nothing here calls back.

Examples
--------
>>> import numpy as np
>>> from genbacklash_core import Estimate, Structure
>>> from genbacklash_ros.node.align import AlignedBatch
>>> from genbacklash_ros.node.health import StreamHealth
>>> t = np.array([10, 20, 40], dtype=np.int64)
>>> batch = AlignedBatch(t, np.zeros(3), np.ones(3), t, np.zeros(3, bool), 10.0, True)
>>> out = Screen().run(batch, StreamHealth(), Estimate.empty(Structure(3)))
>>> out.breaks.tolist(), out.events
([True, False, True], [])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from genbacklash_core import Estimate
from genbacklash_core.samples import lift_bridged, stamp_steps
from genbacklash_ros.node.align import AlignedBatch
from genbacklash_ros.node.health import HealthEvent, StreamHealth
from genbacklash_ros.node.sample_rule import keep_breaks, link_breaks

__all__ = ["Screen", "Screened", "early_stamps", "linked_breaks"]


@dataclass(frozen=True, slots=True)
class Screened:
    """The samples to identify from (what the screen stage hands on).

    Attributes
    ----------
    us, ys : numpy.ndarray
        Inputs and readings of the samples kept.
    breaks : numpy.ndarray of bool
        ``breaks[k]``: sample ``k`` does not follow the sample before it (for ``k = 0``:
        the last sample handed on before).
    events : list of Drop or Note
        Spikes and samples held back after a gap (drops), and the notes of faults.
    restarts : numpy.ndarray of bool
        The breaks after which the drivetrain's path is not known (the guard's restarts):
        ``breaks`` without those of a reading stamped early (:func:`early_stamps`) when
        none was taken out between (module notes).
    commands : numpy.ndarray or None
        With a servo modelled: the commands holding at the samples kept (``us`` is the
        modelled servo output); None otherwise.
    command_restarts : numpy.ndarray of bool or None
        With a servo modelled: the restarts of a free run on the commands, lost readings
        bridged where the commands were monotone (the rule of ``restarts`` for a backlash
        on the commands, :class:`~genbacklash_ros.node.judges.CompensationJudges`); None
        otherwise.
    """

    us: np.ndarray
    ys: np.ndarray
    breaks: np.ndarray
    events: list[HealthEvent]
    restarts: np.ndarray
    commands: np.ndarray | None = None
    command_restarts: np.ndarray | None = None

    @property
    def size(self) -> int:
        """Number of samples kept."""
        return int(self.us.size)


def linked_breaks(
    held: np.ndarray,
    period: float,
    previous: int | None,
    monotone: np.ndarray | None = None,
) -> np.ndarray:
    """The sample rule's breaks of samples holding the readings stamped ``held`` (see
    :func:`~genbacklash_ros.node.sample_rule.link_breaks`), the first linked to the stamp
    ``previous`` (None: it breaks); with ``monotone`` (a backlash alone), those lifted that
    lost readings made where the commands in force were monotone (the rule of
    :func:`~genbacklash_core.samples.lift_bridged`: the backlash is rate independent, so the
    readings around such a gap are consecutive states).

    The stamp differences are taken in integer nanoseconds, exactly, and counted in periods
    once for both rules.

    >>> linked_breaks(np.array([10, 30, 60]), 10.0, 0).tolist()
    [False, True, True]
    >>> linked_breaks(np.array([10, 30, 60]), 10.0, 0, np.array([True, True, False])).tolist()
    [False, False, True]
    """
    steps = np.rint(stamp_steps(held, previous) / period)
    breaks: np.ndarray = steps != 1.0
    if previous is None:
        breaks[0] = True
    if monotone is None:
        return breaks
    return lift_bridged(breaks, steps - 1.0, monotone)  # steps - 1: readings lost before


def early_stamps(held: np.ndarray, period: float, previous: int | None) -> np.ndarray:
    """``early[k]``: the reading held by sample ``k`` is stamped less than half a ``period``
    after the one before (``previous`` for ``k = 0``; None: not early): no reading can have
    been lost between the two, whatever their stamps say (module notes).

    >>> early_stamps(np.array([10, 14, 24, 44]), 10.0, 0).tolist()
    [False, True, False, False]
    >>> early_stamps(np.array([10, 12]), 10.0, None).tolist()
    [False, True]
    """
    early: np.ndarray = np.rint(stamp_steps(held, previous) / period) <= 0.0
    if previous is None and early.size:
        early[0] = False
    return early


class Screen:
    """Screens aligned batches and links them by the sample rule (see the module notes)."""

    __slots__ = ("_bridge", "_last_t")

    def __init__(self, *, bridge: bool = False) -> None:
        self._bridge = bridge  # a backlash alone: bridge lost readings along monotone commands
        self._last_t: int | None = None  # stamp held by the last sample kept (None: breaks)

    def run(self, batch: AlignedBatch, health: StreamHealth, estimate: Estimate) -> Screened:
        """The samples of ``batch`` to identify from, judged with ``estimate`` (the estimate
        in use) by ``health``."""
        previous = self._last_t if batch.linked else None
        command_restarts = None
        if batch.period is None:  # no period known yet: every sample breaks
            breaks = link_breaks(batch.held, None, previous_ns=previous)
            restarts = breaks.copy()
            if batch.commands is not None:
                command_restarts = breaks.copy()
        else:
            bridge = batch.monotone if self._bridge else None
            breaks = linked_breaks(batch.held, batch.period, previous, bridge)
            early = early_stamps(batch.held, batch.period, previous)
            restarts = breaks & ~early
            if batch.commands is not None:  # the commands' path is known across lost readings
                along = batch.command_monotone
                lifted = (
                    breaks
                    if along is None
                    else linked_breaks(batch.held, batch.period, previous, along)
                )
                command_restarts = lifted & ~early
        if command_restarts is not None:
            command_restarts |= batch.marks
        breaks |= batch.marks
        restarts |= batch.marks
        us, ys, held, commands = batch.us, batch.ys, batch.held, batch.commands
        screening = health.screen(batch.times, us, ys, estimate, batch.resumed)
        kept = screening.keep
        last_t: int | None = int(held[-1])
        if kept is not None:
            breaks, tail = keep_breaks(breaks, kept)
            restarts, _ = keep_breaks(restarts, kept)
            if command_restarts is not None:
                command_restarts, _ = keep_breaks(command_restarts, kept)
            us, ys, held = us[kept], ys[kept], held[kept]
            commands = None if commands is None else commands[kept]
            last_t = None if tail or held.size == 0 else int(held[-1])
        self._last_t = last_t
        return Screened(us, ys, breaks, screening.events, restarts, commands, command_restarts)
