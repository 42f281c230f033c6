"""The rclpy node's own wait loop (:class:`~genbacklash_ros.transports.rclpy_node.WaitLoop`),
against the real rclpy (the ROS 2 wheels, Fast DDS).

In process: the loop takes ``command`` and ``encoder`` itself, in source-timestamp order (a
reading at the next wake-up: it does not wake the loop), while
executors no longer see them (and see them again once it is closed); it still serves the
parameter services, the 1 Hz timer and a ``/clock`` subscription made at run time through the
executor; it ends on an external shutdown. As processes (mirroring ``test_multijoint_node.py``):
``genbacklash node --transport rclpy`` fed a three-joint arm (``arm_player.py``: readings at
1 kHz, commands at 100 Hz) answers every command while another process's parameter requests
are answered (one taken, one refused with the reason, one taken), and exits 0 on SIGINT.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from ._dds import stop_node
from ._ros2 import domain_id, rclpy_missing

HERE = Path(__file__).parent

pytestmark = pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")


def _until(condition: Callable[[], bool], step: Callable[[], object], seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        step()


def _reading(value: float, stamp_ns: int) -> Any:
    from sensor_msgs.msg import JointState

    msg = JointState(name=["j"], position=[value])
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    return msg


def _first(raw: bytes, kind: str) -> float:
    """The first command element or reading of a message the node's raw subscriptions took
    (CDR bytes: ``raw=True``)."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    assert isinstance(raw, bytes)
    if kind == "command":
        return float(deserialize_message(raw, Float64MultiArray).data[0])
    return float(deserialize_message(raw, JointState).position[0])


@dataclass
class _Wired:
    node: Any  # the BacklashIdentifierNode
    command: Any  # the peer's /command publisher
    encoder: Any  # the peer's /encoder publisher
    executor: Any  # an executor with the node added
    loop: Any  # the node's WaitLoop over it


