"""``periodic_error``: an output error periodic in the load position (gear runout, encoder
eccentricity) - add harmonics of a period the data reveal.

The reading is ``z + E(z)`` with ``E(z) = sum_j cos_j cos(2 pi j z / P) + sin_j sin(2 pi j z /
P)``, ``z`` the load position (:class:`~genbacklash_core.diagnose.model.PeriodicError`). The
period is not known in advance: the detector scans it.

Signature: a periodogram of the residual against the model's load position. For periods from
``_MAX_CYCLES`` down to ``_MIN_CYCLES`` per travel (a grid in ``1/P`` fine enough that the
phase slips by a quarter cycle at most over the travel, and never shorter than
``_MIN_QUANTA`` encoder counts: the quantisation error is itself periodic, with a period of
one count), the residual is regressed on the first two harmonics; the best period is refined
(and halved when half of it explains as much: twice the true period fits the true one as its
second harmonic) and tested beyond the model's Jacobian, its p-value Bonferroni-corrected over
the grid.
Augmentation: refit with 1, 2 and 3 harmonics of that period (the period refitted too); the
BIC picks.
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.diagnose.context import Context
from genbacklash_core.diagnose.fit import ModelFit, best_fit
from genbacklash_core.diagnose.model import AugmentedModel, PeriodicError
from genbacklash_core.diagnose.spec import ModelSpec
from genbacklash_core.diagnose.stats import nested_f_test

from ._base import Detection, format_p

__all__ = ["EFFECT", "PeriodicErrorEffect", "harmonic_columns", "scan_periods"]

_MIN_CYCLES = 2.5  # the travel must hold this many periods
_MAX_CYCLES = 60.0
_MIN_QUANTA = 20.0  # a period is at least this many encoder counts
_SCAN_HARMONICS = 2
_SAME_SHARE = 0.95  # a half period explaining this share of the best's is preferred
_SCAN_SAMPLES = 6000  # the scan looks at every k-th sample of longer records
_HARMONICS = (1, 2, 3)


def harmonic_columns(z: FloatArray, period: float, harmonics: int) -> FloatArray:
    """Columns ``cos(2 pi j z / P), sin(2 pi j z / P)`` for ``j = 1..K``.

    >>> harmonic_columns(np.array([0.0, 0.25]), 1.0, 1).round(6).tolist()
    [[1.0, 0.0], [0.0, 1.0]]
    """
    out = np.empty((z.size, 2 * harmonics))
    for j in range(1, harmonics + 1):
        phase = (2.0 * math.pi * j / period) * z
        out[:, 2 * j - 2] = np.cos(phase)
        out[:, 2 * j - 1] = np.sin(phase)
    return out


def _share(e: FloatArray, columns: FloatArray) -> float:
    """Share of ``e``'s sum of squares the columns (and a constant) explain."""
    design = np.column_stack([np.ones(e.size), columns])
    gram = design.T @ design
    rhs = design.T @ e
    try:
        coef = np.linalg.solve(gram, rhs)
    except np.linalg.LinAlgError:
        return 0.0
    ec = e - np.mean(e)
    total = float(ec @ ec)
    explained = float(coef @ rhs) - e.size * float(np.mean(e)) ** 2
    return explained / total if total > 0 else 0.0


