"""Batch identification of a general backlash (eqs. 22-29) and of the cascade (eqs. 31-37).

Both run the paper's iteration with internal-variable estimation: from the current parameter
estimate, compute the switching functions ``f1, f2`` and the internal variables ``xi1, xi2``
(and for the cascade the internal output ``x`` of eq. 36), solve one linear least-squares
problem for the separated parameter vector (eqs. 23/33), and repeat. By default the result is
then refined by output-error minimisation (:mod:`genbacklash_core.refine`), which removes the
iteration's noise bias.
"""

from __future__ import annotations

from .batch import backlash_misfit, identify_backlash, identify_cascade
from .fitting import described_breaks
from .regression import backlash_rows
from .results import (
    MAX_ITERATIONS,
    TOL,
    Fit,
    IdentificationResult,
    IterationCallback,
    IterationHistory,
    nrmse,
)

__all__ = [
    "MAX_ITERATIONS",
    "TOL",
    "Fit",
    "IdentificationResult",
    "IterationCallback",
    "IterationHistory",
    "backlash_misfit",
    "backlash_rows",
    "described_breaks",
    "identify_backlash",
    "identify_cascade",
    "nrmse",
]