@contextmanager
def _node_and_peer(
    peer_name: str, callbacks: Callable[[Any], tuple[Callable[..., None], Callable[..., None]]]
) -> Iterator[_Wired]:
    """The node, its wait loop and a peer publishing ``/command`` and ``/encoder``, matched
    both ways (rclpy initialised by the test's ``ros_init``); all torn down after.
    ``callbacks(encoder publisher)``: the node's command and encoder callbacks, installed
    before the loop takes the subscriptions over."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    peer = rclpy.create_node(peer_name)
    command = peer.create_publisher(Float64MultiArray, "/command", 10)
    encoder = peer.create_publisher(JointState, "/encoder", qos_profile_sensor_data)
    node._command_sub.callback, node._encoder_sub.callback = callbacks(encoder)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    loop = rclpy_node.WaitLoop(node, executor)
    try:
        _until(
            lambda: command.get_subscription_count() and encoder.get_subscription_count(),
            lambda: time.sleep(0.05),
            15.0,
        )
        time.sleep(0.5)  # both directions of discovery
        yield _Wired(node, command, encoder, executor, loop)
    finally:
        loop.close()
        executor.shutdown()
        peer.destroy_node()
        node.finish()
        node.destroy_node()


def test_the_loop_takes_both_topics_in_source_order_and_executors_do_not(
    ros_init: Callable[..., Any],
) -> None:
    from std_msgs.msg import Float64MultiArray

    ros_init()
    seen: list[tuple[str, float]] = []
    with _node_and_peer(
        "wait_loop_peer",
        lambda _: (
            lambda msg, info: seen.append(("command", _first(msg, "command"))),
            lambda msg, info: seen.append(("encoder", _first(msg, "encoder"))),
        ),
    ) as w:
        # a reading first, then two commands, then a reading: taken in one wake-up, the
        # commands' subscription first, yet handed on in the order they were published
        w.encoder.publish(_reading(0.5, 1))
        w.command.publish(Float64MultiArray(data=[1.0]))
        w.command.publish(Float64MultiArray(data=[2.0]))
        w.encoder.publish(_reading(0.75, 2))
        time.sleep(0.3)  # all four delivered, none taken yet
        # an executor spun on the node does not take them while the loop holds them
        w.executor.spin_once(timeout_sec=0.2)
        assert seen == []
        _until(lambda: len(seen) >= 4, lambda: w.loop.run_once(0.1), 5.0)
        assert seen == [("encoder", 0.5), ("command", 1.0), ("command", 2.0), ("encoder", 0.75)]
        assert w.loop.taken == 4
        # closed, the loop gives them back: the executor takes the next one itself
        w.loop.close()
        w.command.publish(Float64MultiArray(data=[3.0]))
        _until(lambda: len(seen) >= 5, lambda: w.executor.spin_once(timeout_sec=0.1), 5.0)
        assert seen[-1] == ("command", 3.0)


def test_a_reading_that_comes_while_a_command_is_handled_is_taken_in_the_same_wake_up(
    ros_init: Callable[..., Any],
) -> None:
    """The loop takes again before it waits (``WaitLoop._drain``): at 1 kHz the reading
    published right after a command is handed on in the wake-up that took the command."""
    from std_msgs.msg import Float64MultiArray

    ros_init()
    seen: list[tuple[str, float]] = []

    def callbacks(encoder: Any) -> tuple[Callable[..., None], Callable[..., None]]:
        def on_command(msg: Any, info: Any) -> None:
            seen.append(("command", _first(msg, "command")))
            encoder.publish(_reading(0.25, 2))  # comes while the command is being handled
            time.sleep(0.05)

        return on_command, lambda msg, info: seen.append(("encoder", _first(msg, "encoder")))

    with _node_and_peer("wait_loop_drain_peer", callbacks) as w:
        w.command.publish(Float64MultiArray(data=[1.0]))
        time.sleep(0.05)  # delivered, not taken
        assert w.loop.run_once(1.0) == 2
        assert seen == [("command", 1.0), ("encoder", 0.25)]
        assert w.loop.taken == 2


def test_a_reading_does_not_wake_the_loop_the_next_command_takes_it(
    ros_init: Callable[..., Any],
) -> None:
    """The encoder's subscription is not in the wait set (a reading needs no answer): a
    reading alone waits for the wait's timeout, and a command then takes it with itself, the
    reading first (it came first)."""
    from std_msgs.msg import Float64MultiArray

    ros_init()
    seen: list[tuple[str, float]] = []
    with _node_and_peer(
        "wait_loop_lazy_peer",
        lambda _: (
            lambda msg, info: seen.append(("command", _first(msg, "command"))),
            lambda msg, info: seen.append(("encoder", _first(msg, "encoder"))),
        ),
    ) as w:
        assert w.node._encoder_sub not in w.loop._waited
        for timer in w.node.timers:  # the 1 Hz tick would wake the wait too
            timer.cancel()
        w.encoder.publish(_reading(0.5, 1))
        time.sleep(0.2)  # delivered
        start = time.monotonic()
        assert w.loop.run_once(0.6) == 1  # taken when the wait timed out, not before
        assert time.monotonic() - start >= 0.55
        assert seen == [("encoder", 0.5)]
        w.encoder.publish(_reading(0.25, 2))
        time.sleep(0.2)
        w.command.publish(Float64MultiArray(data=[1.0]))
        time.sleep(0.2)
        start = time.monotonic()
        assert w.loop.run_once(5.0) == 2  # the command woke it, the reading came along
        assert time.monotonic() - start < 2.0
        assert seen[1:] == [("encoder", 0.25), ("command", 1.0)]


def test_services_timer_and_a_clock_made_at_run_time_are_served(
    ros_init: Callable[..., Any],
) -> None:
    """A parameter request from another node, the 1 Hz diagnostics (STALE: no data) and, after
    ``use_sim_time`` is set at run time, the ``/clock`` subscription rclpy then makes."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from rosgraph_msgs.msg import Clock

    from genbacklash_ros.transports import rclpy_node

    ros_init()
    node = rclpy_node.BacklashIdentifierNode()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    loop = rclpy_node.WaitLoop(node, executor)
    # the client side on an executor of its own, in a thread (as another process would be)
    peer = rclpy.create_node("wait_loop_client")
    statuses: list[Any] = []
    peer.create_subscription(DiagnosticArray, "/diagnostics", statuses.append, 10)
    clock = peer.create_publisher(Clock, "/clock", 10)
    peer_executor = SingleThreadedExecutor()
    peer_executor.add_node(peer)
    spinner = threading.Thread(target=peer_executor.spin, daemon=True)
    spinner.start()
    client = AsyncParameterClient(peer, "backlash_identifier")
    try:
        assert client.wait_for_services(timeout_sec=15.0)
        future = client.set_parameters(
            [Parameter("publish_rate", value=5.0), Parameter("degree", value=12)]
        )
        _until(future.done, lambda: loop.run_once(0.05), 10.0)
        taken, refused = future.result().results
        assert taken.successful and not refused.successful and "degree" in refused.reason
        assert node._params.publish_rate == 5.0 and node._params.degree == 3
        _until(lambda: bool(statuses), lambda: loop.run_once(0.05), 5.0)
        assert statuses[-1].status[0].level == bytes([3])  # STALE: nothing came
        # use_sim_time at run time: rclpy subscribes /clock; the loop waits on it too
        assert not any(s.topic_name == "/clock" for s in loop._subs)
        future = client.set_parameters([Parameter("use_sim_time", value=True)])
        _until(future.done, lambda: loop.run_once(0.05), 10.0)
        assert future.result().results[0].successful
        assert any(s.topic_name == "/clock" for s in loop._subs)
        _until(lambda: clock.get_subscription_count() > 0, lambda: loop.run_once(0.05), 10.0)
        time.sleep(0.3)
        clock.publish(Clock(clock=rclpy.time.Time(seconds=42).to_msg()))
        _until(
            lambda: node.get_clock().now().nanoseconds == 42_000_000_000,
            lambda: loop.run_once(0.05),
            5.0,
        )
    finally:
        loop.close()
        peer_executor.shutdown()
        spinner.join(5.0)
        executor.shutdown()
        peer.destroy_node()
        node.finish()
        node.destroy_node()


