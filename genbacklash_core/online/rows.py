"""Regression rows and the sample rule, for both online identifiers.

A row of the paper's regression pairs ``x(t)`` with ``x(t-1)`` (eq. 24, a backlash alone) or
with ``x(t-i)``, ``y(t-j)`` (eq. 32, the cascade). Both identifiers form rows by one rule:

* **The sample rule.** A row is formed only when the samples it pairs are consecutive on the
  encoder's clock (``breaks``, :mod:`genbacklash_core.samples`): a lost reading never pairs
  two states that are not neighbours.
* **Only moves.** A row carries information only when the input moved by more than a
  deadband (``input_deadband`` of the input span) and a branch was engaged (eqs. 27-28), or,
  for the cascade, the internal ``x`` changed within the linear block's settling horizon.

The two identifiers hold their data differently, so the row builders differ in what they
start from (the difference is on purpose):

* the windowed identifier rebuilds every row of a window of samples at each fit
  (:func:`window_rows`; the cascade's internal ``x`` by eq. (36) over the window, from the
  first sample where it no longer depends on the unknown start);
* the recursive one forms each row once, as its samples arrive, and carries the lags between
  calls (:func:`cascade_memory_rows`, :class:`CascadeLags`; rows are :func:`row_width` fields
  wide, see :func:`~genbacklash_core.online.memory.memory_regression`).

:class:`SampleRing` holds the most recent samples for both (the windowed identifier's window;
the recursive identifier's buffer for the cascade's cold start).

Examples
--------
>>> ring = SampleRing(3)
>>> ring.extend(np.array([1.0, 2.0, 3.0, 4.0]), np.zeros(4))
>>> u, _ = ring.window()
>>> u.tolist(), ring.breaks().tolist()  # the oldest sample held always breaks
([2.0, 3.0, 4.0], [True, False, False])
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.identify.regression import (
    backlash_columns,
    backlash_rows,
    switching_functions,
)
from genbacklash_core.play import play_operator
from genbacklash_core.samples import breaks_to_rows
from genbacklash_core.simulate import play_bounds
from genbacklash_core.structure import Structure

__all__ = [
    "CascadeLags",
    "SampleRing",
    "WindowRows",
    "cascade_memory_rows",
    "memory_regression",
    "row_width",
    "samples_since_change",
    "settling_samples",
    "window_rows",
]

# --------------------------------------------------------------------------- recent samples


class SampleRing:
    """Last ``size`` samples of ``(u, y)`` in preallocated arrays, readable as one view.

    Each sample is written twice, at ``k`` and ``k + size``, so the latest ``size`` samples
    are always the contiguous slice ``[k, k + size)``: reading the window copies nothing.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self.u = np.zeros(2 * size)
        self.y = np.zeros(2 * size)
        self.b = np.ones(2 * size, dtype=bool)  # the sample rule: a break before the sample
        self.count = 0

    def push(self, u: float, y: float, brk: bool = False) -> None:
        k = self.count % self.size
        self.u[k] = self.u[k + self.size] = u
        self.y[k] = self.y[k + self.size] = y
        self.b[k] = self.b[k + self.size] = brk or self.count == 0
        self.count += 1

    def extend(self, u: FloatArray, y: FloatArray, breaks: BoolArray | None = None) -> None:
        n = u.size
        b = np.zeros(n, dtype=bool) if breaks is None else breaks.copy()
        if self.count == 0 and n:
            b[0] = True
        if n > self.size:  # only the last `size` samples survive
            self.count += n - self.size
            u, y, b, n = u[-self.size :], y[-self.size :], b[-self.size :], self.size
        size = self.size
        start = self.count % size
        first = min(n, size - start)  # up to the end of the ring, the rest from its start
        rest = n - first
        for store, values in ((self.u, u), (self.y, y), (self.b, b)):
            head = values[:first]
            store[start : start + first] = store[start + size : start + size + first] = head
            if rest:
                store[:rest] = store[size : size + rest] = values[first:]
        self.count += n

    def __len__(self) -> int:
        return min(self.count, self.size)

    def window(self, last: int | None = None) -> tuple[FloatArray, FloatArray]:
        """The latest ``last`` (default all held) samples, oldest first (views)."""
        held = len(self)
        n = held if last is None else min(last, held)
        end = held if self.count <= self.size else self.count % self.size + self.size
        return self.u[end - n : end], self.y[end - n : end]

    def breaks(self, last: int | None = None) -> BoolArray:
        """The sample rule's breaks of :meth:`window` (the oldest sample always breaks)."""
        held = len(self)
        n = held if last is None else min(last, held)
        end = held if self.count <= self.size else self.count % self.size + self.size
        out = self.b[end - n : end].copy()
        if n:
            out[0] = True
        return out


