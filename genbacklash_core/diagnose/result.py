"""The outcome of a diagnosis: the steps taken, the gaps, the final model (GUIDE §4 contract)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from genbacklash_core.errors import GenBacklashError

from .effects import Detection
from .fit import ModelFit
from .floor import NoiseFloor
from .gap import GapReport, Split
from .model import AugmentedModel
from .residuals import ResidualAnalysis

__all__ = ["Diagnosis", "DiagnosisStep", "Round", "Trial"]


def _check_gap(name: str, value: float) -> None:
    if not (isinstance(value, float) and (value >= 0.0 or math.isinf(value))):
        raise GenBacklashError(f"{name} must be a float >= 0, got {value!r}")


@dataclass(frozen=True)
class DiagnosisStep:
    """One accepted effect.

    Attributes
    ----------
    effect : str
        Catalog name (GUIDE §4).
    evidence : str
        The detector's sentence and the improvement that got the effect accepted.
    gap_before, gap_after : float
        Validation gap before and after adding it.
    bic_change : float
        Change of the BIC on the estimation data (negative: better).
    model : AugmentedModel
        The model after the step.
    """

    effect: str
    evidence: str
    gap_before: float
    gap_after: float
    bic_change: float
    model: AugmentedModel

    def __post_init__(self) -> None:
        if not self.effect or not self.evidence:
            raise GenBacklashError("a step needs an effect name and its evidence")
        _check_gap("gap_before", self.gap_before)
        _check_gap("gap_after", self.gap_after)

    def to_dict(self) -> dict[str, Any]:
        """``{"effect", "evidence", "gap_before", "gap_after"}`` (GUIDE §4), and the same
        numbers as ``misfit_before``, ``misfit_after``: the misfit is the validation NRMSE
        (the old keys stay; "gap" elsewhere means the play c_L + c_R)."""
        return {
            "effect": self.effect,
            "evidence": self.evidence,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "misfit_before": self.gap_before,
            "misfit_after": self.gap_after,
        }


UNEXPLAINED_TIMES_FLOOR = 3.0
"""A final misfit above this many times the floor is reported as unexplained."""


@dataclass(frozen=True)
class Trial:
    """One augmentation tried in a round, and the verdict."""

    effect: str
    bic_change: float
    gap_after: float | None
    accepted: bool
    verdict: str


@dataclass(frozen=True, eq=False)
class Round:
    """One pass of the loop: the model's gap, its residual tests, detections and trials."""

    gap: float
    analysis: ResidualAnalysis
    detections: tuple[Detection, ...]
    trials: tuple[Trial, ...]


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`~genbacklash_core.diagnose.diagnose`.

    Attributes
    ----------
    steps : tuple of DiagnosisStep
        Accepted effects in order (empty when nothing is missing).
    gap_initial, gap_final : float
        Validation gap of the starting and of the final model.
    model : AugmentedModel
        The final model.
    fit : ModelFit
        Its fit on the estimation segment.
    initial_fit : ModelFit
        The starting model's fit on the estimation segment.
    split : Split
        Estimation and validation segments.
    reports : tuple of GapReport
        Gap and breakdown of the starting model and after each step.
    rounds : tuple of Round
        Every pass of the loop (the last one found nothing to add or hit the step limit).
    reason : str
        Why the loop stopped.
    floor : NoiseFloor, optional
        What quantisation and noise allow (the gap no model can beat).
    """

    steps: tuple[DiagnosisStep, ...]
    gap_initial: float
    gap_final: float
    model: AugmentedModel
    fit: ModelFit
    initial_fit: ModelFit
    split: Split
    reports: tuple[GapReport, ...]
    rounds: tuple[Round, ...]
    reason: str
    floor: NoiseFloor | None = None

    def __post_init__(self) -> None:
        _check_gap("gap_initial", self.gap_initial)
        _check_gap("gap_final", self.gap_final)
        if len(self.reports) != len(self.steps) + 1:
            raise GenBacklashError(
                f"need one gap report per step plus the start, got {len(self.reports)} for "
                f"{len(self.steps)} steps"
            )

    @property
    def initial_model(self) -> AugmentedModel:
        """The starting model, fitted on the estimation segment."""
        return self.initial_fit.model

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the accepted effects, in order."""
        return tuple(step.effect for step in self.steps)

    def model_dict(self) -> dict[str, Any]:
        """The identify JSON shape (GUIDE §4) plus the added effects' fields."""
        shape = self.model.to_dict()
        out: dict[str, Any] = {"model": shape.pop("model"), "backlash": shape.pop("backlash")}
        if "linear" in shape:
            out["linear"] = shape.pop("linear")
        out["iterations"] = self.fit.steps
        out["converged"] = self.fit.converged
        out["reason"] = self.fit.reason
        out["fit"] = {"nrmse": self.fit.nrmse, "misfit": self.fit.nrmse}
        backlash = out["backlash"]
        out["play"] = float(backlash["c_left"] + backlash["c_right"])  # rad
        out.update(shape)  # delay, offset, drift, saturation, input_lag, periodic_error
        return out

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``genbacklash diagnose --json`` (GUIDE §4), plus
        ``gap_floor``: the misfit quantisation and noise allow (null when not measured).

        The misfit (the free-run NRMSE on the held-out data) is also under the keys
        ``misfit_initial``, ``misfit_final``, ``misfit_floor`` (and per step
        ``misfit_before``, ``misfit_after``): one word for it, the ``gap_*`` keys kept.
        """
        floor = None if self.floor is None else self.floor.gap
        unexplained = self.unexplained
        return {
            "unexplained": None
            if unexplained is None
            else {"misfit": self.gap_final, "floor": floor, "times_floor": unexplained},
            "steps": [step.to_dict() for step in self.steps],
            "gap_initial": self.gap_initial,
            "gap_final": self.gap_final,
            "gap_floor": floor,
            "misfit_initial": self.gap_initial,
            "misfit_final": self.gap_final,
            "misfit_floor": floor,
            "model": self.model_dict(),
        }

    def summary(self) -> str:
        """A few readable lines: the steps, the gaps and why the loop stopped."""
        lines = [f"validation misfit {self.gap_initial:.4f} with the starting model"]
        if self.floor is not None:
            lines.append(self.floor.describe())
        for i, step in enumerate(self.steps, 1):
            lines.append(
                f"{i}. {step.effect}: misfit {step.gap_before:.4f} -> {step.gap_after:.4f}. "
                f"{step.evidence}"
            )
        if not self.steps:
            lines.append("no missing effect named")
        lines.append(f"final misfit {self.gap_final:.4f}; {self.reason}")
        if self.unexplained is not None:
            lines.append(self.unexplained_text())
        return "\n".join(lines)

    @property
    def unexplained(self) -> float | None:
        """How many times the floor the final misfit is, when no effect of the catalog
        brought it within :data:`UNEXPLAINED_TIMES_FLOOR` of the floor (None: explained, or
        no floor measured)."""
        if self.floor is None or not self.floor.gap > 0.0:
            return None
        times = self.gap_final / self.floor.gap
        return times if times > UNEXPLAINED_TIMES_FLOOR else None

    def unexplained_text(self) -> str:
        """The sentence for a misfit no named effect explains ("" when explained)."""
        times = self.unexplained
        if times is None or self.floor is None:
            return ""
        named = ", ".join(self.effects) or "none"
        return (
            f"unexplained: the final misfit {self.gap_final:.4f} is {times:.0f} times the floor "
            f"{self.floor.gap:.4f}, and no effect of the catalog explains the rest (named: "
            f"{named}); the drivetrain has an effect the model lacks"
        )
