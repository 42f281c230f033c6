"""``thread_priority``: the calling thread under SCHED_FIFO, or a one-line warning saying
why not; and the identify stage in a child process whenever a priority is asked for."""

from __future__ import annotations

import os
import threading

import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.identify import live_worker
from genbacklash_ros.node.identify_process import process_worker
from genbacklash_ros.node.joints import JointSet
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.transports import thread_priority
from genbacklash_ros.transports.thread_priority import apply_thread_priority, worker_for

pytestmark = pytest.mark.skipif(
    not hasattr(os, "sched_setscheduler"), reason="this system has no sched_setscheduler"
)


def _on_a_thread(priority: int) -> tuple[str | None, int]:
    """apply_thread_priority on a thread of its own (the test's thread keeps its policy)."""
    got: list[tuple[str | None, int]] = []

    def run() -> None:
        problem = apply_thread_priority(priority)
        got.append((problem, os.sched_getscheduler(0)))

    t = threading.Thread(target=run)
    t.start()
    t.join()
    return got[0]


def test_a_priority_puts_the_thread_under_fifo_or_says_why_not() -> None:
    problem, policy = _on_a_thread(10)
    if problem is None:
        assert policy == os.SCHED_FIFO
    else:  # not permitted on this machine: the default scheduler, and the reason
        assert policy == os.SCHED_OTHER
        assert problem.startswith("thread_priority 10 not applied") and "CAP_SYS_NICE" in problem
    assert os.sched_getscheduler(0) == os.SCHED_OTHER  # only the thread that asked


def test_zero_leaves_the_scheduler_alone() -> None:
    assert _on_a_thread(0) == (None, os.SCHED_OTHER)


def test_a_refusal_is_one_line_with_the_remedy(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(thread_priority.os, "sched_setscheduler", refuse)
    problem = apply_thread_priority(50)
    assert problem is not None and "\n" not in problem
    assert "Operation not permitted" in problem and "ulimit -r" in problem


def test_the_worker_follows_the_priority() -> None:
    assert worker_for(0) is live_worker
    assert worker_for(1) is process_worker and worker_for(99) is process_worker


@pytest.mark.parametrize("value", [-1, 100, 2.5, True])
def test_out_of_range_priorities_are_refused(value: object) -> None:
    with pytest.raises(GenBacklashError, match="thread_priority"):
        NodeParameters(thread_priority=value)  # type: ignore[arg-type]


def test_a_priority_is_the_nodes_not_a_joints() -> None:
    with pytest.raises(GenBacklashError, match="cannot be set per joint"):
        JointSet.from_mapping({"joints": ["a"], "command_indices": [0], "a.thread_priority": 5})
