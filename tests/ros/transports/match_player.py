"""An rclpy publisher that is already writing when the node starts: what is lost after the match.

Run as ``python tests/ros/transports/match_player.py [--rate HZ] [--seconds S]`` (``ROS_DOMAIN_ID``
from the environment). From its start, at ``rate`` Hz, it publishes a
``std_msgs/Float64MultiArray`` command ``[u_k, k, t_k]`` on ``/command`` (default QoS; ``t_k`` the
publish time, monotonic ns) and, stamped after it, the ``sensor_msgs/JointState`` reading ``y_k``
of joint ``j`` on ``/encoder`` (sensor-data QoS): the paper's Example 1, repeated. It prints
``publishing`` (flushed) once its endpoints exist, so that a test starts the node after it, as
a node joins a running robot. The *match* is the first tick at which its command publisher
counts a subscription (rclpy's ``get_subscription_count``, checked before every command): it
publishes from that moment without a pause, for ``seconds`` more, waits for the node's replies
on ``/compensated_command`` (matched to commands by ``k``, element 1, which the node passes
unchanged) and prints one JSON line: ``k_match`` (the first command published after the match),
``k_last``, ``lost`` (the commands from ``k_match`` on without a reply), ``latency_ms`` (median
of the replies) and ``error`` when nothing matched within ``--match-timeout``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from genbacklash_core import paper_example


def main(argv: list[str] | None = None) -> int:
    # run as a script: this file's folder is on sys.path
    from _player import spinning, wait_for

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=500.0)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--match-timeout", type=float, default=60.0)
    parser.add_argument("--reply-timeout", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from genbacklash_ros.node.wiring import READER_DEPTH

    data = paper_example(1).generate(args.seed, n_samples=4000)
    rclpy.init()
    node = rclpy.create_node("genbacklash_match_player")
    replies: dict[int, int] = {}
    sent: dict[int, int] = {}

    def on_compensated(msg: Any) -> None:
        now = time.monotonic_ns()
        replies.setdefault(int(msg.data[1]), now)

    # a deep history: a reply lost in this process's own queue is not the node's loss
    node.create_subscription(
        Float64MultiArray, "/compensated_command", on_compensated, READER_DEPTH
    )
    command = node.create_publisher(Float64MultiArray, "/command", 10)
    encoder = node.create_publisher(JointState, "/encoder", qos_profile_sensor_data)
    with spinning(node):
        print("publishing", flush=True)
        period = 1.0 / args.rate
        k_match = -1
        end = time.monotonic() + args.match_timeout
        next_write = time.monotonic()
        k = 0
        while time.monotonic() < end:
            if k_match < 0 and command.get_subscription_count() >= 1:
                k_match = k
                end = time.monotonic() + args.seconds
            i = k % len(data.u)
            cmd = Float64MultiArray()
            cmd.data = [float(data.u[i]), float(k), float(time.monotonic_ns())]
            sent[k] = time.monotonic_ns()
            command.publish(cmd)
            reading = JointState()
            reading.header.stamp = node.get_clock().now().to_msg()  # after its command
            reading.name = ["j"]
            reading.position = [float(data.y[i])]
            encoder.publish(reading)
            k += 1
            next_write += period
            if (remaining := next_write - time.monotonic()) > 0:
                time.sleep(remaining)
            elif remaining < -0.1:  # descheduled: do not burst to catch up
                next_write = time.monotonic()
        if k_match < 0:
            print(json.dumps({"error": f"no subscription matched in {args.match_timeout} s"}))
            return 1
        wanted = range(k_match, k)
        wait_for(lambda: all(j in replies for j in wanted), args.reply_timeout)
        lost = [j for j in wanted if j not in replies]
        latency = sorted((replies[j] - sent[j]) / 1e6 for j in wanted if j in replies)
        summary = {
            "k_match": k_match,
            "k_last": k - 1,
            "lost": lost,
            "latency_ms": latency[len(latency) // 2] if latency else None,
        }
        print(json.dumps(summary), flush=True)
        return 0


if __name__ == "__main__":
    sys.exit(main())
