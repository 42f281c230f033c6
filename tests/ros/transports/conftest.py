"""Fixtures shared by the transport tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from ._ros2 import domain_id


@pytest.fixture
def ros_init() -> Iterator[Callable[..., None]]:
    """``ros_init(*ros_args)``: rclpy initialised (the global context) with those
    ``--ros-args`` on a DDS domain of its own, after shutting down any earlier one; shut down
    after the test."""
    import rclpy

    def init(*ros_args: str) -> None:
        rclpy.try_shutdown()
        rclpy.init(args=["backlash_identifier", "--ros-args", *ros_args], domain_id=domain_id())

    try:
        yield init
    finally:
        rclpy.try_shutdown()
