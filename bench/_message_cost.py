"""The six-joint pipeline's CPU per message in process, and its outputs for a sameness check.

    python bench/_message_cost.py TREE cpu [--seconds S] [--reps K]
    python bench/_message_cost.py TREE same OUT [--seconds S] [--kind joint_state]

A hand-run helper (issue 24, not in ``run_all``): ``TREE`` is the source tree whose
``genbacklash_core`` and ``genbacklash_ros`` are imported (a ``git archive`` of another
commit, or this worktree), so that two commits are measured and compared with one script.

``cpu``: the arm of ``bench/six_joint.py`` (six drivetrains of the operation scenario, seed
1, commands and readings at 1 kHz) fed to a :class:`MultiJointPipeline` as the rclpy
transport does (``answer`` then ``periodic`` for a command, ``on_encoder`` for a reading),
as fast as it takes them; the thread's CPU time (``thread_time``) per message, with the
synchronous identify workers' CPU (their ``submit``) taken out: the message thread's work
in the node, where identification runs on its own thread. Prints the total per message
and the median and mean per command and per reading.

``same``: two feeds of the arm (clean; with faults sprinkled in: non-finite, short and
mistyped arrays, duplicates, commands out of order, readings with their names reordered,
missing, repeated or extra, non-finite positions, a stuck joint, a gap, a reading without
stamp, wrong message types) through the pipeline with the synchronous workers, ``on_command``
and ``answer``/``periodic`` in turn; every message's outputs (``repr``), the counters and
estimates every 500 messages and the final outputs written to ``OUT`` and hashed. Two trees
with the same hash gave the same outputs, message by message.
"""

from __future__ import annotations

import hashlib
import sys
import time
from typing import Any

TREE = sys.argv[1] if len(sys.argv) > 1 else "."
sys.path.insert(0, TREE)

import numpy as np  # noqa: E402
from six_joint import FACTORS, JOINTS, arm_data  # noqa: E402

from genbacklash_core.scenarios import OPERATION_BACKLASH, worn  # noqa: E402
from genbacklash_ros.blas_threads import one_blas_thread  # noqa: E402
from genbacklash_ros.node.identify import SyncWorker  # noqa: E402
from genbacklash_ros.node.joints import JointSet  # noqa: E402
from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time  # noqa: E402
from genbacklash_ros.node.multijoint import MultiJointPipeline  # noqa: E402

TICK = 1_000_000
T0 = 1_700_000_000 * 1_000_000_000
Feed = list[tuple[str, Any, int]]
_IDENTIFY_NS = [0]


def arm(seconds: float) -> tuple[list[list[float]], list[list[float]]]:
    """Commands ``[u_1 .. u_6, k]`` and readings ``[y_1 .. y_6]`` per tick (six_joint's)."""
    u, y = arm_data([worn(OPERATION_BACKLASH, f) for f in FACTORS], seconds, 1)
    rows = np.vstack([u, np.arange(u.shape[1], dtype=np.float64)]).T.tolist()
    return rows, y.T.tolist()


def clean_feed(seconds: float) -> Feed:
    rows, readings = arm(seconds)
    feed: Feed = []
    for k, (row, reading) in enumerate(zip(rows, readings, strict=True)):
        at = T0 + k * TICK
        feed.append(("c", Float64MultiArray(data=tuple(row)), at))
        stamp = Header(Time.from_ns(at + 100_000))
        feed.append(("e", JointState(stamp, JOINTS, tuple(reading)), at + 200_000))
    return feed


def _command(row: list[float], k: int, at: int, kind: str) -> Any:
    if k % 997 == 13:
        row[k % 7] = float("nan")
    if k % 1709 == 7:
        row[2] = float("inf")
    if k % 2113 == 5:
        row = row[:3]  # joints 4-6 out of range
    if k % 3001 == 11:
        row[1] = 1  # an int
    if k % 4001 == 17:  # the other message type
        return JointState(name=JOINTS) if kind != "joint_state" else Float64MultiArray(data=(0.0,))
    if kind != "joint_state":
        return Float64MultiArray(data=tuple(row))
    order = list(range(6))[::-1] if k % 1301 == 3 else list(range(6))
    values = row[:6] + [0.0] * (6 - len(row[:6]))
    names = tuple(JOINTS[i] for i in order)
    return JointState(Header(Time.from_ns(at)), names, tuple(values[i] for i in order))


def _reading(position: list[float], k: int, at: int) -> JointState:
    names = list(JOINTS)
    stamp = at + 100_000
    if k % 1301 == 0:
        names, position = names[::-1], position[::-1]
    if k % 1703 == 1:
        names, position = names[:5], position[:5]  # the last joint missing
    if k % 2011 == 2:
        position[k % len(position)] = float("nan")
    if k % 2503 == 3:
        names, position = [*names, names[0]], [*position, 99.0]  # a repeated name
    if k % 3307 == 4:
        names, position = [*names, "gripper"], [*position, 0.5]
    if k % 3907 == 5:
        position = position[:-1]  # fewer positions than names
    if k % 4409 == 6:
        stamp = 0  # no stamp: the receive time
    if k % 6007 == 8:
        stamp = at - 50 * TICK  # out of order
    if k % 5003 == 10:
        position[0] = 7  # type: ignore[call-overload]
    return JointState(Header(Time.from_ns(stamp)), tuple(names), tuple(position))