# --------------------------------------------------------------------------- rows of a window


@dataclass
class WindowRows:
    """One regression over a window (internal).

    ``informative`` flags, for the latest samples (end-aligned with the series), the rows that
    carry information: for a backlash alone a branch engaged while the input moved; for the
    cascade the input moved (every such row informs the linear part).
    """

    phi: FloatArray
    target: FloatArray
    informative: BoolArray
    x: FloatArray | None = None  # cascade: internal x (eq. 36), valid from index `first`
    first: int = 0


def _window_backlash_rows(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    deadband: float,
    breaks: BoolArray | None = None,
) -> WindowRows:
    """Rows of eq. (24) for the measured backlash output ``y`` (the informative ones): the
    batch iteration's rule (:func:`~genbacklash_core.identify.backlash_rows`) with the
    input's ``deadband``."""
    return WindowRows(*backlash_rows(structure, p, u, y, breaks, deadband))


def _merge_index(lo: FloatArray, hi: FloatArray, x_low: FloatArray) -> int:
    """First sample from which the play operator no longer depends on its start, or -1.

    ``x_low`` is the play operator started from ``-inf``; from ``+inf`` it is the same from
    the first sample on which they agree (the first engagement any start would see). That
    is almost always early, so the ``+inf`` run is tried on a short prefix first.
    """
    for length in (min(64, lo.size), lo.size):
        x_high = play_operator(lo[:length], hi[:length], math.inf)
        merged = x_high == x_low[:length]
        if merged.any():
            return int(np.argmax(merged))
    return -1


_MAX_SETTLING = 1000  # cap of the linear block's settling horizon, in samples


def settling_samples(structure: Structure, p: FloatArray) -> int:
    """Samples the linear block takes to settle to 1 % (from its slowest pole), at least
    ``max(na, nb, 2) + 2``: rows further than that from the last change of ``x`` carry only
    noise about the linear block."""
    floor = max(structure.na, structure.nb, 2) + 2
    _, b = structure.linear_part(p)
    if b.size == 0:
        return floor
    rho = float(np.max(np.abs(np.roots(np.concatenate([[1.0], b])))))
    if not 0.0 < rho < 1.0:
        return floor if rho == 0.0 else _MAX_SETTLING
    return int(min(max(math.ceil(math.log(0.01) / math.log(rho)), floor), _MAX_SETTLING))


def samples_since_change(x: FloatArray) -> FloatArray:
    """For each sample, how many samples ago ``x`` last changed (inf before any change)."""
    index = np.arange(x.size, dtype=np.float64)
    changed = np.empty(x.size, dtype=bool)
    changed[0] = False
    np.not_equal(x[1:], x[:-1], out=changed[1:])
    last = np.where(changed, index, -np.inf)
    np.maximum.accumulate(last, out=last)
    return np.asarray(index - last, dtype=np.float64)


