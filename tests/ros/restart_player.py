"""A drivetrain publisher process for the restart tests: plays Example 1's backlash over DDS.

Run as ``python tests/ros/restart_player.py --domain-id N [--rate HZ] [--seconds S]``. It waits
until a node's readers match, then at ``rate`` Hz writes a ``std_msgs/Float64MultiArray``
command ``[u_k, k, t_k]`` on ``rt/command`` (default QoS; ``k`` the sequence number, ``t_k``
the wall-clock write time in ns, i.e. the node's data time of the command) and a
``sensor_msgs/JointState`` encoder reading ``y_k`` (joint ``j``, stamped just after) on
``rt/encoder`` (sensor-data QoS). ``u`` is uniform random in ``(-2, 2)``, ``y`` the noisy
output (SNR 25) of Example 1's general backlash whose dead-zone widths grow by ``--wear``
over the run. It keeps writing whether or not a node is listening (a node may be killed and
restarted meanwhile). At the end it prints one JSON line: sent count, achieved rate, ``u``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main() -> int:
    # imported here: pytest's doctest collection imports this file where cyclonedds may be missing
    import numpy as np
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    from genbacklash_core import GeneralBacklash, paper_example
    from genbacklash_core.simulate import simulate_backlash
    from genbacklash_ros.dds_node import DEFAULT_QOS, SENSOR_QOS
    from genbacklash_ros.dds_types import (
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
    parser.add_argument("--seconds", type=float, default=16.0)
    parser.add_argument("--wear", type=float, default=0.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--match-timeout", type=float, default=30.0)
    args = parser.parse_args()

    n = int(args.rate * args.seconds)
    rng = np.random.default_rng(args.seed)
    u = rng.uniform(-2.0, 2.0, n)
    base = paper_example(1).backlash
    x = np.empty(n)
    x_prev = 0.0
    for start in range(0, n, 100):  # the gap widens linearly, in blocks of 100 samples
        factor = 1.0 + args.wear * (start + 50) / n
        worn = GeneralBacklash(
            base.m_left, base.c_left * factor, base.m_right, base.c_right * factor
        )
        x[start : start + 100] = simulate_backlash(worn, u[start : start + 100], x_prev)
        x_prev = float(x[min(start + 100, n) - 1])
    y = x + rng.normal(0.0, float(np.std(x)) / 25.0, n)

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
    layout = MultiArrayLayout_([MultiArrayDimension_("u,seq,t_ns", 3, 3)], 0)
    period = 1.0 / args.rate
    start_time = time.monotonic()
    for k in range(n):
        delay = start_time + k * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        now = time.time_ns()
        command.write(Float64MultiArray_(layout, [float(u[k]), float(k), float(now)]))
        # stamped after the command was written (its source time): the sample sees u_k
        sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
        encoder.write(JointState_(Header_(Time_(sec, nanosec), ""), ["j"], [float(y[k])], [], []))
    elapsed = time.monotonic() - start_time
    time.sleep(0.5)  # let reliable samples be acknowledged before the participant goes
    print(json.dumps({"sent": n, "seconds": elapsed, "rate": n / elapsed, "u": u.tolist()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
