"""The rclpy node in process, against the real rclpy (the bundled ROS 2 Jazzy, GUIDE §5).

Each test makes its own rclpy context on a DDS domain of its own. Skipped, with the reason,
where rclpy does not import (ROS 2 not installed, or its setup.bash not sourced).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from genbacklash_ros.cli.node import choose_transport, ros2_main

from ._ros2 import domain_id, rclpy_missing

needs_rclpy = pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")


@pytest.mark.skipif(not rclpy_missing(), reason="rclpy imports here: the message is not shown")
def test_without_rclpy_the_cli_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(Exception, match="rclpy cannot be imported"):
        choose_transport("rclpy")
    assert choose_transport("auto") == "dds"
    assert ros2_main() == 2
    assert "genbacklash node --transport dds" in capsys.readouterr().err


@pytest.fixture
def ros_args() -> Iterator[list[str]]:
    """rclpy initialised (global context) on a domain of its own; the test may re-init with
    its own arguments after ``rclpy.try_shutdown()``."""
    import rclpy

    rclpy.init(args=[], domain_id=domain_id())
    try:
        yield []
    finally:
        rclpy.try_shutdown()


@needs_rclpy
def test_descriptors_carry_ranges_and_descriptions() -> None:
    from genbacklash_ros.node.parameters import PARAMETER_SPECS
    from genbacklash_ros.transports import rclpy_node

    by_name = {s.name: s for s in PARAMETER_SPECS}
    degree = rclpy_node.descriptor(by_name["degree"])
    assert degree.integer_range[0].from_value == 1 and degree.integer_range[0].to_value == 9
    gate = rclpy_node.descriptor(by_name["gate_low"])
    assert gate.floating_point_range[0].to_value == 1.0
    assert rclpy_node.descriptor(by_name["command_type"]).read_only
    assert all(rclpy_node.descriptor(s).description for s in PARAMETER_SPECS)


@needs_rclpy
def test_destroy_node_is_clean(ros_args: list[str]) -> None:
    """rclpy's ``Node`` keeps its publishers in ``self._publishers``; the node must not
    shadow it, or every ``destroy_node()`` (each shutdown) ends in a KeyError."""
    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    own = {p.topic_name for p in node.publishers}
    assert {"/compensated_command", "/backlash_identifier/estimate", "/diagnostics"} <= own
    node.finish()
    node.destroy_node()  # raised KeyError: 0
    assert not list(node.publishers)


@needs_rclpy
def test_node_rejects_bad_parameters_with_the_reason(ros_args: list[str]) -> None:
    from rclpy.parameter import Parameter

    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    try:
        result = node.set_parameters([Parameter("degree", value=12)])[0]
        assert not result.successful and "degree" in result.reason
        result = node.set_parameters([Parameter("publish_rate", value=5.0)])[0]
        assert result.successful
        assert node.get_parameter("publish_rate").value == 5.0
    finally:
        node.finish()
        node.destroy_node()


@needs_rclpy
def test_message_conversion_round_trip() -> None:
    from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
    from genbacklash_ros.transports import rclpy_node

    for msg in (
        Float64MultiArray(data=(0.5, 1.5)),
        JointState(Header(Time(3, 4), "f"), ("a",), (0.1,), (), ()),
    ):
        assert rclpy_node.from_ros(rclpy_node.to_ros(msg)) == msg
