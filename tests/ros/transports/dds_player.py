"""A publisher process for the DDS node tests: plays the paper's Example 1 over DDS.

Run as ``python tests/ros/transports/dds_player.py --domain-id N [--rate HZ] [--seconds S] [--clock
monotonic|wall]``. It waits until the node's readers match, then at ``rate`` Hz writes a
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
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main() -> int:
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

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--domain-id", type=int, required=True)
    parser.add_argument("--rate", type=float, default=500.0)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--match-timeout", type=float, default=30.0)
    parser.add_argument("--clock", choices=("monotonic", "wall"), default="monotonic")
    args = parser.parse_args()
    clock_ns = time.monotonic_ns if args.clock == "monotonic" else time.time_ns

    n = int(args.rate * args.seconds)
    data = paper_example(1).generate(args.seed, n_samples=n)
    dp = DomainParticipant(args.domain_id)
    command = DataWriter(dp, Topic(dp, "rt/command", Float64MultiArray_), qos=DEFAULT_QOS)
    encoder = DataWriter(dp, Topic(dp, "rt/encoder", JointState_), qos=SENSOR_QOS)
    deadline = time.monotonic() + args.match_timeout
    while time.monotonic() < deadline:
        if (
            command.get_publication_matched_status().current_count >= 1
            and encoder.get_publication_matched_status().current_count >= 1
        ):
            break
        time.sleep(0.05)
    else:
        print(json.dumps({"error": "the node's readers did not match"}))
        return 1
    time.sleep(0.3)  # let the remote readers finish matching both ways
    label = "u,seq,t_mono_ns" if args.clock == "monotonic" else "u,seq,t_ns"
    layout = MultiArrayLayout_([MultiArrayDimension_(label, 3, 3)], 0)
    period = 1.0 / args.rate
    start = time.monotonic()
    late = 0
    for k in range(n):
        target = start + k * period
        delay = target - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -period:
            late += 1
        u, y = float(data.u[k]), float(data.y[k])
        command.write(Float64MultiArray_(layout, [u, float(k), float(clock_ns())]))
        sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
        encoder.write(JointState_(Header_(Time_(sec, nanosec), ""), ["j"], [y], [], []))
    elapsed = time.monotonic() - start
    time.sleep(0.5)  # let reliable samples be acknowledged before the participant goes
    summary = {"sent": n, "seconds": elapsed, "rate": n / elapsed, "late": late}
    summary["u"] = data.u.tolist()
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
