"""One BLAS thread while the node, a replay or any ``genbacklash`` command runs (process-wide,
undone when the last user ends).

numpy's OpenBLAS starts a thread per core and hands vectors above a few thousand elements,
and the identifiers' larger least-squares problems, to all of them. Here that buys nothing and
costs a core's worth of waiting: the fits are small, the machine's cores are the control
loop's, and OpenBLAS's threads spin while they wait for work or for each other. Measured
(BENCHMARKS.md): in the rclpy node serving six joints the OpenBLAS thread alone used 0.11 of a
core, more than the identify thread it served (0.07), and the six-joint pipeline with every
identification in line took 0.43-0.50 of a core with numpy's default threads against
0.23-0.28 with one ("Six joints through one node"); a replay of the 60 s operation bag used
1.7-2 times the CPU time with the default threads, its output bags byte for byte the same
("Replay throughput").

The limit is :mod:`threadpoolctl`'s (a dependency of the package), set when the first user of
the process enters :func:`one_blas_thread` and restored when the last one leaves (the fleet
runs several replays on threads at once). Without threadpoolctl (a ROS 2 install built with
colcon has no rosdep key for it) the BLAS keeps its default threads: slower, and the fits'
last bits may differ (a multi-threaded BLAS sums in another order), which a nonlinear fit
can carry far: ``genbacklash diagnose`` on one physics bag (gravity, 20 Hz servo) ended at a
validation misfit of 0.0292 with one thread and 0.0288 with two, on the same path of effects.
Every ``genbacklash`` command therefore runs with one thread, so that a command's answer on a
bag does not depend on the machine's core count. Benchmarks and tests that start many
processes set ``OPENBLAS_NUM_THREADS=1`` themselves for the same reason
(``bench/diagnose.py``, ``tests/ros/fleet/conftest.py``).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["one_blas_thread"]

_lock = threading.Lock()
_users = 0
_limiter: Any = None  # threadpoolctl's limiter while anyone is inside


@contextmanager
def one_blas_thread() -> Iterator[bool]:
    """Run the body with every BLAS library loaded (OpenBLAS, MKL...) on one thread.

    Yields
    ------
    bool
        True when the limit is in force, False when ``threadpoolctl`` is not installed (the
        BLAS keeps its default). The previous limits come back when the last user leaves,
        whatever the order users leave in, and after an exception.

    Examples
    --------
    >>> import numpy  # loads numpy's OpenBLAS
    >>> from threadpoolctl import threadpool_info
    >>> with one_blas_thread() as limited:
    ...     limited, {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}
    (True, {1})
    """
    global _users, _limiter
    with _lock:
        if _users == 0:
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:  # pragma: no cover - threadpoolctl is a dependency
                _limiter = None
            else:
                _limiter = threadpool_limits(limits=1, user_api="blas")
        _users += 1
        limited = _limiter is not None
    try:
        yield limited
    finally:
        with _lock:
            _users -= 1
            if _users == 0 and _limiter is not None:
                _limiter.restore_original_limits()
                _limiter = None
