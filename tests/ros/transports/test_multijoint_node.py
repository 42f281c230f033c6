"""One node, three joints, as real processes: the node (rclpy, or the plain-DDS transport) and
a player publishing a simulated arm over rclpy (``arm_player.py``: a three-joint JointState at
1 kHz, a four-element Float64MultiArray command at 100 Hz whose element 1 is no joint's).

Checked per transport: every command answered with one compensated array (the free element
unchanged, every joint's element compensated), each joint's estimate on
``/backlash_identifier/<joint>/estimate`` near its own truth (three different drivetrains), one
``/diagnostics`` status per joint named after it, and a clean exit on SIGINT. The rclpy node
and the DDS node run twice each: with the default scheduler, and with ``thread_priority``
(the message thread under ``SCHED_FIFO``, identification in a child process of its own).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.ros._proc import children

from ._dds import Played, play_against_node
from ._ros2 import rclpy_missing

HERE = Path(__file__).parent
NAMES = ("shoulder", "elbow", "wrist")
SECONDS = 10.0

pytestmark = pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")


PARAMS = (
    "/**/backlash_identifier:\n"
    "  ros__parameters:\n"
    "    command_type: float64_multi_array\n"
    "    joints: [shoulder, elbow, wrist]\n"
    "    command_indices: [0, 2, 3]\n"
    "    publish_rate: 5.0\n"
    "    wrist:\n"
    "      publish_rate: 10.0\n"
)


PRIORITY = 10


def _threads_and_children(pid: int) -> dict[str, Any]:
    """The node's main thread's scheduling policy, and its child processes (Linux)."""
    return {"policy": os.sched_getscheduler(pid), "children": list(children(pid))}


@pytest.fixture(scope="module", params=["rclpy", "dds", "rclpy-priority", "dds-priority"])
def played(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Played]:
    variant = str(request.param)
    transport = variant.split("-")[0]
    if transport == "dds":
        pytest.importorskip("cyclonedds", reason="cyclonedds is not installed (pip install .[dds])")
    params = PARAMS
    if variant.endswith("priority"):
        params += f"    thread_priority: {PRIORITY}\n"
    tmp = tmp_path_factory.mktemp(f"arm_{variant}")
    yield play_against_node(
        tmp,
        transport,
        params,
        "arm_player.py",
        ["--seconds", str(SECONDS), "--settle", "0.5"],
        timeout=120,
        inspect=_threads_and_children,
    )


def test_every_command_is_answered_with_one_compensated_array(played: Played) -> None:
    sent = np.array(played.summary["sent"])
    answered = played.summary["answered"]
    assert len(answered) == len(sent), played.log  # 100 %: one array per command
    got = np.array([answered[str(k)] for k in range(len(sent))])
    assert got.shape == sent.shape == (len(sent), 4)
    assert np.array_equal(got[:, 1], sent[:, 1])  # no joint's element: passed through
    # each joint's element compensated once its model is in (when depends on the joint's
    # motion and, live, on the run: from 1 to 8 s here; checked to the bit in process by
    # tests/ros/node/test_multijoint.py)
    for index in (0, 2, 3):
        assert np.sum(got[:, index] != sent[:, index]) >= 20, index


def test_each_joint_estimate_is_near_its_own_truth(played: Played) -> None:
    s = played.summary
    for name in NAMES:
        assert s["estimate_counts"][name] >= 5, name
        assert s["labels"][name].startswith("m_left_1,"), name
        error = np.max(np.abs(np.array(s["estimates"][name]) - np.array(s["truth"][name])))
        assert error < 0.05, (name, error)
    # the wrist publishes at its own rate (10 Hz against the node's 5 Hz)
    assert s["estimate_counts"]["wrist"] > 1.5 * s["estimate_counts"]["shoulder"]


def test_one_diagnostics_status_per_joint(played: Played) -> None:
    names = played.summary["status_names"]
    for joint in NAMES:
        assert [n for n in names if n.endswith(joint)] == [f"backlash_identifier: {joint}"]
    assert "backlash_identifier" not in names  # no single-joint status besides


def test_the_node_exits_cleanly(played: Played) -> None:
    assert played.returncode == 0, played.log
    assert "Traceback" not in played.log


def test_a_thread_priority_moves_identification_to_a_child(
    played: Played, request: pytest.FixtureRequest
) -> None:
    """With ``thread_priority`` the node identifies in one child process (its estimates are
    checked above) and its message thread runs under SCHED_FIFO, or the log says why not;
    without, it has no child and the default scheduler."""
    seen = played.inspected
    if not request.node.callspec.params["played"].endswith("priority"):
        assert seen["children"] == [] and seen["policy"] == os.SCHED_OTHER
        return
    assert len(seen["children"]) == 1, seen
    if seen["policy"] != os.SCHED_FIFO:  # not permitted here: said, and the default kept
        assert "thread_priority 10 not applied" in played.log, played.log
        assert seen["policy"] == os.SCHED_OTHER
