"""A synthetic fleet shared by the fleet tests (written once per session: ~5 s), and BLAS on
one thread while they run."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

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


@pytest.fixture(scope="package", autouse=True)
def one_blas_thread() -> Iterator[None]:
    """BLAS on one thread while the fleet tests run, as in a Dask worker process (the other
    test packages keep the default).

    Dask's worker processes start with ``OPENBLAS_NUM_THREADS=1``; the tests run their workers
    as threads of this process, where OpenBLAS would start a thread per core for each of them.
    On a machine whose cores are busy those threads wait on each other: the diagnosis of a
    10 s bag took 3x as long under load (``test_command_line`` 3.4 s idle, 9-11 s loaded).
    """
    with threadpool_limits(1, "blas"):
        yield
