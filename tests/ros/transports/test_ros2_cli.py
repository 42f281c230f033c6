"""The node as a ROS 2 user runs it: ``colcon build``, ``ros2 launch``, ``ros2 topic echo``,
``ros2 param set``/``get``, a namespaced launch with a params file, Ctrl-C.

The package is built once per test session with the real ``colcon build``
(:func:`~tests.ros.transports._ros2.built_workspace`); each launch runs in a process group
of its own on a DDS domain of its own, and is stopped as a terminal's Ctrl-C stops it: SIGINT
to the whole group (``ros2 launch`` and the node), then a second one. One launch is shared by
the checks of the default launch (fed, echoed, parameters set), then interrupted; a second
launch checks the namespace, the params file and the wiring diagnostics. Skipped, with the
reason, where the ``ros2`` command or launch_ros (neither is on PyPI: a sourced ROS 2 Jazzy
installation has them) or colcon is missing.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

from genbacklash_core import paper_example

from ._ros2 import built_workspace, domain_id, params_file, ros2_launch_missing, workspace_env

pytestmark = pytest.mark.skipif(bool(ros2_launch_missing()), reason=ros2_launch_missing() or "-")

HERE = Path(__file__).resolve().parent
LAUNCH = ("ros2", "launch", "genbacklash_ros", "backlash_identifier.launch.py")
STOP_TIMEOUT_S = 30.0


@dataclass
class Launched:
    """A ``ros2 launch`` in its own process group, its output collected in a file."""

    process: subprocess.Popen[bytes]
    log: Path
    env: dict[str, str]
    checkpoint: Path

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def interrupt(self, times: int, gap_s: float = 0.1) -> int:
        """SIGINT to the group ``times`` times (a terminal's Ctrl-C); the exit status."""
        for k in range(times):
            if k:
                time.sleep(gap_s)
            os.killpg(self.process.pid, signal.SIGINT)
        return self.process.wait(timeout=STOP_TIMEOUT_S)

    def kill(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()


def _ros2(env: dict[str, str], *args: str, timeout: float = 60.0) -> str:
    done = subprocess.run(["ros2", *args], env=env, capture_output=True, text=True, timeout=timeout)
    return done.stdout + done.stderr


def _launch(env: dict[str, str], tmp: Path, name: str, *arguments: str) -> Launched:
    log = tmp / f"{name}.log"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [*LAUNCH, *arguments],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # a process group, as a terminal's job
        )
    return Launched(process, log, env, tmp / f"{name}.json")


def _wait_for_node(launched: Launched, fqn: str, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while fqn not in _ros2(launched.env, "node", "list").split():
        assert launched.process.poll() is None, launched.output()
        assert time.monotonic() < deadline, f"{fqn} did not come up:\n{launched.output()}"
        time.sleep(0.5)


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, str]]:
    ws = built_workspace(tmp_path_factory.mktemp("colcon"))
    environment = workspace_env(ws, domain_id())
    yield environment
    # `ros2 node list` and `ros2 param` start a ros2 daemon on the test's domain: stop it, or
    # the daemons of past runs pile up on a shared machine, each holding UDP ports that a
    # later run's DDS participant may need ("failed to bind ... address in use")
    _ros2(environment, "daemon", "stop")


@pytest.fixture(scope="module")
def launched(env: dict[str, str], tmp_path_factory: pytest.TempPathFactory) -> Iterator[Launched]:
    """`ros2 launch genbacklash_ros backlash_identifier.launch.py` with the shipped params
    file, but a checkpoint file in a temporary directory."""
    tmp = tmp_path_factory.mktemp("launch")
    params = params_file(tmp / "params.yaml", checkpoint_file=f'"{tmp / "default.json"}"')
    running = _launch(env, tmp, "default", f"params_file:={params}")
    try:
        _wait_for_node(running, "/backlash_identifier")
        yield running
    finally:
        running.kill()


