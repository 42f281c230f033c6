"""The recursive identifier's batch-fit attempts (genbacklash_core.online.attempts)."""

from __future__ import annotations

import numpy as np

from genbacklash_core import Structure
from genbacklash_core.online.attempts import AttemptSchedule, min_rows
from genbacklash_core.online.memory import BinnedRows
from genbacklash_core.online.rows import row_width
from genbacklash_core.online.settings import RecursiveSettings


def test_a_backlash_attempt_waits_for_enough_fresh_rows_then_a_quarter_more() -> None:
    structure = Structure(1)
    schedule = AttemptSchedule(RecursiveSettings(), structure)
    memory = BinnedRows(row_width(structure), 4, 100, 2)
    rows = np.zeros((min_rows(structure), row_width(structure)))
    rows[:, 1] = np.linspace(0.1, 1.0, rows.shape[0])  # moves up: the right branch
    schedule.file(memory, rows[:5], np.arange(5))
    assert not schedule.rows_due(len(memory))
    schedule.file(memory, rows[5:], np.arange(5, rows.shape[0]))
    assert schedule.rows_due(len(memory))
    assert schedule.attempted(samples=500, cascade=False) == 0
    schedule.used(80)
    assert schedule.next_attempt == 500 + RecursiveSettings().block
    assert (schedule.fresh, schedule.need) == (0, 20)


def test_the_cascade_attempts_at_doubling_intervals_up_to_the_buffer() -> None:
    settings = RecursiveSettings(initial_samples=400, buffer=1000)
    schedule = AttemptSchedule(settings, Structure(3, 2, 2))
    gaps = []
    for _ in range(5):
        before = 10_000
        schedule.attempted(before, cascade=True)
        gaps.append(schedule.next_attempt - before)
    assert gaps == [200, 400, 800, 1000, 1000]
    schedule.restart(20_000)
    assert schedule.next_attempt == 20_100 and schedule.attempts == 0
