"""Inverse-backlash compensation: the feedforward command that cancels a general backlash.

Given a desired load position ``x_d(t)`` and a model, the compensator sends the command
``u(t)`` for which the modelled backlash output equals ``x_d(t)``. The output of the model
(eqs. 8-10, 13-15) is

    x(t) = L(u(t))  if u(t) <= z_L,   x(t-1)  if z_L <= u(t) <= z_R,   R(u(t))  if u(t) >= z_R,

with ``L(z_L) = R(z_R) = x(t-1)`` (eqs. 9-10, 14-15); for the paper's polynomial branches
(eqs. 11-12) this is the clamp ``x(t) = min(max(x(t-1), lo(u)), hi(u))`` with
``lo, hi = min/max(L(u), R(u))`` (the switching of eq. 20). Inverting it gives three cases:

* ``x_d > x(t-1)``: the lower branch must push the output up: solve ``lo(u) = x_d``
  (``R`` for increasing branches, ``L`` for decreasing ones);
* ``x_d < x(t-1)``: the upper branch must push it down: solve ``hi(u) = x_d``;
* ``x_d = x(t-1)``: any ``u`` in the hold interval ``[z_L, z_R]`` keeps the output; the
  compensator keeps its previous command (moved to the nearest edge if it left the interval).

A reversal of ``x_d`` therefore makes the command jump across the dead zone, by about
``c_L + c_R`` for an ideal unit-slope backlash. Each branch is inverted on its monotone part
inside the valid input range (a safeguarded Newton iteration on a bisection bracket); where
``x_d`` lies beyond what the branch reaches there, the range end is used.

On top of the exact inverse the compensator offers gap-crossing smoothing (the jump is spread
over a number of samples, like printer firmware's backlash smoothing), confidence gating (the
correction fades to the pass-through command ``u = x_d`` when the model is not trusted), and a
rate limit and output limits that always hold. The modelled output ``x`` in the state is
advanced with the command actually sent, so the compensator's picture of the gap stays right
whatever the limits, smoothing and gating did.

For a :class:`~genbacklash_core.Cascade` only the backlash is inverted: the linear block
belongs to the user's controller.

Two forms, which the tests hold equal: the pure :func:`compensate_step` (and its loop
:func:`compensate`) on a frozen :class:`CompensatorState`, and the stateful
:class:`InverseBacklash` with ``step(x_d, confidence)``.
"""

from __future__ import annotations

import bisect
import functools
import itertools
import math
import numbers
import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ._typing import ArrayLike, FloatArray
from .backlash import GeneralBacklash
from .cascade import Cascade
from .errors import GenBacklashError
from .structure import as_order

__all__ = [
    "CompensatorOptions",
    "CompensatorState",
    "InverseBacklash",
    "branch_inverse",
    "compensate",
    "compensate_step",
    "hold_interval",
    "invertible_range",
]

_EPS = sys.float_info.epsilon
_MAX = sys.float_info.max
_BIG = 1e300  # cap of a search bracket on an unbounded monotone piece
_HOLD_ULPS = 64.0  # |x_d - x| below this many ulps of the branch scale counts as "hold"
_TINY = 1e-290  # absolute floor of the root-finder's step tolerance
_MAX_ITER = 200  # Newton/bisection iterations; Newton converges in a handful
_PLAN_CACHE = 64  # models (with ranges) whose inversion plans are kept
_TABLE_NODES = 1024  # nodes of a branch's inverse table (cubic Hermite between them)
_TABLE_SPAN = 8.0  # an unbounded piece is tabled over -shift +- this * max(1, |shift|)
_POLISH_TOL = 1e-9  # a table guess is taken when its Newton step is below this * (1 + |u|)


# --------------------------------------------------------------------------- options, state


def _real(name: str, value: object) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise GenBacklashError(f"{name} must be a real number, got {value!r}")
    result = float(value)
    if math.isnan(result):
        raise GenBacklashError(f"{name} must not be NaN")
    return result