def _window_cascade_rows(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    deadband: float,
    settling: int | None = None,
    breaks: BoolArray | None = None,
) -> WindowRows:
    """Rows of eq. (35) with the internal ``x`` of eq. (36), for a window taken mid-stream.

    The state before the window is unknown: ``x`` is only known from the sample on which the
    play operator started from ``-inf`` and from ``+inf`` agree (the first engagement that
    any start would see); rows that need an earlier ``x`` are dropped. So are rows whose
    input did not move, and rows where no branch is engaged and ``x`` has rested for longer
    than the linear block takes to settle: their regressors are constants plus output noise,
    which carries no information and biases the equation error (errors in variables).
    """
    left, right = structure.branches(p, u)
    lo, hi = play_bounds(left, right)
    x = play_operator(lo, hi, -math.inf)  # eq. (36)
    size = structure.n_parameters
    first = _merge_index(lo, hi, x)
    if first < 0:
        return WindowRows(np.empty((0, size)), np.empty(0), np.zeros(0, dtype=bool), x, u.size)
    na, nb = structure.na, structure.nb
    t0 = max(first + max(2, na), nb, 1)  # rows t = t0 .. N-1
    count = u.size
    if t0 >= count:
        return WindowRows(np.empty((0, size)), np.empty(0), np.zeros(0, dtype=bool), x, first)
    u_prev = u[t0 - 1 : count - 1]  # u(t-1)
    x_prev2 = x[t0 - 2 : count - 2]  # x(t-2)
    f1, f2 = switching_functions(structure, p, u_prev, x_prev2)  # f(t-1), eqs. (27)-(28)
    moving = np.abs(u_prev - u[t0 - 2 : count - 2]) > deadband
    resting = samples_since_change(x)[t0 - 2 : count - 2]  # up to x(t-2)
    horizon = settling_samples(structure, p) if settling is None else settling
    live = ((f1 + f2) > 0.0) | (resting <= horizon)
    informative = moving & live  # such rows inform the linear part too (eq. 35)
    if breaks is not None:  # the measured lags y(t-1) .. y(t-nb) must be consecutive
        lags = max(nb, 1)
        informative &= breaks_to_rows(breaks, lags)[t0 - lags :]
    use = informative
    m = int(np.count_nonzero(use))
    n_bl = structure.n_backlash
    phi = np.empty((m, size), order="F")
    phi[:, :n_bl] = backlash_columns(structure, p, u_prev[use], f1[use], f2[use])
    col = n_bl
    for i in range(2, na + 1):
        phi[:, col] = x[t0 - i : count - i][use]  # x(t-i), eq. (32)
        col += 1
    for j in range(1, nb + 1):
        phi[:, col] = -y[t0 - j : count - j][use]  # -y(t-j), eq. (32)
        col += 1
    hold = x_prev2 * (1.0 - f1) * (1.0 - f2)  # x(t-2)[1-f1(t-1)][1-f2(t-1)]
    target = (y[t0:] - hold)[use]  # eq. (37)
    return WindowRows(phi, target, informative, x, first)


def window_rows(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    deadband: float,
    settling: int | None = None,
    breaks: BoolArray | None = None,
) -> WindowRows:
    """The regression of eq. (24) or (35) over a window, at parameters ``p``.

    ``settling`` (cascade only) is the linear block's settling horizon; default from ``p``.
    ``breaks``: the sample rule; no row reaches across a break.
    """
    if structure.cascade:
        return _window_cascade_rows(structure, p, u, y, deadband, settling, breaks)
    return _window_backlash_rows(structure, p, u, y, deadband, breaks)


# --------------------------------------------------------------------------- rows as they come


@dataclass
class CascadeLags:
    """The signals the next cascade row needs, relative to the next sample ``t``.

    The internal ``x`` is carried as bounds: the play operator (eq. 36) run from the lowest
    and from the highest state any lost reading may have left. Where they agree ``x`` is
    known; after a break they part, and meet again at the next engagement of a branch.
    """

    u1: float  # u(t-1)
    u2: float  # u(t-2)
    x_low: list[float]  # internal x(t-2), .., x(t-m), m = max(na, 2): lower bound
    x_high: list[float]  # the same, upper bound
    y: list[float]  # y(t-1), .., y(t-nb)
    resting: int  # samples since x last changed, up to x(t-2)

    @classmethod
    def unknown(cls, structure: Structure, u1: float = 0.0, u2: float = 0.0) -> CascadeLags:
        """Lags with an internal ``x`` not known yet (after a seed, at a window's start)."""
        m = max(structure.na, 2)
        return cls(u1, u2, [-math.inf] * (m - 1), [math.inf] * (m - 1), [0.0] * structure.nb, 0)


def row_width(structure: Structure) -> int:
    """Fields per memory row (see :func:`memory_regression`)."""
    if structure.cascade:
        return max(structure.na, 2) + structure.nb + 2
    return 6


