"""One row of the results table (:class:`BagResult`) and the statuses it may have
(:data:`STATUSES`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from genbacklash_core import (
    GenBacklashError,
    __version__,
)

from .settings import json_safe

STATUSES = ("ok", "poor_fit", "not_converged", "no_motion", "unreadable", "failed")
"""Every value of :attr:`BagResult.status`."""


@dataclass(frozen=True)
class BagResult:
    """One row of the results table: a bag and a joint (see :mod:`genbacklash_ros.fleet.database`
    for the meaning of each column)."""

    bag_hash: str
    joint: str
    settings_key: str
    robot: str
    bag_path: str
    status: str
    reason: str = ""
    recorded_ns: int | None = None
    time_source: str | None = None
    command_index: int = 0
    model: str | None = None
    degree: int | None = None
    c_left: float | None = None
    c_left_std: float | None = None
    c_right: float | None = None
    c_right_std: float | None = None
    gap: float | None = None
    gap_std: float | None = None
    parameters: dict[str, float] | None = None
    parameter_std: dict[str, float] | None = None
    estimate: dict[str, Any] | None = None
    nrmse: float | None = None
    iterations: int | None = None
    converged: bool | None = None
    n_samples: int | None = None
    duration_s: float | None = None
    truncated: bool | None = None
    recorded_s: float | None = None
    diagnose_effects: str | None = None
    diagnose_gap_initial: float | None = None
    diagnose_gap_final: float | None = None
    diagnosis: dict[str, Any] | None = None
    replay_gap: float | None = None
    replay_gap_std: float | None = None
    replay_state: str | None = None
    replay: dict[str, Any] | None = None
    settings: dict[str, Any] | None = None
    software_version: str = __version__
    compute_s: float | None = None

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise GenBacklashError(f"status must be one of {STATUSES}, got {self.status!r}")

    def to_row(self) -> dict[str, Any]:
        """The column -> value mapping (JSON-safe values in the JSON columns)."""
        row = asdict(self)
        for name in ("parameters", "parameter_std", "estimate", "diagnosis", "replay", "settings"):
            row[name] = json_safe(row[name])
        for name, value in row.items():
            if isinstance(value, float) and not math.isfinite(value):
                row[name] = None  # an uninformed std: unknown, not a number
        return row
