"""Commissioning motion: a short trajectory after which the online identifier has converged.

The online identifier (:class:`~genbacklash_core.online.windowed.WindowedIdentifier`, the node's
default method) learns from *rows*: pairs of consecutive encoder readings between which the
command moved (one per command while the joint moves), filed by branch (moves up: the right
branch; moves down: the left branch) and by input region (16 per branch over the range seen,
:class:`~genbacklash_core.online.memory.RowMemory`). It needs rows over each branch's whole range
and reversals that cross the gap. Its first fit, the cold start, needs two reversals; it is
tried after 48 rows and, while it fails, after 98, 198, 385, 572, ... rows. A cold start
on a partial view of the branches can settle on a poor estimate that later fits cannot
leave (they freeze it as ``no_excitation``). A drivetrain in operation may take minutes to
show both branches; :func:`commissioning_trajectory` shows them in a few seconds, for users
who can run a motion at commissioning time:

1. from the start position to the *farther* end of the range;
2. ``sweeps`` end-to-end sweeps (default 2: back to the near end and out again), each timed
   to take about 90 commands (``v_max`` permitting): the second reversal then comes after
   row 98 and both branches are covered over the whole range before row 198, so the first
   cold start that can run sees everything. A joint too slow for that (a sweep of more than
   97 commands) gets more sweeps instead, so that >= 300 commands follow full coverage;
3. optionally ``jog_points`` jogs spread over the range on the last sweep (to the point,
   back one jog of a few gap widths, on): more reversals across the gap, at more places;
4. back to the start position, so that the motion can be repeated.

Every move is a time-optimal trapezoidal (or triangular) velocity profile from rest to rest,
as in :mod:`genbacklash_core.scenarios`; the commands are its samples at ``command_rate``.
Their finite differences respect the limits exactly (planned with a margin for float
rounding): ``max |v| <= v_max``, ``max |a| <= a_max``, every position within
``[low, high]``, at rest at both ends. No command moves more than half a region (1/32 of
the range), so every region gets moves in both directions.

:func:`verify` runs a trajectory through the drivetrain of :mod:`genbacklash_core.scenarios`
(commands held by the servo, a 1 kHz encoder quantised to 4096 counts/rev whose stamps
jitter and whose readings are lost with probability 0.02, the play operator) into a default
:class:`~genbacklash_core.online.windowed.WindowedIdentifier` (degree 3) and reports when it
converged and the free-run NRMSE of its final estimate against the truth.

Measured on the scenario's drivetrain (travel -1.2..1.2 rad, 3 rad/s, 30 rad/s^2, 100 Hz,
start in the middle; models :data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`,
:data:`~genbacklash_core.scenarios.STRAIGHT_BACKLASH`, the same with a wider play
c_L = c_R = 0.1 rad, a narrower one 0.02 rad and an uneven one 0.02/0.08 rad; 40 seeds
each): the default motion lasts 2.84 s (3 reversals); the identifier converged in all 200
runs, at 2.04-2.15 s (median 2.08 s), free-run NRMSE <= 0.0003. Shorter variants did not
hold up: one sweep (1.93 s) never converged (the cold start finds too few reversals at
rows 48 and 98 and waits until row 198, after the motion); leaving out the way back to the
start (2.33 s), an opening jog at the start (2.2-2.5 s) or a staircase of jogs before the
sweeps (2.3-3.6 s) failed in 0.4-23 % of the runs over other limits and start positions: an
early cold start on a few jogs settles on a poor estimate. ``sweeps=3`` (3.75 s) and
``jog_points=4`` (4.08 s) converge as reliably and no earlier.

Over 0.6-4.8 rad of travel, ``v_max`` of 1-20 rad/s, ``a_max`` of 3-100 ``v_max`` per
second, start in the middle, at 1/4 or at an end, and 50-1000 commands/s, the default
converged in every run with a travel of >= 1.2 rad but one case: at 1000 commands/s on
4.8 rad at 1 rad/s and 3 rad/s^2 the identifier ended ``no_excitation`` (frozen by its
coverage test) in 5 of 15 runs, the estimate good. On 0.6 rad (6 gap widths) with the start
in the middle it ended ``converging`` in about half the runs, the estimate good (NRMSE <=
0.001); with ``sweeps=3`` in 1 of 36.

Examples
--------
>>> limits = MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0)
>>> traj = commissioning_trajectory(limits)
>>> round(traj.duration, 2), traj.reversals
(2.84, 3)
>>> bool(traj.peak_velocity <= 3.0 and traj.peak_acceleration <= 30.0)
True
>>> float(traj.u.min()), float(traj.u.max()), float(traj.u[0]), float(traj.u[-1])
(-1.2, 1.2, 0.0, 0.0)
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ._typing import FloatArray
from .backlash import GeneralBacklash
from .data import as_float_array, count_reversals
from .errors import GenBacklashError
from .estimate import EstimatorState
from .identify import nrmse
from .online.windowed import WindowedIdentifier, WindowedSettings
from .samples import sample_breaks
from .scenarios import (
    OPERATION_BACKLASH,
    OperationSettings,
    drive,
    operation_record,
    trapezoid,
)
from .simulate import simulate_backlash

__all__ = [
    "CommissioningCheck",
    "MotionLimits",
    "Trajectory",
    "Verification",
    "check_commissioning",
    "commissioning_trajectory",
    "verify",
]

_EPS = float(np.finfo(np.float64).eps)
_TOLERANCE = 1e-9  # relative tolerance of the limit checks (finite differences)
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


def _finite(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise GenBacklashError(f"{name} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise GenBacklashError(f"{name} must be finite, got {value!r}")
    return out


def _positive(name: str, value: object) -> float:
    out = _finite(name, value)
    if not out > 0.0:
        raise GenBacklashError(f"{name} must be > 0, got {value!r}")
    return out


def _whole(name: str, value: object, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise GenBacklashError(f"{name} must be a whole number >= {low}, got {value!r}")
    if int(value) < low:
        raise GenBacklashError(f"{name} must be a whole number >= {low}, got {value!r}")
    return int(value)


# --------------------------------------------------------------------------- limits


@dataclass(frozen=True)
class MotionLimits:
    """What the joint may do: its position range and its velocity and acceleration limits.

    Attributes
    ----------
    low, high : float
        Position range (the command's units, e.g. rad), ``low < high``.
    v_max : float
        Largest speed, units per second (> 0).
    a_max : float
        Largest acceleration, units per second squared (> 0).

    Examples
    --------
    >>> MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0).span
    2.4
    >>> MotionLimits(-1.2, 1.2, v_max=-3.0, a_max=30.0)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: v_max must be > 0, got -3.0
    """

    low: float
    high: float
    v_max: float
    a_max: float

    def __post_init__(self) -> None:
        low, high = _finite("low", self.low), _finite("high", self.high)
        if not low < high:
            raise GenBacklashError(
                f"the position range needs low < high, got low={low!r}, high={high!r}"
            )
        if not math.isfinite(high - low):
            raise GenBacklashError(f"the position range [{low:g}, {high:g}] is too wide")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)
        object.__setattr__(self, "v_max", _positive("v_max", self.v_max))
        object.__setattr__(self, "a_max", _positive("a_max", self.a_max))

    @property
    def span(self) -> float:
        """``high - low``."""
        return self.high - self.low


# --------------------------------------------------------------------------- trajectory


def _differences(u: FloatArray, rate: float) -> tuple[FloatArray, FloatArray]:
    """Velocity and acceleration by finite differences, the motion at rest before and after
    (the first and last command repeated)."""
    padded = np.concatenate([u[:1], u, u[-1:]])
    velocity = np.diff(padded) * rate
    acceleration = np.diff(padded, 2) * (rate * rate)
    return np.asarray(velocity, dtype=np.float64), np.asarray(acceleration, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Position commands at a fixed rate, checked against motion limits.

    Attributes
    ----------
    limits : MotionLimits
    command_rate : float
        Commands per second; command ``k`` is due at ``t = k / command_rate``.
    u : ndarray
        The commands (read-only), at least two. The motion starts and ends at rest: the
        finite differences are taken with the first and last command repeated.

    Raises
    ------
    GenBacklashError
        A command outside ``[low, high]``, or a finite-difference velocity or acceleration
        beyond ``v_max`` or ``a_max`` by more than ``1e-9`` of the limit.

    Examples
    --------
    >>> limits = MotionLimits(0.0, 1.0, v_max=1.0, a_max=100.0)
    >>> Trajectory(limits, 10.0, np.array([0.0, 0.05, 0.1, 0.1])).duration
    0.3
    >>> Trajectory(limits, 10.0, np.array([0.0, 0.5, 0.5]))
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: command 1 moves at 5 units/s; v_max is 1
    """

    limits: MotionLimits
    command_rate: float
    u: FloatArray = field(repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.limits, MotionLimits):
            raise GenBacklashError(f"limits must be MotionLimits, got {self.limits!r}")
        rate = _positive("command_rate", self.command_rate)
        object.__setattr__(self, "command_rate", rate)
        u = np.array(as_float_array("u", self.u), dtype=np.float64)
        if u.ndim != 1 or u.size < 2:
            raise GenBacklashError(f"u must be one-dimensional with >= 2 commands, got {u.shape}")
        if not np.all(np.isfinite(u)):
            raise GenBacklashError("u holds NaN or infinite commands")
        lim = self.limits
        outside = np.flatnonzero((u < lim.low) | (u > lim.high))
        if outside.size:
            k = int(outside[0])
            raise GenBacklashError(
                f"command {k} ({u[k]:.6g}) lies outside the range [{lim.low:g}, {lim.high:g}]"
            )
        velocity, acceleration = _differences(u, rate)
        for name, values, limit, unit in (
            ("moves at", velocity, lim.v_max, "units/s"),
            ("accelerates at", acceleration, lim.a_max, "units/s^2"),
        ):
            k = int(np.argmax(np.abs(values)))
            if abs(values[k]) > limit * (1.0 + _TOLERANCE):
                limit_name = "v_max" if unit == "units/s" else "a_max"
                raise GenBacklashError(
                    f"command {k} {name} {abs(values[k]):.6g} {unit}; {limit_name} is {limit:g}"
                )
        u.flags.writeable = False
        object.__setattr__(self, "u", u)

    @property
    def t(self) -> FloatArray:
        """Times of the commands, seconds from the first."""
        return np.arange(self.u.size) / self.command_rate

    @property
    def duration(self) -> float:
        """Seconds from the first command to the last."""
        return (self.u.size - 1) / self.command_rate

    @property
    def reversals(self) -> int:
        """How often the motion changes direction."""
        return count_reversals(self.u)

    @property
    def velocity(self) -> FloatArray:
        """Finite-difference velocity between consecutive commands (and from/to rest)."""
        return _differences(self.u, self.command_rate)[0]

    @property
    def acceleration(self) -> FloatArray:
        """Finite-difference acceleration at each command (at rest before and after)."""
        return _differences(self.u, self.command_rate)[1]

    @property
    def peak_velocity(self) -> float:
        """Largest finite-difference speed."""
        return float(np.max(np.abs(self.velocity)))

    @property
    def peak_acceleration(self) -> float:
        """Largest finite-difference acceleration."""
        return float(np.max(np.abs(self.acceleration)))


