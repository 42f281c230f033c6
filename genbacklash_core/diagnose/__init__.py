"""Discrepancy diagnosis: where do a backlash model and the measurements disagree, which effect
is missing, and does adding it close the gap?

:func:`diagnose` fits a starting model (the ideal backlash of eq. 1 by default) on the first
part of a record, measures the free-run gap on the held-out rest, analyses the residual with
real statistics (:mod:`.residuals`), lets each effect of the catalog (:mod:`.effects`) test
its signature, adds the best-supported effect to an :class:`AugmentedModel`, and repeats while
the gap drops significantly and stays above the floor quantisation and noise allow
(:mod:`.floor`). The result's ``to_dict()`` is the ``genbacklash diagnose --json``
contract of GUIDE §4.

Examples
--------
>>> from genbacklash_core.diagnose import diagnose, synthetic_case
>>> clean = synthetic_case([], seed=0, n_samples=1500)
>>> diagnose(clean.u, clean.y).to_dict()["steps"]
[]
"""

from __future__ import annotations

from .effects import CATALOG, Detection, Effect, effect_names
from .fit import ModelFit, fit_model
from .floor import NoiseFloor, noise_floor
from .gap import GapGroup, GapReport, Split, measure_gap, split_record
from .loop import StartStructure, diagnose, gap_drop_test
from .model import AugmentedModel, Drift, PeriodicError, Saturation
from .residuals import ResidualAnalysis, analyse_residuals
from .result import Diagnosis, DiagnosisStep, Round, Trial
from .settings import DiagnoseSettings
from .synthetic import (
    EFFECT_NAMES,
    OPERATION_EFFECTS,
    OperationCase,
    SyntheticCase,
    operation_case,
    random_walk_input,
    synthetic_case,
)

__all__ = [
    "CATALOG",
    "EFFECT_NAMES",
    "OPERATION_EFFECTS",
    "AugmentedModel",
    "Detection",
    "DiagnoseSettings",
    "Diagnosis",
    "DiagnosisStep",
    "Drift",
    "Effect",
    "GapGroup",
    "GapReport",
    "ModelFit",
    "NoiseFloor",
    "OperationCase",
    "PeriodicError",
    "ResidualAnalysis",
    "Round",
    "Saturation",
    "Split",
    "StartStructure",
    "SyntheticCase",
    "Trial",
    "analyse_residuals",
    "diagnose",
    "effect_names",
    "fit_model",
    "gap_drop_test",
    "measure_gap",
    "noise_floor",
    "operation_case",
    "random_walk_input",
    "split_record",
    "synthetic_case",
]
