"""When the windowed identifier fits: every ``K`` samples (or rows), ``K`` growing with the
window.

Once the feed holds ``min_samples`` (samples, or rows for a memory of rows), the windowed
identifier fits; after that, every ``K = max(refit_every, refit_fraction * len)`` steps of
the feed's progress (:attr:`~genbacklash_core.online.feeds.Feed.progress`), which bounds the
amortised cost per sample however large the window is. While cold starts fail, it backs
off (``refit_every * 2^failures``) but retries at least every ``window / 8`` steps, since a
slow reference excites the system slowly. :class:`FitSchedule` keeps the next fit's
progress and what the last fit saw, so that a fit can tell what is new since.

Examples
--------
>>> from genbacklash_core.online.settings import WindowedSettings
>>> schedule = FitSchedule(first=40)
>>> schedule.due(39), schedule.due(40)
(False, True)
>>> schedule.plan(WindowedSettings(), length=1000, progress=40, samples=60, cold_failures=0)
>>> schedule.next_fit, schedule.new_samples(100)
(190, 40)
"""

from __future__ import annotations

import math

from .settings import WindowedSettings

__all__ = ["FitSchedule"]


class FitSchedule:
    """The next fit's progress and the last fit's (see the module notes).

    Parameters
    ----------
    first : int
        The feed's progress at which the first fit is tried (``min_samples``).
    """

    def __init__(self, first: int) -> None:
        self.next_fit = first
        self.fit_samples = 0  # samples at the last fit
        self.fit_progress = 0  # the feed's progress at the last fit

    def due(self, progress: int) -> bool:
        """Whether the feed's ``progress`` reached the next fit."""
        return progress >= self.next_fit

    def restart(self, samples: int, progress: int, first: int) -> None:
        """Start over as after a fit at ``samples`` and ``progress`` (a seed): the next fit
        ``first`` steps later."""
        self.fit_samples = samples
        self.fit_progress = progress
        self.next_fit = progress + first

    def recent(self, progress: int, length: int, early: bool) -> int:
        """The feed's progress since the last fit. ``early`` (``refit``): at least as much as
        the scheduled fit would have seen (at most ``length``, the feed's), so that a record
        ending at rest does not freeze a converged estimate as ``no_excitation``."""
        recent = progress - self.fit_progress
        if early:
            span = self.next_fit - self.fit_progress
            recent = max(recent, min(span, length))
        return recent

    def new_samples(self, samples: int) -> int:
        """Samples since the last fit."""
        return samples - self.fit_samples

    def plan(
        self,
        settings: WindowedSettings,
        *,
        length: int,
        progress: int,
        samples: int,
        cold_failures: int,
    ) -> None:
        """Schedule the next fit after one at ``samples`` and ``progress`` (``length``: what
        the feed holds; ``cold_failures``: cold starts failed in a row)."""
        s = settings
        k = max(s.refit_every, math.ceil(s.refit_fraction * length))
        if cold_failures:  # back off while cold starts fail,
            # but retry at least every W/8 samples: slow references excite the system slowly
            k = min(s.refit_every * 2 ** min(cold_failures, 10), max(s.window // 8, 1))
        self.fit_samples = samples
        self.fit_progress = progress
        self.next_fit = progress + k