# --------------------------------------------------------------------------- the motion


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
    rate = _positive("command_rate", command_rate)
    if sweeps is not None:
        sweeps = _whole("sweeps", sweeps, 1)
    jog_points = _whole("jog_points", jog_points, 0)
    regions = _whole("regions", regions, 1)
    span = limits.span
    if gap_hint is None:
        jog = _DEFAULT_JOG * span
    else:
        gap = _positive("gap_hint", gap_hint)
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
        start = _finite("start", start)
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


# --------------------------------------------------------------------------- verification


class Verification(NamedTuple):
    """What :func:`verify` found."""

    converged_at: float | None
    """Seconds from the first command from which the estimate stayed converged to the end
    of the trajectory (None: not converged at the end)."""
    nrmse: float
    """Free-run NRMSE of the final estimate against the truth (``inf`` without one)."""


@dataclass(frozen=True)
class CommissioningCheck:
    """The identifier on a simulated run of a trajectory (:func:`check_commissioning`).

    Attributes
    ----------
    converged_at : float or None
        Seconds from the first command from which the state stayed ``converged`` to the
        end of the trajectory; None when it was not converged at the end.
    nrmse : float
        Free-run NRMSE of the final estimate against the noise-free truth on an independent
        record of the scenario's ``"operation"`` motion over the same travel (``inf``
        without an estimate).
    state : EstimatorState
        The identifier's state at the end.
    reason : str
        Its reason.
    model : GeneralBacklash or None
        The final estimate (in the model's units).
    rows : int
        Encoder readings that arrived.
    """

    converged_at: float | None
    nrmse: float
    state: EstimatorState
    reason: str
    model: GeneralBacklash | None
    rows: int

    @property
    def converged(self) -> bool:
        """Converged at the end of the trajectory."""
        return self.converged_at is not None