def cascade_memory_rows(
    structure: Structure,
    p: FloatArray,
    lags: CascadeLags,
    u: FloatArray,
    y: FloatArray,
    run: IntArray,
    run_before: int,
    deadband: FloatArray,
    settling: int,
) -> tuple[FloatArray, IntArray, CascadeLags]:
    """Memory rows of eq. (32) for a stretch of samples, the internal ``x`` by eq. (36).

    A row at ``t`` needs samples ``t - max(m, nb) .. t`` consecutive (``run``: consecutive
    samples ending at each, ``run_before`` at the sample before the stretch), the internal
    ``x(t-2) .. x(t-m)`` known (after a break the state a lost reading left is not: the
    bounds of :class:`CascadeLags` restart there), an input that moved from ``u(t-2)`` to
    ``u(t-1)``, and a branch engaged or an ``x`` that changed within the linear block's
    ``settling`` horizon (otherwise its regressors are constants plus noise). Returns the
    rows, their positions in the stretch and the lags after it.
    """
    na, nb, size = structure.na, structure.nb, u.size
    m = max(na, 2)
    u_lag1 = np.concatenate([[lags.u1], u[:-1]])  # u(t-1) per row
    u_lag2 = np.concatenate([[lags.u2], u_lag1[:-1]])  # u(t-2)
    lo, hi = play_bounds(*structure.branches(p, u_lag1))
    # x(t-1) per row, eq. (36); where sample t-1 broke the chain its prior state is unknown:
    # the lower bound restarts from -inf (clamped to lo), the upper one from +inf (to hi)
    restart = np.concatenate([[run_before <= 1], run[:-1] <= 1])
    low = play_operator(lo, np.where(restart, lo, hi), lags.x_low[0])
    high = play_operator(np.where(restart, hi, lo), hi, lags.x_high[0])
    x_seq = np.concatenate([lags.x_low[::-1], low])  # x(T-m) .. x(T-2), x(T-1) .. x(T+n-2)
    known_seq = np.concatenate(
        [np.equal(lags.x_low, lags.x_high)[::-1], low == high]
    )  # x determined (both bounds agree)
    x2 = x_seq[m - 2 : m - 2 + size]  # x(t-2) per row
    f1, f2 = switching_functions(structure, p, u_lag1, x2)  # f(t-1), eqs. (27)-(28)
    moving = np.abs(u_lag1 - u_lag2) > deadband
    resting = np.empty(size)  # samples since x last changed, up to x(t-2)
    resting[0] = lags.resting
    if size > 1:
        since = samples_since_change(np.concatenate([[x_seq[m - 2]], low[:-1]]))[1:]
        resting[1:] = np.minimum(since, lags.resting + np.arange(1, size))
    changed_last = low[-1] != (low[-2] if size > 1 else x_seq[m - 2])
    known = np.ones(size, dtype=bool)
    for i in range(2, m + 1):
        known &= known_seq[m - i : m - i + size]  # x(t-i) determined
    complete = run >= max(m, nb) + 1  # every lag consecutive (the sample rule)
    live = complete & known & moving & (((f1 + f2) > 0.0) | (resting <= settling))
    at = np.flatnonzero(live)
    rows = np.empty((at.size, m + nb + 2))
    rows[:, 0], rows[:, 1] = u_lag2[at], u_lag1[at]
    for i in range(2, m + 1):
        rows[:, i] = x_seq[m - i + at]  # x(t-i)
    y_seq = np.concatenate([lags.y[::-1], y])  # y(T-nb) .. y(T-1), y(T) ..
    for j in range(1, nb + 1):
        rows[:, m + j] = y_seq[nb - j + at]  # y(t-j)
    rows[:, -1] = y[at]  # y(t)
    high_seq = np.concatenate([lags.x_high[::-1], high])
    after = CascadeLags(
        u1=float(u[-1]),
        u2=float(u_lag1[-1]),
        x_low=[float(v) for v in x_seq[-(m - 1) :][::-1]],
        x_high=[float(v) for v in high_seq[-(m - 1) :][::-1]],
        y=[float(v) for v in y_seq[-nb:][::-1]] if nb else [],
        resting=0 if changed_last else int(min(resting[-1] + 1, 1e9)),
    )
    return rows, at, after


