"""Play a physics drivetrain with a motor encoder to a backlash_identifier over rclpy.

Run as ``python tests/ros/transports/motor_player.py --domain-id N [--seconds S]``. A MuJoCo
drivetrain (:mod:`genbacklash_ros.physics`, ``near_ideal`` at 60 Hz servo bandwidth; no
loss, no jitter) in operation, played in real time: every 1 ms a ``sensor_msgs/JointState``
of ``drive_joint`` on ``/encoder`` (the load) and one on ``/motor_encoder`` (the rotor), both
stamped with the same time (a drive sampling its two encoders together), every 10 ms first a
``std_msgs/Float64`` on ``/command``. It waits until the node's endpoints match, plays, waits
for the answers and prints one JSON line: the commands sent, the compensated commands
received, the last estimate (values and labels), and the geometric play.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any


def main() -> int:
    # run as a script: this file's folder is on sys.path
    from _player import await_answers, spinning, tick_in_real_time, wait_for

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain-id", type=int, required=True)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--settle", type=float, default=0.5)
    parser.add_argument("--match-timeout", type=float, default=30.0)
    args = parser.parse_args()

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, Float64MultiArray

    from genbacklash_core.scenarios import OperationSettings
    from genbacklash_ros.physics.record import physics_record
    from genbacklash_ros.physics.variants import variant

    params = variant("near_ideal", bandwidth=60.0)
    settings = OperationSettings(
        duration=args.seconds, command_jitter=0.0, stamp_jitter=0.0, loss=0.0
    )
    rec = physics_record(params, settings, args.seed)
    commands = rec.command_u.tolist()
    loads, motors = rec.y_all.tolist(), rec.motor_y.tolist()
    n_cmd, n_enc = len(commands), len(loads)
    per_command = n_enc // n_cmd

    rclpy.init(domain_id=args.domain_id)
    node = rclpy.create_node("motor_player")
    command = node.create_publisher(Float64, "command", 10)
    encoder = node.create_publisher(JointState, "encoder", qos_profile_sensor_data)
    motor = node.create_publisher(JointState, "motor_encoder", qos_profile_sensor_data)
    keep = QoSProfile(depth=n_cmd + 100, reliability=ReliabilityPolicy.RELIABLE)
    answered: list[float] = []
    estimate: dict[str, Any] = {"values": [], "label": "", "count": 0}

    def on_compensated(msg: Any) -> None:
        answered.append(float(msg.data))

    def on_estimate(msg: Any) -> None:
        estimate["values"] = [float(v) for v in msg.data]
        estimate["label"] = msg.layout.dim[0].label if msg.layout.dim else ""
        estimate["count"] += 1

    node.create_subscription(Float64, "compensated_command", on_compensated, keep)
    node.create_subscription(Float64MultiArray, "/backlash_identifier/estimate", on_estimate, keep)
    with spinning(node):
        if not wait_for(
            lambda: (
                command.get_subscription_count() >= 1
                and encoder.get_subscription_count() >= 1
                and motor.get_subscription_count() >= 1
                and node.count_publishers("compensated_command") >= 1
                and node.count_publishers("/backlash_identifier/estimate") >= 1
            ),
            args.match_timeout,
        ):
            print(json.dumps({"error": "the node's subscriptions did not match"}))
            return 1
        time.sleep(args.settle)
        sent: list[float] = []

        def tick(k: int) -> None:
            if k % per_command == 0 and k // per_command < n_cmd:
                value = commands[k // per_command]
                sent.append(value)
                command.publish(Float64(data=value))
            stamp = node.get_clock().now().to_msg()
            for publisher, value in ((motor, motors[k]), (encoder, loads[k])):
                reading = JointState(name=["drive_joint"], position=[value])
                reading.header.stamp = stamp
                publisher.publish(reading)

        tick_in_real_time(n_enc, 1e-3, tick)
        await_answers(answered, len(sent))
        time.sleep(1.5)  # an estimate more
        summary = {
            "sent": sent,
            "answered": answered,
            "estimate": estimate,
            "geometric_play": params.c_left + params.c_right,
        }
        print(json.dumps(summary))
        return 0


if __name__ == "__main__":
    sys.exit(main())
