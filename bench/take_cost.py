"""CPU per message of the rclpy node: rclpy's executor against the node's own wait loop (issue 24).

    python bench/take_cost.py [--messages N] [--rounds K] [--quick]

The six-joint node (``BacklashIdentifierNode`` with ``joints: [joint_1 .. joint_6]``, the
pipeline and its live workers as ``genbacklash node`` runs them, one BLAS thread) in a
process of its own, on a DDS domain of its own, with a peer node in the same process that
publishes N commands (a 7-element ``Float64MultiArray``) and N six-joint ``JointState``
readings into the node's reader histories before anything is taken (reliable, so none is
lost). Then the draining thread's CPU time (``thread_time``) and the process's
(``process_time``) while the node takes and handles all 2 N messages, per message, three
ways:

* ``executor``: what ``genbacklash node --transport rclpy`` did before, a
  ``SingleThreadedExecutor`` spun once at a time (one message per ``spin_once``);
* ``loop``: the node's own wait loop (``WaitLoop``), one message per subscription and
  wake-up (``TAKE_BATCH`` 1, ``DRAIN_ROUNDS`` 0), as at 1 kHz where each wake-up finds one
  or two;
* ``pipeline``: the same messages (taken by the loop first) handed to the node's callbacks
  with nothing else: the floor.

CPU time rather than wall time: the machine is shared, and another process's load does not
enter it (it still cools the caches). Modes run round robin, ``K`` rounds each, a fresh
process per run; the median per mode is reported, and the middleware's share (mode less
pipeline).
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import command_line, machine_description, md_table, write_section

MODES = ("executor", "loop", "pipeline")
JOINTS = tuple(f"joint_{i + 1}" for i in range(6))


def child(mode: str, n: int) -> int:
    """One run: publish, drain, print ``thread_us process_us count``."""
    import math

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from genbacklash_ros.transports import rclpy_node

    with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as params:
        params.write(
            "/**/backlash_identifier:\n  ros__parameters:\n"
            "    command_type: float64_multi_array\n"
            f"    joints: [{', '.join(JOINTS)}]\n    command_indices: [0, 1, 2, 3, 4, 5]\n"
        )
    rclpy.init(args=["take_cost", "--ros-args", "--params-file", params.name])
    node = rclpy_node.BacklashIdentifierNode()
    count = [0]
    stored: list[tuple[object, object, object]] = []
    for sub in (node._command_sub, node._encoder_sub):

        def counted(msg: object, info: object, callback: object = sub.callback) -> None:
            count[0] += 1
            if mode == "pipeline":
                stored.append((callback, msg, info))
            else:
                callback(msg, info)  # type: ignore[operator]

        sub.callback = counted
    peer = rclpy.create_node("take_cost_peer")
    reliable = QoSProfile(depth=n, reliability=ReliabilityPolicy.RELIABLE)
    command = peer.create_publisher(Float64MultiArray, "/command", QoSProfile(depth=n))
    encoder = peer.create_publisher(JointState, "/encoder", reliable)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while not (command.get_subscription_count() and encoder.get_subscription_count()):
        time.sleep(0.05)
    time.sleep(1.0)
    t0 = time.time_ns()
    for k in range(n):
        u = [0.5 * math.sin(k / 200 + j) for j in range(6)] + [float(k)]
        command.publish(Float64MultiArray(data=u))
        reading = JointState(name=list(JOINTS), position=[0.4 * v for v in u[:6]])
        reading.header.stamp.sec, reading.header.stamp.nanosec = divmod(
            t0 + k * 1_000_000 + 100_000, 1_000_000_000
        )
        encoder.publish(reading)
        if k % 100 == 99:
            time.sleep(0.02)  # let the reader keep up: none lost
    time.sleep(1.0)
    rclpy_node.TAKE_BATCH = 1
    # one wake-up per message: the loop's drain (take again before waiting) would find the
    # whole pre-filled history and take it without waiting, which at 1 kHz it does not
    rclpy_node.DRAIN_ROUNDS = 0
    loop = rclpy_node.WaitLoop(node, executor) if mode != "executor" else None
    deadline = time.monotonic() + 300
    c0, p0 = time.thread_time(), time.process_time()
    while count[0] < 2 * n and time.monotonic() < deadline:
        if loop is not None:
            loop.run_once(0.1)
        else:
            executor.spin_once(timeout_sec=0.1)
    if mode == "pipeline":
        c0, p0 = time.thread_time(), time.process_time()
        for callback, msg, info in stored:
            callback(msg, info)  # type: ignore[operator]
    c1, p1 = time.thread_time(), time.process_time()
    print(f"{1e6 * (c1 - c0) / count[0]:.1f} {1e6 * (p1 - p0) / count[0]:.1f} {count[0]}")
    sys.stdout.flush()
    os._exit(0)  # (the node's threads and rclpy's teardown are not what is measured)


def run(n: int, rounds: int) -> str:
    results: dict[str, list[tuple[float, float]]] = {m: [] for m in MODES}
    started = time.perf_counter()
    for _ in range(rounds):
        for mode in MODES:
            env = {**os.environ, "ROS_DOMAIN_ID": str(random.randint(201, 231))}
            done = subprocess.run(
                [sys.executable, __file__, "--child", mode, "--messages", str(n)],
                capture_output=True,
                text=True,
                env=env,
                timeout=600,
                check=True,
            )
            thread_us, process_us, count = done.stdout.split()
            if int(count) != 2 * n:
                raise RuntimeError(f"{mode}: {count} of {2 * n} messages taken")
            results[mode].append((float(thread_us), float(process_us)))

    def median(mode: str, i: int) -> float:
        values = sorted(r[i] for r in results[mode])
        return values[len(values) // 2]

    floor = median("pipeline", 0)
    rows = [
        [
            mode,
            f"{median(mode, 0):.0f}",
            f"{median(mode, 1):.0f}",
            f"{median(mode, 0) - floor:.0f}" if mode != "pipeline" else "",
            ", ".join(f"{r[0]:.0f}" for r in results[mode]),
        ]
        for mode in MODES
    ]
    table = md_table(
        [
            "mode",
            "thread CPU per message (us, median)",
            "process CPU per message (us)",
            "less the pipeline (us)",
            "thread CPU per run (us)",
        ],
        rows,
    )
    over_executor = median("executor", 0) - floor
    over_loop = median("loop", 0) - floor
    return f"""## rclpy take cost: the executor against the node's wait loop (issue 24)

