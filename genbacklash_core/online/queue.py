"""The recursive identifier's queue: samples wait for the schedule's next event.

:meth:`~genbacklash_core.online.recursive.RecursiveIdentifier.update` and
:meth:`~genbacklash_core.online.recursive.RecursiveIdentifier.update_many` queue the samples
and process them at the same fixed sample counts (the end of a block, a batch fit's attempt),
so that they agree to rounding whatever the chunking. :class:`SampleQueue` cuts each series
into stretches that end at most at the next event (:meth:`SampleQueue.take`) and hands the
queued samples over in one piece at the event (:meth:`SampleQueue.flush`), which it counts:
the estimate's excitation and ages change there only.

Examples
--------
>>> import numpy as np
>>> queue = SampleQueue()
>>> u = np.arange(5.0)
>>> [n for n in queue.take(u, u, np.zeros(5, dtype=bool), lambda: 2)]
[2, 2, 1]
>>> queue.queued, queue.moved()
(5, True)
>>> uu, yy, bb, first = queue.flush(samples=5)
>>> uu.tolist(), first, queue.queued, queue.events
([0.0, 1.0, 2.0, 3.0, 4.0], 0, 0, 1)
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray

__all__ = ["SampleQueue"]


class SampleQueue:
    """Samples not seen yet, and the events that flushed them (see the module notes)."""

    def __init__(self) -> None:
        self._parts: list[tuple[FloatArray, FloatArray, BoolArray]] = []
        self.queued = 0  # samples waiting
        self.events = 0  # flushes (the estimate's excitation and ages change there)

    def take(
        self, u: FloatArray, y: FloatArray, b: BoolArray, room: Callable[[], int]
    ) -> Iterator[int]:
        """Queue validated samples in stretches of at most ``room()`` (read before each, at
        least one), yielding each stretch's length."""
        start = 0
        while start < u.size:
            take = min(u.size - start, max(room(), 1))
            part = slice(start, start + take)
            self._parts.append((u[part], y[part], b[part]))
            self.queued += take
            start += take
            yield take

    def flush(self, samples: int) -> tuple[FloatArray, FloatArray, BoolArray, int] | None:
        """The queued samples in one piece and the index of the first (``samples``: taken
        so far, the queued ones included); None when none wait."""
        if not self.queued:
            return None
        if len(self._parts) == 1:
            u, y, b = self._parts[0]
        else:
            u = np.concatenate([q[0] for q in self._parts])
            y = np.concatenate([q[1] for q in self._parts])
            b = np.concatenate([q[2] for q in self._parts])
        first = samples - self.queued
        self._parts = []
        self.queued = 0
        self.events += 1
        return u, y, b, first

    def moved(self) -> bool:
        """Whether the input moves within the queued samples."""
        return any(np.ptp(u) > 0.0 for u, _, _ in self._parts if u.size)
