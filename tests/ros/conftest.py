"""The environment the ROS 2 tests need, set up here so that the plain ``python -m pytest`` runs
them (no sourced ROS 2, no variables set by hand).

- ``AMENT_PREFIX_PATH``: the ROS 2 wheels (the ``ros`` extra) install their ament index and the
  messages' type description JSON files under the environment's prefix (``share/``), but
  nothing points ROS's lookups there; the type-hash tests read those files, and the ROS
  processes the tests start inherit it. Prepended only where the wheels' index is there; a
  sourced ROS 2 keeps its own path behind it.
- ``ROS_DOMAIN_ID``: a DDS domain of this test run's own for anything not given one
  explicitly (the tests give each node one), so runs side by side on one machine do not
  cross-talk. A value already set is kept.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from .transports._ros2 import domain_id


def wheels_prefix() -> Path | None:
    """The environment's prefix when the ROS 2 wheels installed their ament index there."""
    prefix = Path(sys.prefix)
    return prefix if (prefix / "share" / "ament_index").is_dir() else None


@pytest.fixture(scope="session", autouse=True)
def ros_environment() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        prefix = wheels_prefix()
        paths = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
        if prefix is not None and str(prefix) not in paths:
            patch.setenv("AMENT_PREFIX_PATH", os.pathsep.join([str(prefix), *paths]))
        if not os.environ.get("ROS_DOMAIN_ID", "").strip():
            patch.setenv("ROS_DOMAIN_ID", str(domain_id()))
        yield