def test_an_external_shutdown_ends_the_loop(ros_init: Callable[..., Any]) -> None:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    from genbacklash_ros.transports import rclpy_node

    ros_init()
    node = rclpy_node.BacklashIdentifierNode()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    loop = rclpy_node.WaitLoop(node, executor)
    threading.Timer(0.3, rclpy.shutdown).start()
    try:
        with pytest.raises(ExternalShutdownException):
            for _ in range(100):
                loop.run_once(0.1)
    finally:
        loop.close()
        node.finish()
        node.destroy_node()


# --------------------------------------------------------------------------- as processes

_PARAMETER_CLIENT = """
import json, sys, time
import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
rclpy.init()
node = rclpy.create_node("wait_loop_parameter_client")
client = AsyncParameterClient(node, "backlash_identifier")
assert client.wait_for_services(timeout_sec=30.0)
out = []
for values in ([("publish_rate", 4.0)], [("window", 1)], [("gate_low", 0.3)]):
    start = time.monotonic()
    future = client.set_parameters([Parameter(n, value=v) for n, v in values])
    rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
    result = future.result().results[0]
    out.append([result.successful, result.reason, time.monotonic() - start])
print(json.dumps(out), flush=True)
node.destroy_node()
rclpy.try_shutdown()
"""


def test_a_fed_node_answers_every_command_and_its_parameter_services(tmp_path: Path) -> None:
    """The node as its own process, fed for 4 s by ``arm_player.py``; meanwhile another
    process sets a parameter, is refused one and sets another, each answered within a second;
    every command answered; SIGINT: exit 0."""
    domain = str(domain_id())
    params = tmp_path / "arm.yaml"
    params.write_text(
        "/**/backlash_identifier:\n  ros__parameters:\n    command_type: float64_multi_array\n"
        "    joints: [shoulder, elbow, wrist]\n    command_indices: [0, 2, 3]\n"
    )
    log = tmp_path / "node.log"
    node = subprocess.Popen(
        [
            *(sys.executable, "-m", "genbacklash_ros.cli.node", "--transport", "rclpy"),
            *("--params-file", str(params), "--domain-id", domain),
        ],
        stdout=subprocess.DEVNULL,
        stderr=log.open("wb"),
    )
    try:
        client = subprocess.Popen(
            [sys.executable, "-c", _PARAMETER_CLIENT],
            env={**os.environ, "ROS_DOMAIN_ID": domain},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        player = subprocess.run(
            [
                *(sys.executable, str(HERE / "arm_player.py"), "--domain-id", domain),
                *("--seconds", "4", "--settle", "0.5"),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        out, err = client.communicate(timeout=60)
        assert player.returncode == 0, player.stdout + player.stderr + log.read_text()
        assert client.returncode == 0, err
        summary = json.loads(player.stdout.strip().splitlines()[-1])
        returncode = stop_node(node, log)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait(10)
    text = log.read_text()
    assert len(summary["answered"]) == len(summary["sent"]), text
    (rate_ok, _, rate_s), (window_ok, reason, _), (gate_ok, _, gate_s) = json.loads(out)
    assert rate_ok and gate_ok and not window_ok and "window" in reason
    assert max(rate_s, gate_s) < 1.0
    assert returncode == 0 and "Traceback" not in text, text