def memory_regression(
    structure: Structure, p: FloatArray, rows: FloatArray, *, holds: bool = True
) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray, BoolArray]:
    """The regression of eq. (24) (backlash) or eq. (35) (cascade) over memory rows at ``p``.

    Backlash rows are ``[u(t-1), u(t), x(t-1), x(t), u_a, d_a]``: the switching functions
    (eqs. 27-28) use the measured ``x(t-1)``, and on the rows that engage a branch the target
    is ``x(t)`` (the hold term of eq. 24 vanishes). A row with neither branch engaged holds
    the state (eqs. 20-21); eq. (29) leaves it out, but when the row knows its *anchor* --
    the input ``u_a`` of the row just before it, when that row engaged the left
    (``d_a = -1``) or right (``+1``) branch with no reading lost between them -- its ``x(t)``
    is one more reading of that branch at ``u_a`` (the play operator holds the value the
    branch left), and with ``holds`` it enters as such (``d_a = 0``: no anchor). Output-error
    fits use those readings too; without them the recursive identifier's default estimate
    on the paper's Example 1 was 12 % less accurate (parameter RMSE 0.0049 against 0.0043)
    and tracked a drifting gap 2x later.

    Cascade rows are ``[u(t-2), u(t-1), x(t-2), .., x(t-m), y(t-1), .., y(t-nb), y(t)]``
    with ``m = max(na, 2)`` and ``x`` the internal output of eq. (36).

    Returns
    -------
    phi, target : ndarray
        Regressors (eq. 22 / 32) and targets of the rows used.
    used : ndarray of bool
        Which rows were used.
    left, right : ndarray of bool
        Per used row: the left (f1) or right (f2) branch is engaged.

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> truth = paper_example(1).model
    >>> x_r = float(truth.right([1.5])[0])
    >>> rows = np.array([[0.0, 1.5, 0.0, x_r, 0.0, 0.0],  # engages R
    ...                  [0.0, 0.1, 0.0, 0.0, 0.0, 0.0],  # inside the gap, no anchor
    ...                  [1.5, 1.4, x_r, x_r, 1.5, 1.0]])  # holds what R left at u = 1.5
    >>> phi, target, used, left, right = memory_regression(Structure(3), truth.parameters(),
    ...                                                    rows)
    >>> used.tolist(), right.tolist(), bool(np.allclose(phi @ truth.theta(), target))
    ([True, False, True], [True, True], True)
    >>> memory_regression(Structure(3), truth.parameters(), rows, holds=False)[2].tolist()
    [True, False, False]
    """
    if structure.cascade:
        na, nb = structure.na, structure.nb
        m = max(na, 2)
        u1, x2 = rows[:, 1], rows[:, 2]
        f1, f2 = switching_functions(
            structure, p, u1, x2
        )  # f(t-1), eqs. (27)-(28), internal x(t-2)
        phi = np.empty((rows.shape[0], structure.n_parameters), order="F")
        n_bl = structure.n_backlash
        phi[:, :n_bl] = backlash_columns(structure, p, u1, f1, f2)  # eq. (32)
        phi[:, n_bl : n_bl + na - 1] = rows[:, 2 : 1 + na]  # x(t-2) .. x(t-r), eq. (32)
        phi[:, n_bl + na - 1 :] = -rows[:, 1 + m : 1 + m + nb]  # -y(t-1) .. -y(t-p)
        target = rows[:, -1] - x2 * (1.0 - f1) * (1.0 - f2)  # eq. (35)
        used = np.ones(rows.shape[0], dtype=bool)
        return phi, target, used, f1 > 0.0, f2 > 0.0
    u, x_prev = rows[:, 1], rows[:, 2]
    f1, f2 = switching_functions(structure, p, u, x_prev)  # eqs. (27)-(28), measured x(t-1)
    used = (f1 + f2) > 0.0  # eq. (29): other rows carry no information of their own
    if holds:
        held = ~used & (rows[:, 5] != 0.0)  # a hold with its anchor: x(t) = branch(u_a)
        if held.any():
            u = np.where(held, rows[:, 4], u)
            f1 = np.where(held, (rows[:, 5] < 0.0).astype(np.float64), f1)
            f2 = np.where(held, (rows[:, 5] > 0.0).astype(np.float64), f2)
            used = used | held
    f1, f2 = f1[used], f2[used]
    phi = backlash_columns(structure, p, u[used], f1, f2)  # eq. (22)
    return phi, rows[used, 3], used, f1 > 0.0, f2 > 0.0  # target x(t), eq. (24)
