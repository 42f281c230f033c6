"""An rclpy subscriber of ``/compensated_command`` that the test can deschedule.

Run as ``python tests/ros/transports/reply_listener.py`` (``ROS_DOMAIN_ID`` from the
environment). It subscribes ``std_msgs/Float64MultiArray`` on ``/compensated_command`` (default
QoS, a history deep enough to keep everything), prints ``listening`` (flushed) once it exists
and ``answered`` at the first answer, and at SIGINT prints one JSON line: the command indices
``k`` it received (element 1 of each answer, which the node passes unchanged, as
``match_player.py`` sends it). A test stops it with
SIGSTOP while the node answers and continues it with SIGCONT: what the kernel dropped meanwhile
must be resent by the node's writer.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
from typing import Any


def main() -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray

    from genbacklash_ros.node.wiring import READER_DEPTH

    rclpy.init()
    node = rclpy.create_node("genbacklash_reply_listener")
    seen: set[int] = set()

    def on_answer(msg: Any) -> None:
        if not seen:
            print("answered", flush=True)
        seen.add(int(msg.data[1]))

    node.create_subscription(Float64MultiArray, "/compensated_command", on_answer, READER_DEPTH)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print("listening", flush=True)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.05)
    print(json.dumps({"k": sorted(seen)}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
