"""What a record of normal operation is made of: the drivetrains' backlash, the motion, clocks
and encoder (:class:`OperationSettings`) and the effects a record may hide
(:class:`HiddenEffects`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import FloatArray, IntArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.errors import GenBacklashError

# A mildly curved backlash with a few degrees of play each side (radians, load side; the
# command is the motor position over the gear ratio): c_L 2.6 deg, c_R 2.9 deg.
OPERATION_BACKLASH = GeneralBacklash((1.0, 0.03, -0.015), 0.045, (1.0, 0.025, -0.012), 0.05)
# The same play with straight branches (the ideal backlash of eq. 1, degree 1).
STRAIGHT_BACKLASH = GeneralBacklash((1.0,), 0.045, (1.0,), 0.05)

PHASE_KINDS = ("operation", "one_way", "pick_and_place", "sine_sweep")


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
