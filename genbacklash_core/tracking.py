"""Compatibility module: the bands' tracking term lives in :mod:`genbacklash_core.online`."""

from __future__ import annotations

from .online.tracking import DRIFT_Z, DeadZoneDrift, dead_zone_drift, one_step_sensitivity

__all__ = ["DRIFT_Z", "DeadZoneDrift", "dead_zone_drift", "one_step_sensitivity"]
