"""Feed the paper's Example 1 to a running backlash_identifier over rclpy; print what came back.

Run as ``python tests/ros/transports/ros2_player.py [--namespace NS] [--rate HZ]
[--samples N] [--min-seconds S] [--tolerance T]`` in a sourced ROS 2 (``ROS_DOMAIN_ID`` from
the environment). It waits until the node subscribes ``command`` and ``encoder``, then at each
tick publishes a ``std_msgs/Float64MultiArray`` command ``u_k`` and, stamped after it, the
``sensor_msgs/JointState`` reading ``y_k`` of joint ``j`` (the true backlash's noisy response),
until the estimate is within ``--tolerance`` of the truth (after at least ``--min-seconds``)
or ``--samples`` are sent. It prints one JSON line: ``sent``, ``compensated`` (commands
answered), ``estimates``, ``error`` (max |parameter error| of the last estimate, null without
one) and ``labels`` (the estimate's parameter names). Exit status 0, or 3 when the node's
subscriptions did not show up within 30 s.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np

from genbacklash_core import paper_example


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--namespace", default="")
    parser.add_argument("--rate", type=float, default=200.0)
    parser.add_argument("--samples", type=int, default=4000)
    parser.add_argument("--min-seconds", type=float, default=0.0)
    parser.add_argument("--tolerance", type=float, default=0.1)
    parser.add_argument("--seed", type=int, default=4)
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    ns = "/" + args.namespace.strip("/") if args.namespace.strip("/") else ""
    truth = paper_example(1).model.parameters()
    rclpy.init()
    node = rclpy.create_node("genbacklash_ros2_player")
    estimates: list[Any] = []
    compensated: list[Any] = []
    node.create_subscription(
        Float64MultiArray, f"{ns}/backlash_identifier/estimate", estimates.append, 10
    )
    node.create_subscription(
        Float64MultiArray, f"{ns}/compensated_command", compensated.append, 100
    )
    command = node.create_publisher(Float64MultiArray, f"{ns}/command", 10)
    encoder = node.create_publisher(JointState, f"{ns}/encoder", qos_profile_sensor_data)
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def error() -> float | None:
        if not estimates:
            return None
        return float(np.max(np.abs(np.array(estimates[-1].data) - truth)))

    try:
        deadline = time.monotonic() + 30.0
        while command.get_subscription_count() < 1 or encoder.get_subscription_count() < 1:
            if time.monotonic() > deadline:
                print("ros2_player: the node did not subscribe within 30 s", file=sys.stderr)
                return 3
            executor.spin_once(timeout_sec=0.05)
        data = paper_example(1).generate(args.seed, n_samples=args.samples)
        period = 1.0 / args.rate
        start = next_write = time.monotonic()
        sent = 0
        for k in range(args.samples):
            cmd = Float64MultiArray()
            cmd.data = [float(data.u[k])]
            command.publish(cmd)
            reading = JointState()
            reading.header.stamp = node.get_clock().now().to_msg()  # after its command
            reading.name = ["j"]
            reading.position = [float(data.y[k])]
            encoder.publish(reading)
            sent += 1
            next_write += period
            while (remaining := next_write - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=remaining)
            if k % 50 == 0 and time.monotonic() - start >= args.min_seconds:
                e = error()
                if e is not None and e < args.tolerance:
                    break
        end = time.monotonic() + 1.0  # answers still in flight
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        labels = estimates[-1].layout.dim[0].label if estimates else None
        summary = {
            "sent": sent,
            "compensated": len(compensated),
            "estimates": len(estimates),
            "error": error(),
            "labels": labels,
        }
        print(json.dumps(summary), flush=True)
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
