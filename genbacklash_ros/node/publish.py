"""The publish stage's clock: which periodic outputs are due at a time of the data.

Every decision is taken on the data's own time (the latest accepted message time, the *data
clock*), so a replay of a bag is deterministic. :class:`Schedule` keeps when the next
estimate (every ``1 / publish_rate``), diagnostics report (every second), checkpoint (every
``checkpoint_period``, when a file is set) and identifier feed (``batch_ns`` after the last)
are due, on multiples of their periods.

Examples
--------
>>> clock = Schedule(publish_ns=100, checkpoint_ns=None, feed_ns=30, diagnostics_ns=1000)
>>> clock.tick(5)  # the first message starts the clock
False
>>> clock.tick(50), clock.due(50)
(True, Due(feed=True, estimate=False, checkpoint=False, diagnostics=False))
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["DIAGNOSTICS_PERIOD_NS", "Due", "Schedule", "next_multiple"]

DIAGNOSTICS_PERIOD_NS = 1_000_000_000  # /diagnostics at 1 Hz of data time


def next_multiple(now: int, period: int) -> int:
    """The first multiple of ``period`` after ``now``.

    >>> next_multiple(10, 5), next_multiple(11, 5)
    (15, 15)
    """
    return (now // period + 1) * period


class Due(NamedTuple):
    """Which periodic steps are due now."""

    feed: bool
    estimate: bool
    checkpoint: bool
    diagnostics: bool


class Schedule:
    """The data clock and the periodic schedule (see the module notes).

    Parameters
    ----------
    publish_ns : int
        Estimate period.
    checkpoint_ns : int or None
        Checkpoint period (None: no checkpoints).
    feed_ns : int
        Data time between identifier feeds at most.
    diagnostics_ns : int
        Diagnostics period.
    """

    def __init__(
        self,
        *,
        publish_ns: int,
        checkpoint_ns: int | None,
        feed_ns: int,
        diagnostics_ns: int = DIAGNOSTICS_PERIOD_NS,
    ) -> None:
        self._publish_ns = publish_ns
        self._checkpoint_ns = checkpoint_ns
        self._feed_ns = feed_ns
        self._diagnostics_ns = diagnostics_ns
        self.now: int | None = None
        self._next_estimate = 0
        self._next_diagnostics = 0
        self._next_checkpoint = 0
        self._next_feed = 0
        self._next_due = 0

    def configure(self, *, publish_ns: int, checkpoint_ns: int | None) -> None:
        """New periods: the schedule restarts from the data clock."""
        self._publish_ns = publish_ns
        self._checkpoint_ns = checkpoint_ns
        if self.now is not None:
            self._start(self.now)

    def restart(self) -> None:
        """The next accepted message restarts the clock (a re-anchor)."""
        self.now = None

    def _start(self, now: int) -> None:
        self._next_estimate = next_multiple(now, self._publish_ns)
        self._next_diagnostics = next_multiple(now, self._diagnostics_ns)
        if self._checkpoint_ns is not None:
            self._next_checkpoint = next_multiple(now, self._checkpoint_ns)
        self._next_feed = now + self._feed_ns
        self.settle()

    def settle(self) -> None:
        """Recompute when the next step is due (after handling those due)."""
        due = min(self._next_estimate, self._next_diagnostics, self._next_feed)
        if self._checkpoint_ns is not None:
            due = min(due, self._next_checkpoint)
        self._next_due = due

    def tick(self, stamp: int) -> bool:
        """Move the data clock to ``stamp`` (it never goes back); True when a periodic step
        is due (then ask :meth:`due`)."""
        now = self.now
        if now is None:
            self.now = stamp
            self._start(stamp)
            return False
        if stamp > now:
            self.now = now = stamp
        return now >= self._next_due

    @property
    def next_due(self) -> int | None:
        """The data time at which the next periodic step is due (None before the clock
        starts): a batch of messages all before it makes no step due (:meth:`tick` is then
        False for each)."""
        return None if self.now is None else self._next_due

    def copy(self) -> Schedule:
        """An independent copy (to look ahead at what would come due, leaving this one)."""
        twin = Schedule.__new__(Schedule)
        twin.__dict__.update(self.__dict__)
        return twin

    def due(self, now: int) -> Due:
        """What is due at ``now``."""
        return Due(
            now >= self._next_feed,
            now >= self._next_estimate,
            self._checkpoint_ns is not None and now >= self._next_checkpoint,
            now >= self._next_diagnostics,
        )

    def fed(self) -> None:
        """The identifier was fed now: the next feed is due ``feed_ns`` later."""
        if self.now is not None:
            self._next_feed = self.now + self._feed_ns
            self.settle()

    def estimate_done(self, now: int) -> None:
        """The estimate due at ``now`` was handled."""
        self._next_estimate = next_multiple(now, self._publish_ns)

    def checkpoint_done(self, now: int) -> None:
        """The checkpoint due at ``now`` was handled."""
        if self._checkpoint_ns is not None:
            self._next_checkpoint = next_multiple(now, self._checkpoint_ns)

    def diagnostics_done(self, now: int) -> None:
        """The report due at ``now`` was handled."""
        self._next_diagnostics = next_multiple(now, self._diagnostics_ns)
