"""BLAS on one thread while a replay runs (process-wide, undone when the last replay ends).

A replay's linear algebra is small (the identifier's windows, the guard's sums over a few
thousand samples), but OpenBLAS runs the larger of those products on a thread per core, and
its threads spin while they wait for the next. On the 60 s operation bag a replay used 1.7-2
times the CPU time with OpenBLAS's default threads as with one (2 cores, a loaded machine;
BENCHMARKS.md "Replay throughput"), and the output bags were byte for byte the same. Dask's
fleet workers already start with ``OPENBLAS_NUM_THREADS=1`` (tests/ros/fleet/conftest.py).

The limit is :mod:`threadpoolctl`'s, set when the first replay of the process starts and
restored when the last one ends (fleet threads run several at once). Without threadpoolctl
(a ROS install that has no rosdep key for it) the replay runs with the default threads,
slower (its output bags were byte for byte the same on the bags measured).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["one_blas_thread"]

_lock = threading.Lock()
_users = 0
_limiter: Any = None  # threadpoolctl's limiter while a replay runs


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the body with the BLAS libraries loaded (OpenBLAS, MKL...) on one thread.

    Examples
    --------
    >>> from threadpoolctl import threadpool_info
    >>> import numpy
    >>> with one_blas_thread():
    ...     all(i["num_threads"] == 1 for i in threadpool_info() if i["user_api"] == "blas")
    True
    """
    global _users, _limiter
    with _lock:
        if _users == 0:
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:
                _limiter = None
            else:
                _limiter = threadpool_limits(limits=1, user_api="blas")
        _users += 1
    try:
        yield
    finally:
        with _lock:
            _users -= 1
            if _users == 0 and _limiter is not None:
                _limiter.restore_original_limits()
                _limiter = None
