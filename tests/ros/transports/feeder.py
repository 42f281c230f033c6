"""Feed a backlash_identifier at a fixed rate over rclpy until killed, and say when it listens.

Run as ``python tests/ros/transports/feeder.py [--rate HZ]`` (``ROS_DOMAIN_ID`` from the
environment). At each tick it publishes a ``std_msgs/Float64MultiArray`` command ``u_k`` on
``/command`` and, stamped after it, the ``sensor_msgs/JointState`` reading ``y_k`` of joint
``j`` on ``/encoder`` (the paper's Example 1, repeated). It prints ``listeners A,B,...``
(flushed) whenever the set of DDS participants subscribed to both topics changes (each named by
its GUID prefix, in hex), so that a test knows when a node it started is being fed. (A
cyclonedds participant that exits stays in Fast DDS's graph until its lease ends, ~10 s: a new
one is told apart by its prefix.) It runs until SIGTERM/SIGKILL (no clean-up to speak of: it is
a test's helper).
"""

from __future__ import annotations

import argparse
import sys
import time

from genbacklash_core import paper_example


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=1000.0)
    parser.add_argument("--seed", type=int, default=4)
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    data = paper_example(1).generate(args.seed, n_samples=4000)
    rclpy.init()
    node = rclpy.create_node("genbacklash_feeder")
    command = node.create_publisher(Float64MultiArray, "/command", 10)
    encoder = node.create_publisher(JointState, "/encoder", qos_profile_sensor_data)
    period = 1.0 / args.rate
    listeners: frozenset[str] | None = None

    def subscribers(topic: str) -> frozenset[str]:
        return frozenset(
            bytes(info.endpoint_gid[:12]).hex()
            for info in node.get_subscriptions_info_by_topic(topic)
        )

    next_write = time.monotonic()
    k = 0
    while True:
        if k % 20 == 0:
            now = subscribers("/command") & subscribers("/encoder")
            if now != listeners:
                listeners = now
                print(f"listeners {','.join(sorted(listeners))}", flush=True)
        i = k % len(data.u)
        cmd = Float64MultiArray()
        cmd.data = [float(data.u[i])]
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


if __name__ == "__main__":
    sys.exit(main())
