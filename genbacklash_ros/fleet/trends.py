"""Wear trends: a drivetrain's gap against time, a fitted line, the date it crosses a limit.

For one drivetrain with gaps ``g_i +- s_i`` (the batch estimates' ``gap`` and ``gap_std``) at
times ``t_i`` (days since the first), :func:`fit_trend` fits ``g = a + b t`` by weighted
least squares (weights ``1 / s_i^2``). The standard deviations of single bags assume white
residuals and are a lower bound (:mod:`genbacklash_ros.fleet.uncertainty`), so they set only
the relative weights: the covariance of ``(a, b)`` is scaled by ``chi^2 / (n - 2)``, the
scatter the points actually show about the line (the regression with an unknown noise
scale; the Birge ratio squared), and intervals use Student's t with ``n - 2`` degrees of
freedom. With normal scatter the crossing interval then has its nominal coverage
(``tests/ros/fleet/test_trends.py`` checks it).

The limit ``L`` is crossed at ``t* = (L - a) / b`` (only for ``b > 0``). Its interval is
Fieller's: the times ``t`` at which the line's confidence band contains ``L``, i.e. the
roots of ``(a + b t - L)^2 = q^2 var(a + b t)`` with ``q`` the two-sided Student-t quantile
(``n - 2`` degrees of freedom) at ``level``. The interval is bounded when the slope is
significantly different from zero (``b^2 > q^2 var(b)``); otherwise the crossing date cannot
be bounded and both ends are None.

Examples
--------
>>> t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
>>> gap = 0.1 + 0.01 * t + np.array([1, -1, 0, 1, -1]) * 1e-3
>>> trend = fit_trend(t, gap, np.full(5, 1e-3), limit=0.2)
>>> round(trend.slope, 4), round(trend.crossing, 2)
(0.0098, 10.16)
>>> [round(day, 2) for day in trend.crossing_interval]
[9.32, 11.21]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from genbacklash_core import GenBacklashError

__all__ = ["Trend", "fit_trend"]


@dataclass(frozen=True)
class Trend:
    """A fitted gap trend ``gap(t) = intercept + slope * t`` (``t`` in days from the first
    point) and when it crosses ``limit``.

    Attributes
    ----------
    n : int
        Points fitted.
    intercept, slope : float
        Radians and radians per day.
    covariance : ndarray, shape (2, 2)
        Of ``(intercept, slope)``, scaled by ``scale**2``.
    scale : float
        ``sqrt(chi^2 / (n - 2))``: how many times the points scatter more than their standard
        deviations say (1 with no degree of freedom left).
    limit : float
    level : float
        Confidence level of the intervals.
    crossing : float or None
        The day the line reaches ``limit`` (None when the slope is not positive).
    crossing_interval : (float or None, float or None)
        Fieller's interval of ``crossing`` (see the module notes).
    """

    n: int
    intercept: float
    slope: float
    covariance: np.ndarray
    scale: float
    limit: float
    level: float
    crossing: float | None
    crossing_interval: tuple[float | None, float | None]

    @property
    def slope_std(self) -> float:
        """Standard deviation of the slope, radians per day."""
        return float(math.sqrt(max(self.covariance[1, 1], 0.0)))

    def gap_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The line and its standard deviation at days ``t``."""
        tt = np.asarray(t, dtype=np.float64)
        c = self.covariance
        var = c[0, 0] + 2.0 * tt * c[0, 1] + tt * tt * c[1, 1]
        return self.intercept + self.slope * tt, np.sqrt(np.maximum(var, 0.0))


def _fieller(
    a: float, b: float, cov: np.ndarray, limit: float, q: float
) -> tuple[float | None, float | None]:
    d = a - limit
    qa = b * b - q * q * cov[1, 1]
    if qa <= 0.0:
        return None, None  # the slope is not significant: the date cannot be bounded
    qb = 2.0 * (b * d - q * q * cov[0, 1])
    qc = d * d - q * q * cov[0, 0]
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:  # cannot happen with a positive-definite covariance; be safe
        return None, None
    root = math.sqrt(disc)
    r1, r2 = (-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)
    return float(min(r1, r2)), float(max(r1, r2))


def fit_trend(
    t: np.ndarray, gap: np.ndarray, gap_std: np.ndarray, *, limit: float, level: float = 0.95
) -> Trend:
    """Fit the gap trend (see the module notes).

    Parameters
    ----------
    t : ndarray
        Days since the drivetrain's first bag.
    gap, gap_std : ndarray
        The gap and its standard deviation per bag, radians.
    limit : float
        The gap at which the drivetrain needs service, radians.
    level : float
        Confidence level of the crossing interval.

    Raises
    ------
    GenBacklashError
        Fewer than 3 points, points at fewer than 2 distinct times, non-finite values, or a
        level outside (0, 1).
    """
    tt = np.asarray(t, dtype=np.float64)
    gg = np.asarray(gap, dtype=np.float64)
    ss = np.asarray(gap_std, dtype=np.float64)
    if not (tt.shape == gg.shape == ss.shape and tt.ndim == 1):
        raise GenBacklashError("t, gap and gap_std must be one-dimensional and of one length")
    if tt.size < 3 or np.unique(tt).size < 2:
        raise GenBacklashError(
            f"a trend needs at least 3 bags at 2 or more times, got {tt.size} at "
            f"{np.unique(tt).size} times"
        )
    if not (np.all(np.isfinite(tt)) and np.all(np.isfinite(gg)) and np.all(np.isfinite(ss))):
        raise GenBacklashError("t, gap and gap_std must be finite")
    if not 0.0 < level < 1.0:
        raise GenBacklashError(f"level must lie in (0, 1), got {level}")
    floor = max(float(np.median(ss[ss > 0])) if np.any(ss > 0) else 1e-12, 1e-12)
    w = 1.0 / np.maximum(ss, floor * 1e-3) ** 2  # a zero std must not take all the weight
    design = np.column_stack([np.ones_like(tt), tt])
    info = design.T @ (design * w[:, None])
    cov = np.linalg.inv(info)
    a, b = cov @ (design.T @ (w * gg))
    residual = gg - (a + b * tt)
    dof = tt.size - 2
    chi2 = float(np.sum(w * residual * residual))
    scale = math.sqrt(chi2 / dof) if dof > 0 else 1.0
    cov = cov * scale * scale
    q = float(stats.t.ppf(0.5 + level / 2.0, dof))
    crossing = (limit - a) / b if b > 0 else None
    interval = _fieller(float(a), float(b), cov, limit, q)
    return Trend(
        int(tt.size),
        float(a),
        float(b),
        cov,
        scale,
        float(limit),
        float(level),
        None if crossing is None else float(crossing),
        interval,
    )
