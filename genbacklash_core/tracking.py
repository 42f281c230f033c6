"""Compatibility module: the bands' tracking term lives in :mod:`genbacklash_core.online`."""

from __future__ import annotations

from .online.tracking import DRIFT_Z, DeadZoneDrift, dead_zone_drift

__all__ = ["DRIFT_Z", "DeadZoneDrift", "dead_zone_drift"]