def scan_periods(z: FloatArray, e: FloatArray, quantum: float = 0.0) -> tuple[float, float, int]:
    """The period of ``z`` whose first harmonics explain most of ``e``.

    Returns ``(period, share, periods scanned)``; the grid is uniform in ``1/P`` with a step
    of a quarter cycle over the travel, then refined tenfold around the best.

    >>> z = np.linspace(0.0, 3.0, 3000)
    >>> e = 0.01 * np.sin(2 * np.pi * z / 0.4) + np.random.default_rng(0).normal(0, 0.002, 3000)
    >>> period, share, n = scan_periods(z, e)
    >>> round(period, 2), share > 0.8
    (0.4, True)
    """
    span = float(np.ptp(z))
    if span <= 0.0:
        return math.nan, 0.0, 0
    low = _MIN_CYCLES / span
    high = _MAX_CYCLES / span
    if quantum > 0.0:
        high = min(high, 1.0 / (_MIN_QUANTA * quantum))
    if not high > low:
        return math.nan, 0.0, 0
    step = 0.25 / span
    grid = np.arange(low, high + step, step)
    stride = max(1, z.size // _SCAN_SAMPLES)  # the scan needs the shape, not every sample
    z, e = z[::stride], np.asarray(e, dtype=np.float64)[::stride]
    shares = [_share(e, harmonic_columns(z, 1.0 / f, _SCAN_HARMONICS)) for f in grid]
    frequency, share = _refine(z, e, float(grid[int(np.argmax(shares))]), step)
    # twice the period explains as much through its second harmonic: take the shorter one
    # when it does (nearly) as well
    double, double_share = _refine(z, e, 2.0 * frequency, step)
    if double <= high and double_share >= _SAME_SHARE * share:
        frequency, share = double, double_share
    return float(1.0 / frequency), float(share), int(grid.size)


def _refine(z: FloatArray, e: FloatArray, frequency: float, step: float) -> tuple[float, float]:
    """The best frequency within a grid step of ``frequency`` (21 points) and its share."""
    fine = np.linspace(frequency - step, frequency + step, 21)
    fine = fine[fine > 0.0]
    shares = [_share(e, harmonic_columns(z, 1.0 / f, _SCAN_HARMONICS)) for f in fine]
    k = int(np.argmax(shares))
    return float(fine[k]), float(shares[k])


def _quantum(y: FloatArray) -> float:
    """The encoder's step: the smallest difference of distinct readings, when the readings sit
    on its grid (0 for unquantised data)."""
    levels = np.unique(y)
    if levels.size < 3 or levels.size > y.size // 4:
        return 0.0
    steps = np.diff(levels)
    q = float(np.min(steps))
    if q <= 0.0:
        return 0.0
    ratio = steps / q
    return q if float(np.max(np.abs(ratio - np.round(ratio)))) < 0.05 else 0.0


class PeriodicErrorEffect:
    """Detector and augmentation of an error periodic in the load position."""

    name = "periodic_error"

    def applicable(self, model: AugmentedModel) -> bool:
        """Only while the model has no periodic error."""
        return model.periodic is None

    def detect(self, context: Context) -> Detection:
        """Scan the period, then test its harmonics beyond the model's Jacobian."""
        z = context.simulation.load
        settings = context.settings
        period, _, scanned = scan_periods(z, context.residual, _quantum(context.y))
        if not math.isfinite(period):
            return Detection(
                self.name,
                False,
                0.0,
                settings.min_share,
                "the load position does not travel far enough to show a period",
            )
        columns = harmonic_columns(z, period, _SCAN_HARMONICS)
        test = nested_f_test(context.residual, context.jacobian, columns)
        p_value = min(1.0, scanned * test.test.p_value)
        fires = p_value < settings.screen_alpha and test.share >= settings.min_share
        amplitudes = [
            math.hypot(float(test.coefficients[2 * j]), float(test.coefficients[2 * j + 1]))
            for j in range(_SCAN_HARMONICS)
        ]
        evidence = (
            f"against the load position the residual repeats every {period:.4g} "
            f"({float(np.ptp(z)) / period:.1f} periods over the travel; amplitudes "
            + ", ".join(f"{a:.3g}" for a in amplitudes)
            + f" of harmonics 1..{_SCAN_HARMONICS}): they explain {100 * test.share:.1f}% of "
            f"the residual beyond the model's parameters (F = {test.test.statistic:.1f}, "
            f"{format_p(p_value)} over {scanned} periods scanned)"
            + (": a periodic error (runout, eccentricity)" if fires else "")
        )
        return Detection(
            self.name,
            fires,
            test.share,
            settings.min_share,
            evidence,
            {
                "period": period,
                **{f"c{j}": float(test.coefficients[j]) for j in range(2 * _SCAN_HARMONICS)},
            },
        )

    def augment(self, context: Context, detection: Detection) -> ModelFit | None:
        """Refit with 1, 2 and 3 harmonics of the period found (the period refitted too)."""
        period = float(detection.hints.get("period", math.nan))
        if not (math.isfinite(period) and period > 0.0):
            return None
        starts: list[tuple[ModelSpec, FloatArray]] = []
        for harmonics in _HARMONICS:
            spec = context.spec.extended(harmonics=harmonics)
            coefficients = [
                float(detection.hints.get(f"c{j}", 0.0)) if j < 2 * _SCAN_HARMONICS else 0.0
                for j in range(2 * harmonics)
            ]
            model = AugmentedModel(
                context.fit.model.base,
                context.fit.model.delay,
                context.fit.model.offset,
                context.fit.model.drift,
                context.fit.model.saturation,
                context.fit.model.input_lag,
                PeriodicError(period, tuple(coefficients[0::2]), tuple(coefficients[1::2])),
            )
            starts.append((spec, spec.vector(model)))
        return best_fit(starts, context.u, context.y, breaks=context.breaks)


EFFECT = PeriodicErrorEffect()
