"""What the windowed identifier fits on: a memory of rows, or a window of samples.

:class:`~genbacklash_core.online.windowed.WindowedIdentifier` takes its samples through one
of two feeds, chosen by the structure; the identifier itself only schedules and runs the fits:

* :class:`RowFeed` (a backlash alone): the rows of eq. (24), pairs of consecutive samples
  (the sample rule, :mod:`genbacklash_core.samples`) whose input moved, filed by branch and
  input region in a :class:`~genbacklash_core.online.memory.RowMemory`. A dwell or a held
  command adds no row. Fits are scheduled on the rows taken; the recent samples stay in a
  ring for the output-error refinement, which needs samples in order.
* :class:`SampleFeed` (the cascade): the latest ``window`` samples in a
  :class:`~genbacklash_core.online.rows.SampleRing`, except those of a dwell past the linear
  block's settling horizon (:meth:`SampleFeed.settle`): eqs. (30)-(31) at a fixed point repeat
  one steady state, and leaving them out keeps the window's series that of the same
  dynamics. Fits are scheduled on the samples stored.

Both count ``idle``, the samples since the latest one that informed the fits (a row; a
stored sample), and :meth:`take` yields after each stretch of samples at whose end a fit
may be due, so that the identifier fits at the same samples however the series is chunked.

Examples
--------
>>> import numpy as np
>>> feed = RowFeed(window=100, bins=4)
>>> due = lambda: 3  # a fit after three rows
>>> u = np.array([0.0, 0.1, 0.1, 0.2, 0.3, 0.4])
>>> [(n, feed.progress) for n in feed.take(u, 0.5 * u, np.zeros(6, dtype=bool), due)]
[(5, 3), (1, 4)]
>>> feed.idle, len(feed)
(0, 4)
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.samples import run_lengths
from genbacklash_core.structure import Structure

from .advice import BranchCoverage, excitation_advice
from .fits import WindowFit, block_conditioning, outlier_rows, refine_window
from .memory import RowMemory
from .rows import SampleRing, WindowRows, settling_samples
from .tracking import BAND_SAMPLES, DeadZoneDrift, dead_zone_drift

__all__ = ["Feed", "RowFeed", "SampleFeed"]


class Feed(ABC):
    """The samples (or rows) a windowed identifier fits on (see the module notes)."""

    by_rows: bool  # a memory of rows (RowFeed) rather than a window of samples

    def __init__(self, window: int, held: int = 0) -> None:
        self.window = window
        self.ring = SampleRing(max(window, held))  # the latest samples (``held`` at least)
        self.idle = 0  # samples since the latest one that informed the fits

    @property
    @abstractmethod
    def progress(self) -> int:
        """The counter fits are scheduled on: rows taken, or samples stored."""

    @abstractmethod
    def __len__(self) -> int:
        """How much the feed holds: rows, or samples."""

    @abstractmethod
    def take(
        self, u: FloatArray, y: FloatArray, b: BoolArray, due: Callable[[], int]
    ) -> Iterator[int]:
        """Take validated samples, yielding the count of samples taken each time
        :attr:`progress` may have reached ``due()`` (read again after each yield)."""

    @abstractmethod
    def data(self) -> tuple[FloatArray, FloatArray, BoolArray]:
        """What a fit takes: ``(u, y, breaks)``."""

    @abstractmethod
    def seed_left(self, seed_samples: int, seed_progress: int) -> int:
        """How many of a seed's ``seed_samples`` samples the new data have not replaced
        yet (``seed_progress``: :attr:`progress` when the seed was planted)."""

    @abstractmethod
    def conditioning(self, structure: Structure, rows: WindowRows, recent: int) -> FloatArray:
        """Block conditioning of a fit's rows that the excitation test judges."""

    @abstractmethod
    def settle(self, structure: Structure, p: FloatArray) -> None:
        """Take note of a new estimate ``p`` (the cascade's settling horizon)."""

    def coverage(self) -> BranchCoverage | None:
        """Rows per branch and input region (None: not filed by branch)."""
        return None

    def advice(self, samples: int, rows_needed: int) -> str:
        """Excitation advice ("" when none, or not filed by branch)."""
        return ""

    def refine(
        self, structure: Structure, start: FloatArray, fit: WindowFit, iterations: int
    ) -> FloatArray | None:
        """Output-error refinement from ``start`` on the feed's series (None: none)."""
        u, y, b = self.data()
        return refine_window(structure, start, u, y, fit, iterations, b)

    def purge(self, structure: Structure, p: FloatArray, residual: float) -> bool:
        """Forget what the accepted model ``p`` cannot have produced; True when anything
        was forgotten."""
        return False

    def drift(self, structure: Structure, reported: FloatArray) -> DeadZoneDrift | None:
        """The bands' tracking term of the feed's rows (None: none)."""
        return None


