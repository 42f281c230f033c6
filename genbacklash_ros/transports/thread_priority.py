"""The ``thread_priority`` parameter: the message thread under ``SCHED_FIFO``, and the
identify stage where that is safe.

ros2_control runs its control thread under ``SCHED_FIFO`` when the process may; the node's
``thread_priority`` does the same for the thread that takes the messages and answers the
commands (both transports). A real-time thread that shares the interpreter lock with a
thread of ordinary priority is the textbook priority inversion: with the identifier on a
thread of the node, the message thread stalled for 140-470 ms in 2 of 6 trials
(BENCHMARKS.md, "Six joints through one node"). So with a priority the identify stage runs
in a child process (:mod:`genbacklash_ros.node.identify_process`), which shares no lock with
the message thread and keeps the default scheduler.

Examples
--------
>>> from genbacklash_ros.node.identify import live_worker
>>> worker_for(0) is live_worker
True
>>> apply_thread_priority(0) is None
True
"""

from __future__ import annotations

import os

from genbacklash_ros.node.identify import live_worker
from genbacklash_ros.node.identify_process import process_worker
from genbacklash_ros.node.pipeline import WorkerFactory

__all__ = ["apply_thread_priority", "worker_for"]


def worker_for(thread_priority: int) -> WorkerFactory:
    """The identify stage's worker for a live node: on a thread of the node (priority 0),
    in a child process otherwise (see the module notes)."""
    return live_worker if thread_priority <= 0 else process_worker


def apply_thread_priority(thread_priority: int) -> str | None:
    """Put the calling thread under ``SCHED_FIFO`` at ``thread_priority`` (1-99; 0 leaves
    it alone). Returns a one-line warning when it could not (no ``CAP_SYS_NICE`` nor an
    ``rtprio`` limit, or a system without ``SCHED_FIFO``), None otherwise: the node then
    runs on the default scheduler, as ros2_control's does."""
    if thread_priority <= 0:
        return None
    setter = getattr(os, "sched_setscheduler", None)
    if setter is None:
        return f"thread_priority {thread_priority} ignored: this system has no SCHED_FIFO"
    try:
        setter(0, os.SCHED_FIFO, os.sched_param(thread_priority))  # 0: the calling thread
    except OSError as err:
        return (
            f"thread_priority {thread_priority} not applied ({err.strerror or err}): run with "
            "CAP_SYS_NICE or raise the rtprio limit (ulimit -r, /etc/security/limits.conf); "
            "the node runs on the default scheduler"
        )
    return None
