"""The recursive identifier's batch start: a batch fit, then its iteration until settled.

Until its first estimate, and again after a divergence, the recursive identifier starts from
a batch fit (:func:`~genbacklash_core.online.fits.cold_fit`, the paper's iteration from its
start, eqs. 22-29 and 31-37):

* a backlash fits the rows of a memory (:func:`backlash_start`), read as pairs of samples
  (:func:`~genbacklash_core.online.memory.pair_series`), and keeps that memory: its own, or
  while the errors are blown up the rows held back since;
* the cascade fits a window of its recent samples (:func:`cascade_start`); its memory is made
  again from the window's rows at the fit
  (:func:`~genbacklash_core.online.stream.window_cascade_rows`): the internal ``x`` of
  eq. (36) needs an estimate.

From the fit, the iteration over the memory runs until the estimate settles
(:func:`~genbacklash_core.online.iteration.settle_memory`). A restart must also fit
(:func:`rejected`): its residual may not exceed ``divergence_ratio`` times the running one
before the divergence (data holding the fault would not), until :data:`MAX_REJECTIONS`
attempts were rejected (the noise may really have grown).

Examples
--------
>>> rejected(4.0, before=0.1, ratio=5.0, attempt=0)  # residual 2 against 0.316 before
'batch fit rejected: residual 2 against 0.316 before the divergence (the data may hold the fault)'
>>> rejected(4.0, before=0.1, ratio=5.0, attempt=MAX_REJECTIONS) is None  # taken at last
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.structure import Structure

from .fits import cold_fit
from .iteration import MemorySolution, settle_memory
from .memory import BinnedRows, pair_series
from .rows import CascadeLags
from .settings import RecursiveSettings
from .stream import window_cascade_rows

__all__ = ["MAX_REJECTIONS", "BatchStart", "backlash_start", "cascade_start", "rejected"]

MAX_REJECTIONS = 8  # restarts that may be rejected for a poor fit before any fit is taken


@dataclass(frozen=True)
class BatchStart:
    """A batch start that settled.

    Attributes
    ----------
    structure : Structure
        The structure fitted (the branch sense detected when it was not known).
    memory : BinnedRows
        The memory the estimate rests on.
    lags : CascadeLags or None
        The cascade's lags after its window (None for a backlash).
    solution : MemorySolution
        The settled iterate.
    pull : ndarray
        ``R_0``, the pull towards the current estimate of later iterations.
    """

    structure: Structure
    memory: BinnedRows
    lags: CascadeLags | None
    solution: MemorySolution
    pull: FloatArray


def backlash_start(
    structure: Structure,
    sign_known: bool,
    source: BinnedRows,
    settings: RecursiveSettings,
    input_range: tuple[float, float],
) -> BatchStart | str:
    """A batch start on the rows of ``source`` (kept as the memory); or why it failed.
    ``input_range``: the input range seen (the iterates must be valid models on it)."""
    rows, _ = source.rows()
    pairs = pair_series(rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3])
    found = cold_fit(structure, sign_known, *pairs)
    if isinstance(found, str):
        return found
    return _settled(*found, source, None, settings.covariance_bound, input_range)


def cascade_start(
    structure: Structure,
    sign_known: bool,
    window: tuple[FloatArray, FloatArray, BoolArray],
    first: int,
    memory: BinnedRows,
    settings: RecursiveSettings,
    input_range: tuple[float, float],
) -> BatchStart | str:
    """A batch start on a ``window`` of samples ``(u, y, breaks)`` whose first is sample
    ``first``, its rows filed into the empty ``memory``; or why it failed."""
    u, y, b = window
    found = cold_fit(structure, sign_known, u, y, b)
    if isinstance(found, str):
        return found
    structure, p = found
    rows, at, lags = window_cascade_rows(structure, p, u, y, b, settings.input_deadband)
    memory.insert(rows, np.asarray(first + at, dtype=np.intp))
    return _settled(structure, p, memory, lags, settings.covariance_bound, input_range)


def _settled(
    structure: Structure,
    p: FloatArray,
    memory: BinnedRows,
    lags: CascadeLags | None,
    covariance_bound: float,
    input_range: tuple[float, float],
) -> BatchStart | str:
    started = settle_memory(structure, p, memory.rows()[0], covariance_bound, input_range)
    if isinstance(started, str):
        return started
    solution, pull = started
    return BatchStart(structure, memory, lags, solution, pull)


def rejected(sigma2: float, before: float, ratio: float, attempt: int) -> str | None:
    """Why a restart whose residual variance is ``sigma2`` is rejected against the running
    one ``before`` the divergence (NaN: not a restart), or None when it is taken;
    ``ratio``: ``divergence_ratio``; ``attempt``: attempts rejected so far."""
    limit = ratio * ratio * before  # (** may overflow)
    if attempt < MAX_REJECTIONS and math.isfinite(before) and sigma2 > limit:
        return (
            f"batch fit rejected: residual {math.sqrt(sigma2):.3g} against "
            f"{math.sqrt(before):.3g} before the divergence (the data may hold the fault)"
        )
    return None
