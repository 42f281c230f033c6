"""The recursive identifier's divergence test: running scales of its one-step errors.

Each new row is judged before it joins the memory: its a priori one-step error at the
current estimate (eqs. 29/37), normalised by its predicted spread ``1 + phi P phi^T``. A
short running mean of those errors against a long one (its scale) tells a sensor fault or a
sudden change from noise: when the short mean exceeds ``divergence_ratio^2`` times the scale
(:meth:`ErrorScale.blown`), the identifier holds its estimate and keeps the new rows out of
its memory. The scale takes each error clipped to that same limit, so a burst cannot raise
the bar it is judged against, and it holds while the errors are blown up. A third mean, of
the raw squared errors, is the residual the estimate reports.

(The windowed identifier needs no such test: each fit sees its whole window again, and rows
far off an accepted fit are forgotten instead, see
:meth:`~genbacklash_core.online.feeds.RowFeed.purge`.)

Examples
--------
>>> scale = ErrorScale()
>>> scale.restart(1.0)
>>> scale.track(np.ones(50), np.ones(50), ratio=3.0, running=True)
>>> scale.blown(3.0)
False
>>> scale.track(np.full(50, 100.0), np.full(50, 100.0), ratio=3.0, running=False)
>>> scale.blown(3.0), scale.long
(True, 1.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.structure import Structure

from .iteration import ewma
from .rows import memory_regression

__all__ = ["ErrorScale"]

_SHORT_MEMORY = 20.0  # informative rows in the short error average (divergence test)
_LONG_MEMORY = 1000.0  # informative rows in the long error average (its scale)


@dataclass
class ErrorScale:
    """Running means of the squared one-step errors (NaN until :meth:`restart`)."""

    recent: float = math.nan  # raw squared errors, short memory: the reported residual
    short: float = math.nan  # normalised squared errors, short memory: the divergence test
    long: float = math.nan  # normalised squared errors, long memory: their scale
    count: int = 0  # errors taken into the scale since the last restart

    def restart(self, sigma2: float) -> None:
        """Start all three means from the variance ``sigma2`` of a new fit."""
        self.short = self.long = self.recent = sigma2
        self.count = 0

    def track(self, raw: FloatArray, squared: FloatArray, *, ratio: float, running: bool) -> None:
        """Take new errors: ``raw`` squared for the reported residual; ``squared``
        (normalised by their predicted spread) short, for the divergence test, and, while
        ``running`` (not held), long, clipped to ``ratio^2`` times the scale."""
        if squared.size == 0:
            return
        self.recent = ewma(raw, 1.0 / _SHORT_MEMORY, self.recent)
        self.short = ewma(squared, 1.0 / _SHORT_MEMORY, self.short)
        if running:
            limit = ratio * ratio * self.long  # (not **: an OverflowError for a huge ratio)
            self.long = ewma(np.minimum(squared, limit), 1.0 / _LONG_MEMORY, self.long)
            self.count += squared.size

    def judge(
        self,
        structure: Structure,
        theta: FloatArray,
        unit_cov: FloatArray,
        rows: FloatArray,
        *,
        ratio: float,
        running: bool,
    ) -> tuple[BoolArray, BoolArray, BoolArray]:
        """Take the a priori one-step errors of new memory ``rows`` at ``theta`` (eqs.
        29/37), normalised by their spread ``1 + phi P phi^T`` (``P``: ``unit_cov``), as in
        :meth:`track`. Returns which rows carry information of their own, and which of those
        are of the left and of the right branch
        (:func:`~genbacklash_core.online.rows.memory_regression`)."""
        p = structure.from_theta(theta)
        # the rows' own information (holds re-read an anchor: no excitation, no new age)
        phi, target, used, left, right = memory_regression(structure, p, rows, holds=False)
        errors = target - phi @ theta  # a priori one-step errors, eqs. (29)/(37)
        # their variance is sigma^2 (1 + phi P phi^T): a row where the memory knows little
        # (a region not seen yet) may miss by more without anything being wrong
        spread = 1.0 + np.einsum("ij,jk,ik->i", phi, unit_cov, phi)
        self.track(errors * errors, errors * errors / spread, ratio=ratio, running=running)
        return used, left, right

    def blown(self, ratio: float) -> bool:
        """The short-term error exceeds ``ratio`` times its scale (in RMS), once the scale
        has taken enough errors."""
        ratio2 = ratio * ratio
        return self.count > 2 * _SHORT_MEMORY and self.short > ratio2 * self.long
