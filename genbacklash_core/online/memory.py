"""Memory measured in information: what the data taught about each branch, by input region.

An identifier that remembers the last ``W`` samples forgets a drivetrain as soon as it rests:
at 1 kHz a dwell of 1.5 s pushes every move out of a 1500-sample window, and a joint that
runs one way for a minute forgets the other branch. What carries information about the
general backlash is a *row* of the paper's regression, eq. (24): a pair of consecutive
readings ``(x(t-1), x(t))`` with the input ``u(t-1) -> u(t)`` that moved in between. A held
command (the servo holds a 100 Hz command for ten 1 kHz readings) or a dwell repeats the
previous row's state and adds nothing.

:class:`RowMemory` keeps such rows, and only such rows: pairs that are consecutive on the
encoder's clock (:mod:`genbacklash_core.samples`) and whose input moved. It files them by
the direction of the move (up: the right branch, eq. 19; down: the left branch, eq. 18) and
by where the input was, in ``bins`` equal parts of the input range seen so far, and holds
``capacity`` rows in all. When it is full, rows are forgotten from the fullest bins only,
oldest first, down to a common level (water filling): a new row pushes out the oldest row
*of its own bin* once that bin holds its share, and a bin the data rarely reach keeps all it
has. So old information is forgotten only where newer data cover the same region. A wearing
gap is tracked wherever the drivetrain works; the regions it stopped visiting keep what they
knew.

Two memories stand here because the identifiers remember differently on purpose:
:class:`RowMemory` (the windowed identifier, a backlash alone) holds ``capacity`` rows in all
and levels the bins by water filling; :class:`BinnedRows` (the recursive identifier, both
structures) holds rows of any width (:func:`~genbacklash_core.online.rows.row_width`), keeps
``per_direction`` rows per direction of the move (``1 / (1 - forgetting)``, the branch
memory) and a floor per region however old, and stamps each row with its sample so the
divergence test and the tracking term can age it. With the recursive identifier's floor of
``ceil(M / (2 bins))`` rows, a wearing gap is tracked wherever the joint works (about
``M / 2`` rows of the branch behind), a joint at rest or moving one way for minutes keeps
what it knew about the rest, and a narrow sweep does not bend the whole polynomial to its
part of the range.

Examples
--------
>>> import numpy as np
>>> mem = RowMemory(capacity=64, bins=4)
>>> u = np.array([0.0, 0.1, 0.1, 0.1, 0.3, 0.2])  # a move, a dwell, a move, a reversal
>>> y = u - 0.05
>>> mem.add_series(u, y, np.array([True, False, False, False, False, False]))
3
>>> len(mem), mem.per_bin  # not full: every row is kept, no bin is cut yet
(3, 64)
>>> series_u, series_y, breaks = mem.series()
>>> series_u.tolist(), breaks.tolist()
([0.0, 0.1, 0.1, 0.3, 0.3, 0.2], [True, False, True, False, True, False])
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.errors import GenBacklashError

from .advice import BranchCoverage

__all__ = [
    "BinnedRows",
    "RowMemory",
    "pair_series",
]

_PENDING_LIMIT = 256  # rows collected before they are filed into their bins


def pair_series(
    u0: FloatArray, u1: FloatArray, y0: FloatArray, y1: FloatArray
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Rows ``(u(t-1), u(t), x(t-1), x(t))`` as a series of pairs, ``(u, y, breaks)`` with
    a break before each pair: what the batch iteration
    (:func:`~genbacklash_core.identify.identify_backlash`) and the window fits take,
    forming exactly one row of eq. (24) per pair."""
    m = u1.size
    u = np.empty(2 * m)
    y = np.empty(2 * m)
    u[0::2], u[1::2] = u0, u1
    y[0::2], y[1::2] = y0, y1
    breaks = np.zeros(2 * m, dtype=bool)
    breaks[0::2] = True
    return u, y, breaks