@dataclass(frozen=True)
class CompensatorOptions:
    """Limits, smoothing, gating and the inversion range of the compensator.

    Parameters
    ----------
    u_min, u_max : float
        Output limits; every command lies in ``[u_min, u_max]``. Default unlimited.
    max_rate : float
        Largest ``|u(t) - u(t-1)|`` per sample, ``> 0``. Default unlimited.
    smoothing : int
        Number of samples over which the jump across the gap at a reversal is spread;
        ``0`` jumps at once. During the ramp the command still follows the path, then it is
        the exact inverse again.
    gate_low, gate_high : float
        Confidence thresholds in ``[0, 1]``, ``gate_low <= gate_high``. The correction weight
        is ``w = clip((confidence - gate_low) / (gate_high - gate_low), 0, 1)`` (``w = 1`` when
        ``confidence >= gate_high``) and the command ``u = x_d + w (u_inverse - x_d)``: at
        ``w = 0`` the compensator passes ``x_d`` through. A NaN confidence counts as ``0``.
        The defaults (0.2, 0.5) match :attr:`Estimate.confidence <genbacklash_core.Estimate>`:
        full correction once an online estimate has converged (confidence >= 0.5), a fade
        while it converges, pass-through while it warms up or diverged (confidence 0).
    valid_range : (float, float) or None
        Input interval on which the model is trusted and its branches are inverted; ``None``
        uses the output limits. It is intersected with ``[u_min, u_max]``.

    Examples
    --------
    >>> options = CompensatorOptions(u_min=-2.0, u_max=2.0, gate_low=0.5, gate_high=1.0)
    >>> options.inversion_range
    (-2.0, 2.0)
    >>> options.weight(0.75), options.weight(0.2), options.weight(float("nan"))
    (0.5, 0.0, 0.0)
    """

    u_min: float = -math.inf
    u_max: float = math.inf
    max_rate: float = math.inf
    smoothing: int = 0
    gate_low: float = 0.2
    gate_high: float = 0.5
    valid_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        u_min, u_max = _real("u_min", self.u_min), _real("u_max", self.u_max)
        if not u_min < u_max:
            raise GenBacklashError(f"need u_min < u_max, got u_min={u_min} and u_max={u_max}")
        max_rate = _real("max_rate", self.max_rate)
        if not max_rate > 0:
            raise GenBacklashError(f"max_rate must be > 0, got {max_rate}")
        smoothing = as_order("smoothing", self.smoothing)
        if smoothing < 0:
            raise GenBacklashError(f"smoothing must be >= 0 samples, got {smoothing}")
        gate_low, gate_high = _real("gate_low", self.gate_low), _real("gate_high", self.gate_high)
        if not (0.0 <= gate_low <= 1.0 and 0.0 <= gate_high <= 1.0):
            raise GenBacklashError(
                f"gate_low and gate_high must lie in [0, 1], got {gate_low} and {gate_high}"
            )
        if gate_low > gate_high:
            raise GenBacklashError(
                f"need gate_low <= gate_high, got gate_low={gate_low} and gate_high={gate_high}"
            )
        valid_range = self.valid_range
        if valid_range is not None:
            try:
                low_raw, high_raw = valid_range
            except (TypeError, ValueError) as err:
                raise GenBacklashError(
                    f"valid_range must be a pair (low, high), got {valid_range!r}"
                ) from err
            low, high = _real("valid_range[0]", low_raw), _real("valid_range[1]", high_raw)
            if not low < high:
                raise GenBacklashError(f"valid_range needs low < high, got ({low}, {high})")
            if not (low < u_max and high > u_min):
                raise GenBacklashError(
                    f"valid_range ({low}, {high}) does not overlap the output limits "
                    f"[{u_min}, {u_max}]"
                )
            valid_range = (low, high)
        object.__setattr__(self, "u_min", u_min)
        object.__setattr__(self, "u_max", u_max)
        object.__setattr__(self, "max_rate", max_rate)
        object.__setattr__(self, "smoothing", smoothing)
        object.__setattr__(self, "gate_low", gate_low)
        object.__setattr__(self, "gate_high", gate_high)
        object.__setattr__(self, "valid_range", valid_range)

    @property
    def inversion_range(self) -> tuple[float, float]:
        """The input interval on which the branches are inverted (valid range within limits)."""
        if self.valid_range is None:
            return self.u_min, self.u_max
        return max(self.valid_range[0], self.u_min), min(self.valid_range[1], self.u_max)

    def weight(self, confidence: float) -> float:
        """Correction weight ``w`` in ``[0, 1]`` for a model confidence (NaN counts as 0)."""
        c = float(confidence)
        if not c == c:  # NaN: untrusted
            return 0.0
        if c >= self.gate_high:
            return 1.0
        if c <= self.gate_low:
            return 0.0
        return (c - self.gate_low) / (self.gate_high - self.gate_low)


@dataclass(frozen=True)
class CompensatorState:
    """What the compensator remembers between samples.

    Parameters
    ----------
    x : float
        Modelled backlash output after the last command sent (``x(t-1)`` of eq. 8); tells the
        compensator on which side of the gap the load sits.
    u : float
        Last command sent (after smoothing, gating, rate limit and output limits).
    u_inverse : float
        Last exact inverse command, before smoothing and gating; the command held in the gap.
    direction : int
        Last push of the inverse: ``+1`` up, ``-1`` down, ``0`` none yet.
    offset : float
        Part of the last gap-crossing jump still to be delivered (smoothing).
    ramp : int
        Samples left in the smoothing ramp; ``0`` when no ramp runs (then ``offset`` is 0).

    Use :meth:`initial` for a state at rest.
    """

    x: float
    u: float
    u_inverse: float
    direction: int = 0
    offset: float = 0.0
    ramp: int = 0

    def __post_init__(self) -> None:
        # fast path: finite Python floats and ints, as every step makes them
        if not _plain((self.x, self.u, self.u_inverse, self.direction, self.offset, self.ramp)):
            self._validate()

    def _validate(self) -> None:
        for name in ("x", "u", "u_inverse", "offset"):
            raw = getattr(self, name)
            if isinstance(raw, (bool, np.bool_)) or not isinstance(raw, numbers.Real):
                raise GenBacklashError(f"state {name} must be a real number, got {raw!r}")
            value = float(raw)
            if not math.isfinite(value):
                raise GenBacklashError(f"state {name} must be finite, got {value}")
            object.__setattr__(self, name, value)
        direction = as_order("direction", self.direction)
        if direction not in (-1, 0, 1):
            raise GenBacklashError(f"direction must be -1, 0 or +1, got {direction}")
        ramp = as_order("ramp", self.ramp)
        if ramp < 0:
            raise GenBacklashError(f"ramp must be >= 0, got {ramp}")
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "ramp", ramp)

    @classmethod
    def initial(
        cls,
        model: GeneralBacklash | Cascade,
        x0: float = 0.0,
        u0: float | None = None,
        options: CompensatorOptions | None = None,
    ) -> CompensatorState:
        """A state at rest: load at ``x0``, command ``u0``.

        ``u0`` defaults to the middle of the hold interval ``[z_L, z_R]`` of ``x0``
        (eqs. 9-10) within the output limits, i.e. the motor anywhere inside the gap.

        >>> bl = GeneralBacklash.ideal(1.0, 0.5, 0.5)
        >>> CompensatorState.initial(bl, x0=1.0)
        CompensatorState(x=1.0, u=1.0, u_inverse=1.0, direction=0, offset=0.0, ramp=0)
        """
        opts = _DEFAULT_OPTIONS if options is None else _as_options(options)
        x = _real("x0", x0)
        if not math.isfinite(x):
            raise GenBacklashError(f"x0 must be finite, got {x}")
        if u0 is None:
            z_left, z_right = hold_interval(model, x, opts)
            u = min(max(0.5 * z_left + 0.5 * z_right, opts.u_min), opts.u_max)
        else:
            u = _real("u0", u0)
            if not (math.isfinite(u) and opts.u_min <= u <= opts.u_max):
                raise GenBacklashError(
                    f"u0 must be finite and within [{opts.u_min}, {opts.u_max}], got {u}"
                )
        return cls(x=x, u=u, u_inverse=u)


_DEFAULT_OPTIONS = CompensatorOptions()


