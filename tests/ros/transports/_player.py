"""What the rclpy player processes share: spinning, waiting for a match, real-time ticks.

The players (``arm_player``, ``motor_player``, ``dds_player --via rclpy``, ``match_player``)
each run one rclpy node that publishes a scenario in real time and counts what comes back.
They differ in what they publish and what they report; this module holds the rest once.
rclpy is imported inside the functions: pytest's doctest collection imports the players
where rclpy may be missing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sized
from contextlib import contextmanager
from typing import Any

__all__ = ["await_answers", "spinning", "tick_in_real_time", "wait_for"]


@contextmanager
def spinning(node: Any) -> Iterator[None]:
    """Spin ``node`` on a background executor; on exit stop it, destroy it, shut rclpy down."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        yield
    finally:
        executor.shutdown()
        spinner.join(5)
        node.destroy_node()
        rclpy.try_shutdown()


def wait_for(ready: Callable[[], bool], timeout: float, poll: float = 0.02) -> bool:
    """Poll ``ready`` until it holds (True) or ``timeout`` seconds pass (False).

    >>> wait_for(lambda: True, 1.0)
    True
    >>> wait_for(lambda: False, 0.0)
    False
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if ready():
            return True
        time.sleep(poll)
    return ready()


def tick_in_real_time(n: int, period: float, tick: Callable[[int], None]) -> tuple[float, int]:
    """Call ``tick(k)`` for ``k`` in ``0..n-1`` at ``start + k * period``.

    Returns the seconds the ticks took and how many started more than a period late (a late
    tick is not skipped: every message is sent).

    >>> seen = []
    >>> _, late = tick_in_real_time(3, 0.001, seen.append)
    >>> seen
    [0, 1, 2]
    """
    start = time.monotonic()
    late = 0
    for k in range(n):
        delay = start + k * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -period:
            late += 1
        tick(k)
    return time.monotonic() - start, late


def await_answers(answered: Sized, expected: int, timeout: float = 30.0) -> None:
    """Wait until ``answered`` holds ``expected`` items or ``timeout`` seconds pass.

    The default is long: on a loaded machine the node may be seconds behind.
    """
    wait_for(lambda: len(answered) >= expected, timeout)