def _level(counts: IntArray, capacity: int) -> int:
    """The largest ``level`` with ``sum(min(counts, level)) <= capacity`` (water filling):
    bins above it are cut to it, the others keep every row."""
    if int(counts.sum()) <= capacity:
        return capacity
    ordered = np.sort(counts)
    below = np.concatenate([[0], np.cumsum(ordered)[:-1]])  # rows in the smaller bins
    # with the level at ordered[k], the bins from k on hold ordered[k] each
    fits = below + ordered * (ordered.size - np.arange(ordered.size)) <= capacity
    k = int(np.argmin(fits)) if not fits.all() else ordered.size
    # the level lies between ordered[k-1] (fits) and ordered[k] (does not)
    rest = ordered.size - k
    base = int(below[k]) if k < ordered.size else int(ordered.sum())
    return max(1, (capacity - base) // max(rest, 1))


class RowMemory:
    """Regression rows filed by branch direction and input region (see the module notes).

    Parameters
    ----------
    capacity : int
        How many rows the memory holds in all.
    bins : int
        Regions of the input range per direction.
    """

    def __init__(self, capacity: int, bins: int = 16) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 2:
            raise GenBacklashError(f"capacity must be a whole number >= 2, got {capacity!r}")
        if isinstance(bins, bool) or not isinstance(bins, int) or bins < 1:
            raise GenBacklashError(f"bins must be a whole number >= 1, got {bins!r}")
        self.capacity = capacity
        self.bins = bins
        self.per_bin = capacity  # the level the fullest bins are cut to (see _file)
        empty = np.empty(0)
        self._u0, self._u1, self._y0, self._y1 = empty, empty, empty, empty
        self._order: IntArray = np.empty(0, dtype=np.intp)
        self._pending: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = []
        self._singles: list[tuple[float, float, float, float]] = []
        self._pending_count = 0
        self._lo = math.inf
        self._hi = -math.inf
        self.added = 0  # rows ever taken

    def __len__(self) -> int:
        self._file()
        return int(self._u1.size)

    def input_range(self) -> tuple[float, float]:
        """The input range of the rows taken so far (``(inf, -inf)`` when none)."""
        return self._lo, self._hi

    def add_series(self, u: FloatArray, y: FloatArray, breaks: BoolArray) -> int:
        """Take the rows of a series: each pair of consecutive samples (``breaks`` False at
        the second) whose input moved. Returns how many rows were taken."""
        if u.size < 2:
            return 0
        follows = ~breaks[1:]
        moved = u[1:] != u[:-1]  # a held command or a dwell repeats the previous state
        keep = follows & moved
        count = int(np.count_nonzero(keep))
        if count:
            self.add(u[:-1][keep], u[1:][keep], y[:-1][keep], y[1:][keep])
        return count

    def add(self, u0: FloatArray, u1: FloatArray, y0: FloatArray, y1: FloatArray) -> None:
        """Take rows ``(u(t-1), u(t), x(t-1), x(t))`` (consecutive, input moved)."""
        if u1.size == 0:
            return
        self._pending.append((u0.copy(), u1.copy(), y0.copy(), y1.copy()))
        self._pending_count += u1.size
        self._lo = min(self._lo, float(u1.min()))
        self._hi = max(self._hi, float(u1.max()))
        if self._pending_count >= _PENDING_LIMIT:
            self._file()

    def add_one(self, u0: float, u1: float, y0: float, y1: float) -> None:
        """Take one row (as :meth:`add`, without arrays)."""
        self._singles.append((u0, u1, y0, y1))
        self._pending_count += 1
        if u1 < self._lo:
            self._lo = u1
        if u1 > self._hi:
            self._hi = u1
        if self._pending_count >= _PENDING_LIMIT:
            self._file()

    def _keys(self, u0: FloatArray, u1: FloatArray) -> IntArray:
        """Bin key per row: direction (0 down, 1 up) times ``bins`` plus the region."""
        span = self._hi - self._lo
        if span > 0.0:
            region = np.floor((u1 - self._lo) / span * self.bins).astype(np.intp)
            np.clip(region, 0, self.bins - 1, out=region)
        else:
            region = np.zeros(u1.size, dtype=np.intp)
        up = (u1 > u0).astype(np.intp)
        return np.asarray(up * self.bins + region, dtype=np.intp)

    def _file(self) -> None:
        """File the pending rows: every bin keeps its newest ``per_bin`` rows."""
        if self._singles:
            block = np.array(self._singles, dtype=np.float64)
            self._pending.append((block[:, 0], block[:, 1], block[:, 2], block[:, 3]))
            self._singles = []
        if not self._pending:
            return
        start = self.added
        parts = [
            (self._u0, self._u1, self._y0, self._y1),
            *self._pending,
        ]
        u0 = np.concatenate([p[0] for p in parts])
        u1 = np.concatenate([p[1] for p in parts])
        y0 = np.concatenate([p[2] for p in parts])
        y1 = np.concatenate([p[3] for p in parts])
        order = np.concatenate(
            [self._order, np.arange(start, start + self._pending_count, dtype=np.intp)]
        )
        self.added += self._pending_count
        self._pending = []
        self._pending_count = 0
        keys = self._keys(u0, u1)
        newest_first = np.lexsort((-order, keys))  # by bin, newest first within a bin
        sorted_keys = keys[newest_first]
        first_of_bin = np.concatenate([[True], sorted_keys[1:] != sorted_keys[:-1]])
        position = np.arange(sorted_keys.size)
        bin_start = np.maximum.accumulate(np.where(first_of_bin, position, 0))
        rank = position - bin_start
        counts = np.bincount(keys, minlength=2 * self.bins)
        self.per_bin = _level(counts, self.capacity)
        kept = np.sort(newest_first[rank < self.per_bin])  # back in time order
        self._u0, self._u1, self._y0, self._y1 = u0[kept], u1[kept], y0[kept], y1[kept]
        self._order = order[kept]

    def series(self) -> tuple[FloatArray, FloatArray, BoolArray]:
        """The rows as a series of pairs, ``(u, y, breaks)`` with a break before each pair:
        what the batch iteration (:func:`~genbacklash_core.identify.identify_backlash`) and
        the window fits take, forming exactly one row of eq. (24) per pair."""
        self._file()
        return pair_series(self._u0, self._u1, self._y0, self._y1)

    def rows(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The filed rows ``(u(t-1), u(t), x(t-1), x(t))``, in time order (views)."""
        self._file()
        return self._u0, self._u1, self._y0, self._y1

    @property
    def taken(self) -> int:
        """Rows taken so far, filed or not: the memory's clock (a row's ``order`` is the
        clock when it was taken)."""
        return self.added + self._pending_count + len(self._singles)

    def stamps(self) -> tuple[IntArray, BoolArray]:
        """Per filed row (time order, as :meth:`rows`): its order among the rows taken, and
        whether the input moved up (the right branch, eq. 19) rather than down (eq. 18)."""
        self._file()
        return self._order, self._u1 > self._u0

    def discard(self, drop: BoolArray) -> int:
        """Forget the filed rows flagged in ``drop`` (time order, as :meth:`rows`); how many."""
        self._file()
        count = int(np.count_nonzero(drop))
        if count:
            keep = ~drop
            self._u0, self._u1 = self._u0[keep], self._u1[keep]
            self._y0, self._y1 = self._y0[keep], self._y1[keep]
            self._order = self._order[keep]
        return count

    def coverage(self) -> BranchCoverage:
        """Rows per direction and region (for diagnostics and reports)."""
        self._file()
        if not self._u1.size:
            edges = np.zeros(self.bins + 1)
            zeros = np.zeros(self.bins, dtype=np.intp)
            return BranchCoverage(edges, zeros, zeros.copy(), self.per_bin)
        keys = self._keys(self._u0, self._u1)
        counts = np.bincount(keys, minlength=2 * self.bins)
        edges = np.linspace(self._lo, self._hi, self.bins + 1)
        return BranchCoverage(
            edges,
            np.asarray(counts[self.bins :], dtype=np.intp),
            np.asarray(counts[: self.bins], dtype=np.intp),
            self.per_bin,
        )


# --------------------------------------------------------------------------- per direction


class BinnedRows:
    """Regression rows filed by direction of motion and input region (see the module notes).

    A row is a vector of ``width`` fields whose first two are the input before and at the
    row (``u(t-1), u(t)`` for a backlash; ``u(t-2), u(t-1)`` for the cascade): a move up
    files it with the right branch, a move down with the left one, in one of ``bins`` equal
    regions of the input range of the rows seen so far. Each direction keeps its newest
    ``per_direction`` rows, except that every region keeps its newest ``floor`` rows however
    old: new rows push out the oldest rows of regions that hold more than that.

    Parameters
    ----------
    width : int
        Fields per row.
    bins : int
        Regions per direction.
    per_direction : int
        Rows per direction (the branch memory ``M``).
    floor : int
        Rows each region keeps however old.

    Examples
    --------
    >>> mem = BinnedRows(width=4, bins=2, per_direction=3, floor=1)
    >>> up = np.array([[0.0, 0.1, 0, 0], [0.8, 0.9, 0, 0], [0.1, 0.2, 0, 0],
    ...                [0.2, 0.3, 0, 0], [0.3, 0.4, 0, 0]])  # moves up, one high, four low
    >>> mem.insert(up, np.arange(5))
    >>> len(mem), mem.direction_counts()  # the two oldest low rows went, not the high one
    (3, (0, 3))
    >>> mem.rows()[1].tolist()
    [1, 3, 4]
    """

    def __init__(self, width: int, bins: int, per_direction: int, floor: int) -> None:
        self.width = width
        self.bins = bins
        self.per_direction = per_direction
        self.floor = floor
        self._data = np.empty((0, width))
        self._stamp = np.empty(0, dtype=np.intp)  # sample index of each row, increasing
        self.low = math.inf  # the input range of the rows seen
        self.high = -math.inf

    def __len__(self) -> int:
        return int(self._stamp.size)

    @property
    def capacity(self) -> int:
        """Rows the memory holds at most."""
        return 2 * self.per_direction

    def direction_counts(self) -> tuple[int, int]:
        """Rows of moves down (left branch) and up (right branch)."""
        up = int(np.count_nonzero(self._data[:, 1] > self._data[:, 0]))
        return len(self) - up, up

    def rows(self) -> tuple[FloatArray, IntArray]:
        """The rows, oldest first, and the sample index each was taken at."""
        return self._data, self._stamp

    def insert(self, rows: FloatArray, stamps: IntArray) -> None:
        """File ``rows`` (taken at sample indices ``stamps``, in time order)."""
        if rows.shape[0] == 0:
            return
        self.low = min(self.low, float(rows[:, 1].min()))
        self.high = max(self.high, float(rows[:, 1].max()))
        data = np.concatenate([self._data, rows])
        stamp = np.concatenate([self._stamp, stamps])
        up = data[:, 1] > data[:, 0]
        drop = np.zeros(stamp.size, dtype=bool)
        for direction in (~up, up):
            excess = int(np.count_nonzero(direction)) - self.per_direction
            if excess > 0:
                drop[self._oldest(data[:, 1], direction, excess)] = True
        if drop.any():
            data, stamp = data[~drop], stamp[~drop]
        self._data, self._stamp = data, stamp

    def _oldest(self, where: FloatArray, direction: BoolArray, excess: int) -> IntArray:
        """The ``excess`` rows of one direction to forget: the oldest of those beyond their
        region's newest ``floor`` (the oldest of all, should those not be enough)."""
        at = np.flatnonzero(direction)  # time order
        span = self.high - self.low
        if span > 0.0:
            region = ((where[at] - self.low) * (self.bins / span)).astype(np.intp)
            np.clip(region, 0, self.bins - 1, out=region)
        else:
            region = np.zeros(at.size, dtype=np.intp)
        # a row may go when at least ``floor`` newer rows of its region stay: scan the
        # oldest rows, a few more than needed, counting each region's rows from the oldest
        allowed = np.bincount(region, minlength=self.bins) - self.floor
        look = min(at.size, 2 * excess + self.bins)
        while True:
            head = region[:look]
            onehot = head[:, None] == np.arange(self.bins)
            seen = np.cumsum(onehot, axis=0)[np.arange(look), head]  # 1-based, per region
            spare = np.flatnonzero(seen <= allowed[head])
            if spare.size >= excess or look == at.size:
                break
            look = min(at.size, 2 * look)
        if spare.size >= excess:
            return np.asarray(at[spare[:excess]], dtype=np.intp)
        kept = np.setdiff1d(np.arange(at.size), spare)  # not enough: the oldest of all
        return np.asarray(at[np.concatenate([spare, kept[: excess - spare.size]])], dtype=np.intp)
