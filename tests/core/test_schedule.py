"""When the windowed identifier fits (genbacklash_core.online.schedule)."""

from __future__ import annotations

from genbacklash_core.online.schedule import FitSchedule
from genbacklash_core.online.settings import WindowedSettings


def test_the_interval_grows_with_the_window_and_backs_off_while_cold_starts_fail() -> None:
    s = WindowedSettings(window=1600, refit_every=25, refit_fraction=0.15)
    schedule = FitSchedule(first=48)
    assert not schedule.due(47) and schedule.due(48)
    schedule.plan(s, length=100, progress=48, samples=48, cold_failures=0)
    assert schedule.next_fit == 48 + 25  # refit_every
    schedule.plan(s, length=1000, progress=500, samples=600, cold_failures=0)
    assert schedule.next_fit == 500 + 150  # refit_fraction of the window's length
    backoff = []
    for failures in (1, 2, 3, 10):
        schedule.plan(s, length=1000, progress=500, samples=600, cold_failures=failures)
        backoff.append(schedule.next_fit - 500)
    assert backoff == [50, 100, 200, 200]  # at most window / 8 apart


def test_recent_progress_and_an_early_fit() -> None:
    schedule = FitSchedule(first=40)
    schedule.plan(WindowedSettings(), length=200, progress=200, samples=300, cold_failures=0)
    assert schedule.recent(210, length=200, early=False) == 10
    # refit(): judged on as much as the scheduled fit would have seen
    assert schedule.recent(210, length=200, early=True) == 30
    assert schedule.new_samples(330) == 30
    schedule.restart(samples=1000, progress=0, first=40)
    assert (schedule.next_fit, schedule.fit_samples, schedule.fit_progress) == (40, 1000, 0)
