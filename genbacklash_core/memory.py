"""Compatibility module: the row memory lives in :mod:`genbacklash_core.online.memory`."""

from __future__ import annotations

from .online.memory import (
    BranchCoverage,
    RowMemory,
    coverage_of,
    excitation_advice,
    pair_series,
)

__all__ = ["BranchCoverage", "RowMemory", "coverage_of", "excitation_advice", "pair_series"]
