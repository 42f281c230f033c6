"""What the judge hands out and takes in: its verdict (:class:`TrackingVerdict`), and what a
checkpoint carries between starts (:class:`OfflineBaseline`, :class:`HeldHarm`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from genbacklash_core.errors import GenBacklashError


def _finite_number(name: str, value: object, *, above_zero: bool = False) -> None:
    """:class:`GenBacklashError` naming ``name`` unless ``value`` is a finite number (a bool
    is not one), and with ``above_zero`` one above 0."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise GenBacklashError(f"{name} must be a number, got {value!r}")
    if above_zero and not (math.isfinite(value) and value > 0.0):
        raise GenBacklashError(f"{name} must be a finite number > 0, got {value!r}")
    if not math.isfinite(value):
        raise GenBacklashError(f"{name} must be a finite number, got {value!r}")


@dataclass(frozen=True)
class OfflineBaseline:
    """The tracking without compensation measured offline, on a record of the machine's work.

    What :class:`TrackingJudge` measures as its baseline (``rms(e_off)``, ``y - r`` at every
    reading, weighted over ``window`` seconds) over a record in which no compensated
    command drove the drivetrain; a checkpoint start takes it as its baseline
    (:meth:`TrackingJudge.start_from`).

    Parameters
    ----------
    rms : float
        The root-mean-square tracking error without compensation (rad, > 0).
    seconds : float
        Seconds of readings it was measured on (> 0).

    Examples
    --------
    >>> OfflineBaseline(0.036, 40.0).rms
    0.036
    """

    rms: float
    seconds: float

    def __post_init__(self) -> None:
        for name in ("rms", "seconds"):
            _finite_number(name, getattr(self, name), above_zero=True)


@dataclass(frozen=True)
class HeldHarm:
    """A verdict of harm the judge holds: compensation off for a model of this play.

    What a checkpoint carries to the next start (:meth:`TrackingJudge.held_harm`,
    :meth:`TrackingJudge.hold`), so that a restarted node holds the model it measured
    tracking worse than without off, as a running node does, until a new model or ``retry``
    (measured in BENCHMARKS.md, issue 23: a restart that tried the same model again tracked
    2.4 % worse than without compensation over a whole physics record).

    Parameters
    ----------
    play : float
        ``c_L + c_R`` of the model judged harmful (rad, finite).
    ratio : float
        The measured ratio ``q`` harm was judged on (finite, > 0).
    held : float
        Seconds of readings without compensation it has been held off so far (>= 0): the
        retry counts on from there.

    Examples
    --------
    >>> HeldHarm(0.0384, 1.11, 12.5).ratio
    1.11
    """

    play: float
    ratio: float
    held: float

    def __post_init__(self) -> None:
        for name in ("play", "ratio", "held"):
            _finite_number(name, getattr(self, name))
        if self.ratio <= 0.0 or self.held < 0.0:
            raise GenBacklashError(
                f"ratio must be > 0 and held >= 0, got {self.ratio!r} and {self.held!r}"
            )


@dataclass(frozen=True)
class TrackingVerdict:
    """The judge's verdict after the readings so far.

    Attributes
    ----------
    trust : float
        In ``[0, 1]``: the factor on the compensation's weight (0 before a full baseline and
        during a probe; up to ``trial`` during compensation's first ``min_time`` seconds).
    state : str
        ``"judging"`` (not enough of both kinds yet), ``"on"``, ``"faded"``, ``"off"``
        (judged harmful), ``"probing"`` (compensation held off to measure the baseline), or
        ``"watching"`` (not in the loop: trust 1).
    ratio : float
        ``q = rms(e_on) / rms(e_off)`` (NaN until both kinds have readings).
    on_rms, off_rms : float
        The measured tracking errors, compensated and not (rad).
    on_time, off_time : float
        Seconds of readings of each kind judged so far (``off_time``: the offline
        baseline's seconds while it is in use).
    reason : str
        One sentence, with the numbers.
    baseline : str
        What ``off_rms`` is: ``"measured"`` (on the machine) or ``"offline"`` (the
        :class:`OfflineBaseline` of a checkpoint start, until the live one is probed, and
        after while the live one is shorter than ``min_time`` and agrees with it).
    live_time : float
        Seconds of readings without compensation measured on the machine, whichever
        baseline is in use.
    """

    trust: float
    state: str
    ratio: float
    on_rms: float
    off_rms: float
    on_time: float
    off_time: float
    reason: str
    baseline: str = "measured"
    live_time: float = 0.0
