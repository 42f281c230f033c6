"""launch_testing: ``launch/backlash_identifier.launch.py`` brings up a working node.

The launch file's own description (its arguments at their defaults, so the installed
``config/params.yaml``) is included in a test launch with ``ReadyToTest``; the node gets a DDS
domain of its own. While the node runs, a test process feeds it the paper's Example 1 (a
``std_msgs/Float64MultiArray`` command and a ``sensor_msgs/JointState`` encoder reading of
joint ``j`` stamped after it, 200 Hz) and waits for ``/backlash_identifier/estimate`` close to
the true model, ``/diagnostics`` from ``backlash_identifier`` and ``compensated_command``.
After the launch shuts down (SIGINT to the node), the node's exit code must be 0 and its
output free of tracebacks.

Run with the ``launch_test`` command in a sourced ROS 2 Jazzy with the package built
(``test_launch.py`` does that against the session's ``colcon build``):
``GENBACKLASH_TEST_DOMAIN_ID=N python -m launch_testing.launch_test
tests/ros/transports/launch_fed_node.py``. Not a pytest module: launch_testing's pytest plugin
cannot load under pytest 9 (pyproject.toml's addopts). Collected for doctests only, where
it is skipped without launch_testing.
"""

from __future__ import annotations

import os
import time
import unittest
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip(
    "launch_testing",
    reason="launch_testing cannot be imported (it is not on PyPI): this launch_testing file "
    "runs under the launch_test command in a sourced ROS 2 Jazzy (test_launch.py runs it)",
)

import launch_testing.actions
import launch_testing.asserts
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from launch.actions import IncludeLaunchDescription, SetEnvironmentVariable
from launch.launch_description_sources import get_launch_description_from_python_launch_file
from launch_ros.actions import Node
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

import launch
from genbacklash_core import paper_example

LAUNCH_FILE = Path(__file__).resolve().parents[3] / "launch" / "backlash_identifier.launch.py"
TRUTH = paper_example(1).model
SEED = 4
RATE_HZ = 200.0
MAX_SAMPLES = 4000  # 20 s at 200 Hz: the estimate is within tolerance long before
TOLERANCE = 0.1  # max |parameter error| of the estimate
NAME = "backlash_identifier"
MATCH_TIMEOUT_S = 30.0
# a domain of its own (another run, or a robot on the developer's domain, never sees our
# commands); GENBACKLASH_TEST_DOMAIN_ID overrides it
DOMAIN_ID = int(os.environ.get("GENBACKLASH_TEST_DOMAIN_ID") or 150 + os.getpid() % 80)


def _launch_file() -> Path:
    """The launch file of this source tree, else the installed one."""
    if LAUNCH_FILE.is_file():
        return LAUNCH_FILE
    from ament_index_python.packages import get_package_share_directory

    share = Path(get_package_share_directory("genbacklash_ros"))
    return share / "launch" / "backlash_identifier.launch.py"


def generate_test_description() -> tuple[launch.LaunchDescription, dict[str, Any]]:
    """The launch file's description (arguments at their defaults) and ReadyToTest; the
    node action is handed to the tests as ``identifier``."""
    description = get_launch_description_from_python_launch_file(str(_launch_file()))
    nodes = [e for e in description.entities if isinstance(e, Node)]
    assert len(nodes) == 1, f"expected one node in the launch file, found {len(nodes)}"
    test_description = launch.LaunchDescription(
        [
            SetEnvironmentVariable("ROS_DOMAIN_ID", str(DOMAIN_ID)),
            IncludeLaunchDescription(launch.LaunchDescriptionSource(description)),
            launch_testing.actions.ReadyToTest(),
        ]
    )
    return test_description, {"identifier": nodes[0]}


def _values(diagnostics: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in diagnostics.status[0].values}


