"""How old the recursive identifier's information is: the sample of each block's newest row.

The recursive identifier forgets per branch, so the age of its information is that of the
branch whose newest row is oldest (:meth:`RowAges.age`), and an estimate is held
(``no_excitation``) once no informative row of any block came for ``idle_samples`` samples
(:meth:`RowAges.idle`). A start, a restart or a seed counts as fresh information for every
block. (The windowed identifier counts its feed's samples since the latest informative one,
:attr:`~genbacklash_core.online.feeds.Feed.idle`.)

Examples
--------
>>> import numpy as np
>>> ages = RowAges(cascade=False)
>>> ages.note(np.array([5, 9]), np.array([True, False]), np.array([False, True]))
>>> ages.idle(20), ages.age(20)
(11, 15)
"""

from __future__ import annotations

from genbacklash_core._typing import BoolArray, IntArray

__all__ = ["RowAges"]


class RowAges:
    """The sample count at the newest row of the left and right branch (and the linear
    block, for a cascade)."""

    def __init__(self, cascade: bool) -> None:
        self._cascade = cascade
        self._last = [0] * (3 if cascade else 2)

    def restart(self, samples: int) -> None:
        """Every block's information is new at ``samples``."""
        self._last = [samples] * len(self._last)

    def note(self, newest: IntArray, left: BoolArray, right: BoolArray) -> None:
        """Informative rows that end at the samples ``newest`` (``left``, ``right``: of which
        branch); every one informs the cascade's linear block."""
        if newest.size:
            if left.any():
                self._last[0] = int(newest[left][-1])
            if right.any():
                self._last[1] = int(newest[right][-1])
            if self._cascade:
                self._last[2] = int(newest[-1])

    def idle(self, samples: int) -> int:
        """Samples since the newest informative row."""
        return samples - max(self._last)

    def age(self, samples: int) -> int:
        """Samples since the newest row of the block whose newest row is oldest."""
        return samples - min(self._last)
