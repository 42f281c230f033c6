"""A publisher process for the DDS node tests: plays the paper's Example 1 over DDS.

Run as ``python tests/ros/transports/dds_player.py --domain-id N [--rate HZ] [--seconds S] [--clock
monotonic|wall] [--via cyclonedds|rclpy]``. It waits until the node's readers match, then at
``rate`` Hz writes a
``std_msgs/Float64MultiArray`` command ``[u_k, k, t_k]`` on ``rt/command`` (default QoS; ``k``
the sequence number, ``t_k`` the write time in ns on the system-wide monotonic clock, for
latency, or with ``--clock wall`` on the wall clock, i.e. the node's data time of the command)
and then a
``sensor_msgs/JointState`` encoder reading ``y_k`` (joint ``j``, header stamp taken after the
command was written) on ``rt/encoder`` (sensor-data QoS). ``u`` is Example 1's uniform random
input, ``y`` its noisy backlash output. It keeps writing whether or not a node is listening
once one has matched (a node may be killed and restarted meanwhile). At the end it prints one
JSON line: sent count, achieved rate, and the inputs (so the test can check every compensated
command).

``--via rclpy`` plays the same messages from a real ROS 2 node (``dds_interop_player``; needs a
sourced ROS 2): the interop test. It also subscribes to the node's compensated commands and
estimates, and reports what it received and what its ROS graph shows (node names, and the node
name and type hash of each endpoint on the node's topics).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import Any


def main() -> int:
    # run as a script: this file's folder is on sys.path
    from _player import tick_in_real_time, wait_for

    # imported here: pytest's doctest collection imports this file where cyclonedds may be missing
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from genbacklash_core import paper_example
    from genbacklash_ros.transports.dds_node import DEFAULT_QOS, SENSOR_QOS
    from genbacklash_ros.transports.dds_types import (
        Float64MultiArray_,
        Header_,
        JointState_,
        MultiArrayDimension_,
        MultiArrayLayout_,
        Time_,
    )
    from genbacklash_ros.transports.ros_graph import endpoint_qos

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--domain-id", type=int, required=True)
    parser.add_argument("--rate", type=float, default=500.0)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--match-timeout", type=float, default=30.0)
    parser.add_argument("--clock", choices=("monotonic", "wall"), default="monotonic")
    parser.add_argument("--via", choices=("cyclonedds", "rclpy"), default="cyclonedds")
    args = parser.parse_args()
    clock_ns = time.monotonic_ns if args.clock == "monotonic" else time.time_ns

    n = int(args.rate * args.seconds)
    data = paper_example(1).generate(args.seed, n_samples=n)
    if args.via == "rclpy":
        summary = _play_rclpy(args, data.u.tolist(), data.y.tolist(), clock_ns)
        print(json.dumps(summary))
        return 1 if "error" in summary else 0
    dp = DomainParticipant(args.domain_id)
    command_qos = endpoint_qos(DEFAULT_QOS, "std_msgs/msg/Float64MultiArray")
    encoder_qos = endpoint_qos(SENSOR_QOS, "sensor_msgs/msg/JointState")
    command = DataWriter(dp, Topic(dp, "rt/command", Float64MultiArray_), qos=command_qos)
    encoder = DataWriter(dp, Topic(dp, "rt/encoder", JointState_), qos=encoder_qos)
    if not wait_for(
        lambda: (
            command.get_publication_matched_status().current_count >= 1
            and encoder.get_publication_matched_status().current_count >= 1
        ),
        args.match_timeout,
    ):
        print(json.dumps({"error": "the node's readers did not match"}))
        return 1
    time.sleep(0.3)  # let the remote readers finish matching both ways
    label = "u,seq,t_mono_ns" if args.clock == "monotonic" else "u,seq,t_ns"
    layout = MultiArrayLayout_([MultiArrayDimension_(label, 3, 3)], 0)

    def tick(k: int) -> None:
        u, y = float(data.u[k]), float(data.y[k])
        command.write(Float64MultiArray_(layout, [u, float(k), float(clock_ns())]))
        sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
        encoder.write(JointState_(Header_(Time_(sec, nanosec), ""), ["j"], [y], [], []))

    elapsed, late = tick_in_real_time(n, 1.0 / args.rate, tick)
    time.sleep(0.5)  # let reliable samples be acknowledged before the participant goes
    summary = {"sent": n, "seconds": elapsed, "rate": n / elapsed, "late": late}
    summary["u"] = data.u.tolist()
    print(json.dumps(summary))
    return 0


def _play_rclpy(
    args: argparse.Namespace, u: list[float], y: list[float], clock_ns: Callable[[], int]
) -> dict[str, Any]:
    """The same stream from an rclpy node; what came back and what the ROS graph shows."""
    # run as a script: this file's folder is on sys.path
    import rclpy
    from _player import await_answers, spinning, tick_in_real_time, wait_for
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

    n = len(u)
    rclpy.init(domain_id=args.domain_id)
    node = rclpy.create_node("dds_interop_player")
    command = node.create_publisher(Float64MultiArray, "command", 10)
    encoder = node.create_publisher(JointState, "encoder", qos_profile_sensor_data)
    keep = QoSProfile(depth=n + 100, reliability=ReliabilityPolicy.RELIABLE)
    answered: dict[int, float] = {}
    estimates: list[tuple[str, list[float]]] = []

    def on_compensated(msg: Any) -> None:
        answered[int(msg.data[1])] = float(msg.data[0])

    def on_estimate(msg: Any) -> None:
        label = msg.layout.dim[0].label if msg.layout.dim else ""
        estimates.append((label, [float(v) for v in msg.data]))

    node.create_subscription(Float64MultiArray, "compensated_command", on_compensated, keep)
    node.create_subscription(Float64MultiArray, "/backlash_identifier/estimate", on_estimate, keep)
    with spinning(node):
        if not wait_for(
            lambda: command.get_subscription_count() >= 1 and encoder.get_subscription_count() >= 1,
            args.match_timeout,
        ):
            return {"error": "the node's subscriptions did not match"}
        time.sleep(0.3)
        label = "u,seq,t_mono_ns" if args.clock == "monotonic" else "u,seq,t_ns"
        layout = MultiArrayLayout(dim=[MultiArrayDimension(label=label, size=3, stride=3)])

        def tick(k: int) -> None:
            command.publish(Float64MultiArray(layout=layout, data=[u[k], float(k), clock_ns()]))
            reading = JointState(name=["j"], position=[y[k]])
            reading.header.stamp = node.get_clock().now().to_msg()
            encoder.publish(reading)

        elapsed, _ = tick_in_real_time(n, 1.0 / args.rate, tick)
        await_answers(answered, n, timeout=10.0)
        time.sleep(0.3)
        graph = {
            "nodes": sorted(
                ns.rstrip("/") + "/" + name for name, ns in node.get_node_names_and_namespaces()
            ),
            "endpoints": [
                {
                    "topic": topic,
                    "kind": kind,
                    "node": info.node_namespace.rstrip("/") + "/" + info.node_name,
                    "type": info.topic_type,
                    "type_hash": str(info.topic_type_hash),
                }
                for topic in ("/command", "/encoder", "/backlash_identifier/estimate")
                for kind, infos in (
                    ("publisher", node.get_publishers_info_by_topic(topic)),
                    ("subscription", node.get_subscriptions_info_by_topic(topic)),
                )
                for info in infos
            ],
        }
        summary = {
            "sent": n,
            "seconds": elapsed,
            "rate": n / elapsed,
            "answered": len(answered),
            "answered_in_range": sum(1 for k in answered if 0 <= k < n),
            "estimates": len(estimates),
            "last_estimate": estimates[-1] if estimates else None,
            "graph": graph,
        }
        return summary


if __name__ == "__main__":
    sys.exit(main())
