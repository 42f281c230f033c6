"""Each branch of a general backlash inverted on its monotone piece (eqs. 11-12): a
safeguarded Newton iteration on a bisection bracket, started from a cubic Hermite table;
the hold interval of an output (eqs. 9-10) and the range on which both branches invert.
"""

from __future__ import annotations

import bisect
import functools
import itertools
import math
import sys

import numpy as np

from genbacklash_core._typing import ArrayLike, FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade, backlash_of
from genbacklash_core.errors import GenBacklashError

from .options import DEFAULT_OPTIONS, CompensatorOptions, as_options, real_number

EPS = sys.float_info.epsilon
MAX = sys.float_info.max
_BIG = 1e300  # cap of a search bracket on an unbounded monotone piece
HOLD_ULPS = 64.0  # |x_d - x| below this many ulps of the branch scale counts as "hold"
_TINY = 1e-290  # absolute floor of the root-finder's step tolerance
_MAX_ITER = 200  # Newton/bisection iterations; Newton converges in a handful
_PLAN_CACHE = 64  # models (with ranges) whose inversion plans are kept
_TABLE_NODES = 1024  # nodes of a branch's inverse table (cubic Hermite between them)
_TABLE_SPAN = 8.0  # an unbounded piece is tabled over -shift +- this * max(1, |shift|)
_POLISH_TOL = 1e-9  # a table guess is taken when its Newton step is below this * (1 + |u|)


# --------------------------------------------------------------------------- branch inversion


class Branch:
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
        self.table: InverseTable | None = None  # built at the first fast inversion

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
            if abs(step) <= 2.0 * EPS * abs(u) + _TINY:  # converged to about an ulp
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
            table = self.table = InverseTable(self)
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
            table = self.table = InverseTable(self)
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


class InverseTable:
    """Nodes of a branch's inverse function ``u(g)``, ``g = sense * B(u)`` increasing, with
    its slopes ``du/dg = 1 / g'(u)``: a cubic Hermite guess of :meth:`Branch.invert`.

    The nodes are equally spaced in ``u`` over the monotone piece ``[a, b]`` (an unbounded
    end cut at ``-shift -+ _TABLE_SPAN * max(1, |shift|)``).
    """

    __slots__ = ("du", "du_list", "g", "g_list", "u", "u_list")

    def __init__(self, branch: Branch) -> None:
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


class Plan:
    """Both branches of a backlash prepared for inversion on one input range."""

    __slots__ = ("down", "left", "right", "up")

    def __init__(self, backlash: GeneralBacklash, lo: float, hi: float) -> None:
        sense = backlash.sign
        self.left = Branch(backlash.m_left, backlash.c_left, sense, "left", lo, hi)
        self.right = Branch(backlash.m_right, -backlash.c_right, sense, "right", lo, hi)
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
        return min(max(x, -MAX), MAX)  # saturate rather than carry an infinity


@functools.lru_cache(maxsize=_PLAN_CACHE)
def inversion_plan(backlash: GeneralBacklash, lo: float, hi: float) -> Plan:
    return Plan(backlash, lo, hi)


def plan_for(model: object, options: CompensatorOptions) -> Plan:
    lo, hi = options.inversion_range
    return inversion_plan(backlash_of(model), lo, hi)


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
    opts = DEFAULT_OPTIONS if options is None else as_options(options)
    plan = plan_for(model, opts)
    y = real_number("x", x)
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
    opts = DEFAULT_OPTIONS if options is None else as_options(options)
    plan = plan_for(model, opts)
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
    opts = DEFAULT_OPTIONS if options is None else as_options(options)
    plan = plan_for(model, opts)
    low, high = max(plan.left.a, plan.right.a), min(plan.left.b, plan.right.b)
    if not low < high:
        raise GenBacklashError(
            f"the branches' monotone parts do not overlap (left on [{plan.left.a:.6g}, "
            f"{plan.left.b:.6g}], right on [{plan.right.a:.6g}, {plan.right.b:.6g}]): no input "
            "inverts both"
        )
    return low, high