class RowFeed(Feed):
    """The rows of a backlash alone in a :class:`RowMemory` (see the module notes)."""

    by_rows = True

    def __init__(self, window: int, bins: int) -> None:
        # the ring holds the refinement's `window` samples and the bands' free run's
        # `BAND_SAMPLES` (online.tracking): one ring, read at either length
        super().__init__(window, BAND_SAMPLES)
        self.memory = RowMemory(window, bins)
        self.rows = 0  # rows taken
        self.last: tuple[float, float] | None = None  # the latest sample

    @property
    def progress(self) -> int:
        return self.rows

    def __len__(self) -> int:
        return len(self.memory)

    def push(self, u: float, y: float, follows: bool) -> None:
        """Take one validated sample (``follows``: it follows the previous one taken)."""
        self.ring.push(u, y, not follows)
        last = self.last
        if last is not None and follows and u != last[0]:
            self.memory.add_one(last[0], u, last[1], y)  # a row of eq. (24)
            self.rows += 1
            self.idle = 0
        else:
            self.idle += 1
        self.last = (u, y)

    def take(
        self, u: FloatArray, y: FloatArray, b: BoolArray, due: Callable[[], int]
    ) -> Iterator[int]:
        if self.last is None:
            prev_u, prev_y, link = u[0], y[0], False
        else:
            prev_u, prev_y = self.last
            link = not bool(b[0])
        u_prev = np.concatenate([[prev_u], u[:-1]])
        y_prev = np.concatenate([[prev_y], y[:-1]])
        follows = ~b
        follows[0] = link
        row = follows & (u != u_prev)  # a held command or a dwell adds no row
        counts = row.cumsum()  # rows up to each sample of the call
        start = 0
        while start < u.size:
            need = due() - self.rows
            before = int(counts[start - 1]) if start else 0
            hit = int(counts[start:].searchsorted(before + max(need, 1)))
            stop = u.size if hit >= counts.size - start else start + hit + 1
            part = slice(start, stop)
            self.ring.extend(u[part], y[part], b[part])  # the refinement's recent series
            taken = row[part]
            if taken.any():
                m = self.memory
                m.add(u_prev[part][taken], u[part][taken], y_prev[part][taken], y[part][taken])
                self.rows += int(np.count_nonzero(taken))
                self.idle = stop - 1 - (start + int(taken.nonzero()[0][-1]))
            else:
                self.idle += stop - start
            start = stop
            yield stop - part.start
        self.last = (float(u[-1]), float(y[-1]))

    def data(self) -> tuple[FloatArray, FloatArray, BoolArray]:
        return self.memory.series()

    def settle(self, structure: Structure, p: FloatArray) -> None:
        """Nothing: rows are not samples of a dwell."""

    def seed_left(self, seed_samples: int, seed_progress: int) -> int:
        return seed_samples - (self.rows - seed_progress)  # the rows taken since replace it

    def conditioning(self, structure: Structure, rows: WindowRows, recent: int) -> FloatArray:
        """All the rows: the memory keeps every region it has seen."""
        return block_conditioning(structure, rows.phi.T @ rows.phi)

    def coverage(self) -> BranchCoverage:
        return self.memory.coverage()

    def advice(self, samples: int, rows_needed: int) -> str:
        return excitation_advice(
            self.memory.coverage(),
            moved=not (samples > 1 and self.rows == 0),
            rows_needed=max(rows_needed, 0),
        )

    def refine(
        self, structure: Structure, start: FloatArray, fit: WindowFit, iterations: int
    ) -> FloatArray | None:
        """On the recent series: the free-run simulation error needs samples in order, not
        rows filed by region."""
        ru, ry = self.ring.window(self.window)
        if ru.size <= 4 * structure.n_parameters:
            return None
        breaks = self.ring.breaks(self.window)
        return refine_window(structure, start, ru, ry, fit, iterations, breaks)

    def purge(self, structure: Structure, p: FloatArray, residual: float) -> bool:
        """Forget the rows the accepted model cannot have produced: one-step prediction
        errors beyond ``OUTLIER_SIGMAS`` robust standard deviations (a burst of garbage
        readings would otherwise stay for good in the regions rarely visited)."""
        _, u1, y0, y1 = self.memory.rows()
        drop = outlier_rows(structure, p, u1, y0, y1, residual)
        return drop is not None and bool(self.memory.discard(drop))

    def drift(self, structure: Structure, reported: FloatArray) -> DeadZoneDrift | None:
        """The memory's rows, each aged by the rows taken since, fitted with dead zones
        that drift (:mod:`genbacklash_core.online.tracking`); on the rows' own clock, so
        chunking does not matter. The free run of the model term over the latest
        ``BAND_SAMPLES`` readings."""
        order, _ = self.memory.stamps()
        age = self.memory.taken - order
        u, y = self.ring.window(BAND_SAMPLES)
        recent = (u, y, self.ring.breaks(BAND_SAMPLES))
        return dead_zone_drift(structure, reported, self.memory.rows(), age, recent)


