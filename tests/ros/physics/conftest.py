"""The physics tests need mujoco (the ``[physics]`` extra, in ``[dev]``)."""

from __future__ import annotations

import pytest

pytest.importorskip("mujoco", reason="the physics drivetrains need mujoco (genbacklash[physics])")