`{command_line()}`. Machine: {machine_description()}. Run time
{time.perf_counter() - started:.0f} s.

The six-joint node in process; {n} commands and {n} readings published into its reader
histories first, then taken and handled ({rounds} runs per mode, round robin, a process each;
CPU time, so the machine's load enters only through the caches).

{table}

Per message at 1 kHz (2,000 messages a second): rclpy's executor costs
{over_executor:.0f} us over the pipeline ({2000 * over_executor / 1e6:.2f} of a core), the
wait loop {over_loop:.0f} us ({2000 * over_loop / 1e6:.2f} of a core);
executor / loop, whole message: {median("executor", 0) / median("loop", 0):.2f}x.
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--messages", type=int, default=1500, help="commands (and readings)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--child", choices=MODES, help=argparse.SUPPRESS)
    parser.add_argument("--quick", action="store_true", help="500 messages, 1 round")
    args = parser.parse_args(argv)
    if args.child:
        from genbacklash_ros.blas_threads import one_blas_thread

        with one_blas_thread():  # as `genbacklash node` runs the node
            return child(args.child, args.messages)
    if args.quick:
        args.messages, args.rounds = 500, 1
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.ros.transports._ros2 import rclpy_missing

    if reason := rclpy_missing():
        write_section("take_cost", f"## rclpy take cost (issue 24)\n\nSkipped: {reason}.")
        return 0
    text = run(args.messages, args.rounds)
    print(text)
    write_section("take_cost", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
