"""Standard deviations of a batch estimate: the output-error fit's Gauss-Newton covariance.

Used by ``genbacklash identify`` (the parameters' and the play's standard deviations) and by
the fleet (:mod:`genbacklash_ros.fleet.job`). The *play* is ``c_L + c_R`` (rad): the whole
dead band between the branches.

The batch identifier (:func:`genbacklash_core.identify_backlash`, its output-error refinement)
returns a point estimate. Around it the free-run simulation error is locally linear in the
parameters, so ``cov(p) = s^2 (J^T J)^-1`` with ``J = d y_sim / d p`` at the estimate and
``s^2 = ||y - y_sim||^2 / (N - P)`` (the classical nonlinear least-squares covariance). ``J`` is
the refinement's own analytic Jacobian of the same simulation
(:func:`genbacklash_core.refine.simulation_jacobian`, restarted at the sample rule's breaks):
one simulation, where central differences took ``2P + 1`` (they agree to ~1e-9 relative).

It assumes white residuals. Encoder quantisation is not white on a slowly moving load, and
a model the drivetrain does not follow (a servo's lag, a coasting load, a spring, gravity)
leaves a residual that does not average out, so these standard deviations are a lower bound;
the fleet's wear trend (``genbacklash_ros.fleet.trends``) scales them up by the scatter the
bags show when that is larger. :func:`batch_uncertainty` adds the model-error part
(:mod:`genbacklash_core.model_error`: the correlated misfit's worst bias) beside the
statistical one; ``genbacklash identify`` reports both and their sum.

Examples
--------
>>> from genbacklash_core import identify_backlash, paper_example
>>> example = paper_example(1)  # c_L = 0.7
>>> data = example.generate(seed=0)
>>> result = identify_backlash(data.u, data.y, 3)
>>> names, values, std = parameter_std(result.model, data.u, data.y)
>>> names[3], bool(abs(values[3] - 0.7) < 3 * std[3]), bool(0 < std[3] < 0.01)
('c_left', True, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .backlash import GeneralBacklash
from .cascade import Cascade
from .model_error import Misfit, correlated_misfit, model_error_covariance
from .refine import simulation_jacobian
from .structure import Structure

__all__ = [
    "BatchUncertainty",
    "batch_uncertainty",
    "free_run_residual",
    "gap_std",
    "parameter_covariance",
    "parameter_std",
    "play_std",
]


@dataclass(frozen=True)
class BatchUncertainty:
    """A batch estimate's covariance in two parts (see the module notes).

    Attributes
    ----------
    statistical : ndarray, shape (P, P)
        ``s^2 (J^T J)^+``: the noise's (:func:`parameter_covariance`).
    model : ndarray, shape (P, P)
        The model error's (:func:`~genbacklash_core.model_error.model_error_covariance`);
        zeros when the residual is white.
    misfit : Misfit
        The residual's correlated part the model term comes from.
    """

    statistical: np.ndarray
    model: np.ndarray
    misfit: Misfit

    @property
    def total(self) -> np.ndarray:
        """``statistical + model``: the estimate's mean squared error."""
        return np.asarray(self.statistical + self.model, dtype=np.float64)


