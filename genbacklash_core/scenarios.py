"""Drivetrains in normal operation: records that look like the field, with their truth.

The paper's input (a new uniform value every sample) is the easy case. A drivetrain doing its
job moves smoothly between targets, dwells, jogs back and forth a few times a second, gets
position commands at 100 Hz that the servo holds, and is read by a quantised encoder at
1 kHz whose readings jitter and are sometimes lost. :func:`operation_record` simulates that,
pure numpy, and keeps the noise-free truth so that estimates can be judged against it.

Motions (``phases``, each ``(kind, seconds)``, run one after the other):

* ``"operation"``: point-to-point moves to random targets in the travel with trapezoidal
  velocity (random fraction of ``v_max``, ``a_max``), dwells of 0.1-0.5 s, and small jogs
  that reverse the last move (half the moves);
* ``"one_way"``: a slow traverse in one direction only, with speed changes and stops (one
  branch engaged for minutes, the other never);
* ``"pick_and_place"``: the same two targets (a few millimetres of scatter) again and again,
  with dwells at both: only the part of each branch between them is ever seen;
* ``"sine_sweep"``: a slow sine over most of the travel whose frequency sweeps from 0.05 to
  0.5 Hz.

Time line: commands at ``command_rate`` (100 Hz) with up to ``command_jitter`` of delay,
held by the drivetrain (zero-order hold) until the next; encoder readings at
``encoder_rate`` (1 kHz), each taken at its nominal instant plus Gaussian ``stamp_jitter``
(clipped to a third of the period) and stamped with the instant it was taken; the reading is
the load position at that instant (the backlash is rate-independent, so the play operator on
the held command at the sampling instants is exact), plus optional white ``noise``,
quantised to ``counts_per_rev``. Each reading is lost with probability ``loss``. With
``wear``, both dead zones ``c_L``, ``c_R`` grow linearly by that fraction over the record.

Examples
--------
>>> rec = operation_record(OperationSettings(duration=2.0), seed=1)
>>> rec.command_t_ns.size, rec.sample_t_ns.size
(200, 2000)
>>> bool(0.95 < rec.received.mean() < 1.0)
True
>>> u, y, breaks = rec.series()
>>> u.size == y.size == breaks.size == int(rec.received.sum())
True
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ._typing import BoolArray, FloatArray, IntArray
from .backlash import GeneralBacklash
from .errors import GenBacklashError
from .samples import bridge_lost, sample_breaks
from .simulate import simulate_backlash

__all__ = [
    "OPERATION_BACKLASH",
    "PHASE_KINDS",
    "STRAIGHT_BACKLASH",
    "HiddenEffects",
    "OperationRecord",
    "OperationSettings",
    "arm_records",
    "operation_commands",
    "operation_record",
    "readings",
    "simulate_worn",
    "timeline",
    "trapezoid",
    "worn",
]

# A mildly curved backlash with a few degrees of play each side (radians, load side; the
# command is the motor position over the gear ratio): c_L 2.6 deg, c_R 2.9 deg.
OPERATION_BACKLASH = GeneralBacklash((1.0, 0.03, -0.015), 0.045, (1.0, 0.025, -0.012), 0.05)
# The same play with straight branches (the ideal backlash of eq. 1, degree 1).
STRAIGHT_BACKLASH = GeneralBacklash((1.0,), 0.045, (1.0,), 0.05)

PHASE_KINDS = ("operation", "one_way", "pick_and_place", "sine_sweep")
_BLOCK = 250  # samples per wear step of the simulation (0.25 s at 1 kHz)


@dataclass(frozen=True)
class OperationSettings:
    """What a drivetrain in operation looks like (see the module notes).

    Attributes
    ----------
    duration : float
        Record length in seconds, when ``phases`` is empty (all ``"operation"``).
    phases : tuple of (str, float)
        Motions in order, each ``(kind, seconds)``; kinds in :data:`PHASE_KINDS`. Overrides
        ``duration``.
    model : GeneralBacklash
        The drivetrain at the start of the record.
    travel : (float, float)
        Position range of the commands, radians.
    v_max, a_max : float
        Velocity (rad/s) and acceleration (rad/s^2) limits of the moves.
    dwell : (float, float)
        Range of the dwell after each move, seconds.
    jog_probability : float
        Share of moves that are small jogs reversing the previous move.
    jog_size : (float, float)
        Range of a jog's length, radians.
    command_rate, encoder_rate : float
        Hz.
    command_jitter : float
        Commands arrive up to this many seconds after their nominal tick (uniform).
    stamp_jitter : float
        Standard deviation of the encoder's sampling instants around the nominal ones, s.
    counts_per_rev : int
        Encoder resolution (0: no quantisation).
    noise : float
        Standard deviation of white noise added before quantisation, radians.
    loss : float
        Probability that a reading is lost.
    wear : float
        Relative growth of both dead zones over the record (0.5: 50 % wider at the end).
    """

    duration: float = 60.0
    phases: tuple[tuple[str, float], ...] = ()
    model: GeneralBacklash = OPERATION_BACKLASH
    travel: tuple[float, float] = (-1.2, 1.2)
    v_max: float = 3.0
    a_max: float = 30.0
    dwell: tuple[float, float] = (0.1, 0.5)
    jog_probability: float = 0.5
    jog_size: tuple[float, float] = (0.02, 0.15)
    command_rate: float = 100.0
    encoder_rate: float = 1000.0
    command_jitter: float = 2e-4
    stamp_jitter: float = 5e-5
    counts_per_rev: int = 4096
    noise: float = 0.0
    loss: float = 0.02
    wear: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.model, GeneralBacklash):
            raise GenBacklashError(f"model must be a GeneralBacklash, got {self.model!r}")
        lo, hi = self.travel
        if not lo < hi:
            raise GenBacklashError(f"travel must be (low, high) with low < high, got {self.travel}")
        for name in ("v_max", "a_max", "command_rate", "encoder_rate"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise GenBacklashError(f"{name} must be a positive number, got {value!r}")
        if self.encoder_rate < self.command_rate:
            raise GenBacklashError("encoder_rate must be at least command_rate")
        for name, value, high in (
            ("jog_probability", self.jog_probability, 1.0),
            ("loss", self.loss, 0.95),
            ("wear", self.wear, 10.0),
        ):
            if not 0.0 <= value <= high:
                raise GenBacklashError(f"{name} must lie in [0, {high}], got {value!r}")
        for name, pair in (("dwell", self.dwell), ("jog_size", self.jog_size)):
            if not 0.0 <= pair[0] <= pair[1]:
                raise GenBacklashError(f"{name} must be (low, high) with 0 <= low <= high")
        if not (0.0 <= self.command_jitter < 1.0 / self.command_rate):
            raise GenBacklashError("command_jitter must lie in [0, 1 / command_rate)")
        if not 0.0 <= self.stamp_jitter:
            raise GenBacklashError("stamp_jitter must be >= 0")
        if not self.noise >= 0.0 or self.counts_per_rev < 0:
            raise GenBacklashError("noise and counts_per_rev must be >= 0")
        for kind, seconds in self.schedule:
            if kind not in PHASE_KINDS:
                raise GenBacklashError(f"unknown phase {kind!r}; choose from {PHASE_KINDS}")
            if not seconds > 0.0:
                raise GenBacklashError(f"phase {kind!r} must last > 0 s, got {seconds!r}")
        if not self.model.branches_separated(lo, hi):
            raise GenBacklashError("the model's branches cross within the travel")

    @property
    def schedule(self) -> tuple[tuple[str, float], ...]:
        """The phases, or one ``"operation"`` phase of ``duration``."""
        return self.phases if self.phases else (("operation", float(self.duration)),)

    @property
    def total_seconds(self) -> float:
        """Length of the record."""
        return float(sum(seconds for _, seconds in self.schedule))

    @property
    def quantum(self) -> float:
        """One encoder count in radians (0 without quantisation)."""
        return 2.0 * math.pi / self.counts_per_rev if self.counts_per_rev else 0.0


@dataclass(frozen=True)
class HiddenEffects:
    """Effects of a drivetrain beyond its backlash, for records with a known missing effect.

    The chain, per encoder sampling instant ``t``:

        command (held) -> dead time -> servo lag -> backlash -> load lag -> periodic error,
        offset -> limit -> reading (noise, quantisation)

    Attributes
    ----------
    delay : float
        Dead time between the command and the motor, seconds (the held command at
        ``t - delay`` drives the motor).
    input_lag : float
        Time constant of the servo's first-order lag, seconds: the motor position ``m``
        follows the held command by ``dm/dt = (v - m) / input_lag`` (solved exactly over each
        sampling interval, the command switching at its stamp). 0: the motor follows at once.
    load_lag : float
        Time constant of a first-order lag between the backlash output and the load,
        seconds (linear dynamics after the backlash): ``z_k = p z_{k-1} + (1 - p) x_{k-1}``,
        ``p = exp(-(t_k - t_{k-1}) / load_lag)``.
    offset : float
        Added to the load position (an encoder zero that is not the backlash's), radians.
    limit : (float or None, float or None)
        Lower and upper limits of the output (a hard stop or a sensor range), radians.
    period : float
        Period in load position of the periodic error (gear runout, encoder eccentricity),
        radians; 0: none.
    harmonics : tuple of (float, float)
        ``(amplitude, phase)`` of harmonics ``1, 2, ..`` of the periodic error:
        ``e(z) = sum_j A_j sin(2 pi j z / period + phi_j)``.

    Examples
    --------
    >>> HiddenEffects(delay=0.005).delay
    0.005
    >>> HiddenEffects(period=0.5)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: a periodic error needs a period > 0 and harmonics
    """

    delay: float = 0.0
    input_lag: float = 0.0
    load_lag: float = 0.0
    offset: float = 0.0
    limit: tuple[float | None, float | None] = (None, None)
    period: float = 0.0
    harmonics: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("delay", "input_lag", "load_lag", "period"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise GenBacklashError(f"{name} must be a number >= 0, got {value!r}")
        if not math.isfinite(self.offset):
            raise GenBacklashError(f"offset must be finite, got {self.offset!r}")
        low, high = self.limit
        if low is not None and high is not None and not low < high:
            raise GenBacklashError(f"limit must be (low, high) with low < high, got {self.limit}")
        if (self.period > 0.0) != bool(self.harmonics):
            raise GenBacklashError("a periodic error needs a period > 0 and harmonics")

    @property
    def names(self) -> tuple[str, ...]:
        """The diagnose catalog names of the effects present (GUIDE §4)."""
        present = (
            (self.delay > 0.0, "time_delay"),
            (self.input_lag > 0.0, "input_lag"),
            (self.load_lag > 0.0, "linear_dynamics"),
            (self.offset != 0.0, "output_offset"),
            (self.limit != (None, None), "saturation"),
            (self.period > 0.0, "periodic_error"),
        )
        return tuple(name for flag, name in present if flag)

    def motor(self, cmd_t: IntArray, values: FloatArray, t: IntArray) -> FloatArray:
        """The backlash input at the sampling instants ``t``: the commands (stamps ``cmd_t``)
        delayed and lagged."""
        delay_ns = round(self.delay * 1e9)
        k = np.maximum(np.searchsorted(cmd_t, t - delay_ns, side="right") - 1, 0)
        held = np.asarray(values[k], dtype=np.float64)
        if self.input_lag <= 0.0:
            return held
        tau = self.input_lag * 1e9
        switch = cmd_t[k] + delay_ns  # when the command in force at t_k took over
        out = np.empty_like(held)
        m = float(held[0])
        out[0] = m
        for i in range(1, held.size):
            old, new = float(held[i - 1]), float(held[i])
            if old != new:  # toward the old command until the switch, then toward the new
                s = min(max(float(switch[i]), float(t[i - 1])), float(t[i]))
                m = old + (m - old) * math.exp(-(s - float(t[i - 1])) / tau)
                m = new + (m - new) * math.exp(-(float(t[i]) - s) / tau)
            else:
                m = new + (m - new) * math.exp(-(float(t[i]) - float(t[i - 1])) / tau)
            out[i] = m
        return out

    def load(self, x: FloatArray, t: IntArray) -> FloatArray:
        """The output before noise for the backlash output ``x`` at the instants ``t``."""
        z = np.asarray(x, dtype=np.float64)
        if self.load_lag > 0.0:
            p = np.exp(-np.diff(t.astype(np.float64)) / (self.load_lag * 1e9))
            lagged = np.empty_like(z)
            lagged[0] = z[0]
            for i in range(1, z.size):
                lagged[i] = p[i - 1] * lagged[i - 1] + (1.0 - p[i - 1]) * z[i - 1]
            z = lagged
        out = z + self.offset
        if self.period > 0.0:
            for j, (amplitude, phase) in enumerate(self.harmonics, 1):
                out = out + amplitude * np.sin(2.0 * math.pi * j * z / self.period + phase)
        low, high = self.limit
        if low is not None or high is not None:
            out = np.clip(out, -np.inf if low is None else low, np.inf if high is None else high)
        return np.asarray(out, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class OperationRecord:
    """A simulated record and its truth.

    Attributes
    ----------
    settings : OperationSettings
    seed : int
    command_t_ns, command_u : ndarray
        Command times (ns from the start) and values, radians.
    sample_t_ns : ndarray of int
        Every encoder sampling instant, lost readings included (the stamps).
    u_all : ndarray
        The held command at each sampling instant (the backlash input).
    x_all : ndarray
        The noise-free load position at each instant.
    y_all : ndarray
        The reading the encoder makes at each instant (noise, quantisation).
    received : ndarray of bool
        Readings that arrive (the others are lost).
    c_left, c_right : ndarray
        The true dead zones at each instant (they change with wear).
    phase_starts : tuple of (str, float)
        Each phase's kind and start, seconds.
    hidden : HiddenEffects or None
        The effects beyond the backlash the record was made with (``x_all`` is then the
        output before noise, not the backlash output).
    """

    settings: OperationSettings
    seed: int
    command_t_ns: IntArray
    command_u: FloatArray
    sample_t_ns: IntArray
    u_all: FloatArray
    x_all: FloatArray
    y_all: FloatArray
    received: BoolArray
    c_left: FloatArray
    c_right: FloatArray
    phase_starts: tuple[tuple[str, float], ...] = field(default=())
    hidden: HiddenEffects | None = None

    @property
    def truth(self) -> GeneralBacklash:
        """The drivetrain at the start."""
        return self.settings.model

    def truth_at(self, index: int) -> GeneralBacklash:
        """The drivetrain at sample ``index`` (wear included)."""
        m = self.settings.model
        return GeneralBacklash(
            m.m_left, float(self.c_left[index]), m.m_right, float(self.c_right[index])
        )

    @property
    def truth_end(self) -> GeneralBacklash:
        """The drivetrain at the end."""
        return self.truth_at(self.sample_t_ns.size - 1)

    @property
    def encoder_t_ns(self) -> IntArray:
        """Stamps of the readings that arrive."""
        return self.sample_t_ns[self.received]

    @property
    def encoder_y(self) -> FloatArray:
        """The readings that arrive."""
        return self.y_all[self.received]

    def series(self, *, bridge: bool = False) -> tuple[FloatArray, FloatArray, BoolArray]:
        """``(u, y, breaks)`` as the node sees it: one sample per reading that arrived, the
        input the command held at its stamp, and the sample rule's breaks
        (:func:`~genbacklash_core.samples.sample_breaks`).

        With ``bridge``, the breaks that lost readings caused along a monotone input are
        lifted (:func:`~genbacklash_core.samples.bridge_lost`): right for a backlash alone,
        as the node does with ``model: backlash``; not for linear dynamics after it.
        """
        period = 1e9 / self.settings.encoder_rate
        breaks = sample_breaks(self.encoder_t_ns, period)
        if bridge:
            breaks = bridge_lost(breaks, self.u_all, np.flatnonzero(self.received))
        return self.u_all[self.received], self.y_all[self.received], breaks


def worn(model: GeneralBacklash, factor: float) -> GeneralBacklash:
    """``model`` with both dead zones scaled by ``factor``."""
    return GeneralBacklash(
        model.m_left, model.c_left * factor, model.m_right, model.c_right * factor
    )


def simulate_worn(
    model: GeneralBacklash,
    u: FloatArray,
    x0: float,
    c_left: FloatArray,
    c_right: FloatArray,
) -> FloatArray:
    """``model`` with the dead zones ``c_left[k]``, ``c_right[k]`` at sample ``k`` (a gap that
    wears), driven by ``u`` from the state ``x0``: the play operator of eqs. (20)-(21) over each
    run of equal dead zones, the state carried from one run to the next.

    >>> m = GeneralBacklash((1.0,), 0.1, (1.0,), 0.1)
    >>> simulate_worn(m, np.array([0.5, 0.0, 0.5]), 0.0, np.array([0.1, 0.1, 0.2]),
    ...               np.array([0.1, 0.1, 0.2])).tolist()
    [0.4, 0.1, 0.3]
    """
    out = np.empty(u.size)
    change = np.flatnonzero((np.diff(c_left) != 0.0) | (np.diff(c_right) != 0.0)) + 1
    starts = np.concatenate([[0], change]).astype(int)
    stops = np.append(change, u.size).astype(int)
    x = float(x0)
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        piece = GeneralBacklash(model.m_left, float(c_left[a]), model.m_right, float(c_right[a]))
        out[a:b] = simulate_backlash(piece, u[a:b], x)
        x = float(out[b - 1])
    return out


# --------------------------------------------------------------------------- motions


def trapezoid(distance: float, v: float, a: float, dt: float) -> FloatArray:
    """Positions (from 0 to ``distance``) of a trapezoidal-velocity move, sampled every
    ``dt``, the last sample at the target."""
    d = abs(distance)
    if d == 0.0:
        return np.zeros(1)
    t_acc = v / a
    if a * t_acc * t_acc >= d:  # triangular: never reaches v
        t_acc = math.sqrt(d / a)
        v = a * t_acc
        t_flat = 0.0
    else:
        t_flat = (d - a * t_acc * t_acc) / v
    total = 2.0 * t_acc + t_flat
    t = np.arange(1, math.ceil(total / dt) + 1) * dt
    t = np.minimum(t, total)
    s = np.where(
        t < t_acc,
        0.5 * a * t * t,
        np.where(
            t < t_acc + t_flat,
            0.5 * a * t_acc * t_acc + v * (t - t_acc),
            d - 0.5 * a * np.square(np.maximum(total - t, 0.0)),
        ),
    )
    return np.asarray(math.copysign(1.0, distance) * s, dtype=np.float64)


def _operation(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    out: list[FloatArray] = []
    pos, last_dir, count = start, 1.0, 0
    while count < n:
        if rng.random() < cfg.jog_probability:
            step = -last_dir * rng.uniform(*cfg.jog_size)
            target = float(np.clip(pos + step, lo, hi))
        else:
            target = float(rng.uniform(lo, hi))
        if abs(target - pos) < 1e-3:
            target = float(np.clip(pos - last_dir * cfg.jog_size[1], lo, hi))
        v = cfg.v_max * rng.uniform(0.3, 1.0)
        path = pos + trapezoid(target - pos, v, cfg.a_max, dt)
        dwell = np.full(max(1, round(rng.uniform(*cfg.dwell) / dt)), target)
        out += [path, dwell]
        count += path.size + dwell.size
        last_dir = math.copysign(1.0, target - pos)
        pos = target
    return np.concatenate(out)[:n]


def _one_way(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    direction = 1.0 if (hi - start) >= (start - lo) else -1.0
    room = (hi - start) if direction > 0 else (start - lo)
    # speeds that vary smoothly, with stops; scaled to cover most of the room
    knots = rng.uniform(0.0, 1.0, max(2, n // 500 + 2))
    knots[rng.random(knots.size) < 0.25] = 0.0
    speed = np.interp(np.linspace(0, knots.size - 1, n), np.arange(knots.size), knots)
    path = np.cumsum(speed)
    if path[-1] > 0:
        path *= 0.9 * room / path[-1]
    return np.asarray(start + direction * path, dtype=np.float64)


def _pick_and_place(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    span = hi - lo
    pick, place = lo + 0.3 * span, lo + 0.65 * span
    out: list[FloatArray] = []
    pos, count, k = start, 0, 0
    while count < n:
        target = (pick if k % 2 == 0 else place) + rng.normal(0.0, 0.002)
        path = pos + trapezoid(target - pos, 0.8 * cfg.v_max, cfg.a_max, dt)
        dwell = np.full(max(1, round(rng.uniform(0.2, 0.4) / dt)), target)
        out += [path, dwell]
        count += path.size + dwell.size
        pos, k = target, k + 1
    return np.concatenate(out)[:n]


def _sine_sweep(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    centre, amplitude = 0.5 * (lo + hi), 0.45 * (hi - lo)
    t = np.arange(n) * dt
    duration = max(n * dt, dt)
    f0, f1 = 0.05, 0.5
    phase = 2.0 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t * t / duration)  # linear chirp
    sweep = centre + amplitude * np.sin(phase)
    ramp = np.clip(t / 1.0, 0.0, 1.0)  # blend from the start position over 1 s
    return np.asarray((1.0 - ramp) * start + ramp * sweep, dtype=np.float64)


_MOTIONS = {
    "operation": _operation,
    "one_way": _one_way,
    "pick_and_place": _pick_and_place,
    "sine_sweep": _sine_sweep,
}


def operation_commands(
    rng: np.random.Generator, cfg: OperationSettings
) -> tuple[FloatArray, tuple[tuple[str, float], ...]]:
    """Command values at the nominal ticks of ``cfg.command_rate``, phase by phase, and each
    phase's kind and start (s); the first random draws of :func:`operation_record`."""
    dt = 1.0 / cfg.command_rate
    pos = 0.5 * (cfg.travel[0] + cfg.travel[1])
    pieces: list[FloatArray] = []
    starts: list[tuple[str, float]] = []
    elapsed = 0
    for kind, seconds in cfg.schedule:
        n = max(1, round(seconds * cfg.command_rate))
        piece = _MOTIONS[kind](rng, cfg, pos, n, dt)
        starts.append((kind, elapsed * dt))
        pieces.append(piece)
        pos = float(piece[-1])
        elapsed += n
    return np.clip(np.concatenate(pieces), *cfg.travel), tuple(starts)


def timeline(
    rng: np.random.Generator,
    n_commands: int,
    *,
    command_rate: float,
    encoder_rate: float,
    command_jitter_ns: int,
    stamp_jitter_ns: float,
) -> tuple[IntArray, IntArray]:
    """The clocks of a drivetrain in operation (see the module notes): ``(command stamps,
    reading stamps)`` in ns from the start, for ``n_commands`` commands at the nominal ticks of
    ``command_rate`` (each up to ``command_jitter_ns`` late) and readings at ``encoder_rate``
    over the same span (Gaussian ``stamp_jitter_ns``, clipped to a third of the period, kept
    in order, the first not before the first command). Draws from ``rng`` in this order:
    command jitter, stamp jitter (each only when non-zero).

    >>> cmd_t, t = timeline(np.random.default_rng(0), 3, command_rate=100.0,
    ...                     encoder_rate=1000.0, command_jitter_ns=0, stamp_jitter_ns=0.0)
    >>> cmd_t.tolist(), t.size
    ([0, 10000000, 20000000], 30)
    """
    cmd_period = 1e9 / command_rate
    cmd_t = np.round(np.arange(n_commands) * cmd_period).astype(np.int64)
    if command_jitter_ns > 0:
        cmd_t += rng.integers(0, command_jitter_ns + 1, n_commands)
    total_ns = n_commands * cmd_period
    enc_period = 1e9 / encoder_rate
    n = math.floor(total_ns / enc_period)
    nominal = np.round(np.arange(n) * enc_period)
    jitter = rng.normal(0.0, stamp_jitter_ns, n) if stamp_jitter_ns > 0 else 0.0
    clip = enc_period / 3.0
    t = (nominal + np.clip(jitter, -clip, clip)).astype(np.int64)
    t[0] = max(int(t[0]), int(cmd_t[0]))  # the first reading after the first command
    return cmd_t, np.maximum.accumulate(t)


def readings(
    rng: np.random.Generator,
    x: FloatArray,
    *,
    noise: float = 0.0,
    quantum: float = 0.0,
    loss: float = 0.0,
) -> tuple[FloatArray, BoolArray]:
    """What an encoder makes of the positions ``x`` (see the module notes): ``(readings,
    received)``, white ``noise`` added, quantised to ``quantum``, each lost with probability
    ``loss`` (the first always received). Draws from ``rng`` in this order: noise (only when
    non-zero), loss (always).

    >>> y, ok = readings(np.random.default_rng(0), np.array([0.0, 0.26, 0.74]), quantum=0.5)
    >>> y.tolist(), ok.tolist()
    ([0.0, 0.5, 0.5], [True, True, True])
    """
    n = x.size
    y = x + (rng.normal(0.0, noise, n) if noise > 0 else 0.0)
    if quantum > 0:
        y = np.round(y / quantum) * quantum
    received = rng.random(n) >= loss
    received[0] = True
    return np.asarray(y, dtype=np.float64), received


def drive(
    rng: np.random.Generator,
    values: FloatArray,
    model: GeneralBacklash,
    *,
    command_rate: float,
    encoder_rate: float,
    command_jitter_ns: int,
    stamp_jitter_ns: float,
    wear: float = 0.0,
    noise: float = 0.0,
    quantum: float = 0.0,
    loss: float = 0.0,
    hidden: HiddenEffects | None = None,
) -> tuple[
    IntArray, IntArray, FloatArray, FloatArray, FloatArray, BoolArray, FloatArray, FloatArray
]:
    """The drivetrain's time line for commands ``values`` at the nominal command ticks (see
    the module notes): ``(command stamps, reading stamps, held input, load, reading,
    received, c_left, c_right)``, every reading included. Draws from ``rng`` in this order:
    command jitter, stamp jitter, noise, loss (each only when non-zero, loss always;
    :func:`timeline`, then :func:`readings`).
    ``hidden`` adds effects beyond the backlash (:class:`HiddenEffects`; it draws nothing):
    the held input stays the command, the load is the output before noise."""
    cmd_t, t = timeline(
        rng,
        values.size,
        command_rate=command_rate,
        encoder_rate=encoder_rate,
        command_jitter_ns=command_jitter_ns,
        stamp_jitter_ns=stamp_jitter_ns,
    )
    n = t.size
    k = np.searchsorted(cmd_t, t, side="right") - 1
    u = values[np.maximum(k, 0)]
    # the drivetrain, with linear wear of the dead zones, in blocks
    factor = 1.0 + wear * (np.arange(n) / max(n - 1, 1))
    block_factor = np.repeat(
        [float(np.mean(factor[s : min(s + _BLOCK, n)])) for s in range(0, n, _BLOCK)], _BLOCK
    )[:n]
    c_left, c_right = model.c_left * block_factor, model.c_right * block_factor
    v = u if hidden is None else hidden.motor(cmd_t, values, t)
    x0 = 0.5 * float(model.left(v[:1])[0] + model.right(v[:1])[0])  # at rest, mid-gap
    x = simulate_worn(model, v, x0, c_left, c_right)
    if hidden is not None:
        x = hidden.load(x, t)
    y, received = readings(rng, x, noise=noise, quantum=quantum, loss=loss)
    return cmd_t, t, u, x, y, received, c_left, c_right


def operation_record(
    settings: OperationSettings | None = None, seed: int = 0, *, hidden: HiddenEffects | None = None
) -> OperationRecord:
    """Simulate a drivetrain in operation (see the module notes).

    Parameters
    ----------
    settings : OperationSettings, optional
        Default: 60 s of ``"operation"`` with :data:`OPERATION_BACKLASH`.
    seed : int
        Seeds everything random (motions, jitter, loss, noise).
    hidden : HiddenEffects, optional
        Effects of the drivetrain beyond its backlash (a servo lag, a dead time, a load lag,
        an encoder offset, an output limit, a periodic error); none by default. They draw
        nothing from the random stream: the same seed gives the same motion, stamps, noise
        and losses with and without them.
    """
    cfg = OperationSettings() if settings is None else settings
    if not isinstance(cfg, OperationSettings):
        raise GenBacklashError(f"settings must be OperationSettings, got {cfg!r}")
    rng = np.random.default_rng([int(seed), 12])
    values, phase_starts = operation_commands(rng, cfg)
    return _driven_record(rng, cfg, seed, values, phase_starts, hidden)


def _driven_record(
    clock: np.random.Generator,
    cfg: OperationSettings,
    seed: int,
    values: FloatArray,
    phase_starts: tuple[tuple[str, float], ...],
    hidden: HiddenEffects | None = None,
) -> OperationRecord:
    """``cfg.model`` driven by the commands ``values`` (:func:`drive`, drawing the clocks,
    noise and losses from ``clock``), as an :class:`OperationRecord`."""
    cmd_t, t, u, x, y, received, c_left, c_right = drive(
        clock,
        values,
        cfg.model,
        command_rate=cfg.command_rate,
        encoder_rate=cfg.encoder_rate,
        command_jitter_ns=round(cfg.command_jitter * 1e9),
        stamp_jitter_ns=cfg.stamp_jitter * 1e9,
        wear=cfg.wear,
        noise=cfg.noise,
        quantum=cfg.quantum,
        loss=cfg.loss,
        hidden=hidden,
    )
    return OperationRecord(
        settings=cfg,
        seed=int(seed),
        command_t_ns=cmd_t,
        command_u=values,
        sample_t_ns=t,
        u_all=u,
        x_all=x,
        y_all=np.asarray(y, dtype=np.float64),
        received=received,
        c_left=c_left,
        c_right=c_right,
        phase_starts=phase_starts,
        hidden=hidden,
    )


def arm_records(
    models: tuple[GeneralBacklash, ...] | list[GeneralBacklash],
    settings: OperationSettings | None = None,
    seed: int = 0,
) -> list[OperationRecord]:
    """An arm of several drivetrains on one clock: one :class:`OperationRecord` per model.

    Each joint moves on its own (its commands drawn from its own stream, seeded by ``seed``
    and the joint's index) with its own backlash, but the commands, the readings' stamps and
    the lost readings are shared, as when one controller sends one command array and one
    encoder message holds every joint. ``settings.model`` is replaced by each joint's.

    >>> recs = arm_records([OPERATION_BACKLASH, worn(OPERATION_BACKLASH, 2.0)],
    ...                    OperationSettings(duration=2.0), seed=3)
    >>> bool((recs[0].sample_t_ns == recs[1].sample_t_ns).all())
    True
    >>> bool((recs[0].command_u != recs[1].command_u).any())
    True
    """
    base = OperationSettings() if settings is None else settings
    if not isinstance(base, OperationSettings):
        raise GenBacklashError(f"settings must be OperationSettings, got {base!r}")
    if len(models) == 0:
        raise GenBacklashError("arm_records needs at least one model")
    out: list[OperationRecord] = []
    for j, model in enumerate(models):
        cfg = dataclasses.replace(base, model=model)
        values, phase_starts = operation_commands(np.random.default_rng([int(seed), 12, j]), cfg)
        clock = np.random.default_rng([int(seed), 13])  # the same clocks and losses for all
        out.append(_driven_record(clock, cfg, seed, values, phase_starts))
    return out
