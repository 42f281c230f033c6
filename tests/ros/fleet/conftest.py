"""A synthetic fleet shared by the fleet tests (written once per session: ~5 s)."""

from __future__ import annotations

from pathlib import Path

import pytest

from genbacklash_ros.fleet.synthetic import (
    SyntheticFleet,
    SyntheticFleetSpec,
    write_synthetic_fleet,
)

# 5 drivetrains x 8 days of 10 s bags; one bag cut short, one without motion
FLEET_SPEC = SyntheticFleetSpec(drivetrains=5, days=8, seconds=10.0, corrupt=1, no_motion=1, seed=0)


@pytest.fixture(scope="session")
def synthetic_fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SyntheticFleet]:
    root = tmp_path_factory.mktemp("fleet") / "archive"
    return root, write_synthetic_fleet(root, FLEET_SPEC)
