"""What batch identification returns (the estimate, its fit, the iteration's history) and the
free-run NRMSE it is judged by; the iteration's defaults.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade, model_to_dict
from genbacklash_core.data import (
    as_float_array,
)
from genbacklash_core.errors import GenBacklashError, NonFiniteInputError
from genbacklash_core.refine import (
    RefinementResult,
)

IterationCallback = Callable[[int, FloatArray], None]

CYCLE_LOOKBACK = 4  # how many earlier iterates a limit cycle may span
MAX_ITERATIONS = 30
"""The paper's iteration's default iteration limit (every identification function's)."""
TOL = 1e-4
"""The default convergence tolerance: the iteration stops when no parameter moves more than
``TOL * max(1, max|p|)``."""
WARM_START_SAMPLES = 20_000  # prefix length for the warm start on long records
RESTART_DEAD_ZONES = (0.05, 0.2)  # restart dead zones, as fractions of the input span
HOLD_ROUNDS = 3  # refinements at most, each with the falsified holds of the estimate before it
USELESS_FIT = 0.95  # free-run NRMSE from which a model explains nothing (SNR 1 gives ~0.71)


@dataclass(frozen=True, eq=False)
class IterationHistory:
    """Parameter estimates per iteration (row 0 is the start), for the paper's Figs. 4-12."""

    names: tuple[str, ...]
    values: FloatArray

    def __post_init__(self) -> None:
        if self.values.ndim != 2 or self.values.shape[1] != len(self.names):
            raise GenBacklashError(
                f"history values must be (iterations+1, {len(self.names)}), got {self.values.shape}"
            )

    def series(self, name: str) -> FloatArray:
        """Estimates of one parameter over the iterations."""
        return self.values[:, self.names.index(name)]


@dataclass(frozen=True)
class Fit:
    """Quality of fit: free-run simulation NRMSE, ``||y - y_sim|| / ||y - mean(y)||``."""

    nrmse: float


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Outcome of :func:`identify_backlash` or :func:`identify_cascade`.

    Attributes
    ----------
    model : GeneralBacklash or Cascade
        The estimate (after refinement when it ran). When ``converged`` is False this is the
        last valid estimate, or the start model when there was none.
    iterations : int
        Iterations of the paper's method that were run.
    converged : bool
        True when the iteration met its criterion (and the refinement, when run, too).
    reason : str
        A sentence saying why it stopped.
    fit : Fit
        Free-run NRMSE of ``model`` on the data.
    history : IterationHistory
        The iteration's parameter estimates, start included.
    equation_error_model : GeneralBacklash or Cascade
        The iteration's estimate before refinement.
    refinement : RefinementResult or None
        The output-error refinement, when it ran.
    """

    model: GeneralBacklash | Cascade
    iterations: int
    converged: bool
    reason: str
    fit: Fit
    history: IterationHistory
    equation_error_model: GeneralBacklash | Cascade
    refinement: RefinementResult | None

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of the CLI contract (GUIDE §4), plus ``play`` (``c_L + c_R``, rad)
        and ``fit.misfit`` (the free-run NRMSE, also under its old key ``fit.nrmse``)."""
        out = model_to_dict(self.model)
        out["iterations"] = self.iterations
        out["converged"] = self.converged
        out["reason"] = self.reason
        backlash = self.model.backlash if isinstance(self.model, Cascade) else self.model
        out["play"] = float(backlash.c_left + backlash.c_right)  # rad, the whole dead band
        # the misfit: the free-run NRMSE ("nrmse" kept for the contract)
        out["fit"] = {"nrmse": self.fit.nrmse, "misfit": self.fit.nrmse}
        return out


def nrmse(y: FloatArray, y_sim: FloatArray) -> float:
    """Normalised root-mean-square error ``||y - y_sim|| / ||y - mean(y)||``.

    ``inf`` when ``y_sim`` holds NaN or inf (a simulation that blew up); NaN/inf in the
    measured ``y`` raise :class:`~genbacklash_core.errors.NonFiniteInputError`.

    >>> nrmse(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    0.0
    """
    yy, ys = as_float_array("y", y), as_float_array("y_sim", y_sim)
    if yy.ndim != 1 or yy.shape != ys.shape or yy.size == 0:
        raise GenBacklashError(
            f"y and y_sim must be non-empty, one-dimensional and of one length, got shapes "
            f"{yy.shape} and {ys.shape}"
        )
    if not np.all(np.isfinite(yy)):
        raise NonFiniteInputError("y holds NaN or infinite samples; clean the data first")
    if not np.all(np.isfinite(ys)):
        return math.inf  # a simulation that blew up fits infinitely badly
    scale = max(float(np.max(np.abs(yy))), float(np.max(np.abs(ys))))
    if scale > 0.0:  # the ratio does not change with the scale; this keeps squares finite
        yy, ys = yy / scale, ys / scale
    spread = float(np.sum((yy - np.mean(yy)) ** 2))
    if spread == 0.0:
        return 0.0 if np.array_equal(yy, ys) else math.inf
    with np.errstate(over="ignore"):  # a nearly constant y: the ratio may overflow to inf
        return float(np.sqrt(np.sum((yy - ys) ** 2) / spread))
