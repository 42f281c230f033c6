"""One BLAS thread while the node runs.

numpy's OpenBLAS starts a thread per core and splits the identifiers' larger least-squares
problems between them. In the node that buys nothing and costs a core's worth of waiting: the
identify thread's fits are small, the machine's cores are the control loop's, and OpenBLAS's
threads spin while they wait for work or for each other. Measured (BENCHMARKS.md, "Six joints
through one node", 2026-11-27 nodecpu): the six-joint pipeline alone, every identification in
line, took 0.43-0.50 of a core with numpy's default threads and 0.23-0.28 with one, the same
20 s of data; in the rclpy node the OpenBLAS thread alone used 0.11 of a core, more than the
identify thread it served (0.07).

Both transports run the node inside :func:`one_blas_thread`. It uses ``threadpoolctl`` (a
dependency of the package); where that is missing (a ROS 2 install built with colcon without
it) the node runs with the BLAS's own default, as before, and :func:`one_blas_thread` says so.
Benchmarks and tests that start many processes set ``OPENBLAS_NUM_THREADS=1`` themselves for
the same reason (``bench/diagnose.py``, ``tests/ros/fleet/conftest.py``).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["one_blas_thread"]


@contextmanager
def one_blas_thread() -> Iterator[bool]:
    """Limit every BLAS library loaded in the process to one thread for the block.

    Yields
    ------
    bool
        True when the limit is in force, False when ``threadpoolctl`` is not installed (the
        BLAS keeps its default). The previous limits are restored when the block ends.

    Examples
    --------
    >>> import numpy  # loads numpy's OpenBLAS
    >>> from threadpoolctl import threadpool_info
    >>> with one_blas_thread() as limited:
    ...     limited, {p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}
    (True, {1})
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        yield False
        return
    with threadpool_limits(limits=1, user_api="blas"):
        yield True