class SampleFeed(Feed):
    """The cascade's window of samples, settled dwells left out (see the module notes)."""

    by_rows = False

    def __init__(self, window: int) -> None:
        super().__init__(window)
        self.kept = 0  # samples stored (settled dwells left out)
        self.still = 0  # samples at the latest input, its move included
        self.held_u = math.nan  # that value
        self.dwell: int | None = None  # dwell samples stored (see settle)

    @property
    def progress(self) -> int:
        return self.kept

    def __len__(self) -> int:
        return len(self.ring)

    def settle(self, structure: Structure, p: FloatArray) -> None:
        """The samples of a dwell the window stores: twice the linear block's settling
        horizon at ``p`` (to 1e-4 of a step)."""
        self.dwell = 2 * settling_samples(structure, p)

    def unsettled(self, u: FloatArray) -> BoolArray:
        """Which samples the window stores: all but those of a dwell (the input held at one
        value) past ``dwell`` samples (:meth:`settle`); a reading lost among them changes
        nothing either: the state did not move."""
        moved = np.empty(u.size, dtype=bool)
        moved[0] = u[0] != self.held_u
        np.not_equal(u[1:], u[:-1], out=moved[1:])
        run = run_lengths(moved, self.still)  # samples at this input, the move included
        self.still = int(min(run[-1], 1 << 40))
        self.held_u = float(u[-1])
        if self.dwell is None:  # no estimate yet: every sample
            return np.ones(u.size, dtype=bool)
        return np.asarray(run <= self.dwell + 1)  # the move and `dwell` held samples

    def take(
        self, u: FloatArray, y: FloatArray, b: BoolArray, due: Callable[[], int]
    ) -> Iterator[int]:
        stored = self.unsettled(u)
        if stored.any():  # idle: samples since the last one stored
            self.idle = int(u.size - 1 - np.flatnonzero(stored)[-1])
        else:
            self.idle += int(u.size)
        if not stored.all():  # a settled dwell: counted as seen, not stored
            yield int(u.size - np.count_nonzero(stored))
            u, y, b = u[stored], y[stored], b[stored]
        start = 0
        while start < u.size:
            take = min(u.size - start, due() - self.kept)
            part = slice(start, start + take)
            self.ring.extend(u[part], y[part], b[part])
            self.kept += take
            start += take
            yield take

    def data(self) -> tuple[FloatArray, FloatArray, BoolArray]:
        u, y = self.ring.window()
        return u, y, self.ring.breaks()

    def seed_left(self, seed_samples: int, seed_progress: int) -> int:
        return min(seed_samples, self.window - len(self))

    def conditioning(self, structure: Structure, rows: WindowRows, recent: int) -> FloatArray:
        """The rows of the latest ``recent`` samples (``excitation_window``)."""
        count = int(np.count_nonzero(rows.informative[-recent:]))
        phi = rows.phi[rows.phi.shape[0] - count :]  # rows follow the informative samples
        return block_conditioning(structure, phi.T @ phi)
