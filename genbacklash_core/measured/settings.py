"""The tracking judge's settings (:class:`TrackingJudgeSettings`) and the shares and factors
its rules are written with (the module notes of :mod:`genbacklash_core.measured`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from genbacklash_core.errors import GenBacklashError

RETRY_CHANGE = 0.1
"""A new model whose play differs from the one judged harmful by more than this share is
tried again at once."""

STRONG_HARM = 1.3
"""A ratio above this times ``ratio_off`` is judged harmful after :data:`HARM_SHARE` of
``min_time`` of compensating."""

HARM_SHARE = 1.0 / 3.0
"""The share of ``min_time`` of compensated readings on which clear harm is judged."""

RAMP_START = 0.1
"""The share of the trial weight a trial starts at; it grows linearly to all of it over
:data:`HARM_SHARE` of ``min_time``, while nothing could judge the harm it may do."""

OFFLINE_CHECK = HARM_SHARE
"""On a start from an :class:`OfflineBaseline`: the share of ``min_time`` of compensating
after which the baseline is probed live (module notes)."""

OFFLINE_PROBE = HARM_SHARE / 2.0
"""On a start from an :class:`OfflineBaseline`: the share of ``min_time`` the live probe
lasts; a live baseline that long replaces the offline one unless it agrees with it
(:data:`OFFLINE_AGREE`; module notes)."""

OFFLINE_AGREE = 1.35
"""A live baseline shorter than ``min_time`` within this factor of the offline one confirms
it, and the offline one (measured over a whole record) stays in use: the error of a second
of work varies with its motion by more than a third (an operation-shaped seeded start's
half-second probe read 0.040 rad against 0.048 offline, and its trial was judged harmful
against it at a raw 1.44 where compensating kept 1 % of the error; BENCHMARKS.md, issue
23). Further apart, the live one replaces it: the offline one is stale or of other work."""


@dataclass(frozen=True)
class TrackingJudgeSettings:
    """How the measured tracking is judged (module notes).

    Parameters
    ----------
    in_loop : bool
        The compensated command drives the drivetrain: the judge's trust counts. False: it
        only watches.
    window : float
        Seconds (of each kind's own readings) over which the mean squares are weighted.
    min_time : float
        Seconds of readings of each kind before the judge judges (and a probe's length).
    ratio_full, ratio_off : float
        The ratio ``q`` at or below which compensation is kept in full, at or above which it
        is off (``0 < ratio_full < ratio_off``).
    retry : float
        Seconds with compensation held off for harm before it is tried again (a new model
        tries at once).
    probe_every : float
        Seconds of compensating between probes of the uncompensated baseline (``inf``: only
        when there is no baseline at all).
    trial : float
        The share of compensation applied during its first ``min_time`` seconds, while it
        is measured (in ``(0, 1]``): what a harmful compensation costs before the verdict.
    ratio_wiring : float
        Watching only: ``q`` below this says the compensated command seems to drive the
        drivetrain.

    Examples
    --------
    >>> try:
    ...     TrackingJudgeSettings(ratio_full=1.2, ratio_off=1.0)
    ... except GenBacklashError as err:
    ...     print(err)
    ratio_full must be > 0 and below ratio_off, got 1.2 and 1.0
    """

    in_loop: bool = True
    window: float = 10.0
    min_time: float = 3.0
    ratio_full: float = 0.9
    ratio_off: float = 1.0
    retry: float = 120.0
    probe_every: float = 600.0
    trial: float = 0.5
    ratio_wiring: float = 0.7

    def __post_init__(self) -> None:
        full, off = float(self.ratio_full), float(self.ratio_off)
        if not (math.isfinite(full) and math.isfinite(off) and 0.0 < full < off):
            raise GenBacklashError(
                f"ratio_full must be > 0 and below ratio_off, got {self.ratio_full} and "
                f"{self.ratio_off}"
            )
        for name in ("window", "min_time", "retry"):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise GenBacklashError(f"{name} must be a finite number > 0, got {value!r}")
        if not 0.0 < float(self.trial) <= 1.0:
            raise GenBacklashError(f"trial must lie in (0, 1], got {self.trial!r}")
        if not float(self.probe_every) > 0.0:
            raise GenBacklashError(f"probe_every must be > 0, got {self.probe_every!r}")
