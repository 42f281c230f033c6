"""Output-error fit of an augmented model: Levenberg-Marquardt on the free-run simulation error.

The same method as :mod:`genbacklash_core.refine` (column-scaled, damped normal equations;
steps that leave the valid set or raise the cost are rejected), on the augmented parameter
vector of :class:`~genbacklash_core.diagnose.spec.ModelSpec`. The fit is judged by the
Bayesian information criterion ``N ln(SSE/N) + P ln N``.

With ``breaks`` (the sample rule, :mod:`genbacklash_core.samples`) the simulation of a model
without linear dynamics restarts at the measured output after each break
(:func:`~genbacklash_core.diagnose.spec.anchors_of`): a lost reading never lets the fit
carry the state across inputs it did not see.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import nrmse
from genbacklash_core.samples import as_breaks

from .model import AugmentedModel
from .spec import ModelSpec, SimulationOutput, anchors_of

__all__ = ["ModelFit", "best_fit", "bic", "fit_model"]


def bic(sse: float, n_samples: int, n_parameters: int) -> float:
    """Bayesian information criterion of a Gaussian output-error fit.

    >>> round(bic(1.0, 100, 2), 3)
    -451.307
    """
    if n_samples < 1:
        raise GenBacklashError(f"need at least one sample, got {n_samples}")
    mean_square = max(sse / n_samples, 1e-300)
    return n_samples * math.log(mean_square) + n_parameters * math.log(n_samples)


@dataclass(frozen=True, eq=False)
class ModelFit:
    """An augmented model fitted on one record.

    Attributes
    ----------
    model : AugmentedModel
        The fitted model.
    sse : float
        Sum of squared free-run simulation errors on the record.
    n_samples : int
        Record length.
    nrmse : float
        Free-run NRMSE on the record.
    steps : int
        Accepted Levenberg-Marquardt steps.
    converged : bool
        True when the relative cost decrease fell below the tolerance.
    reason : str
        Why the fit stopped.
    """

    model: AugmentedModel
    sse: float
    n_samples: int
    nrmse: float
    steps: int
    converged: bool
    reason: str

    def __post_init__(self) -> None:
        if self.n_samples < 1 or not self.sse >= 0.0:
            raise GenBacklashError(
                f"a fit needs n_samples >= 1 and sse >= 0, got {self.n_samples}, {self.sse}"
            )

    @property
    def n_free(self) -> int:
        """Free parameters (the dead time counts as one)."""
        return ModelSpec.of(self.model).n_free

    @property
    def bic(self) -> float:
        """Bayesian information criterion on the fitting record."""
        return bic(self.sse, self.n_samples, self.n_free)


def _levenberg_marquardt(
    spec: ModelSpec,
    theta: FloatArray,
    u: FloatArray,
    y: FloatArray,
    *,
    max_iterations: int,
    tol: float,
    anchors: BoolArray | None = None,
) -> tuple[FloatArray, SimulationOutput, float, int, bool, str]:
    y_start = float(y[0])
    u_range = (float(np.min(u)), float(np.max(u)))
    s = spec.coordinate(u)
    s_max = 0.0 if s is None else float(s[-1])
    out = spec.simulate(theta, u, y_start, anchors, y)
    residual = y - out.y
    cost = float(residual @ residual)
    damping = 1e-3
    accepted = 0
    for _ in range(max_iterations):
        jac = spec.jacobian(theta, u, out, y_start, anchors)
        gram = jac.T @ jac
        grad = jac.T @ residual
        scale = np.sqrt(np.diag(gram))
        scale[scale == 0.0] = 1.0
        scaled = gram / np.outer(scale, scale)
        rhs = grad / scale
        improved = False
        while damping <= 1e10:
            system = scaled + damping * np.eye(scaled.shape[0])
            step = np.linalg.lstsq(system, rhs, rcond=None)[0] / scale
            candidate = theta + step
            if spec.problem(candidate, u_range, s_max) is None:
                out_new = spec.simulate(candidate, u, y_start, anchors, y)
                res_new = y - out_new.y
                cost_new = float(res_new @ res_new)
                if cost_new < cost:
                    improved = True
                    break
            damping *= 4.0
        if not improved:
            return theta, out, cost, accepted, accepted > 0, "no step lowers the simulation error"
        decrease = (cost - cost_new) / max(cost, 1e-300)
        theta, out, residual, cost = candidate, out_new, res_new, cost_new
        accepted += 1
        damping = max(damping / 5.0, 1e-12)
        if decrease < tol:
            return theta, out, cost, accepted, True, "relative cost decrease below tolerance"
    return theta, out, cost, accepted, False, f"stopped after {max_iterations} steps"


def fit_model(
    start: AugmentedModel | tuple[ModelSpec, FloatArray],
    u: FloatArray,
    y: FloatArray,
    *,
    max_iterations: int = 60,
    tol: float = 1e-9,
    breaks: ArrayLike | None = None,
) -> ModelFit:
    """Fit an augmented model by minimising its free-run simulation error on ``(u, y)``.

    Parameters
    ----------
    start : AugmentedModel or (ModelSpec, ndarray)
        The start: a model, or a spec with a flat parameter vector. Its dead time and drift
        basis stay fixed; everything else is fitted.
    u, y : ndarray
        Input and measured output; the simulation starts from ``y[0]``.
    max_iterations, tol : int, float
        Step limit and relative cost-decrease tolerance.
    breaks : array_like of bool, optional
        The sample rule: True where a sample does not follow the one before it (see the
        module notes). Default: all consecutive.

    Returns
    -------
    ModelFit

    Raises
    ------
    GenBacklashError
        When the start is not a valid model on the data.

    Examples
    --------
    >>> from genbacklash_core import GeneralBacklash
    >>> from genbacklash_core.diagnose.synthetic import random_walk_input
    >>> u = random_walk_input(1500, np.random.default_rng(0))
    >>> truth = AugmentedModel(GeneralBacklash.ideal(1.0, 0.3, 0.2), delay=3)
    >>> y = truth.simulate(u)
    >>> fit = fit_model(AugmentedModel(GeneralBacklash.ideal(0.8, 0.2, 0.2), delay=3), u, y)
    >>> round(fit.model.backlash.m_left[0], 6), round(fit.model.backlash.c_left, 6)
    (1.0, 0.3)
    """
    if isinstance(start, AugmentedModel):
        spec = ModelSpec.of(start)
        theta = spec.vector(start)
    else:
        spec, theta = start
        theta = np.asarray(theta, dtype=np.float64).copy()
    uu = np.asarray(u, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if uu.shape != yy.shape or uu.ndim != 1 or uu.size < 2:
        raise GenBacklashError(
            f"u and y must be 1-D of one length >= 2, got {uu.shape}, {yy.shape}"
        )
    s = spec.coordinate(uu)
    s_max = 0.0 if s is None else float(s[-1])
    if (problem := spec.problem(theta, (float(uu.min()), float(uu.max())), s_max)) is not None:
        raise GenBacklashError(f"cannot fit from an invalid start: {problem}")
    anchors = anchors_of(None if breaks is None else as_breaks(breaks, uu.size))
    theta, out, cost, steps, converged, reason = _levenberg_marquardt(
        spec, theta, uu, yy, max_iterations=max_iterations, tol=tol, anchors=anchors
    )
    y_fit = out.y  # the simulation of the final theta (the fit's own, not run again)
    return ModelFit(spec.model(theta), cost, uu.size, nrmse(yy, y_fit), steps, converged, reason)


def best_fit(
    starts: Sequence[AugmentedModel | tuple[ModelSpec, FloatArray]],
    u: FloatArray,
    y: FloatArray,
    *,
    max_iterations: int = 60,
    breaks: ArrayLike | None = None,
) -> ModelFit | None:
    """Fit from every valid start and keep the lowest BIC (None when no start is valid)."""
    best: ModelFit | None = None
    for start in starts:
        try:
            fit = fit_model(start, u, y, max_iterations=max_iterations, breaks=breaks)
        except GenBacklashError:
            continue  # an invalid start (branches crossing on this record, say)
        if best is None or fit.bic < best.bic:
            best = fit
    return best