def messy_feed(seconds: float, kind: str) -> Feed:
    """The arm's data with faults sprinkled in: every branch of the per-message code."""
    rows, readings = arm(seconds)
    feed: Feed = []
    stuck = len(rows) // 3
    for k, (row, reading) in enumerate(zip(rows, readings, strict=True)):
        at = T0 + k * TICK
        command = _command(list(row), k, at, kind)
        feed.append(("c", command, at))
        if k % 1499 == 9:
            feed.append(("c", command, at))  # a duplicate
        if k % 2999 == 21:
            feed.append(("c", _command(list(rows[k - 1]), k - 1, at - TICK, kind), at - TICK))
        if 5000 <= k < 5300:
            continue  # a gap in the readings
        position = list(reading)
        if stuck <= k < stuck + 600:
            position[3] = readings[stuck][3]  # joint 4 stuck
        msg = _reading(position, k, at)
        feed.append(("e", msg, at + 200_000))
        if k % 1901 == 12:
            feed.append(("e", msg, at + 210_000))  # a duplicate
        if k % 4999 == 14:
            feed.append(("e", Float64MultiArray(data=(1.0,)), at + 220_000))
    return feed


def same(out: str, seconds: float, kind: str) -> str:
    """Every output of both feeds into ``out``; their SHA-256."""
    mapping: dict[str, object] = {"joints": list(JOINTS), "command_indices": list(range(6))}
    if kind == "joint_state":
        mapping = {"joints": list(JOINTS), "command_type": "joint_state"}
    joints = JointSet.from_mapping(mapping)
    feeds = [("messy", messy_feed(seconds, kind))]
    if kind != "joint_state":
        feeds.insert(0, ("clean", clean_feed(seconds)))
    digest = hashlib.sha256()
    np.set_printoptions(precision=17, floatmode="unique", threshold=10**9)
    with open(out, "w", encoding="utf-8") as file, one_blas_thread():
        for name, feed in feeds:
            pipe = MultiJointPipeline(joints, worker=SyncWorker)
            for i, (stream, msg, at) in enumerate(feed):
                if stream == "e":
                    outputs = pipe.on_encoder(msg, at)
                elif i % 2:
                    answer = pipe.answer(msg, at)
                    outputs = ([answer] if answer is not None else []) + pipe.periodic()
                else:
                    outputs = pipe.on_command(msg, at)
                line = f"{name} {i} {stream} {outputs!r}\n"
                if i % 500 == 0:
                    joints_now = pipe.pipelines.values()
                    line += f"stats {pipe.stats!r} {[p.stats for p in joints_now]!r}\n"
                    line += f"estimates {[p.estimate for p in joints_now]!r}\n"
                file.write(line)
                digest.update(line.encode())
            line = f"{name} finish {pipe.finish()!r} {pipe.stats!r}\n"
            line += f"diagnostics {pipe.diagnostics(T0 + 10**12)!r}\n"
            file.write(line)
            digest.update(line.encode())
            pipe.close()
    return digest.hexdigest()


def _timed_sync(identifier: Any) -> SyncWorker:
    """A synchronous worker whose identification CPU (``submit``) is counted apart."""
    worker = SyncWorker(identifier)
    submit = worker.submit

    def timed(us: Any, ys: Any, breaks: Any) -> None:
        start = time.thread_time_ns()
        submit(us, ys, breaks)
        _IDENTIFY_NS[0] += time.thread_time_ns() - start

    worker.submit = timed  # type: ignore[method-assign]
    return worker


def cpu(feed: Feed) -> str:
    """One run: CPU per message (us), identification apart."""
    joints = JointSet.from_mapping({"joints": list(JOINTS), "command_indices": list(range(6))})
    clock = time.thread_time_ns
    commands: list[int] = []
    readings: list[int] = []
    _IDENTIFY_NS[0] = 0
    with one_blas_thread():
        pipe = MultiJointPipeline(joints, worker=_timed_sync)
        first = clock()
        for stream, msg, at in feed:
            identify, start = _IDENTIFY_NS[0], clock()
            if stream == "c":
                pipe.answer(msg, at)
                pipe.periodic()
                commands.append(clock() - start - (_IDENTIFY_NS[0] - identify))
            else:
                pipe.on_encoder(msg, at)
                readings.append(clock() - start - (_IDENTIFY_NS[0] - identify))
        total = clock() - first - _IDENTIFY_NS[0]
        pipe.close()
    c, e = np.array(commands) / 1e3, np.array(readings) / 1e3
    return (
        f"per message {total / 1e3 / len(feed):.1f} us | command median {np.median(c):.1f} "
        f"mean {c.mean():.1f} | reading median {np.median(e):.1f} mean {e.mean():.1f} | "
        f"identification {_IDENTIFY_NS[0] / 1e9:.2f} s apart"
    )


def main(argv: list[str]) -> int:
    mode, rest = argv[2], argv[3:]

    def option(name: str, default: str) -> str:
        return rest[rest.index(name) + 1] if name in rest else default

    seconds = float(option("--seconds", "20"))
    if mode == "same":
        print(same(rest[0], seconds, option("--kind", "float64_multi_array")))
        return 0
    feed = clean_feed(seconds)
    for _ in range(int(option("--reps", "1"))):
        print(cpu(feed))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
