"""The commissioning motion planned (:func:`commissioning_trajectory`; the module notes of
:mod:`genbacklash_core.excite`): sweeps timed to the identifier's cold starts, jogs across the
gap, time-optimal moves from rest to rest.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.scenarios import (
    trapezoid,
)

from .limits import MotionLimits, as_finite, as_positive, as_whole
from .trajectory import Trajectory

_EPS = float(np.finfo(np.float64).eps)
_MAX_COMMANDS = 2_000_000  # about 5.5 hours at 100 Hz: beyond, the limits are unreasonable
_GAP_WIDTHS = 3.0  # one jog, in gap widths (gap_hint)
_RANGE_IN_GAPS = 12.0  # the range holds at least this many gap widths
_DEFAULT_JOG = 1.0 / 16.0  # a jog without a gap hint, share of the range
# The identifier's cold start (two reversals needed) is tried after 48, 98, 198, 385, ...
# rows (one row per command while moving): sweeps of ~90 commands put the second reversal
# after row 98 and full coverage before row 198. Slower sweeps get more of them instead.
_SWEEP_COMMANDS = 90.0
_ALIGNED_COMMANDS = 97
_AFTER_COVERAGE = 300.0


def _move(start: float, target: float, v: float, a: float, dt: float) -> FloatArray:
    """Samples (after ``start``, the last exactly at ``target``) of a time-optimal
    trapezoidal move from rest to rest (:func:`~genbacklash_core.scenarios.trapezoid`)."""
    if target == start:
        return np.zeros(0)
    out = start + trapezoid(target - start, v, a, dt)
    out[-1] = target
    return np.asarray(out, dtype=np.float64)


def _waypoints(
    limits: MotionLimits, start: float, jog: float, sweeps: int, jog_points: int
) -> list[float]:
    """Where the motion turns (see the module notes), from ``start`` back to it."""
    low, high = limits.low, limits.high
    far, near = (high, low) if high - start >= start - low else (low, high)
    stops = [low + (k + 1) * limits.span / (jog_points + 1) for k in range(jog_points)]
    points = [start, far]
    end = far
    for sweep in range(sweeps):
        here, end = end, (near if end == far else far)
        heading = 1.0 if end > here else -1.0
        if sweep == sweeps - 1:  # jogs on the last sweep: to the stop, back one swing, on
            for stop in sorted(stops, key=lambda q: heading * q):
                if heading * (stop - here) > jog and heading * (end - stop) > 0.0:
                    points += [stop, stop - heading * jog]
        points.append(end)
    points.append(start)
    return [p for k, p in enumerate(points) if k == 0 or p != points[k - 1]]


def _sweep_seconds(span: float, v: float, a: float) -> float:
    """Duration of a rest-to-rest move over ``span`` at speed ``v``, acceleration ``a``."""
    if v * v / a >= span:  # triangular
        return 2.0 * math.sqrt(span / a)
    return span / v + v / a


def _sweep_speed(span: float, v_max: float, a: float, seconds: float) -> float:
    """The speed (at most ``v_max``) at which a sweep over ``span`` lasts ``seconds``."""
    disc = a * a * seconds * seconds - 4.0 * a * span
    if disc < 0.0:  # it cannot be that quick
        return v_max
    return min(v_max, 0.5 * (a * seconds - math.sqrt(disc)))


def commissioning_trajectory(
    limits: MotionLimits,
    *,
    command_rate: float = 100.0,
    gap_hint: float | None = None,
    start: float | None = None,
    sweeps: int | None = None,
    jog_points: int = 0,
    regions: int = 16,
) -> Trajectory:
    """The commissioning motion: the shortest after which the identifier has converged.

    See the module notes for its parts, why it is timed as it is and the measured
    convergence.

    Parameters
    ----------
    limits : MotionLimits
        Position range, ``v_max`` and ``a_max``; all respected exactly.
    command_rate : float
        Commands per second (the rate the drivetrain is commanded at).
    gap_hint : float, optional
        The expected play in input units (``c_L + c_R``: how far the input travels after a
        reversal before the load follows). It sizes the jogs (3 gap widths) and the range
        must hold 12 gap widths. Without it a jog is 1/16 of the range.
    start : float, optional
        Where the joint rests when the motion begins (and ends); default the middle of the
        range.
    sweeps : int, optional
        End-to-end sweeps after the way to the farther end (>= 1). Default: 2, or more when
        a sweep takes more than 97 commands (a slow joint, a high ``command_rate``), so
        that >= 300 commands follow the point where both branches are covered. One sweep
        covers both branches, but the identifier's cold start comes too late for it.
    jog_points : int
        Jogs spread evenly over the range on the last sweep (>= 0): to the point, back one
        jog, on; reversals across the gap at more places (e.g. for a play that varies along
        the travel). Each adds about two short moves.
    regions : int
        The identifier's input regions per branch (``WindowedSettings.bins``); no command
        moves more than half a region.

    Returns
    -------
    Trajectory

    Raises
    ------
    GenBacklashError
        Bad limits or options, a range too small for ``gap_hint``, or a motion so slow that
        it would take more than 2 000 000 commands.

    Examples
    --------
    >>> limits = MotionLimits(0.0, 3.0, v_max=2.0, a_max=10.0)
    >>> traj = commissioning_trajectory(limits, start=0.0, jog_points=2)
    >>> traj.reversals, float(traj.u[0]), float(traj.u.max()), round(traj.duration, 2)
    (7, 0.0, 3.0, 8.0)
    >>> commissioning_trajectory(limits, gap_hint=0.5)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: the range [0, 3] is too small for a gap of 0.5: ...
    """
    if not isinstance(limits, MotionLimits):
        raise GenBacklashError(f"limits must be MotionLimits, got {limits!r}")
    rate = as_positive("command_rate", command_rate)
    if sweeps is not None:
        sweeps = as_whole("sweeps", sweeps, 1)
    jog_points = as_whole("jog_points", jog_points, 0)
    regions = as_whole("regions", regions, 1)
    span = limits.span
    if gap_hint is None:
        jog = _DEFAULT_JOG * span
    else:
        gap = as_positive("gap_hint", gap_hint)
        jog = _GAP_WIDTHS * gap
        if _RANGE_IN_GAPS * gap > span * (1.0 + 1e-12):
            raise GenBacklashError(
                f"the range [{limits.low:g}, {limits.high:g}] is too small for a gap of "
                f"{gap:g}: it should hold at least {_RANGE_IN_GAPS:g} gap widths "
                f"({_RANGE_IN_GAPS * gap:g})"
            )
    if start is None:
        start = limits.low + 0.5 * span
    else:
        start = as_finite("start", start)
        if not limits.low <= start <= limits.high:
            raise GenBacklashError(
                f"start {start:g} lies outside the range [{limits.low:g}, {limits.high:g}]"
            )
    # plan inside the limits by the rounding of the samples and of their differences
    magnitude = max(abs(limits.low), abs(limits.high), span)
    v = limits.v_max - 16.0 * _EPS * magnitude * rate
    a = limits.a_max - 64.0 * _EPS * magnitude * rate * rate
    if not (v > 0.5 * limits.v_max and a > 0.5 * limits.a_max):
        raise GenBacklashError(
            f"v_max {limits.v_max:g} and a_max {limits.a_max:g} are too small for positions "
            f"of magnitude {magnitude:g} at {rate:g} commands/s: float rounding alone would "
            "exceed them"
        )
    v = min(v, 0.5 * span / regions * rate)  # at most half a region per command
    v = _sweep_speed(span, v, a, _SWEEP_COMMANDS / rate)  # no quicker than ~90 commands
    per_sweep = math.ceil(_sweep_seconds(span, v, a) * rate)
    if sweeps is None:
        sweeps = 2
        if per_sweep > _ALIGNED_COMMANDS:
            sweeps = max(2, 1 + math.ceil(_AFTER_COVERAGE / per_sweep))
    points = _waypoints(limits, start, jog, sweeps, jog_points)
    distance = sum(abs(q - p) for p, q in itertools.pairwise(points))
    expected = (distance / v + 2.0 * len(points) * v / a + len(points) / rate) * rate
    if expected > _MAX_COMMANDS:
        raise GenBacklashError(
            f"the motion would take about {expected / rate:.3g} s ({expected:.3g} commands "
            f"at {rate:g}/s, more than {_MAX_COMMANDS}): raise v_max or a_max, or narrow "
            "the range"
        )
    dt = 1.0 / rate
    pieces = [np.array([start])]
    pieces += [_move(p, q, v, a, dt) for p, q in itertools.pairwise(points)]
    u = np.clip(np.concatenate(pieces), limits.low, limits.high)  # rounding only
    return Trajectory(limits, rate, u)
