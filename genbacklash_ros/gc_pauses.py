"""Fewer and shorter garbage-collector pauses while the node or a replay runs (process-wide,
undone when the last user ends).

Both allocate a few tuples, lists and messages per message and keep almost none, so
Python's collector (a young collection every 700 allocations, and a full one, which scans
every object the process holds, whenever the survivors have grown by a quarter) spends its
time scanning what lives anyway: the imported modules (numpy, rclpy, the message types),
the node and its history. A full collection of that heap took 45 ms in the six-joint rclpy
node, in the middle of a 1 kHz feed: 45 commands waited for it (BENCHMARKS.md "Six joints
through one node").

:func:`few_collections` freezes what exists when it is entered (:func:`gc.freeze`: the
collector no longer scans it, so a full collection scans only what came after) and collects
the young generation every :data:`YOUNG` allocations instead of 700. Cycles are still
collected. Enter it once the long-lived objects exist (the node built, the bag opened).
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["YOUNG", "few_collections"]

YOUNG = 50_000
"""Allocations between young-generation collections while a user is inside."""

_lock = threading.Lock()
_users: list[tuple[int, int, int]] = []  # the thresholds to restore, one per user inside


@contextmanager
def few_collections() -> Iterator[None]:
    """Run the body with what exists frozen out of the collections and the young generation
    collected every :data:`YOUNG` allocations; both undone when the last user leaves (fleet
    threads run several replays at once), whatever the order, and after an exception.

    Examples
    --------
    >>> import gc
    >>> before = gc.get_threshold()
    >>> with few_collections():
    ...     gc.get_threshold()[0], gc.get_freeze_count() > 0
    (50000, True)
    >>> gc.get_threshold() == before
    True
    """
    with _lock:
        if not _users:
            gc.freeze()
        _users.append(gc.get_threshold())
        gc.set_threshold(YOUNG, *_users[0][1:])
    try:
        yield
    finally:
        with _lock:
            first = _users[0]
            _users.pop()
            if not _users:
                gc.set_threshold(*first)
                gc.unfreeze()
