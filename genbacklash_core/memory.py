"""Compatibility module: the row memory lives in :mod:`genbacklash_core.online.memory`, the
coverage and excitation advice in :mod:`genbacklash_core.online.advice`."""

from __future__ import annotations

from .online.advice import BranchCoverage, coverage_of, excitation_advice
from .online.memory import RowMemory, pair_series

__all__ = ["BranchCoverage", "RowMemory", "coverage_of", "excitation_advice", "pair_series"]
