"""When the recursive identifier tries a batch fit: its start, and a restart after divergence.

Until its first estimate (and while the one-step errors are blown up, or after a stop) the
recursive identifier tries batch fits (:mod:`~genbacklash_core.online.restart`):

* a backlash on its rows, once they number at least :func:`min_rows` and grew by a quarter
  since the last attempt (the first waits for :func:`min_rows` fresh rows);
* the cascade on its recent samples, first after ``initial_samples`` samples, then at
  doubling intervals of ``initial_samples / 4`` (at most ``buffer``).

:class:`AttemptSchedule` keeps that count. (The windowed identifier's fits have their own,
:class:`~genbacklash_core.online.schedule.FitSchedule`.)

Examples
--------
>>> from genbacklash_core.online.settings import RecursiveSettings
>>> from genbacklash_core.structure import Structure
>>> schedule = AttemptSchedule(RecursiveSettings(), Structure(3))
>>> schedule.next_attempt, schedule.need, schedule.interval()
(300, 24, 75)
>>> schedule.rows_due(rows=30), schedule.fresh
(False, 0)
"""

from __future__ import annotations

from genbacklash_core._typing import FloatArray, IntArray
from genbacklash_core.structure import Structure

from .memory import BinnedRows
from .settings import RecursiveSettings

__all__ = ["AttemptSchedule", "min_rows"]


def min_rows(structure: Structure) -> int:
    """Rows a batch fit on the memory needs at least.

    >>> min_rows(Structure(3))
    24
    """
    return max(3 * structure.n_parameters, 20)


class AttemptSchedule:
    """The next batch-fit attempt (see the module notes).

    Parameters
    ----------
    settings : RecursiveSettings
    template : Structure
        The structure the identifier starts from (its rows needed).
    """

    def __init__(self, settings: RecursiveSettings, template: Structure) -> None:
        self._settings = settings
        self.min_rows = min_rows(template)
        self.next_attempt = settings.initial_samples
        self.attempts = 0  # attempts since the last start
        self.fresh = 0  # rows filed since the last batch-fit attempt (backlash)
        self.need = self.min_rows  # fresh rows the next attempt waits for

    def file(self, memory: BinnedRows, rows: FloatArray, stamps: IntArray) -> None:
        """File rows into a memory, counting them for the schedule."""
        if rows.shape[0]:
            memory.insert(rows, stamps)
            self.fresh += rows.shape[0]

    def rows_due(self, rows: int) -> bool:
        """A backlash's attempt is due on a memory of ``rows`` rows."""
        return rows >= self.min_rows and self.fresh >= self.need

    def interval(self) -> int:
        """Samples to the next batch-fit attempt of the cascade (doubling, at most buffer)."""
        s = self._settings
        interval: int = max(s.initial_samples // 4, 1) * 2 ** min(self.attempts, 6)
        return min(interval, s.buffer)

    def restart(self, samples: int) -> None:
        """Start counting again (the errors blew up): the next attempt after the interval
        (the cascade), after :attr:`min_rows` fresh rows (a backlash)."""
        self.attempts = 0
        self.next_attempt = samples + self.interval()
        self.fresh = 0
        self.need = self.min_rows

    def attempted(self, samples: int, cascade: bool) -> int:
        """Count an attempt at ``samples``, schedule the next; the attempt's number since the
        last start (0: the first)."""
        attempt = self.attempts
        self.attempts += 1
        self.next_attempt = samples + (self.interval() if cascade else self._settings.block)
        return attempt

    def used(self, rows: int) -> None:
        """A backlash's attempt used ``rows`` rows: the next waits for a quarter more."""
        self.fresh = 0
        self.need = max(rows // 4, 1)
