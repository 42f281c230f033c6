"""The rclpy node: run where rclpy imports (a sourced ROS 2 Jazzy), skipped here."""

from __future__ import annotations

import importlib.util

import pytest

from genbacklash_ros.cli.node import choose_transport, ros2_main

RCLPY_MISSING = "rclpy is not installable on this machine (not on PyPI, not in Debian bookworm)"


def _rclpy_available() -> bool:
    try:
        return importlib.util.find_spec("rclpy") is not None
    except (ImportError, ValueError):
        return False


needs_rclpy = pytest.mark.skipif(not _rclpy_available(), reason=RCLPY_MISSING)


@pytest.mark.skipif(_rclpy_available(), reason="rclpy is installed here")
def test_without_rclpy_the_cli_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(Exception, match="rclpy cannot be imported"):
        choose_transport("rclpy")
    assert choose_transport("auto") == "dds"
    assert ros2_main() == 2
    assert "genbacklash node --transport dds" in capsys.readouterr().err


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
def test_node_rejects_bad_parameters_with_the_reason() -> None:
    import rclpy
    from rclpy.parameter import Parameter

    from genbacklash_ros.transports import rclpy_node

    rclpy.init()
    try:
        node = rclpy_node.BacklashIdentifierNode()
        result = node.set_parameters([Parameter("gate_low", value=0.99)])[0]
        assert not result.successful and "gate_low" in result.reason
        result = node.set_parameters([Parameter("publish_rate", value=5.0)])[0]
        assert result.successful
        assert node.get_parameter("publish_rate").value == 5.0
        node.finish()
        node.destroy_node()
    finally:
        rclpy.try_shutdown()


@needs_rclpy
def test_message_conversion_round_trip() -> None:
    from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
    from genbacklash_ros.transports import rclpy_node

    for msg in (
        Float64MultiArray(data=(0.5, 1.5)),
        JointState(Header(Time(3, 4), "f"), ("a",), (0.1,), (), ()),
    ):
        assert rclpy_node.from_ros(rclpy_node.to_ros(msg)) == msg
