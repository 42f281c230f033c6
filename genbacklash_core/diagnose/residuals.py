"""Residual analysis: is what the model leaves consistent with white noise, and if not, how not.

For a residual ``e`` (measurement minus free-run simulation) and the input ``u``:

* autocorrelation of ``e`` with the 95% bound ``1.96/sqrt(N)`` and the Ljung-Box test;
* cross-correlation of the prewhitened input with ``e`` (Box-Jenkins: the input is filtered by
  its own AR model so the bound ``1.96/sqrt(N)`` holds) and its portmanteau test;
* higher-order correlation tests for nonlinear structure (Billings and Voon, 1986):
  ``phi_{u^2' e}``, ``phi_{u^2' e^2}`` and ``phi_{e (e u)}``, each zero for a model whose residual
  is independent of the input;
* tests of the mean and of a linear trend with a Newey-West long-run variance;
* a model-error model: an FIR from the input to ``e`` fitted by least squares, with its F-test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.errors import GenBacklashError

from .stats import (
    TestResult,
    correlation,
    lagged_matrix,
    ljung_box,
    long_run_variance,
    nested_f_test,
    prewhitening_filter,
    whiten,
)

__all__ = [
    "CorrelationTest",
    "ModelErrorModel",
    "ResidualAnalysis",
    "analyse_residuals",
    "model_error_model",
]

_Z95 = 1.959963984540054  # scipy.stats.norm.ppf(0.975) (a test checks it)


@dataclass(frozen=True, eq=False)
class CorrelationTest:
    """A correlation function with its 95% bound and a test over all its lags.

    The test is Bonferroni over the lags on ``max |r| sqrt(N)`` (standard normal each).
    """

    name: str
    lags: FloatArray
    values: FloatArray
    bound: float
    test: TestResult

    @property
    def outside(self) -> int:
        """How many lags fall outside the 95% bound."""
        return int(np.sum(np.abs(self.values) > self.bound))


def _correlation_test(name: str, x: FloatArray, e: FloatArray, lags: FloatArray) -> CorrelationTest:
    from scipy import stats  # here: a slow import most runs never need

    n = e.size
    values = correlation(x, e, lags)
    biggest = float(np.max(np.abs(values))) if values.size else 0.0
    p_single = 2.0 * float(stats.norm.sf(biggest * math.sqrt(n)))
    test = TestResult(biggest * math.sqrt(n), float(values.size), min(1.0, values.size * p_single))
    return CorrelationTest(name, lags, values, _Z95 / math.sqrt(n), test)


@dataclass(frozen=True, eq=False)
class ModelErrorModel:
    """An FIR model of the residual: ``e(t) = sum_k g_k x(t - k) + c``, least squares.

    Attributes
    ----------
    regressor : str
        What ``x`` is (e.g. ``"input"``).
    lags : ndarray
        The lags ``k``.
    taps : ndarray
        The coefficients ``g_k``.
    std_errors : ndarray
        Their standard errors (from the least-squares residual variance).
    covariance : ndarray
        Their covariance matrix (the taps of a smooth regressor are strongly correlated).
    test : TestResult
        F-test of all taps against a constant.
    share : float
        Fraction of the residual's variance the FIR explains.
    """

    regressor: str
    lags: FloatArray
    taps: FloatArray
    std_errors: FloatArray
    covariance: FloatArray
    test: TestResult
    share: float

    @property
    def significant_taps(self) -> FloatArray:
        """Lags whose tap is more than 1.96 standard errors from zero."""
        return self.lags[np.abs(self.taps) > _Z95 * self.std_errors]


def model_error_model(
    e: FloatArray,
    x: FloatArray,
    lags: FloatArray | range,
    regressor: str = "input",
    extra: FloatArray | None = None,
) -> ModelErrorModel:
    """Fit the FIR ``e(t) = sum_k g_k x(t-k) + c [+ extra columns]`` and test it.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = rng.normal(size=1000)
    >>> e = 0.5 * np.concatenate([[0.0, 0.0], u[:-2]]) + 0.1 * rng.normal(size=1000)
    >>> fir = model_error_model(e, u, range(5))
    >>> fir.significant_taps.tolist(), round(float(fir.taps[2]), 2)
    ([2.0], 0.5)
    """
    lag_array = np.asarray(list(lags), dtype=np.float64)
    n = e.size
    z = lagged_matrix(x - np.mean(x), lag_array)
    base = np.ones((n, 1))
    if extra is not None:
        base = np.column_stack([base, extra])
    nested = nested_f_test(e, base, z)
    design = np.column_stack([base, z])
    coef, *_ = np.linalg.lstsq(design, e, rcond=None)
    resid = e - design @ coef
    dof = max(1, n - design.shape[1])
    sigma2 = float(resid @ resid) / dof
    k = base.shape[1]
    cov = np.asarray(sigma2 * np.linalg.pinv(design.T @ design)[k:, k:], dtype=np.float64)
    std = np.asarray(np.sqrt(np.maximum(np.diag(cov), 0.0)), dtype=np.float64)
    taps = np.asarray(coef[k:], dtype=np.float64)
    return ModelErrorModel(regressor, lag_array, taps, std, cov, nested.test, nested.share)


@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """Statistics of a residual against white noise independent of the input.

    Attributes
    ----------
    n : int
        Samples.
    rms : float
        Root mean square of the residual.
    autocorrelation : CorrelationTest
        ``r_ee(k)``, ``k = 1..K``.
    ljung_box : TestResult
        Portmanteau test of whiteness.
    cross_correlation : CorrelationTest
        ``r_{u e}(k)``, ``k = -K..K``, of the prewhitened input with the residual.
    cross_portmanteau : TestResult
        ``N sum_{k=0}^{K} r_{ue}(k)^2``, chi-square with ``K+1`` dof under independence.
    higher_order : tuple of CorrelationTest
        The Billings-Voon tests ``u2_e``, ``u2_e2``, ``e_eu``.
    mean : TestResult
        ``t`` statistic of the mean (Newey-West variance), two-sided normal p-value.
    mean_value : float
        The residual's mean.
    trend : TestResult
        ``t`` statistic of the slope of ``e`` against time (Newey-West), two-sided.
    trend_change : float
        Fitted change of the residual's level over the record.
    fir : ModelErrorModel
        FIR from the input to the residual.
    """

    n: int
    rms: float
    autocorrelation: CorrelationTest
    ljung_box: TestResult
    cross_correlation: CorrelationTest
    cross_portmanteau: TestResult
    higher_order: tuple[CorrelationTest, ...]
    mean: TestResult
    mean_value: float
    trend: TestResult
    trend_change: float
    fir: ModelErrorModel

    def white(self, alpha: float = 0.01) -> bool:
        """True when the Ljung-Box test does not reject whiteness at ``alpha``."""
        return not self.ljung_box.significant(alpha)

    def independent_of_input(self, alpha: float = 0.01) -> bool:
        """True when the input cross-correlation portmanteau does not reject at ``alpha``."""
        return not self.cross_portmanteau.significant(alpha)

    def nonlinear_structure(self, alpha: float = 0.01) -> bool:
        """True when a higher-order test rejects (Bonferroni over the three tests)."""
        return any(t.test.p_value < alpha / len(self.higher_order) for t in self.higher_order)

    def consistent_with_noise(self, alpha: float = 0.01) -> bool:
        """White, uncorrelated with the input and without higher-order structure: nothing
        left for a model to explain. (With a white input a missing nonlinearity leaves a white
        residual uncorrelated with ``u``; only the higher-order tests see it.)"""
        return (
            self.white(alpha)
            and self.independent_of_input(alpha)
            and not self.nonlinear_structure(alpha)
        )

    def summary(self) -> str:
        """A few sentences with the numbers."""
        lb = self.ljung_box
        cp = self.cross_portmanteau
        parts = [
            f"residual RMS {self.rms:.4g} over {self.n} samples",
            f"Ljung-Box Q = {lb.statistic:.1f} ({lb.dof:.0f} lags, p = {lb.p_value:.2g})",
            f"{self.autocorrelation.outside} of {self.autocorrelation.values.size} "
            "autocorrelations outside the 95% bound",
            f"input cross-correlation portmanteau {cp.statistic:.1f} ({cp.dof:.0f} dof, "
            f"p = {cp.p_value:.2g})",
            f"mean {self.mean_value:.3g} (t = {self.mean.statistic:.1f}, "
            f"p = {self.mean.p_value:.2g})",
            f"trend {self.trend_change:+.3g} over the record (t = {self.trend.statistic:.1f}, "
            f"p = {self.trend.p_value:.2g})",
            f"input FIR model error explains {100 * self.fir.share:.1f}% "
            f"(F = {self.fir.test.statistic:.1f}, p = {self.fir.test.p_value:.2g})",
        ]
        for test in self.higher_order:
            parts.append(
                f"{test.name}: max |r| {float(np.max(np.abs(test.values))):.3f} vs bound "
                f"{test.bound:.3f} (p = {test.test.p_value:.2g})"
            )
        return "; ".join(parts) + "."


def _two_sided_t(value: float) -> TestResult:
    from scipy import stats  # here: a slow import most runs never need

    return TestResult(value, math.inf, min(1.0, 2.0 * float(stats.norm.sf(abs(value)))))


def analyse_residuals(
    u: FloatArray,
    e: FloatArray,
    *,
    max_lag: int = 20,
    fir_order: int = 15,
    fitted: int = 0,
) -> ResidualAnalysis:
    """Run the residual tests on ``e`` for input ``u``.

    Parameters
    ----------
    u, e : ndarray, shape (N,)
        Input and residual.
    max_lag : int
        Lags of the correlation tests.
    fir_order : int
        Highest lag of the model-error FIR.
    fitted : int
        Parameters fitted to the data (reduces the Ljung-Box degrees of freedom).

    Examples
    --------
    >>> rng = np.random.default_rng(2)
    >>> u = np.cumsum(rng.normal(size=3000))
    >>> analyse_residuals(u, rng.normal(size=3000)).consistent_with_noise()
    True
    >>> e = np.convolve(rng.normal(size=3000), np.ones(5), "same")
    >>> analyse_residuals(u, e).white()
    False
    """
    from scipy import stats  # here: a slow import most runs never need

    uu = np.asarray(u, dtype=np.float64)
    ee = np.asarray(e, dtype=np.float64)
    n = ee.size
    if uu.size != n:
        raise GenBacklashError(f"u and e must have one length, got {uu.size} and {n}")
    if n < 4 * max_lag or n < 30:
        raise GenBacklashError(f"need at least {max(30, 4 * max_lag)} samples, got {n}")
    rms = float(np.sqrt(np.mean(ee**2)))
    acf = _correlation_test("autocorrelation", ee, ee, np.arange(1.0, max_lag + 1))
    a = prewhitening_filter(uu)
    u_white = whiten(a, uu)
    ccf = _correlation_test(
        "input cross-correlation", u_white, ee, np.arange(-max_lag, max_lag + 1.0)
    )
    causal = ccf.values[max_lag:]
    q_cross = float(n * np.sum(causal**2))
    cross = TestResult(q_cross, causal.size, float(stats.chi2.sf(q_cross, causal.size)))
    u2 = uu**2 - np.mean(uu**2)
    ec = ee - np.mean(ee)
    e2 = ec**2 - np.mean(ec**2)
    lags = np.arange(0.0, max_lag + 1)
    higher = (
        _correlation_test("u2_e", u2, ec, lags),
        _correlation_test("u2_e2", u2, e2, lags),
        # phi_{e(eu)}(k) = E[e(t) e(t-1-k) u(t-1-k)]: shift the product one sample first
        _correlation_test("e_eu", np.concatenate([[0.0], (ec * (uu - uu.mean()))[:-1]]), ec, lags),
    )
    mean_value = float(np.mean(ee))
    lrv = long_run_variance(ee)
    t_mean = mean_value / math.sqrt(lrv / n) if lrv > 0 else 0.0
    time = np.arange(n, dtype=np.float64)
    time -= time.mean()
    slope = float(time @ (ee - mean_value)) / float(time @ time)
    detrended = ee - mean_value - slope * time
    # Newey-West standard error of the slope: long-run variance of time * residual
    lrv_slope = long_run_variance(time * detrended) * n
    se_slope = math.sqrt(lrv_slope) / float(time @ time) if lrv_slope > 0 else math.inf
    t_trend = slope / se_slope if math.isfinite(se_slope) else 0.0
    fir = model_error_model(ee, uu, range(fir_order + 1))
    return ResidualAnalysis(
        n=n,
        rms=rms,
        autocorrelation=acf,
        ljung_box=ljung_box(ee, max_lag, fitted=min(fitted, max_lag - 1)),
        cross_correlation=ccf,
        cross_portmanteau=cross,
        higher_order=higher,
        mean=_two_sided_t(t_mean),
        mean_value=mean_value,
        trend=_two_sided_t(t_trend),
        trend_change=slope * (n - 1),
        fir=fir,
    )
