"""The estimate's covariance: from the separated vector of eq. (23)/(33) to the natural parameters.

Both identifiers solve for the separated vector ``theta`` (eq. 23; the cascade's eq. 33), whose
covariance is the least-squares ``sigma^2 (Phi^T Phi)^-1``, and publish the natural parameters
``p = from_theta(theta)`` (eq. 34: ``c_L = theta_2 / theta_1``, likewise ``c_R``). The
covariance of ``p`` follows by the delta method, ``J cov_theta J^T`` with
``J = d p / d theta`` (:func:`theta_jacobian`).

Two forms of the same delta method stand here on purpose: :func:`natural_covariance` forms the
whole matrix (what an :class:`~genbacklash_core.estimate.Estimate` publishes), and
:func:`natural_variances` only its diagonal on Python floats (what the relative standard
deviation, hence the state and the confidence, needs at every published estimate; forming a
``P x P`` product there would cost more than the rest of the per-sample path). They round
differently in the last bits, so each identifier keeps the form it always used.

Examples
--------
>>> from genbacklash_core.structure import Structure
>>> s = Structure(1)  # theta = [m_L1, m_L1 c_L, m_R1, m_R1 c_R]
>>> theta = np.array([2.0, 0.2, 2.0, 0.4])
>>> natural_from_theta(s, theta.tolist())  # m_left_1, c_left, m_right_1, c_right
[2.0, 0.1, 2.0, 0.2]
>>> cov = np.diag([1e-4, 1e-6, 1e-4, 1e-6])
>>> full = natural_covariance(s, theta, cov)
>>> bool(np.allclose(full.diagonal(), natural_variances(s, theta.tolist(), cov)))
True
"""

from __future__ import annotations

import functools
import math

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.structure import Structure

__all__ = [
    "natural_covariance",
    "natural_from_theta",
    "natural_variances",
    "scaled_inverse",
    "theta_jacobian",
]


@functools.lru_cache(maxsize=32)
def _jacobian_template(structure: Structure) -> FloatArray:
    """``d p / d theta`` without the two dead-zone rows (identity entries), read-only."""
    n = structure.degree
    size = structure.n_parameters
    jac = np.zeros((size, size))
    jac[0, 0] = 1.0
    for i in range(1, n):
        jac[i, i + 1] = 1.0  # m_L(i+1)
        jac[n + 1 + i, n + 2 + i] = 1.0  # m_R(i+1)
    jac[n + 1, n + 1] = 1.0
    for k in range(2 * n + 2, size):
        jac[k, k] = 1.0
    jac.flags.writeable = False
    return jac


def theta_jacobian(structure: Structure, theta: FloatArray) -> FloatArray:
    """``d p / d theta`` of ``Structure.from_theta`` (eq. 34), for the delta method."""
    n = structure.degree
    jac = _jacobian_template(structure).copy()
    jac[n, 0] = -theta[1] / theta[0] ** 2  # c_L = theta_2 / theta_1, eq. (34)
    jac[n, 1] = 1.0 / theta[0]
    jac[2 * n + 1, n + 1] = -theta[n + 2] / theta[n + 1] ** 2  # c_R, eq. (34)
    jac[2 * n + 1, n + 2] = 1.0 / theta[n + 1]
    return jac


def natural_covariance(
    structure: Structure, theta: FloatArray, theta_covariance: FloatArray
) -> FloatArray:
    """Covariance of the natural parameters from that of ``theta`` (delta method)."""
    jac = theta_jacobian(structure, theta)
    return np.asarray(jac @ theta_covariance @ jac.T, dtype=np.float64)


def natural_from_theta(structure: Structure, theta: list[float]) -> list[float]:
    """``Structure.from_theta`` on Python floats (eq. 34), for the per-sample path."""
    n = structure.degree
    return [
        theta[0],
        *theta[2 : n + 1],
        theta[1] / theta[0],  # c_L, eq. (34)
        theta[n + 1],
        *theta[n + 3 : 2 * n + 2],
        theta[n + 2] / theta[n + 1],  # c_R, eq. (34)
        *theta[2 * n + 2 :],
    ]


def natural_variances(
    structure: Structure, theta: list[float], theta_covariance: FloatArray
) -> list[float]:
    """Diagonal of :func:`natural_covariance` without forming it (Python floats)."""
    n = structure.degree
    diag = theta_covariance.diagonal().tolist()

    def ratio_variance(k: int) -> float:  # var(theta_{k+1} / theta_k), delta method
        if theta[k] == 0.0:  # m_1 vanished: c is undetermined
            return math.inf
        g1 = 1.0 / theta[k]
        g0 = -theta[k + 1] * g1 * g1  # (not / theta**2: no OverflowError or ZeroDivisionError)
        c01 = float(theta_covariance[k, k + 1])
        return float(g0 * g0 * diag[k] + 2.0 * g0 * g1 * c01 + g1 * g1 * diag[k + 1])

    return [
        diag[0],
        *diag[2 : n + 1],
        ratio_variance(0),
        diag[n + 1],
        *diag[n + 3 : 2 * n + 2],
        ratio_variance(n + 1),
        *diag[2 * n + 2 :],
    ]


def scaled_inverse(gram: FloatArray) -> FloatArray | None:
    """Inverse of a symmetric positive definite matrix, column-scaled; None when singular."""
    diag = np.diag(gram)
    if not np.all(diag > 0.0) or not np.all(np.isfinite(gram)):  # NaN fails too
        return None
    scale = np.sqrt(diag)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # checked below
        outer = np.outer(scale, scale)
        try:
            inverse = np.linalg.inv(gram / outer) / outer
        except np.linalg.LinAlgError:
            return None
    if not np.all(np.isfinite(inverse)):
        return None
    return np.asarray(inverse, dtype=np.float64)
