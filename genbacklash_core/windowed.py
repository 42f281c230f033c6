"""Compatibility module: the windowed identifier lives in :mod:`genbacklash_core.online`.

Kept so that ``from genbacklash_core.windowed import WindowedIdentifier`` goes on working;
new code imports from :mod:`genbacklash_core.online.windowed` (or :mod:`genbacklash_core`).
"""

from __future__ import annotations

from .online.covariance import natural_covariance
from .online.fits import solve_normal
from .online.rows import SampleRing, window_rows
from .online.windowed import WindowedIdentifier, WindowedSettings

__all__ = [
    "SampleRing",
    "WindowedIdentifier",
    "WindowedSettings",
    "natural_covariance",
    "solve_normal",
    "window_rows",
]