def _fit(
    model: GeneralBacklash | Cascade,
    u: np.ndarray,
    y: np.ndarray,
    breaks: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The free-run residual ``y - y_sim`` of ``model`` on ``(u, y)`` and its Jacobian."""
    return free_run_residual(Structure.of(model), model.parameters(), u, y, breaks)


def free_run_residual(
    structure: Structure,
    p: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    breaks: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The free-run residual ``y - y_sim`` of the parameter vector ``p`` of ``structure`` on
    ``(u, y)`` and its Jacobian ``dy_sim/dp`` (a backlash alone starts from the first
    reading and restarts at the sample rule's ``breaks``): what :func:`batch_uncertainty`
    reads, and the online bands' free-run model term
    (:func:`genbacklash_core.online.tracking.free_run_model`).

    >>> s = Structure(1)
    >>> p = np.array([1.0, 0.1, 1.0, 0.1])
    >>> r, jac = free_run_residual(s, p, np.array([0.0, 1.0, 0.5]), np.array([0.0, 0.9, 0.5]))
    >>> np.round(r, 12).tolist(), jac[:, 3].tolist()  # the right branch, then the left
    ([0.0, 0.0, -0.1], [0.0, -1.0, 0.0])
    """
    yy = np.asarray(y, dtype=np.float64)
    x0 = 0.0 if structure.cascade else float(yy[0])
    y_sim, jac = simulation_jacobian(
        structure, np.asarray(p, dtype=np.float64), np.asarray(u, dtype=np.float64), yy, x0, breaks
    )
    return yy - y_sim, jac


def _statistical(residual: np.ndarray, jac: np.ndarray) -> np.ndarray:
    """``s^2 (J^T J)^+`` with an infinite variance where ``J`` has a zero column."""
    size = jac.shape[1]
    dof = max(residual.size - size, 1)
    s2 = float(residual @ residual) / dof
    informed = np.any(jac != 0.0, axis=0)
    cov = np.full((size, size), np.nan)
    sub = jac[:, informed]
    cov[np.ix_(informed, informed)] = s2 * np.linalg.pinv(sub.T @ sub)
    cov[~informed, :] = cov[:, ~informed] = 0.0
    cov[~informed, ~informed] = np.inf
    return cov


def parameter_covariance(
    model: GeneralBacklash | Cascade,
    u: np.ndarray,
    y: np.ndarray,
    breaks: np.ndarray | None = None,
) -> np.ndarray:
    """``s^2 (J^T J)^+`` of ``model``'s parameter vector on ``(u, y)`` (see the module notes).

    A parameter the data do not inform (a zero column of ``J``) gets an infinite variance
    rather than a misleading zero.
    """
    return _statistical(*_fit(model, u, y, breaks))


def batch_uncertainty(
    model: GeneralBacklash | Cascade,
    u: np.ndarray,
    y: np.ndarray,
    breaks: np.ndarray | None = None,
) -> BatchUncertainty:
    """The statistical and the model-error covariance of ``model``'s parameters on
    ``(u, y)``, from one simulation (see the module notes).

    >>> from genbacklash_core import identify_backlash, paper_example
    >>> data = paper_example(1).generate(seed=0)  # the model is exact, the noise white
    >>> result = identify_backlash(data.u, data.y, 3)
    >>> spread = batch_uncertainty(result.model, data.u, data.y)
    >>> spread.misfit.significant, bool(np.all(spread.model == 0.0))
    (False, True)
    """
    residual, jac = _fit(model, u, y, breaks)
    misfit = correlated_misfit(residual, breaks)
    return BatchUncertainty(
        _statistical(residual, jac), model_error_covariance(jac, misfit), misfit
    )


def parameter_std(
    model: GeneralBacklash | Cascade,
    u: np.ndarray,
    y: np.ndarray,
    breaks: np.ndarray | None = None,
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """``(names, values, standard deviations)`` of ``model``'s parameters on ``(u, y)``."""
    cov = parameter_covariance(model, u, y, breaks)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return model.parameter_names, model.parameters(), std


def play_std(model: GeneralBacklash | Cascade, covariance: np.ndarray) -> float:
    """Standard deviation of the play ``c_L + c_R`` (rad) from the parameter covariance: the
    covariance propagated by the play's gradient (1 at ``c_L`` and ``c_R``, 0 elsewhere).

    >>> m = GeneralBacklash((1.0,), 0.1, (1.0,), 0.1)
    >>> play_std(m, np.diag([0.0, 0.09, 0.0, 0.16]))
    0.5
    """
    structure = Structure.of(model)
    i = structure.degree  # c_left follows m_left_1..n
    j = 2 * structure.degree + 1  # c_right ends the backlash part
    var = covariance[i, i] + covariance[j, j] + 2.0 * covariance[i, j]
    return float(np.sqrt(max(var, 0.0)))


gap_std = play_std
"""The former name of :func:`play_std` (the fleet's ``gap`` column is the play)."""
