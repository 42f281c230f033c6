"""Play a simulated arm to a backlash_identifier over rclpy and report what came back.

Run as ``python tests/ros/transports/arm_player.py --domain-id N [--seconds S] [--settle S]``.
Three joints (``shoulder``, ``elbow``, ``wrist``), each with its own motion and its own
backlash (:data:`MODELS`; :func:`genbacklash_core.scenarios.arm_records`, no loss, no
jitter), played in real time: every 1 ms a ``sensor_msgs/JointState`` on ``/encoder`` with the
three positions (stamped when published), every 10 ms first a ``std_msgs/Float64MultiArray``
on ``/command`` of four elements: ``[shoulder, k, elbow, wrist]`` with ``k`` the command's
sequence number (element 1 is no joint's: it must come back unchanged). It waits until the
node's endpoints match (its subscriptions and its publishers, both ways), then ``--settle``
seconds, plays, waits for the answers and prints
one JSON line: what was sent, the compensated arrays received (by ``k``), the last estimate on
each ``/backlash_identifier/<joint>/estimate``, the ``/diagnostics`` status names seen, and
each joint's true parameters.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

NAMES = ("shoulder", "elbow", "wrist")
INDICES = (0, 2, 3)
SIZE = 4


def models() -> tuple[Any, ...]:
    from genbacklash_core import GeneralBacklash
    from genbacklash_core.scenarios import OPERATION_BACKLASH, worn

    return (
        OPERATION_BACKLASH,
        worn(OPERATION_BACKLASH, 1.6),
        GeneralBacklash((1.0, 0.02, -0.01), 0.03, (1.0, 0.02, -0.01), 0.025),
    )


def main() -> int:
    # run as a script: this file's folder is on sys.path
    from _player import await_answers, spinning, tick_in_real_time, wait_for

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain-id", type=int, required=True)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--settle", type=float, default=0.3)
    parser.add_argument("--match-timeout", type=float, default=30.0)
    args = parser.parse_args()

    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

    from genbacklash_core.scenarios import OperationSettings, arm_records

    truth = models()
    settings = OperationSettings(
        duration=args.seconds, command_jitter=0.0, stamp_jitter=0.0, loss=0.0
    )
    records = arm_records(truth, settings, args.seed)
    commands = [r.command_u.tolist() for r in records]
    readings = [r.y_all.tolist() for r in records]
    n_cmd, n_enc = len(commands[0]), len(readings[0])
    per_command = n_enc // n_cmd

    rclpy.init(domain_id=args.domain_id)
    node = rclpy.create_node("arm_player")
    command = node.create_publisher(Float64MultiArray, "command", 10)
    encoder = node.create_publisher(JointState, "encoder", qos_profile_sensor_data)
    keep = QoSProfile(depth=n_cmd + 100, reliability=ReliabilityPolicy.RELIABLE)
    answered: dict[int, list[float]] = {}
    estimates: dict[str, list[float]] = {}
    labels: dict[str, str] = {}
    counts: dict[str, int] = {name: 0 for name in NAMES}
    status_names: set[str] = set()

    def on_compensated(msg: Any) -> None:
        answered[int(msg.data[1])] = [float(v) for v in msg.data]

    def on_estimate(name: str) -> Any:
        def take(msg: Any) -> None:
            estimates[name] = [float(v) for v in msg.data]
            labels[name] = msg.layout.dim[0].label if msg.layout.dim else ""
            counts[name] += 1

        return take

    def on_diagnostics(msg: Any) -> None:
        status_names.update(str(s.name) for s in msg.status)

    from diagnostic_msgs.msg import DiagnosticArray

    node.create_subscription(Float64MultiArray, "compensated_command", on_compensated, keep)
    for name in NAMES:
        node.create_subscription(
            Float64MultiArray, f"/backlash_identifier/{name}/estimate", on_estimate(name), keep
        )
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, keep)
    with spinning(node):
        if not wait_for(
            lambda: (
                command.get_subscription_count() >= 1
                and encoder.get_subscription_count() >= 1
                and node.count_publishers("compensated_command") >= 1  # both ways matched
                and all(
                    node.count_publishers(f"/backlash_identifier/{n}/estimate") >= 1 for n in NAMES
                )
            ),
            args.match_timeout,
        ):
            print(json.dumps({"error": "the node's subscriptions did not match"}))
            return 1
        time.sleep(args.settle)
        layout = MultiArrayLayout(dim=[MultiArrayDimension(label="arm", size=SIZE, stride=SIZE)])
        sent: list[list[float]] = []

        def tick(k: int) -> None:
            if k % per_command == 0 and k // per_command < n_cmd:
                i = k // per_command
                data = [0.0] * SIZE
                data[1] = float(i)
                for j, index in enumerate(INDICES):
                    data[index] = commands[j][i]
                sent.append(data)
                command.publish(Float64MultiArray(layout=layout, data=data))
            reading = JointState(name=list(NAMES), position=[readings[j][k] for j in range(3)])
            reading.header.stamp = node.get_clock().now().to_msg()
            encoder.publish(reading)

        elapsed, _ = tick_in_real_time(n_enc, 1e-3, tick)
        await_answers(answered, len(sent))
        time.sleep(1.5)  # an estimate and a diagnostics report more
        summary = {
            "sent": sent,
            "seconds": elapsed,
            "answered": {str(k): v for k, v in answered.items()},
            "estimates": estimates,
            "labels": labels,
            "estimate_counts": counts,
            "status_names": sorted(status_names),
            "truth": {n: m.parameters().tolist() for n, m in zip(NAMES, truth, strict=True)},
        }
        print(json.dumps(summary))
        return 0


if __name__ == "__main__":
    sys.exit(main())