class TestNodeWhileFed(unittest.TestCase):
    """Feed command and encoder; the node answers on every output."""

    context: Any
    node: Any

    @classmethod
    def setUpClass(cls) -> None:
        cls.context = Context()
        rclpy.init(context=cls.context, domain_id=DOMAIN_ID)
        cls.node = rclpy.create_node("genbacklash_launch_test", context=cls.context)

    @classmethod
    def tearDownClass(cls) -> None:
        cls.node.destroy_node()
        rclpy.try_shutdown(context=cls.context)

    def test_estimate_diagnostics_and_compensated_command(self, identifier: Any) -> None:
        node = self.node
        estimates: list[Any] = []
        diagnostics: list[Any] = []
        compensated: list[Any] = []
        node.create_subscription(
            Float64MultiArray, "/backlash_identifier/estimate", estimates.append, 10
        )
        node.create_subscription(DiagnosticArray, "/diagnostics", diagnostics.append, 10)
        node.create_subscription(Float64MultiArray, "/compensated_command", compensated.append, 10)
        command = node.create_publisher(Float64MultiArray, "/command", 10)
        encoder = node.create_publisher(JointState, "/encoder", qos_profile_sensor_data)
        executor = SingleThreadedExecutor(context=self.context)
        executor.add_node(node)

        deadline = time.monotonic() + MATCH_TIMEOUT_S
        while command.get_subscription_count() < 1 or encoder.get_subscription_count() < 1:
            self.assertLess(time.monotonic(), deadline, "the node did not subscribe in time")
            executor.spin_once(timeout_sec=0.05)

        def converged() -> bool:
            """The estimate is close, and a diagnostics report (1 Hz of data time) has
            come since it was."""
            ours = [d for d in diagnostics if d.status and d.status[0].name == NAME]
            if not estimates or not ours:
                return False
            error = np.max(np.abs(np.array(estimates[-1].data) - TRUTH.parameters()))
            return bool(error < TOLERANCE) and _values(ours[-1])["state"] != "warming_up"

        data = paper_example(1).generate(SEED, n_samples=MAX_SAMPLES)
        period = 1.0 / RATE_HZ
        next_write = time.monotonic()
        for k in range(MAX_SAMPLES):
            cmd = Float64MultiArray()
            cmd.data = [float(data.u[k])]
            command.publish(cmd)
            reading = JointState()
            reading.header.stamp = node.get_clock().now().to_msg()
            reading.name = ["j"]
            reading.position = [float(data.y[k])]
            encoder.publish(reading)
            next_write += period
            while (remaining := next_write - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=remaining)
            if k % 50 == 0 and converged():
                break
        end = time.monotonic() + 2.0  # outputs still in flight
        while time.monotonic() < end and not (estimates and diagnostics and compensated):
            executor.spin_once(timeout_sec=0.05)
        executor.remove_node(node)
        executor.shutdown()

        self.assertTrue(estimates, "no /backlash_identifier/estimate")
        last = estimates[-1]
        self.assertEqual(last.layout.dim[0].label, ",".join(TRUTH.parameter_names))
        error = float(np.max(np.abs(np.array(last.data) - TRUTH.parameters())))
        self.assertLess(error, TOLERANCE, f"estimate {list(last.data)}")

        ours = [d for d in diagnostics if d.status and d.status[0].name == NAME]
        self.assertTrue(ours, "no /diagnostics from backlash_identifier")
        self.assertIn(_values(ours[-1])["state"], ("converging", "converged"))

        self.assertTrue(compensated, "no compensated_command")
        self.assertTrue(all(len(m.data) == 1 for m in compensated))


@launch_testing.post_shutdown_test()
class TestNodeShutdown(unittest.TestCase):
    """After the launch has shut the node down (SIGINT)."""

    def test_exit_code_is_zero(self, proc_info: Any, identifier: Any) -> None:
        launch_testing.asserts.assertExitCodes(proc_info, process=identifier)

    def test_no_traceback(self, proc_output: Any, identifier: Any) -> None:
        text = "".join(
            event.text.decode(errors="replace")
            for event in proc_output
            if event.action is identifier
        )
        self.assertNotIn("Traceback", text)