def _drivetrain(
    trajectory: Trajectory,
    u_commands: FloatArray,
    model: GeneralBacklash,
    seed: int,
    encoder_rate: float,
    counts_per_rev: int,
    loss: float,
) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """The scenario's drivetrain on the commands: ``(stamps_ns, u, y, period_ns)`` of the
    readings that arrived (see :func:`genbacklash_core.scenarios.operation_record`)."""
    defaults = OperationSettings()
    cmd_period = 1e9 / trajectory.command_rate
    _, t, u, _, y, received, _, _ = drive(
        np.random.default_rng([int(seed), 31]),
        u_commands,
        model,
        command_rate=trajectory.command_rate,
        encoder_rate=encoder_rate,
        command_jitter_ns=round(min(defaults.command_jitter * 1e9, 0.5 * cmd_period)),
        stamp_jitter_ns=defaults.stamp_jitter * 1e9,
        quantum=2.0 * math.pi / counts_per_rev if counts_per_rev else 0.0,
        loss=loss,
    )
    enc_period = 1e9 / encoder_rate
    return (
        np.asarray(t[received], dtype=np.float64),
        np.asarray(u[received], dtype=np.float64),
        np.asarray(y[received], dtype=np.float64),
        enc_period,
    )


def check_commissioning(
    trajectory: Trajectory,
    model: GeneralBacklash = OPERATION_BACKLASH,
    seed: int = 0,
    *,
    travel: tuple[float, float] | None = None,
    degree: int = 3,
    settings: WindowedSettings | None = None,
    encoder_rate: float = 1000.0,
    counts_per_rev: int = 4096,
    loss: float = 0.02,
) -> CommissioningCheck:
    """Run ``trajectory`` through a simulated drivetrain into the online identifier.

    The drivetrain of :mod:`genbacklash_core.scenarios`: the commands held (zero-order
    hold, up to 0.2 ms late), ``model``'s play operator, an encoder at ``encoder_rate``
    whose stamps jitter (50 us), quantised to ``counts_per_rev`` (of ``2 pi`` units) and
    losing each reading with probability ``loss``. The readings feed a
    :class:`~genbacklash_core.online.windowed.WindowedIdentifier` (``degree``, ``settings``;
    by default the node's: degree 3, ``WindowedSettings()``) in steps of one command
    period. The NRMSE is that of the final estimate simulated free-run against the
    noise-free truth on 20 s of the scenario's ``"operation"`` motion over the same travel
    (an independent record, seeded by ``seed``).

    Parameters
    ----------
    trajectory : Trajectory
    model : GeneralBacklash
        The true drivetrain (in ``travel``'s units).
    seed : int
        Seeds the jitter, the losses and the validation record.
    travel : (float, float), optional
        Map the trajectory's range linearly onto this travel before simulating (the model's
        units): a check of the motion's *shape* on a drivetrain whose travel is another
        one; the identifier sees one row per command change whatever the scale. Default:
        the trajectory's own units.
    degree : int
    settings : WindowedSettings, optional
    encoder_rate : float
    counts_per_rev : int
        0: no quantisation.
    loss : float
        In ``[0, 0.95]``.

    Returns
    -------
    CommissioningCheck

    Examples
    --------
    >>> traj = commissioning_trajectory(MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0))
    >>> check = check_commissioning(traj, seed=1)
    >>> check.state.value, check.converged_at is not None, check.nrmse < 0.02
    ('converged', True, True)
    """
    if not isinstance(trajectory, Trajectory):
        raise GenBacklashError(f"trajectory must be a Trajectory, got {trajectory!r}")
    if not isinstance(model, GeneralBacklash):
        raise GenBacklashError(f"model must be a GeneralBacklash, got {model!r}")
    seed = _whole("seed", seed, 0)
    encoder_rate = _positive("encoder_rate", encoder_rate)
    if encoder_rate < trajectory.command_rate:
        raise GenBacklashError("encoder_rate must be at least the trajectory's command_rate")
    counts_per_rev = _whole("counts_per_rev", counts_per_rev, 0)
    loss = _finite("loss", loss)
    if not 0.0 <= loss <= 0.95:
        raise GenBacklashError(f"loss must lie in [0, 0.95], got {loss!r}")
    lim = trajectory.limits
    if travel is None:
        low, high = lim.low, lim.high
        u_commands = np.asarray(trajectory.u, dtype=np.float64)
    else:
        low, high = _finite("travel[0]", travel[0]), _finite("travel[1]", travel[1])
        if not low < high:
            raise GenBacklashError(f"travel must be (low, high) with low < high, got {travel}")
        scale = (high - low) / lim.span
        u_commands = np.clip(low + (trajectory.u - lim.low) * scale, low, high)
    if not model.branches_separated(low, high):
        raise GenBacklashError(
            f"the model's branches cross within [{low:g}, {high:g}]; it is no backlash there"
        )
    t_ns, u, y, period = _drivetrain(
        trajectory, u_commands, model, seed, encoder_rate, counts_per_rev, loss
    )
    breaks = sample_breaks(t_ns, period)
    ident = WindowedIdentifier(degree, settings=settings)
    step = max(1, round(encoder_rate / trajectory.command_rate))
    converged_at: float | None = None
    estimate = ident.estimate
    for first in range(0, u.size, step):
        part = slice(first, first + step)
        estimate = ident.update_many(u[part], y[part], breaks[part])
        if estimate.state is EstimatorState.CONVERGED:
            if converged_at is None:
                converged_at = float(t_ns[min(first + step, u.size) - 1]) * 1e-9
        else:
            converged_at = None
    found = estimate.model
    fitted = found if isinstance(found, GeneralBacklash) else None
    error = math.inf
    if fitted is not None:
        validation = operation_record(
            OperationSettings(
                duration=20.0,
                model=model,
                travel=(low, high),
                v_max=1.25 * (high - low),  # the scenario's 3 rad/s on 2.4 rad of travel
                a_max=12.5 * (high - low),  # and its 30 rad/s^2
                command_jitter=0.0,
                stamp_jitter=0.0,
                counts_per_rev=0,
                loss=0.0,
            ),
            seed=seed,
        )
        try:
            simulated = simulate_backlash(fitted, validation.u_all, float(validation.x_all[0]))
            error = nrmse(validation.x_all, simulated)
        except GenBacklashError:  # the estimate overflows on the validation input
            error = math.inf
    return CommissioningCheck(
        converged_at, error, estimate.state, estimate.reason, fitted, int(u.size)
    )


def verify(
    trajectory: Trajectory,
    model: GeneralBacklash = OPERATION_BACKLASH,
    seed: int = 0,
    *,
    travel: tuple[float, float] | None = None,
) -> Verification:
    """When the identifier converged on ``trajectory``, and how good its estimate is.

    :func:`check_commissioning` with its defaults (the node's identifier, the scenario's
    encoder), reduced to ``(converged_at, nrmse)``.

    Parameters
    ----------
    trajectory : Trajectory
    model : GeneralBacklash
        The true drivetrain.
    seed : int
    travel : (float, float), optional
        See :func:`check_commissioning`.

    Returns
    -------
    Verification
        ``(converged_at_s or None, nrmse)``.

    Examples
    --------
    >>> from genbacklash_core.scenarios import STRAIGHT_BACKLASH
    >>> traj = commissioning_trajectory(MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0))
    >>> converged_at, error = verify(traj, STRAIGHT_BACKLASH, seed=0)
    >>> bool(converged_at < traj.duration), bool(error < 0.02)
    (True, True)
    """
    found = check_commissioning(trajectory, model, seed, travel=travel)
    return Verification(found.converged_at, found.nrmse)
