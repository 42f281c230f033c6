"""Excitation advice: what the data have not shown yet, and what motion would show it.

Both identifiers file their rows by branch (the direction of the move: down, the left branch,
eq. 18; up, the right branch, eq. 19) and input region, so both can say where a branch has no
rows yet (:class:`BranchCoverage`, :func:`coverage_of`) and what to do about it
(:func:`excitation_advice`). While an identifier warms up it appends that advice to the
reason of its estimate; :class:`AdviceCache` computes it again only when what it depends on
changed (it scans the memory). A backlash alone only: the cascade's rows are not filed by
branch.

Examples
--------
>>> cover = coverage_of(np.array([0.0, 0.2]), np.array([0.2, 0.4]), 2, 10)
>>> cache = AdviceCache()
>>> cache.reason("warming up", 1, lambda: excitation_advice(cover, moved=True))
'warming up: the left branch is not covered yet: move the joint down'
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable

import numpy as np

from genbacklash_core._typing import FloatArray, IntArray

__all__ = ["AdviceCache", "BranchCoverage", "coverage_of", "excitation_advice"]


class BranchCoverage:
    """How much of the input range each branch's rows cover (a snapshot).

    Attributes
    ----------
    edges : ndarray, shape (bins + 1,)
        Bin edges over the input range seen.
    up, down : ndarray of int, shape (bins,)
        Rows per bin for moves up (right branch) and down (left branch).
    per_bin : int
        The level the fullest bins are cut to (the capacity while the memory is not full).
    """

    def __init__(self, edges: FloatArray, up: IntArray, down: IntArray, per_bin: int) -> None:
        self.edges = edges
        self.up = up
        self.down = down
        self.per_bin = per_bin

    def empty_regions(self, branch: str) -> list[tuple[float, float]]:
        """Input intervals where ``branch`` ("left" or "right") has no rows, merged."""
        counts = self.down if branch == "left" else self.up
        out: list[tuple[float, float]] = []
        for k in np.flatnonzero(counts == 0):
            lo, hi = float(self.edges[k]), float(self.edges[k + 1])
            if out and math.isclose(out[-1][1], lo):
                out[-1] = (out[-1][0], hi)
            else:
                out.append((lo, hi))
        return out

    def share(self, branch: str) -> float:
        """Share of the bins that hold at least one row of ``branch``."""
        counts = self.down if branch == "left" else self.up
        return float(np.count_nonzero(counts) / counts.size) if counts.size else 0.0


def coverage_of(u0: FloatArray, u1: FloatArray, bins: int, per_bin: int) -> BranchCoverage:
    """The coverage of rows whose inputs moved ``u0 -> u1``: rows per direction (up: right
    branch; down: left) in ``bins`` equal regions of the range of ``u1``.

    >>> cover = coverage_of(np.array([0.0, 1.0, 0.5]), np.array([1.0, 0.5, 0.6]), 2, 10)
    >>> cover.up.tolist(), cover.down.tolist()
    ([1, 1], [1, 0])
    """
    if u1.size == 0:
        zeros = np.zeros(bins, dtype=np.intp)
        return BranchCoverage(np.zeros(bins + 1), zeros, zeros.copy(), per_bin)
    lo, hi = float(u1.min()), float(u1.max())
    span = hi - lo
    if span > 0.0:
        region = np.floor((u1 - lo) / span * bins).astype(np.intp)
        np.clip(region, 0, bins - 1, out=region)
    else:
        region = np.zeros(u1.size, dtype=np.intp)
    up = u1 > u0
    return BranchCoverage(
        np.linspace(lo, hi, bins + 1),
        np.asarray(np.bincount(region[up], minlength=bins), dtype=np.intp),
        np.asarray(np.bincount(region[~up], minlength=bins), dtype=np.intp),
        per_bin,
    )


def excitation_advice(cover: BranchCoverage, *, moved: bool, rows_needed: int = 0) -> str:
    """What the rows have not shown yet, and what motion would show it ("" when the rows
    cover both branches over the input range seen and no more are needed).

    Parameters
    ----------
    cover : BranchCoverage
        The rows' coverage.
    moved : bool
        Whether any sample so far moved the input (False: the input is constant, or every
        sample was lost).
    rows_needed : int
        Moves still needed before the first fit (0: none, or an estimate exists).

    Examples
    --------
    >>> cover = coverage_of(np.array([0.0, 0.2]), np.array([0.2, 0.4]), 2, 10)
    >>> excitation_advice(cover, moved=True)
    'the left branch is not covered yet: move the joint down'
    """
    if not moved:
        return (
            "the input is constant (or every sample was lost): move the joint back and "
            "forth over its working range"
        )
    missing = []
    for branch, move in (("left", "down"), ("right", "up")):
        if cover.share(branch) == 0.0:
            missing.append(f"the {branch} branch is not covered yet: move the joint {move}")
        else:
            holes = cover.empty_regions(branch)
            if holes and cover.share(branch) < 0.75:
                where = ", ".join(f"[{lo:.3g}, {hi:.3g}]" for lo, hi in holes[:3])
                missing.append(f"the {branch} branch has no data over {where}: move {move} there")
    if not missing and rows_needed > 0:
        missing.append(
            f"{rows_needed} more moves between readings needed before the first fit (moves "
            "that reverse direction across the gap teach the most)"
        )
    return "; ".join(missing)


class AdviceCache:
    """The advice appended to a warming identifier's reason, made again only when its ``key``
    (what the advice depends on: rows remembered, samples seen...) changed."""

    def __init__(self) -> None:
        self._key: Hashable | None = None
        self.text = ""

    def reason(self, reason: str, key: Hashable, advise: Callable[[], str]) -> str:
        """``reason`` with the advice appended (``"reason: advice"``; ``reason`` alone when
        there is nothing to advise), ``advise()`` called only for a new ``key``."""
        if key != self._key:
            self._key, self.text = key, advise()
        return f"{reason}: {self.text}" if self.text else reason
