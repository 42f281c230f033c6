"""Model error in a batch estimate's uncertainty: the misfit the noise does not explain.

The output-error fit's covariance ``s^2 (J^T J)^-1`` (:mod:`genbacklash_core.uncertainty`)
assumes the residual is white noise: it shrinks with the number of samples. When the play
operator (eqs. 20-21) does not describe the drivetrain -- a servo's lag, a load that coasts
across the play, a spring, gravity -- the residual holds a systematic part ``d(t)`` that does
not average out, and the estimate is biased by ``(J^T J)^-1 J^T d``. On the MuJoCo
drivetrains that bias is 5-150 of the statistical standard deviations.

Two things about ``d`` can be read off the residual ``r`` alone, never from a truth:

* its size. Noise is white from sample to sample; a model error is smooth (it follows the
  motion). So the lag-1 autocovariance ``mean(r(t) r(t-1))`` holds ``d``'s power ``e^2``
  and not the noise's: the *correlated misfit*. It counts only when it stands out of its own
  noise (``MISFIT_Z`` standard deviations of the autocovariance of white residuals,
  ``rms^2 / sqrt(m)`` over ``m`` pairs), so an exact model with white noise gets no term.
  Encoder quantisation on a resting or slowly moving load is not white either: its rounding
  error holds still with the load and does not average out, so it counts too (it is a
  systematic error as much as the model's). Subtracting a quantisation floor ``q^2 / 12``
  was tried: on the MuJoCo near_ideal drivetrain (60 Hz servo), whose misfit is about one
  encoder step, it took all of the misfit, and the play's band missed the truth by 50
  standard deviations.
* the worst bias it can cause. For any linear function ``g^T p`` of the parameters (the play
  ``c_L + c_R``), Cauchy-Schwarz bounds the bias ``g^T (J^T J)^-1 J^T d`` by
  ``sqrt(N e^2 g^T (J^T J)^-1 g)`` for an unmodelled signal of RMS ``e`` over ``N`` samples:
  ``d`` shaped like the least visible change of ``g^T p``.

A bound ``+-a`` with nothing else known is taken as a uniform distribution, standard deviation
``a / sqrt(3)`` (the GUM's Type B evaluation, JCGM 100:2008 §4.3.7). The model-error covariance
is therefore ``C_model = (N e^2 / 3) (J^T J)^-1``: the statistical covariance's shape, scaled as
if the correlated misfit did not average out at all. It is reported beside the statistical
one, never instead of it; their sum is the estimate's mean squared error.

It is a scale, not a measurement of the bias: it says how far the estimate can sit from the
drivetrain because the model misfits it, given how much it misfits. Where the misfit is
large beside the play's effect on the output (a load that coasts), it is wider than the play.

Examples
--------
>>> rng = np.random.default_rng(0)
>>> white = rng.normal(0.0, 0.01, 4000)
>>> correlated_misfit(white).rms_model  # white noise: no model error
0.0
>>> smooth = white + 0.02 * np.sin(np.arange(4000) / 50.0)
>>> round(correlated_misfit(smooth).rms_model, 3)  # the sine's RMS, 0.02 / sqrt(2)
0.014
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._typing import BoolArray, FloatArray

__all__ = ["MISFIT_Z", "Misfit", "correlated_misfit", "model_error_covariance"]

MISFIT_Z = 3.0  # the correlated misfit counts when it is this many standard deviations above 0


@dataclass(frozen=True)
class Misfit:
    """What a residual says about the model's error (see the module notes).

    Attributes
    ----------
    rms : float
        RMS of the residual.
    lag_one : float
        Its lag-1 autocovariance ``mean(r(t) r(t-1))`` over consecutive pairs.
    noise : float
        Standard deviation of ``lag_one`` for white residuals of this RMS, ``rms^2 / sqrt(m)``.
    pairs : int
        Consecutive pairs ``m`` (pairs across a break of the sample rule do not count).
    """

    rms: float
    lag_one: float
    noise: float
    pairs: int

    @property
    def significant(self) -> bool:
        """Whether the correlated misfit stands out of its noise (``MISFIT_Z`` sigma)."""
        return bool(self.lag_one > MISFIT_Z * self.noise)

    @property
    def rms_model(self) -> float:
        """RMS ``e`` of the misfit the noise does not explain: ``sqrt(lag_one)`` when
        :attr:`significant`, else 0. Never above :attr:`rms`."""
        if not self.significant:
            return 0.0
        return min(math.sqrt(self.lag_one), self.rms)


def correlated_misfit(residual: FloatArray, breaks: BoolArray | None = None) -> Misfit:
    """The correlated part of ``residual`` (a free-run or one-step prediction error, in time
    order).

    Parameters
    ----------
    residual : ndarray
        The residual; non-finite entries are left out with the pairs they belong to.
    breaks : ndarray of bool, optional
        ``breaks[k]`` True: sample ``k`` does not follow sample ``k - 1`` (the sample rule),
        so that pair does not count.
    """
    r = np.asarray(residual, dtype=np.float64)
    pair = np.isfinite(r[1:]) & np.isfinite(r[:-1])
    if breaks is not None:
        pair &= ~np.asarray(breaks, dtype=bool)[1:]
    finite = r[np.isfinite(r)]
    rms = math.sqrt(float(np.mean(finite**2))) if finite.size else 0.0
    pairs = int(np.sum(pair))
    if pairs == 0:
        return Misfit(rms, 0.0, math.inf, 0)
    lag_one = float(np.mean(r[1:][pair] * r[:-1][pair]))
    return Misfit(rms, lag_one, rms * rms / math.sqrt(pairs), pairs)


def model_error_covariance(
    jacobian: FloatArray,
    misfit: Misfit,
    *,
    gram: tuple[BoolArray, FloatArray] | None = None,
) -> FloatArray:
    """``C_model = (N e^2 / 3) (J^T J)^+`` (see the module notes): ``e`` the misfit's
    :attr:`Misfit.rms_model`, ``N`` the rows of ``jacobian``. A parameter the data do not
    inform (a zero column) gets an infinite variance when ``e > 0``, else zero.

    ``gram``: the informed columns (``np.any(J != 0, axis=0)``) and ``(J_i^T J_i)^+`` over
    them, where the caller has worked them out on this ``jacobian`` already.

    >>> jac = np.ones((100, 1))
    >>> m = Misfit(rms=0.5, lag_one=0.12, noise=0.001, pairs=99)
    >>> round(float(model_error_covariance(jac, m)[0, 0]), 4)  # e^2 / 3, as for a mean
    0.04
    """
    jac = np.asarray(jacobian, dtype=np.float64)
    size = jac.shape[1]
    e = misfit.rms_model
    cov = np.zeros((size, size))
    if e == 0.0:
        return cov
    if gram is None:
        informed = np.any(jac != 0.0, axis=0)
        sub = jac[:, informed]
        gram_inverse = np.linalg.pinv(sub.T @ sub)
    else:
        informed, gram_inverse = gram
    cov[np.ix_(informed, informed)] = jac.shape[0] * e * e / 3.0 * gram_inverse
    cov[~informed, ~informed] = np.inf
    return cov