def test_fed_node_answers_and_ros2_topic_echo_reads_it(launched: Launched) -> None:
    player = subprocess.Popen(
        [sys.executable, str(HERE / "ros2_player.py"), "--rate", "200", "--min-seconds", "8"],
        env=launched.env,
        stdout=subprocess.PIPE,
        text=True,
    )
    echoes: dict[str, subprocess.Popen[str]] = {}
    try:
        echoes = {
            topic: subprocess.Popen(
                ["ros2", "topic", "echo", "--once", topic],
                env=launched.env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            for topic in ("/backlash_identifier/estimate", "/compensated_command", "/diagnostics")
        }
        seen = {topic: echo.communicate(timeout=60)[0] for topic, echo in echoes.items()}
        out, _ = player.communicate(timeout=120)
    finally:
        for process in (player, *echoes.values()):
            if process.poll() is None:
                process.kill()
                process.wait()
    assert player.returncode == 0, out
    summary = json.loads(out.strip().splitlines()[-1])
    names = ",".join(paper_example(1).model.parameter_names)
    assert summary["labels"] == names
    assert summary["error"] is not None and summary["error"] < 0.1, summary
    assert summary["compensated"] >= 0.9 * summary["sent"], summary

    estimate = next(yaml.safe_load_all(seen["/backlash_identifier/estimate"]))
    assert estimate["layout"]["dim"][0]["label"] == names
    assert len(estimate["data"]) == len(names.split(","))
    command = next(yaml.safe_load_all(seen["/compensated_command"]))
    assert len(command["data"]) == 1 and abs(command["data"][0]) < 10
    diagnostics = seen["/diagnostics"]
    assert "name: backlash_identifier" in diagnostics and "key: state" in diagnostics
    assert "key: wiring" in diagnostics


def test_ros2_param_set_accepts_refuses_and_moves_a_pair(launched: Launched) -> None:
    node = "/backlash_identifier"
    assert "Set parameter successful" in _ros2(
        launched.env, "param", "set", node, "publish_rate", "5"
    )
    assert "Double value is: 5.0" in _ros2(launched.env, "param", "get", node, "publish_rate")
    refused = _ros2(launched.env, "param", "set", node, "publish_rate", "0.0")
    assert "Setting parameter failed" in refused and "publish_rate" in refused, refused
    refused = _ros2(launched.env, "param", "set", node, "method", "kalman")
    assert "parameter 'method' must be one of 'windowed', 'recursive'" in refused, refused
    # the pair gate_low/gate_high moves up with gate_low first (refused before)
    for name, value in (("gate_low", "0.7"), ("gate_high", "0.9")):
        done = _ros2(launched.env, "param", "set", node, name, value)
        assert "Set parameter successful" in done, done
    deadline = time.monotonic() + 10.0
    while "'gate_low': 0.7, 'gate_high': 0.9" not in launched.output():
        assert time.monotonic() < deadline, launched.output()
        time.sleep(0.2)
    assert "until the pair is consistent" in launched.output()


def test_double_ctrl_c_exits_cleanly_with_the_final_checkpoint(launched: Launched) -> None:
    """Runs after the fed test: the node has data, so finish() refits and checkpoints."""
    status = launched.interrupt(times=2)
    text = launched.output()
    assert "Traceback" not in text and "KeyError" not in text, text
    assert "process has finished cleanly" in text, text
    assert status == 0, text
    saved = json.loads(launched.checkpoint.read_text())
    assert saved, "empty checkpoint"


def _diagnostics_until(
    env: dict[str, str], topic_type: Any, publish_on: str, wanted: str, timeout_s: float
) -> str:
    """Publish ``topic_type`` messages on ``publish_on`` and wait for a /diagnostics message
    containing ``wanted``; the message text."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    context = Context()
    rclpy.init(context=context, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("genbacklash_wrong_type", context=context)
    texts: list[str] = []
    node.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda m: texts.extend(s.message for s in m.status if s.name == "backlash_identifier"),
        10,
    )
    wrong = node.create_publisher(topic_type, publish_on, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + timeout_s
        while not any(wanted in t for t in texts):
            assert time.monotonic() < deadline, texts[-3:]
            wrong.publish(topic_type(data=1.0))
            executor.spin_once(timeout_sec=0.1)
        return next(t for t in texts if wanted in t)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_namespaced_launch_with_a_params_file(
    env: dict[str, str], tmp_path: Path, launched: Launched
) -> None:
    """`namespace:=arm` with a params file keyed as shipped: the values apply (a whole number
    for a double too), the topics are in the namespace, a publisher of the wrong type on the
    command topic is named in the diagnostics, and one Ctrl-C ends it cleanly."""
    assert launched.process.poll() is not None, "the default launch still runs"
    params = params_file(tmp_path / "arm.yaml", degree=2, publish_rate=10, joint='"knee"')
    running = _launch(env, tmp_path, "arm", "namespace:=arm", f"params_file:={params}")
    try:
        _wait_for_node(running, "/arm/backlash_identifier")
        node = "/arm/backlash_identifier"
        assert "Integer value is: 2" in _ros2(env, "param", "get", node, "degree")
        assert "Double value is: 10.0" in _ros2(env, "param", "get", node, "publish_rate")
        assert "String value is: knee" in _ros2(env, "param", "get", node, "joint")
        topics = _ros2(env, "topic", "list").split()
        assert {"/arm/command", "/arm/encoder", "/arm/backlash_identifier/estimate"} <= set(topics)
        from std_msgs.msg import Float64

        text = _diagnostics_until(env, Float64, "/arm/command", "command_type", 20.0)
        assert "a publisher of std_msgs/msg/Float64 on /arm/command" in text
        assert "set parameter command_type to float64" in text
        status = running.interrupt(times=1)
        output = running.output()
        assert status == 0 and "process has finished cleanly" in output, output
        assert "Traceback" not in output, output
    finally:
        running.kill()
