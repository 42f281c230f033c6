"""The recursive identifier's regression rows as the samples come, and what they carry over.

:class:`~genbacklash_core.online.recursive.RecursiveIdentifier` processes its samples in
pieces (one per block); :class:`RowStream` turns each piece into memory rows
(:func:`~genbacklash_core.online.rows.memory_regression`) and carries from one piece to the
next what the rows of the next one need:

* **The sample rule.** A row pairs ``x(t)`` with ``x(t-1)`` (the cascade: with ``x(t-i)``,
  ``y(t-j)``) only when those samples are consecutive on the encoder's clock (``breaks``,
  :mod:`genbacklash_core.samples`): a lost reading never pairs two states that are not
  neighbours (that would read the missed motion as a branch engaged too early and bias
  both gaps small). The run of consecutive samples ending at the latest one is carried.
* **Only moves.** A backlash row ``[u(t-1), u(t), x(t-1), x(t)]`` is taken only where the
  input moved by more than ``input_deadband`` of the input span seen so far (the span is
  carried, and the latest sample).
* **Holds read their anchor.** A row inside the gap holds the state the last engaged
  branch left (eqs. 20-21); it carries nothing in eq. (29), but the hold just after an
  engaged row is one more reading of that branch at the engaged row's input, and is used as
  such (:func:`~genbacklash_core.online.rows.memory_regression`; the anchor is carried).
* **The cascade.** Rows of eq. (32), with the internal ``x`` of eq. (36) propagated with the
  current estimate (the lags are carried; :func:`~.rows.cascade_memory_rows`).
  A batch start files the rows of a window of samples (:func:`window_cascade_rows`).

Rows need an estimate to be classified (anchors) or formed (the cascade's ``x``): without
one (``theta`` None) a backlash takes its rows unanchored and a cascade takes none.

Examples
--------
>>> import numpy as np
>>> from genbacklash_core import Structure
>>> stream = RowStream(Structure(1), buffer=100)
>>> u = np.array([0.0, 0.1, 0.1, 0.2])
>>> rows, at = stream.take(Structure(1), None, u, 0.5 * u, np.zeros(4, dtype=bool), 1e-4, 0)
>>> at.tolist(), rows[:, :2].tolist()
([1, 3], [[0.0, 0.1], [0.1, 0.2]])
>>> stream.low, stream.high
(0.0, 0.2)
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.identify.regression import switching_functions
from genbacklash_core.samples import run_lengths
from genbacklash_core.structure import Structure

from .inputs import deadband
from .rows import CascadeLags, SampleRing, cascade_memory_rows, row_width, settling_samples
from .tracking import BAND_SAMPLES

__all__ = ["RowStream", "window_cascade_rows"]


class RowStream:
    """Memory rows of successive pieces of samples (see the module notes).

    Parameters
    ----------
    structure : Structure
        The structure the lags are kept for.
    buffer : int
        Recent samples kept (a batch start of the cascade fits them).
    """

    def __init__(self, structure: Structure, buffer: int) -> None:
        # the recent samples: the cascade's `buffer` and the bands' free run's
        # `BAND_SAMPLES` (online.tracking), one ring read at either length
        self.recent = SampleRing(max(buffer, BAND_SAMPLES))
        self.low, self.high = math.inf, -math.inf  # the input range seen
        self.run = 0  # consecutive samples ending at the latest one
        self.u1 = self.y1 = 0.0  # the latest sample (backlash)
        self.anchor = (0.0, 0.0)  # u_a, d_a of the latest engaged row (backlash)
        self.lags = CascadeLags.unknown(structure)  # cascade

    def take(
        self,
        structure: Structure,
        theta: FloatArray | None,
        u: FloatArray,
        y: FloatArray,
        b: BoolArray,
        fraction: float,
        settling: int,
    ) -> tuple[FloatArray, IntArray]:
        """The rows of a piece and the samples they were taken at, classified (anchors) or
        formed (the cascade) at ``theta`` (eqs. 23/33); ``fraction``: ``input_deadband``;
        ``settling``: the cascade's settling horizon."""
        self.recent.extend(u, y, b)
        low = np.minimum(np.minimum.accumulate(u), self.low)
        high = np.maximum(np.maximum.accumulate(u), self.high)
        self.low, self.high = float(low[-1]), float(high[-1])
        band = deadband(fraction, high - low)  # per sample: the span seen so far
        run_before = self.run
        run = run_lengths(b, run_before)
        self.run = int(min(run[-1], 1 << 40))
        if structure.cascade:
            if theta is None:  # the next batch fit takes the recent samples
                return np.empty((0, row_width(structure))), np.empty(0, dtype=np.intp)
            p = structure.from_theta(theta)
            rows, at, self.lags = cascade_memory_rows(
                structure, p, self.lags, u, y, run, run_before, band, settling
            )
            return rows, at
        return self._backlash(structure, theta, u, y, run, band)

    def _backlash(
        self,
        structure: Structure,
        theta: FloatArray | None,
        u: FloatArray,
        y: FloatArray,
        run: IntArray,
        band: FloatArray,
    ) -> tuple[FloatArray, IntArray]:
        """Rows ``[u(t-1), u(t), x(t-1), x(t), u_a, d_a]``: consecutive samples whose input
        moved, anchored at ``theta`` (unanchored without one)."""
        u_prev = np.concatenate([[self.u1], u[:-1]])
        y_prev = np.concatenate([[self.y1], y[:-1]])
        self.u1, self.y1 = float(u[-1]), float(y[-1])
        taken = (run >= 2) & (np.abs(u - u_prev) > band)  # the sample rule; it moved
        at = np.flatnonzero(taken)
        rows = np.zeros((at.size, 6))
        if at.size == 0:
            if np.any(run < 2):
                self.anchor = (0.0, 0.0)  # a lost reading: the state is not known
            return rows, at
        rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3] = u_prev[at], u[at], y_prev[at], y[at]
        if theta is not None:
            self._anchor_rows(structure, structure.from_theta(theta), rows, at, run)
        return rows, at

    def _anchor_rows(
        self, structure: Structure, p: FloatArray, rows: FloatArray, at: IntArray, run: IntArray
    ) -> None:
        """Fill the anchors (``u_a``, ``d_a``; :func:`memory_regression`) of new backlash
        rows taken at samples ``at`` of a piece, classified at ``p``.

        A hold's anchor is the row taken just before it when that row engaged a branch and
        no reading was lost between them (dwells between them do not matter: the state
        holds). Later holds of the same episode get none: one more reading per engagement
        keeps a narrow oscillation from flooding the memory with readings of one point, and
        was the most accurate choice on Example 1 (parameter RMSE 0.0044 over 1000 samples,
        against 0.0045 with every hold and 0.0048 without holds)."""
        f1, f2 = switching_functions(structure, p, rows[:, 1], rows[:, 2])  # eqs. (27)-(28)
        engaged = (f1 + f2) > 0.0
        direction = np.where(f1 > 0.0, -1.0, 1.0)
        lost = np.cumsum(run < 2)  # readings lost (chain breaks) up to each sample
        u_prev = np.concatenate([[self.anchor[0]], rows[:-1, 1]])
        d_prev = np.concatenate([[self.anchor[1]], np.where(engaged, direction, 0.0)[:-1]])
        lost_prev = np.concatenate([[0], lost[at[:-1]]])
        anchored = ~engaged & (d_prev != 0.0) & (lost[at] == lost_prev)
        rows[:, 4] = np.where(anchored, u_prev, 0.0)
        rows[:, 5] = np.where(anchored, d_prev, 0.0)
        # the next piece's first row may anchor on this piece's last one
        ends_engaged = bool(engaged[-1]) and lost[-1] == lost[at[-1]]
        self.anchor = (float(rows[-1, 1]), float(direction[-1])) if ends_engaged else (0.0, 0.0)


def window_cascade_rows(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    b: BoolArray,
    fraction: float,
) -> tuple[FloatArray, IntArray, CascadeLags]:
    """A window's cascade rows at ``p`` (from the first sample on which the internal ``x``
    of eq. 36 is determined), the samples they were taken at, and the lags after the
    window; ``fraction``: ``input_deadband`` of the window's input span."""
    band = deadband(fraction, float(np.ptp(u)))
    return cascade_memory_rows(
        structure,
        p,
        CascadeLags.unknown(structure),
        u,
        y,
        run_lengths(b, 0),
        0,
        np.full(u.size, band),
        settling_samples(structure, p),
    )
