"""Compatibility module: the recursive identifier lives in :mod:`genbacklash_core.online`.

Kept so that ``from genbacklash_core.recursive import RecursiveIdentifier`` goes on working;
new code imports from :mod:`genbacklash_core.online.recursive` (or :mod:`genbacklash_core`).
"""

from __future__ import annotations

from .online.memory import BinnedRows
from .online.recursive import RecursiveIdentifier, RecursiveSettings
from .online.rows import memory_regression

__all__ = ["BinnedRows", "RecursiveIdentifier", "RecursiveSettings", "memory_regression"]
