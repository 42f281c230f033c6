"""What the detectors look at: the current fit on the estimation data and its residual.

Built once per round of the loop and shared by every detector, so the simulation, Jacobian and
residual tests are computed once. Signatures that only some detectors need (the error step
response for the dynamic effects) are computed on first use.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray

from .fit import ModelFit
from .residuals import ModelErrorModel, ResidualAnalysis, analyse_residuals, model_error_model
from .settings import DiagnoseSettings
from .spec import ModelSpec, SimulationOutput, anchors_of

__all__ = ["DEGENERATE_FIT", "SHAPE_MARGIN", "Context", "StepErrorShape", "build_context"]

SHAPE_MARGIN = 0.05  # share of the taps' energy by which one shape must beat the other
DEGENERATE_FIT = 0.9  # free-run NRMSE above which a model explains (almost) nothing

_STEP_LAGS = 16  # taps k = 0..15 of the error step response
_STEP_LEADS = 3  # and 3 leads, which must stay near zero for a causal error


@dataclass(frozen=True, eq=False)
class StepErrorShape:
    """How the residual answers a step of the model output: ``e = sum_k g_k dy_sim(t-k)``.

    A model that misses a dead time ``d`` leaves ``e(t) = y_sim(t-d) - y_sim(t)``, so
    ``g_k = -1`` for ``k < d`` and 0 after: a *box* with a sharp end. A model that misses a lag
    leaves a step response error that *decays* smoothly, ``g_k ~ -h a^k``. Both shapes are
    fitted to the taps; the better fit is the evidence that tells the two apart.

    Attributes
    ----------
    fir : ModelErrorModel
        The FIR from the model-output steps to the residual (with leads).
    taps : ndarray
        ``g_0 .. g_K`` (lags >= 0).
    box_delay : int
        Length ``d`` of the best box.
    box_height : float
        Its height ``-h``.
    box_fit : float
        Share of the taps' energy the box explains.
    decay_pole : float
        Pole ``a`` of the best geometric decay.
    decay_fit : float
        Share of the taps' energy the decay explains.
    """

    fir: ModelErrorModel
    taps: FloatArray
    box_delay: int
    box_height: float
    box_fit: float
    decay_pole: float
    decay_fit: float

    @property
    def box_wins(self) -> bool:
        """True when a dead time explains the shape better than a smooth decay."""
        return self.box_fit > self.decay_fit

    @property
    def verdict(self) -> str:
        """``"dead time"`` or ``"lag"`` when one shape fits clearly better (by
        ``SHAPE_MARGIN`` of the taps' energy), else ``"unclear"``: then both effects are tried
        and the likelihood (BIC) decides. An underdamped lag's step error overshoots, which
        neither shape follows well; that is where the verdict is unclear."""
        if self.box_fit - self.decay_fit >= SHAPE_MARGIN:
            return "dead time"
        if self.decay_fit - self.box_fit >= SHAPE_MARGIN:
            return "lag"
        return "unclear"


def _shape(fir: ModelErrorModel) -> StepErrorShape:
    """Fit a box (``d``, ``h``) and a geometric decay (``a``, ``h``) to the causal taps."""
    # The last tap shares the truncation with the level regressor; the shapes ignore it.
    taps = fir.taps[fir.lags >= 0][:-1]
    energy = float(taps @ taps)
    if energy == 0.0:
        return StepErrorShape(fir, taps, 0, 0.0, 0.0, 0.0, 0.0)
    best_box = (0, 0.0, 0.0)
    for d in range(1, taps.size):
        height = float(np.mean(taps[:d]))
        sse = float(np.sum((taps[:d] - height) ** 2) + np.sum(taps[d:] ** 2))
        if 1.0 - sse / energy > best_box[2]:
            best_box = (d, height, 1.0 - sse / energy)
    best_decay = (0.0, 0.0)
    k = np.arange(taps.size)
    for pole in np.linspace(0.0, 0.97, 98):
        shape = pole**k
        height = float(shape @ taps) / float(shape @ shape)
        sse = float(np.sum((taps - height * shape) ** 2))
        if 1.0 - sse / energy > best_decay[1]:
            best_decay = (float(pole), 1.0 - sse / energy)
    return StepErrorShape(fir, taps, best_box[0], best_box[1], best_box[2], *best_decay)


@dataclass(frozen=True, eq=False)
class Context:
    """The current model on the estimation segment, for the detectors and augmentations.

    Attributes
    ----------
    u, y : ndarray
        Estimation input and output.
    fit : ModelFit
        The current model fitted there.
    spec : ModelSpec
        Its structure.
    theta : ndarray
        Its parameter vector.
    simulation : SimulationOutput
        Its free-run simulation.
    residual : ndarray
        ``y - y_sim``.
    jacobian : ndarray
        ``dy_sim/dtheta``.
    analysis : ResidualAnalysis
        The residual tests.
    settings : DiagnoseSettings
        Thresholds.
    breaks : ndarray of bool or None
        The sample rule on the estimation data (:mod:`genbacklash_core.samples`): every fit
        and identification of an augmentation takes it (``breaks=context.breaks``); the
        simulation and Jacobian above restart at the samples after a break
        (:attr:`anchors`).
    """

    u: FloatArray
    y: FloatArray
    fit: ModelFit
    spec: ModelSpec
    theta: FloatArray
    simulation: SimulationOutput
    residual: FloatArray
    jacobian: FloatArray
    analysis: ResidualAnalysis
    settings: DiagnoseSettings
    breaks: BoolArray | None = None

    @property
    def anchors(self) -> BoolArray | None:
        """Where a simulation restarts at the measurement (:func:`~.spec.anchors_of`)."""
        return anchors_of(self.breaks)

    @property
    def degenerate(self) -> bool:
        """True when the model explains almost none of the output (free-run NRMSE above
        ``DEGENERATE_FIT``): then its simulated output carries no signature to read."""
        return self.fit.nrmse > DEGENERATE_FIT

    @property
    def y_start(self) -> float:
        """The first measured output, where every simulation starts."""
        return float(self.y[0])

    @functools.cached_property
    def step_error(self) -> StepErrorShape:
        """The error step response and its box and decay fits (see :class:`StepErrorShape`)."""
        y_sim = self.simulation.y
        steps = np.diff(y_sim, prepend=y_sim[0])
        level = np.zeros_like(y_sim)  # y_sim(t-K-1): the level the truncated FIR cannot see
        level[_STEP_LAGS:] = y_sim[: y_sim.size - _STEP_LAGS] - np.mean(y_sim)
        fir = model_error_model(
            self.residual,
            steps,
            range(-_STEP_LEADS, _STEP_LAGS),
            regressor="model output steps",
            extra=level[:, None],
        )
        return _shape(fir)


def build_context(
    u: FloatArray,
    y: FloatArray,
    fit: ModelFit,
    settings: DiagnoseSettings,
    breaks: BoolArray | None = None,
) -> Context:
    """Simulate the fitted model, take its Jacobian and run the residual tests (``breaks``:
    the sample rule on ``u, y``, see :class:`Context`)."""
    spec = ModelSpec.of(fit.model)
    theta = spec.vector(fit.model)
    y_start = float(y[0])
    anchors = anchors_of(breaks)
    simulation = spec.simulate(theta, u, y_start, anchors, y)
    residual = y - simulation.y
    jacobian = spec.jacobian(theta, u, simulation, y_start, anchors)
    analysis = analyse_residuals(u, residual)
    return Context(
        u, y, fit, spec, theta, simulation, residual, jacobian, analysis, settings, breaks
    )
