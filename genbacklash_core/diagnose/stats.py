"""Statistical building blocks of the residual analysis (numpy + scipy.stats).

Correlations with their large-sample bounds, portmanteau tests (Ljung-Box), a long-run
(Newey-West) variance for tests on autocorrelated series, autoregressive prewhitening, and the
nested least-squares F-test that the detectors use as a score (Lagrange multiplier) test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.errors import GenBacklashError

__all__ = [
    "NestedTest",
    "TestResult",
    "correlation",
    "lagged_matrix",
    "ljung_box",
    "long_run_variance",
    "nested_f_test",
    "prewhitening_filter",
    "whiten",
]


@dataclass(frozen=True)
class TestResult:
    """A test statistic, its degrees of freedom and p-value.

    Examples
    --------
    >>> TestResult(3.2, 2, 0.2).significant(0.05)
    False
    """

    statistic: float
    dof: float
    p_value: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.p_value <= 1.0:
            raise GenBacklashError(f"p_value must be in [0, 1], got {self.p_value}")

    def significant(self, alpha: float) -> bool:
        """True when the p-value is below ``alpha``."""
        return self.p_value < alpha


def correlation(x: FloatArray, y: FloatArray, lags: FloatArray | range) -> FloatArray:
    """Sample correlation ``r_xy(k) = sum x(t-k) y(t) / (N s_x s_y)`` at each lag ``k``.

    Negative ``k`` means ``y`` leads. Means are removed; the normalisation by ``N`` (not
    ``N - |k|``) keeps the estimate positive definite, as in Box and Jenkins.

    Examples
    --------
    >>> x = np.array([1.0, -1.0, 1.0, -1.0])
    >>> correlation(x, x, range(2)).tolist()
    [1.0, -0.75]
    """
    xc = np.asarray(x, dtype=np.float64) - np.mean(x)
    yc = np.asarray(y, dtype=np.float64) - np.mean(y)
    n = xc.size
    if yc.size != n:
        raise GenBacklashError(f"x and y must have one length, got {xc.size} and {yc.size}")
    scale = math.sqrt(float(xc @ xc) * float(yc @ yc))
    out = np.zeros(len(lags))
    if scale == 0.0:
        return out
    for i, k in enumerate(lags):
        k = int(k)
        if abs(k) >= n:
            continue
        out[i] = float(xc[: n - k] @ yc[k:]) if k >= 0 else float(xc[-k:] @ yc[: n + k])
    return out / scale


def ljung_box(x: FloatArray, max_lag: int, fitted: int = 0) -> TestResult:
    """Ljung-Box portmanteau test of whiteness: ``Q = N (N+2) sum_k r_k^2 / (N - k)``.

    ``Q`` is chi-square with ``max_lag - fitted`` degrees of freedom under white noise.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> ljung_box(rng.normal(size=2000), 20).p_value > 0.01
    True
    """
    from scipy import stats  # here: a slow import most runs never need

    n = x.size
    if not 1 <= max_lag < n:
        raise GenBacklashError(f"need 1 <= max_lag < N, got {max_lag} for N = {n}")
    r = correlation(x, x, range(1, max_lag + 1))
    q = float(n * (n + 2) * np.sum(r**2 / (n - np.arange(1, max_lag + 1))))
    dof = max(1, max_lag - fitted)
    return TestResult(q, dof, float(stats.chi2.sf(q, dof)))


def long_run_variance(x: FloatArray, lags: int | None = None) -> float:
    """Newey-West (Bartlett-kernel) long-run variance of ``x``, for tests on its mean.

    The default bandwidth is ``floor(4 (N/100)^(2/9))``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> round(long_run_variance(rng.normal(size=5000)), 1)
    1.0
    """
    xc = np.asarray(x, dtype=np.float64) - np.mean(x)
    n = xc.size
    bandwidth = int(4 * (n / 100.0) ** (2.0 / 9.0)) if lags is None else int(lags)
    total = float(xc @ xc) / n
    for k in range(1, min(bandwidth, n - 1) + 1):
        weight = 1.0 - k / (bandwidth + 1.0)
        total += 2.0 * weight * float(xc[:-k] @ xc[k:]) / n
    return max(total, 0.0)


def prewhitening_filter(x: FloatArray, order: int = 10) -> FloatArray:
    """AR polynomial ``[1, -phi_1, .., -phi_p]`` that whitens ``x`` (least squares).

    Filtering a series by it (``scipy.signal.lfilter(a, [1], x)``) leaves the innovations.
    """
    xc = np.asarray(x, dtype=np.float64) - np.mean(x)
    order = max(0, min(order, xc.size // 10))
    if order == 0:
        return np.array([1.0])
    lagged = lagged_matrix(xc, range(1, order + 1))
    phi, *_ = np.linalg.lstsq(lagged[order:], xc[order:], rcond=None)
    return np.concatenate([[1.0], -phi])


def whiten(a: FloatArray, x: FloatArray) -> FloatArray:
    """Apply the prewhitening polynomial ``a`` to ``x``."""
    from scipy import signal  # here: a slow import most runs never need

    return np.asarray(signal.lfilter(a, [1.0], x - np.mean(x)), dtype=np.float64)


def lagged_matrix(x: FloatArray, lags: FloatArray | range) -> FloatArray:
    """Columns ``x(t - k)`` for each lag ``k`` (zeros outside the record).

    >>> lagged_matrix(np.array([1.0, 2.0, 3.0]), [0, 1, -1]).tolist()
    [[1.0, 0.0, 2.0], [2.0, 1.0, 3.0], [3.0, 2.0, 0.0]]
    """
    n = x.size
    out = np.zeros((n, len(lags)))
    for j, k in enumerate(lags):
        k = int(k)
        if k >= 0:
            out[k:, j] = x[: n - k] if k < n else 0.0
        else:
            out[: n + k, j] = x[-k:]
    return out


@dataclass(frozen=True, eq=False)
class NestedTest:
    """Least-squares F-test of extra regressors ``Z`` beyond ``X`` for a residual ``e``.

    Attributes
    ----------
    test : TestResult
        The F statistic with ``(q, N - p - q)`` degrees of freedom (``dof`` holds ``q``).
    share : float
        Fraction of the residual sum of squares the extra regressors explain.
    coefficients : ndarray
        The coefficients of ``Z`` (a Gauss-Newton step when ``X`` is the model's Jacobian).
    """

    test: TestResult
    share: float
    coefficients: FloatArray


def nested_f_test(e: FloatArray, x: FloatArray | None, z: FloatArray) -> NestedTest:
    """Test whether columns ``z`` explain ``e`` beyond columns ``x`` (a score test).

    Redundant columns are allowed: ``q`` is the rank the extra columns add.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> t = np.arange(500.0)
    >>> e = 0.01 * t + rng.normal(size=500)
    >>> out = nested_f_test(e, np.ones((500, 1)), t[:, None])
    >>> out.test.p_value < 1e-6, round(float(out.coefficients[0]), 2)
    (True, 0.01)
    """
    from scipy import stats  # here: a slow import most runs never need

    n = e.size
    zz = np.asarray(z, dtype=np.float64).reshape(n, -1)
    if x is None or x.size == 0:
        basis = np.zeros((n, 0))
    else:
        xx = np.asarray(x, dtype=np.float64).reshape(n, -1)
        norms = np.linalg.norm(xx, axis=0)
        xx = xx[:, norms > 0.0] / norms[norms > 0.0]
        u_mat, sv, _ = np.linalg.svd(xx, full_matrices=False)
        basis = u_mat[:, sv > 1e-9 * (sv[0] if sv.size else 1.0)]
    e_perp = e - basis @ (basis.T @ e)
    z_perp = zz - basis @ (basis.T @ zz)
    norms = np.linalg.norm(z_perp, axis=0)
    keep = norms > 1e-9 * max(1.0, float(np.max(np.linalg.norm(zz, axis=0))))
    coefficients = np.zeros(zz.shape[1])
    sse0 = float(e_perp @ e_perp)
    if not keep.any() or sse0 == 0.0:
        return NestedTest(TestResult(0.0, 0.0, 1.0), 0.0, coefficients)
    scaled = z_perp[:, keep] / norms[keep]
    beta, _, rank, _ = np.linalg.lstsq(scaled, e_perp, rcond=1e-9)
    coefficients[keep] = beta / norms[keep]
    fitted = scaled @ beta
    sse1 = max(sse0 - float(fitted @ fitted), 0.0)
    q = int(rank)
    dof2 = n - basis.shape[1] - q
    if q == 0 or dof2 <= 0 or sse1 == 0.0:
        p_value = 0.0 if sse1 == 0.0 and q > 0 else 1.0
        return NestedTest(TestResult(math.inf, q, p_value), 1.0 - sse1 / sse0, coefficients)
    f = ((sse0 - sse1) / q) / (sse1 / dof2)
    return NestedTest(
        TestResult(float(f), q, float(stats.f.sf(f, q, dof2))), 1.0 - sse1 / sse0, coefficients
    )