def _plain(memory: tuple[object, ...]) -> bool:
    """A state's fields in :class:`CompensatorState` order are finite Python floats and ints
    within range: a valid state as it stands (else :meth:`CompensatorState._validate`
    converts them or says why not)."""
    x, u, v, direction, offset, ramp = memory
    return (
        type(x) is float
        and type(u) is float
        and type(v) is float
        and type(offset) is float
        and type(direction) is int
        and type(ramp) is int
        and -_MAX <= x <= _MAX
        and -_MAX <= u <= _MAX
        and -_MAX <= v <= _MAX
        and -_MAX <= offset <= _MAX
        and -1 <= direction <= 1
        and ramp >= 0
    )


def _as_options(options: object) -> CompensatorOptions:
    if not isinstance(options, CompensatorOptions):
        raise GenBacklashError(f"options must be CompensatorOptions, got {options!r}")
    return options


def _backlash_of(model: object) -> GeneralBacklash:
    if isinstance(model, Cascade):
        return model.backlash  # the linear block is the user's controller's business
    if isinstance(model, GeneralBacklash):
        return model
    raise GenBacklashError(f"model must be a GeneralBacklash or a Cascade, got {model!r}")


# --------------------------------------------------------------------------- branch inversion


class _Branch:
    """One polynomial branch ``B(u) = sum_k m_k (u + shift)^k`` (eq. 11 with ``shift = c_L``,
    eq. 12 with ``shift = -c_R``) restricted to its monotone piece ``[a, b]``.
    """

    __slots__ = (
        "a",
        "abs_m",
        "abs_rev",
        "b",
        "ga",
        "gb",
        "lead",
        "low_max",
        "m",
        "rev",
        "sense",
        "shift",
        "table",
    )

    def __init__(
        self, m: tuple[float, ...], shift: float, sense: float, name: str, lo: float, hi: float
    ) -> None:
        self.m = m
        self.rev = m[-2::-1]  # Horner order, as evaluate_branch uses it
        self.abs_m = tuple(abs(c) for c in m)
        self.abs_rev = self.abs_m[-2::-1]
        self.shift = shift
        self.sense = sense
        effective = len(m)
        while m[effective - 1] == 0.0:  # m_1 != 0, so this stops
            effective -= 1
        self.lead = abs(m[effective - 1])
        self.low_max = max(self.abs_m[: effective - 1], default=0.0)
        self.a, self.b = self._monotone_piece(name, lo, hi)
        # sense-signed values at finite piece ends: g(u) = sense * B(u) increases on [a, b]
        self.ga = sense * self.value(self.a) if math.isfinite(self.a) else -math.inf
        self.gb = sense * self.value(self.b) if math.isfinite(self.b) else math.inf
        self.table: _InverseTable | None = None  # built at the first fast inversion

    def value(self, u: float) -> float:
        """``B(u)`` by Horner's rule with exactly the operations of ``evaluate_branch``."""
        s = u + self.shift  # eq. (16) / (17)
        acc = self.m[-1]
        for c in self.rev:
            acc = acc * s + c
        return acc * s  # eq. (11) / (12)

    def value_and_slope(self, u: float) -> tuple[float, float]:
        """``B(u)`` and ``B'(u)`` in one Horner pass."""
        s = u + self.shift
        p = self.m[-1]
        dp = 0.0
        for c in self.rev:
            dp = dp * s + p
            p = p * s + c
        return p * s, dp * s + p

    def magnitude(self, u: float) -> float:
        """``sum_k |m_k| |u + shift|^k``: the scale of the rounding error of :meth:`value`."""
        s = abs(u + self.shift)
        acc = self.abs_m[-1]
        for c in self.abs_rev:
            acc = acc * s + c
        return acc * s

    def _slope_sense(self, u: float) -> float:
        return self.value_and_slope(u)[1] * self.sense

    def _monotone_piece(self, name: str, lo: float, hi: float) -> tuple[float, float]:
        """The monotone piece (slope sign = model sense) of the branch inside ``[lo, hi]``,
        nearest the branch's zero crossing ``u = -shift``; merged over touching pieces.
        """
        derivative = [k * c for k, c in enumerate(self.m, 1)]  # dB/ds, ascending powers of s
        if not all(math.isfinite(d) for d in derivative):
            raise GenBacklashError(
                f"the {name} branch's coefficients are too large to invert it (its slope "
                "overflows float64)"
            )
        # leading terms too small to divide by cannot turn the slope where it is finite
        negligible = 1e-290 * max(abs(d) for d in derivative)
        while len(derivative) > 1 and abs(derivative[-1]) <= negligible:
            derivative.pop()
        cuts: list[float] = []
        if len(derivative) > 1:
            with np.errstate(all="ignore"):
                try:
                    roots = np.polynomial.polynomial.polyroots(derivative)
                except np.linalg.LinAlgError as err:
                    raise GenBacklashError(
                        f"cannot find the monotone part of the {name} branch: its coefficients "
                        "span too many orders of magnitude"
                    ) from err
            for root in roots:
                real, imag = float(np.real(root)), float(np.imag(root))
                if not math.isfinite(real):
                    continue
                if abs(imag) <= 1e-7 * max(1.0, abs(real)):
                    u = real - self.shift
                    if lo < u < hi:
                        cuts.append(u)
        edges = [lo, *sorted(cuts), hi]
        pieces: list[tuple[float, float]] = []
        for left, right in itertools.pairwise(edges):
            if not left < right:
                continue
            if math.isinf(left) and math.isinf(right):
                probe = -self.shift
            elif math.isinf(left):
                probe = right - 1.0 - abs(right)
            elif math.isinf(right):
                probe = left + 1.0 + abs(left)
            else:
                probe = 0.5 * left + 0.5 * right
            if self._slope_sense(probe) > 0.0:
                if pieces and pieces[-1][1] == left:  # a touching zero of the slope
                    pieces[-1] = (pieces[-1][0], right)
                else:
                    pieces.append((left, right))
        if not pieces:
            sense = "increasing" if self.sense > 0 else "decreasing"
            raise GenBacklashError(
                f"the {name} branch is not {sense} anywhere on the inversion range "
                f"[{lo}, {hi}]; the model cannot be inverted there"
            )
        anchor = -self.shift
        return min(pieces, key=lambda p: max(p[0] - anchor, anchor - p[1], 0.0))

    def invert(self, y: float, guess: float) -> float:
        """The ``u`` in ``[a, b]`` with ``B(u) = y``; the piece end where ``y`` is out of reach.

        Safeguarded Newton on a bisection bracket, started from ``guess`` (the previous
        command). The result is always finite.
        """
        sense = self.sense
        target = sense * y
        a, b = self.a, self.b
        if target <= self.ga:  # at or below what the branch reaches: lower end
            return a if math.isfinite(a) else -self.shift - _BIG
        if target >= self.gb:
            return b if math.isfinite(b) else -self.shift + _BIG
        if len(self.m) == 1:  # straight branch: the closed form, eq. (11)/(12) solved for u
            u = y / self.m[0] - self.shift
            if a <= u <= b and math.isfinite(u):
                return u
        if math.isinf(a) or math.isinf(b):
            # Cauchy's bound on the roots of B(u) - y in s = u + shift
            radius = min(1.0 + max(self.low_max, abs(y)) / self.lead, _BIG)
            if math.isinf(a):
                a = min(-self.shift - radius, b)
                if sense * self.value(a) >= target:
                    return a
            if math.isinf(b):
                b = max(-self.shift + radius, a)
                if sense * self.value(b) <= target:
                    return b
        u = guess if a < guess < b else 0.5 * a + 0.5 * b
        dx_old = dx = b - a
        for _ in range(_MAX_ITER):
            value, slope = self.value_and_slope(u)
            g = sense * value - target
            if g == 0.0:
                return u
            if g < 0.0:
                a = u
            else:
                b = u
            dg = sense * slope
            step = g / dg if dg > 0.0 else math.inf
            if abs(step) <= 2.0 * _EPS * abs(u) + _TINY:  # converged to about an ulp
                return u
            u_new = u - step
            if not (a < u_new < b) or abs(2.0 * step) > dx_old:  # Newton unsafe or slow
                u_new = 0.5 * a + 0.5 * b
                dx_old, dx = dx, abs(u_new - u)
                if u_new in (a, b):  # the bracket is down to adjacent floats
                    return u
            else:
                dx_old, dx = dx, abs(step)
            u = u_new
        return u

    def invert_fast(self, y: float, guess: float) -> float:
        """:meth:`invert` from a table: the same ``u`` to within a Newton step of
        ``_POLISH_TOL * (1 + |u|)`` (in practice to the last few ulps).

        The inverse function ``u = B^{-1}(y)`` of the monotone piece (eqs. 11-12 solved for
        ``u``) is tabled once at ``_TABLE_NODES`` nodes with its slope ``1 / B'(u)``; a
        target is looked up (bisection on the node values), interpolated by the cubic
        Hermite polynomial of its interval and polished by one Newton step on ``B(u) = y``.
        A target outside the table, an interval where the slope vanishes, or a step larger
        than the tolerance takes :meth:`invert` (from the table's guess).
        """
        if len(self.m) == 1:  # straight: the closed form in invert is faster still
            return self.invert(y, guess)
        table = self.table
        if table is None:
            table = self.table = _InverseTable(self)
        u = table.guess(self.sense * y)
        if u != u:  # NaN: no table guess there
            return self.invert(y, guess)
        value, slope = self.value_and_slope(u)
        step = (value - y) / slope if slope != 0.0 else math.inf  # Newton on B(u) = y
        u_new = u - step
        if abs(step) <= _POLISH_TOL * (1.0 + abs(u)) and self.a <= u_new <= self.b:
            return u_new
        return self.invert(y, u)

    def values(self, u: FloatArray) -> FloatArray:
        """:meth:`value` of many inputs (the same operations, elementwise)."""
        s = u + self.shift  # eq. (16) / (17)
        acc = np.full_like(s, self.m[-1])
        for c in self.rev:
            acc = acc * s + c
        return np.asarray(acc * s, dtype=np.float64)  # eq. (11) / (12)

    def values_and_slopes(self, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """:meth:`value_and_slope` of many inputs (the same operations, elementwise; an
        overflow gives inf or NaN, no warning)."""
        with np.errstate(all="ignore"):
            s = u + self.shift
            p = np.full_like(s, self.m[-1])
            dp = np.zeros_like(s)
            for c in self.rev:  # value and slope in one Horner pass
                dp = dp * s + p
                p = p * s + c
            return p * s, dp * s + p

    def invert_many(self, y: FloatArray) -> FloatArray:
        """:meth:`invert_fast` of many targets at once (numpy steps; the targets the table
        cannot take are inverted one by one)."""
        out = np.empty(y.shape, dtype=np.float64)
        if len(self.m) == 1:
            for k, target in enumerate(y.tolist()):
                out[k] = self.invert(target, 0.0)
            return out
        table = self.table
        if table is None:
            table = self.table = _InverseTable(self)
        with np.errstate(all="ignore"):
            u = table.guesses(self.sense * y)
            value, slope = self.values_and_slopes(u)
            step = (value - y) / slope
            u_new = u - step
            good = (
                (np.abs(step) <= _POLISH_TOL * (1.0 + np.abs(u)))
                & (u_new >= self.a)
                & (u_new <= self.b)
            )
        out[good] = u_new[good]
        for k in np.flatnonzero(~good).tolist():
            guess = float(u[k]) if math.isfinite(u[k]) else 0.0
            out[k] = self.invert(float(y[k]), guess)
        return out


class _InverseTable:
    """Nodes of a branch's inverse function ``u(g)``, ``g = sense * B(u)`` increasing, with
    its slopes ``du/dg = 1 / g'(u)``: a cubic Hermite guess of :meth:`_Branch.invert`.

    The nodes are equally spaced in ``u`` over the monotone piece ``[a, b]`` (an unbounded
    end cut at ``-shift -+ _TABLE_SPAN * max(1, |shift|)``).
    """

    __slots__ = ("du", "du_list", "g", "g_list", "u", "u_list")

    def __init__(self, branch: _Branch) -> None:
        width = _TABLE_SPAN * max(1.0, abs(branch.shift))
        lo = branch.a if math.isfinite(branch.a) else -branch.shift - width
        hi = branch.b if math.isfinite(branch.b) else -branch.shift + width
        lo, hi = max(lo, -branch.shift - _BIG), min(hi, -branch.shift + _BIG)
        u = np.linspace(lo, hi, _TABLE_NODES) if lo < hi else np.array([lo])
        value, slope = branch.values_and_slopes(u)
        g = branch.sense * value  # eq. (11) / (12), sense-signed: increasing
        slope = branch.sense * slope
        usable = np.isfinite(g) & np.isfinite(slope)
        # the table holds where g strictly increases and the slope is positive; elsewhere
        # (a turning point at a piece end, an overflow) the guess is NaN
        if not usable.all() or np.any(np.diff(g) <= 0.0):
            keep = usable & (slope > 0.0)
            u, g, slope = u[keep], g[keep], slope[keep]
            rising = np.concatenate((np.ones(min(g.size, 1), dtype=bool), np.diff(g) > 0.0))
            u, g, slope = u[rising], g[rising], slope[rising]  # none usable: an empty table
        self.u = u
        self.g = g
        # a subnormal slope overflows to inf, as a zero one gives: no step through it
        with np.errstate(divide="ignore", over="ignore"):
            self.du = np.where(slope > 0.0, 1.0 / slope, np.inf)  # du/dg = 1 / g'(u)
        self.u_list: list[float] = u.tolist()
        self.g_list: list[float] = g.tolist()
        self.du_list: list[float] = self.du.tolist()

    def guess(self, target: float) -> float:
        """The Hermite guess of ``u(target)`` (NaN outside the table or where it fails)."""
        g = self.g_list
        k = bisect.bisect_right(g, target) - 1
        if k < 0 or k >= len(g) - 1:
            return math.nan
        g0, g1 = g[k], g[k + 1]
        h = g1 - g0
        t = (target - g0) / h
        u0, u1 = self.u_list[k], self.u_list[k + 1]
        m0, m1 = self.du_list[k] * h, self.du_list[k + 1] * h
        if not (m0 < math.inf and m1 < math.inf):
            return math.nan
        t2 = t * t
        t3 = t2 * t
        return (
            (2.0 * t3 - 3.0 * t2 + 1.0) * u0
            + (t3 - 2.0 * t2 + t) * m0
            + (3.0 * t2 - 2.0 * t3) * u1
            + (t3 - t2) * m1
        )

    def guesses(self, target: FloatArray) -> FloatArray:
        """:meth:`guess` of many targets."""
        g = self.g
        k = np.searchsorted(g, target, side="right") - 1
        inside = (k >= 0) & (k < g.size - 1)
        k = np.clip(k, 0, max(g.size - 2, 0))
        if g.size < 2:
            return np.full(target.shape, np.nan)
        g0, g1 = g[k], g[k + 1]
        h = g1 - g0
        t = (target - g0) / h
        m0, m1 = self.du[k] * h, self.du[k + 1] * h
        t2 = t * t
        t3 = t2 * t
        u = (
            (2.0 * t3 - 3.0 * t2 + 1.0) * self.u[k]
            + (t3 - 2.0 * t2 + t) * m0
            + (3.0 * t2 - 2.0 * t3) * self.u[k + 1]
            + (t3 - t2) * m1
        )
        return np.where(inside & np.isfinite(u), u, np.nan)


class _Plan:
    """Both branches of a backlash prepared for inversion on one input range."""

    __slots__ = ("down", "left", "right", "up")

    def __init__(self, backlash: GeneralBacklash, lo: float, hi: float) -> None:
        sense = backlash.sign
        self.left = _Branch(backlash.m_left, backlash.c_left, sense, "left", lo, hi)
        self.right = _Branch(backlash.m_right, -backlash.c_right, sense, "right", lo, hi)
        # the lower branch lifts the output, the upper one lowers it (eq. 8 / play_bounds):
        # R below L for increasing branches, L below R for decreasing ones
        self.up, self.down = (self.right, self.left) if sense > 0 else (self.left, self.right)

    def clamp(self, x: float, u: float) -> float:
        """The play-operator step ``min(max(x, lo(u)), hi(u))`` (eqs. 13, 20)."""
        left, right = self.left.value(u), self.right.value(u)
        lo, hi = min(left, right), max(left, right)
        if x < lo:
            x = lo
        if x > hi:
            x = hi
        return min(max(x, -_MAX), _MAX)  # saturate rather than carry an infinity


@functools.lru_cache(maxsize=_PLAN_CACHE)
def _plan(backlash: GeneralBacklash, lo: float, hi: float) -> _Plan:
    return _Plan(backlash, lo, hi)


def _plan_for(model: object, options: CompensatorOptions) -> _Plan:
    lo, hi = options.inversion_range
    return _plan(_backlash_of(model), lo, hi)


def hold_interval(
    model: GeneralBacklash | Cascade, x: float, options: CompensatorOptions | None = None
) -> tuple[float, float]:
    """The hold interval ``[z_L, z_R]`` of output ``x``: ``L(z_L) = R(z_R) = x`` (eqs. 9-10).

    Commands inside it keep the output at ``x``; its width is the gap the command must
    cross on a reversal. Inverted on the options' inversion range (ends where out of reach).

    Examples
    --------
    >>> hold_interval(GeneralBacklash.ideal(1.0, 0.3, 0.5), 1.0)
    (0.7, 1.5)
    """
    opts = _DEFAULT_OPTIONS if options is None else _as_options(options)
    plan = _plan_for(model, opts)
    y = _real("x", x)
    z_left = plan.left.invert(y, 0.0)
    z_right = plan.right.invert(y, 0.0)
    return min(z_left, z_right), max(z_left, z_right)


def branch_inverse(
    model: GeneralBacklash | Cascade,
    x: ArrayLike,
    push: int,
    options: CompensatorOptions | None = None,
) -> FloatArray:
    """The commands that push the backlash output to ``x`` along one branch (vectorised).

    ``push = +1``: the lifting branch, ``lo(u) = x`` (``R`` of eq. 12 for increasing branches,
    ``L`` of eq. 11 for decreasing ones): the command that drives the load up to ``x``, i.e.
    ``z_R`` of eq. (10) for increasing branches. ``push = -1``: the lowering branch,
    ``hi(u) = x``. Each branch is inverted on its monotone piece inside the options'
    inversion range, the piece end where ``x`` is out of reach, as :class:`InverseBacklash`
    does: from a table of the inverse function, a cubic Hermite guess polished by one
    Newton step (the root solve where the table cannot vouch for it), in numpy steps. The
    result agrees with the root solve to far better than ``1e-9`` of the range.

    Parameters
    ----------
    model : GeneralBacklash or Cascade
        Of a cascade only the backlash is inverted.
    x : array_like
        Desired outputs (finite).
    push : {+1, -1}
        The direction the branch pushes the output.
    options : CompensatorOptions, optional
        Only the inversion range is used.

    Returns
    -------
    ndarray
        The commands, the shape of ``x``.

    Examples
    --------
    >>> bl = GeneralBacklash.ideal(1.0, 0.3, 0.5)
    >>> branch_inverse(bl, [0.0, 1.0], +1).tolist()  # R(u) = u - 0.5
    [0.5, 1.5]
    >>> branch_inverse(bl, [0.0, 1.0], -1).round(12).tolist()  # L(u) = u + 0.3
    [-0.3, 0.7]
    """
    if push not in (1, -1) or isinstance(push, bool):
        raise GenBacklashError(f"push must be +1 or -1, got {push!r}")
    opts = _DEFAULT_OPTIONS if options is None else _as_options(options)
    plan = _plan_for(model, opts)
    try:
        target = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise GenBacklashError("x must be a numeric array") from err
    if not np.all(np.isfinite(target)):
        raise GenBacklashError("x must be finite")
    branch = plan.up if push > 0 else plan.down
    flat = target.reshape(-1)
    return branch.invert_many(flat).reshape(target.shape)


def invertible_range(
    model: GeneralBacklash | Cascade, options: CompensatorOptions | None = None
) -> tuple[float, float]:
    """The inputs on which both branches are inverted: their monotone pieces' overlap.

    Each branch is inverted on its monotone piece (slope of the model's sense) inside the
    options' inversion range, the one nearest its zero crossing: the pieces
    :func:`branch_inverse`, :func:`hold_interval` and :class:`InverseBacklash` use. This is
    where both are; an end is infinite where a branch is monotone without bound. Whether the
    branches stay apart there is a separate question
    (:meth:`GeneralBacklash.crossings <genbacklash_core.GeneralBacklash.crossings>`).
    Raises :class:`GenBacklashError` when the pieces do not overlap.

    Examples
    --------
    >>> invertible_range(GeneralBacklash.ideal(1.0, 0.3, 0.5))
    (-inf, inf)
    >>> low, high = invertible_range(GeneralBacklash((1.0, 0.0, -1.0), 0.1, (1.0, 0.0, -1.0), 0.1))
    >>> round(low, 6), round(high, 6)  # the slopes 1 - 3 (u +/- 0.1)^2 vanish at +/-(1/3^0.5 - 0.1)
    (-0.47735, 0.47735)
    """
    opts = _DEFAULT_OPTIONS if options is None else _as_options(options)
    plan = _plan_for(model, opts)
    low, high = max(plan.left.a, plan.right.a), min(plan.left.b, plan.right.b)
    if not low < high:
        raise GenBacklashError(
            f"the branches' monotone parts do not overlap (left on [{plan.left.a:.6g}, "
            f"{plan.left.b:.6g}], right on [{plan.right.a:.6g}, {plan.right.b:.6g}]): no input "
            "inverts both"
        )
    return low, high


# --------------------------------------------------------------------------- the step


_Memory = tuple[float, float, float, int, float, int]
"""A :class:`CompensatorState` as a plain tuple, in its field order (the loops' form)."""


def _memory_of(state: CompensatorState) -> _Memory:
    return (state.x, state.u, state.u_inverse, state.direction, state.offset, state.ramp)


def _step(
    plan: _Plan,
    state: CompensatorState,
    x_d: float,
    options: CompensatorOptions,
    confidence: float,
) -> tuple[float, CompensatorState]:
    u, after = _advance(plan, _memory_of(state), x_d, options, confidence)
    return u, CompensatorState(*after)


def _advance(
    plan: _Plan,
    memory: _Memory,
    x_d: float,
    options: CompensatorOptions,
    confidence: float,
) -> tuple[float, _Memory]:
    """One step of the compensator on the state as a tuple (:func:`_step` without building
    a :class:`CompensatorState`; the loops keep the tuple between samples)."""
    x, u_prev, v_prev, direction, offset, ramp = memory
    if not math.isfinite(x_d):  # no usable target: hold the previous command
        u = min(max(u_prev, options.u_min), options.u_max)
        return u, (plan.clamp(x, u), u, v_prev, direction, offset, ramp)
    up, down = plan.up, plan.down
    # Which case of eq. (8): push up (lower branch), push down (upper branch) or hold.
    scale = max(abs(x), abs(x_d), plan.left.magnitude(v_prev), plan.right.magnitude(v_prev))
    tol = _HOLD_ULPS * _EPS * min(scale, _MAX)
    if x_d - x > tol:
        push = 1
        v = up.invert_fast(x_d, v_prev)  # lo(v) = x_d: R for increasing branches (eq. 12)
    elif x - x_d > tol:
        push = -1
        v = down.invert_fast(x_d, v_prev)  # hi(v) = x_d: L for increasing branches (eq. 11)
    else:  # hold inside the gap (eq. 8, middle case): keep v_prev if it keeps x
        push = 0
        left, right = plan.left.value(v_prev), plan.right.value(v_prev)
        if min(left, right) - x_d > tol:  # v_prev beyond z of the lifting branch
            v = up.invert_fast(x_d, v_prev)
        elif x_d - max(left, right) > tol:
            v = down.invert_fast(x_d, v_prev)
        else:
            v = v_prev

    # Gap-crossing smoothing: a new push direction starts a linear ramp of the jump.
    if push != 0:
        if push != direction and options.smoothing > 0:
            offset = v - (v_prev - offset)  # the whole jump from the last smoothed command
            ramp = options.smoothing
            if not math.isfinite(offset):  # a jump beyond the float range: taken at once
                offset, ramp = 0.0, 0
        direction = push
    if ramp > 0:
        offset -= offset / ramp  # deliver 1/ramp of what is left; exactly 0 at the last
        ramp -= 1
    command = v - offset

    # Confidence gating: fade to pass-through u = x_d.
    w = options.weight(confidence)
    if w >= 1.0:
        u = command
    elif w <= 0.0:
        u = x_d
    else:
        u = x_d + w * (command - x_d)
    if not math.isfinite(u):
        u = u_prev
    # Rate limit, then output limits (the limits win if the previous command was outside).
    rate = options.max_rate
    if u - u_prev > rate:
        u = u_prev + rate
        while u - u_prev > rate:  # undo a rounding up of u_prev + rate
            u = math.nextafter(u, u_prev)
    elif u_prev - u > rate:
        u = u_prev - rate
        while u_prev - u > rate:
            u = math.nextafter(u, u_prev)
    if u < options.u_min:
        u = options.u_min
    elif u > options.u_max:
        u = options.u_max
    # Advance the modelled output with the command actually sent (eq. 20).
    return u, (plan.clamp(x, u), u, v, direction, offset, ramp)


def _same_float(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same number, a zero's sign included (``0.0 == -0.0`` alone
    would let a step's output take the other zero's sign)."""
    return a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))


def _same_memory(a: _Memory, b: _Memory) -> bool:
    """Two states as tuples are the same bit for bit (zeros' signs included)."""
    return (
        a == b
        and _same_float(a[0], b[0])
        and _same_float(a[1], b[1])
        and _same_float(a[2], b[2])
        and _same_float(a[4], b[4])
    )


def _as_float(name: str, value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as err:
        raise GenBacklashError(f"{name} must be a number, got {value!r}") from err


def compensate_step(
    model: GeneralBacklash | Cascade,
    state: CompensatorState,
    x_d: float,
    options: CompensatorOptions | None = None,
    confidence: float = 1.0,
) -> tuple[float, CompensatorState]:
    """One sample of the inverse-backlash compensator (pure function).

    Parameters
    ----------
    model : GeneralBacklash or Cascade
        The model; of a cascade only the backlash is inverted.
    state : CompensatorState
        State after the previous sample (:meth:`CompensatorState.initial` to start).
    x_d : float
        Desired backlash output. A non-finite value holds the previous command.
    options : CompensatorOptions, optional
    confidence : float
        Trust in the model, gated by ``options.gate_low``/``gate_high``.

    Returns
    -------
    u : float
        The command to send; finite, within the limits and the rate limit.
    state : CompensatorState
        The next state; its ``x`` is the modelled output under ``u``.

    Examples
    --------
    >>> bl = GeneralBacklash.ideal(1.0, 0.5, 0.5)
    >>> state = CompensatorState.initial(bl)
    >>> u, state = compensate_step(bl, state, 1.0)  # push up: R(u) = u - 0.5 = 1
    >>> u, state.x
    (1.5, 1.0)
    >>> u, state = compensate_step(bl, state, 0.9)  # reversal: jump to L(u) = u + 0.5 = 0.9
    >>> round(u, 12)
    0.4
    """
    opts = _DEFAULT_OPTIONS if options is None else _as_options(options)
    if not isinstance(state, CompensatorState):
        raise GenBacklashError(f"state must be a CompensatorState, got {state!r}")
    return _step(
        _plan_for(model, opts),
        state,
        _as_float("x_d", x_d),
        opts,
        _as_float("confidence", confidence),
    )


def _series(x_d: ArrayLike, confidence: ArrayLike) -> tuple[list[float], list[float]]:
    try:
        target = np.asarray(x_d, dtype=np.float64)
        trust = np.asarray(confidence, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise GenBacklashError("x_d and confidence must be numeric arrays") from err
    if target.ndim != 1:
        raise GenBacklashError(f"x_d must be one-dimensional, got shape {target.shape}")
    try:
        trust = np.broadcast_to(trust, target.shape)
    except ValueError as err:
        raise GenBacklashError(
            f"confidence of shape {trust.shape} does not fit x_d of shape {target.shape}"
        ) from err
    return target.tolist(), trust.tolist()


def compensate(
    model: GeneralBacklash | Cascade,
    x_d: ArrayLike,
    options: CompensatorOptions | None = None,
    confidence: ArrayLike = 1.0,
    state: CompensatorState | None = None,
) -> FloatArray:
    """Compensated commands for a whole desired path (loops :func:`compensate_step`).

    Parameters
    ----------
    model : GeneralBacklash or Cascade
    x_d : array_like, shape (N,)
        Desired backlash output; non-finite samples hold the previous command.
    options : CompensatorOptions, optional
    confidence : float or array_like, shape (N,)
    state : CompensatorState, optional
        Start state; default :meth:`CompensatorState.initial` (load at rest at ``x = 0``,
        as :func:`~genbacklash_core.simulate_backlash` starts by default).

    Returns
    -------
    ndarray, shape (N,)
        The commands ``u``; the modelled backlash driven by them follows ``x_d``.

    Examples
    --------
    >>> from genbacklash_core import simulate_backlash
    >>> bl = GeneralBacklash((0.5, -0.3, 0.3), 0.7, (0.6, 0.4, 0.2), 0.8)
    >>> x_d = [0.2, 0.6, 0.6, 0.1, -0.4, 0.0]
    >>> u = compensate(bl, x_d)
    >>> np.allclose(simulate_backlash(bl, u), x_d, rtol=0, atol=1e-12)
    True
    """
    opts = _DEFAULT_OPTIONS if options is None else _as_options(options)
    plan = _plan_for(model, opts)
    current = CompensatorState.initial(model, options=opts) if state is None else state
    if not isinstance(current, CompensatorState):
        raise GenBacklashError(f"state must be a CompensatorState, got {current!r}")
    targets, trusts = _series(x_d, confidence)
    out = np.empty(len(targets))
    memory = _memory_of(current)
    for t, (target, trust) in enumerate(zip(targets, trusts, strict=True)):
        out[t], memory = _advance(plan, memory, target, opts, trust)
    return out


# --------------------------------------------------------------------------- stateful form


class InverseBacklash:
    """Stateful inverse-backlash compensator: a feedforward block for a control loop.

    Parameters
    ----------
    model : GeneralBacklash or Cascade
        Of a cascade only the backlash is inverted.
    options : CompensatorOptions, optional
    x0 : float
        Initial load position (modelled backlash output).
    u0 : float, optional
        Initial command; default the middle of the hold interval of ``x0``.

    Examples
    --------
    >>> comp = InverseBacklash(GeneralBacklash.ideal(1.0, 0.5, 0.5))
    >>> [comp.step(x) for x in (0.5, 1.0, 1.0)]
    [1.0, 1.5, 1.5]
    >>> round(comp.step(0.8), 12)  # reversal: across the gap of width 1
    0.3
    >>> comp.set_model(GeneralBacklash.ideal(1.0, 0.4, 0.4))  # an online estimate arrives
    >>> round(comp.step(0.8), 12), comp.state.x
    (0.4, 0.8)
    """

    def __init__(
        self,
        model: GeneralBacklash | Cascade,
        options: CompensatorOptions | None = None,
        x0: float = 0.0,
        u0: float | None = None,
    ) -> None:
        self._options = _DEFAULT_OPTIONS if options is None else _as_options(options)
        self._plan = _plan_for(model, self._options)
        self._model = model
        # the state as a tuple (what the steps take and give), and as a CompensatorState
        # once asked for (None: not built yet; a step on a node's command does not build it)
        state = CompensatorState.initial(model, x0, u0, self._options)
        self._memory: _Memory = _memory_of(state)
        self._snapshot: CompensatorState | None = state
        # a settled step of the last run: (its state, target, confidence, command)
        self._repeat: tuple[_Memory, float, float, float] | None = None
        # the same for the last step() (bit for bit: its own, the run's compares by value)
        self._held: tuple[_Memory, float, float, float] | None = None

    @property
    def model(self) -> GeneralBacklash | Cascade:
        """The model in use."""
        return self._model

    @property
    def options(self) -> CompensatorOptions:
        """The options in use."""
        return self._options

    @property
    def state(self) -> CompensatorState:
        """The current state (a frozen snapshot; assign a state to continue from it)."""
        state = self._snapshot
        if state is None:
            self._snapshot = state = CompensatorState(*self._memory)
        return state

    @state.setter
    def state(self, value: CompensatorState) -> None:
        if not isinstance(value, CompensatorState):
            raise GenBacklashError(f"state must be a CompensatorState, got {value!r}")
        if value is not self._snapshot:
            self._snapshot, self._memory = value, _memory_of(value)

    def set_model(self, model: GeneralBacklash | Cascade) -> None:
        """Replace the model while running; the state carries over.

        Raises (and keeps the old model) when the new one cannot be inverted on the range.
        """
        self._plan = _plan_for(model, self._options)
        self._model = model
        self._repeat = self._held = None  # a step of the old plan

    def reset(self, x0: float = 0.0, u0: float | None = None) -> None:
        """Restart at rest: load at ``x0``, command ``u0`` (as :meth:`CompensatorState.initial`)."""
        state = CompensatorState.initial(self._model, x0, u0, self._options)
        self._snapshot, self._memory = state, _memory_of(state)

    def step(self, x_d: float, confidence: float = 1.0) -> float:
        """The command for one desired output sample; see :func:`compensate_step`.

        A step is a function of (state, target, confidence): a held target on a state the
        last step left unchanged gives the same command and state again, so it is not
        recomputed (as :meth:`steps` does; a node's held commands).
        """
        target = _as_float("x_d", x_d)
        trust = _as_float("confidence", confidence)
        memory = self._memory
        held = self._held
        if (
            held is not None
            and held[0] is memory
            and _same_float(target, held[1])
            and _same_float(trust, held[2])
        ):
            return held[3]
        u, after = _advance(self._plan, memory, target, self._options, trust)
        if _plain(after):  # a valid state as it is: built only when asked for
            self._snapshot = None
        else:  # what CompensatorState makes of it (converted, or why not raised)
            state = CompensatorState(*after)
            self._snapshot, after = state, _memory_of(state)
        self._memory = after
        self._held = (after, target, trust, u) if _same_memory(after, memory) else None
        return u

    def run(self, x_d: ArrayLike, confidence: ArrayLike = 1.0) -> FloatArray:
        """Commands for a block of samples, continuing from (and advancing) the state."""
        targets, trusts = _series(x_d, confidence)
        return np.array(self._run(targets, trusts), dtype=np.float64)

    def steps(self, x_d: Sequence[float], confidence: float = 1.0) -> list[float]:
        """:meth:`step` for each of ``x_d`` in turn, at one ``confidence``: the commands.

        The form for a caller with Python floats at hand (the node's batch path); the same
        commands and state as the calls one by one.

        >>> comp = InverseBacklash(GeneralBacklash.ideal(1.0, 0.5, 0.5))
        >>> comp.steps([0.5, 1.0, 1.0])
        [1.0, 1.5, 1.5]
        """
        targets = [_as_float("x_d", x) for x in x_d]
        trust = _as_float("confidence", confidence)
        return self._run(targets, [trust] * len(targets))

    def _run(self, targets: list[float], trusts: list[float]) -> list[float]:
        memory = start = self._memory
        plan, options = self._plan, self._options
        out = []
        # A step is a function of (state, target, confidence): a held command on a state the
        # step left unchanged gives the same command and state again (a dwell's repeats).
        # ``settled``: (target, confidence, command) of such a step, from the last run too
        # while its state is still the current one and the plan the same.
        repeat = self._repeat
        settled = repeat[1:] if repeat is not None and repeat[0] is start else None
        for target, trust in zip(targets, trusts, strict=True):
            if settled is not None and target == settled[0] and trust == settled[1]:
                out.append(settled[2])
                continue
            u, after = _advance(plan, memory, target, options, trust)
            settled = (target, trust, u) if after == memory else None
            memory = after
            out.append(u)
        if _plain(memory):  # a valid state as it is: built only when asked for (as step)
            self._snapshot = None
            memory = (*memory,)  # a new state object, as a snapshot's would be
        else:  # what CompensatorState makes of it (converted, or why not raised)
            state = CompensatorState(*memory)
            self._snapshot, memory = state, _memory_of(state)
        self._memory = memory
        self._repeat = None if settled is None else (memory, *settled)
        return out
