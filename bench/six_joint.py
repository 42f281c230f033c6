"""Six joints at 1 kHz through one node under rclpy, next to a plain rclpy echo (issue 24).

    python bench/six_joint.py [--seconds S] [--transport rclpy|dds] [--seed N] [--quick]
                              [--domain ID] [--thread-priority P]

Three processes share a DDS domain of their own (``--domain``, else an id in 201-231 at
random, apart from the tests'):
the node (``genbacklash node --transport rclpy`` with ``joints: [joint_1 .. joint_6]`` and
``command_indices: [0 .. 5]``; defaults otherwise), a plain rclpy echo (this script with
``--role echo``: every ``std_msgs/Float64MultiArray`` taken on ``/six_joint/ping`` published
back on ``/six_joint/pong``; default QoS, ``rclpy.spin_once``) and the player (this process,
rclpy). The arm: six drivetrains of the operation scenario's backlash with dead zones 0.6x to
2x (:func:`genbacklash_core.scenarios.arm_records`; each joint its own motion; commands and
readings at 1 kHz, no jitter, no loss). Once the node and the echo have matched, at each 1 ms
tick the player publishes the command ``[u_1 .. u_6, k]`` on ``/command`` (element 6, the
sequence number, is no joint's: the node passes it through), the six-joint
``sensor_msgs/JointState`` stamped after it on ``/encoder`` (sensor-data QoS) and a ping
``[k]``. Between ticks, on the same thread, it takes the pongs, ``/compensated_command``,
every ``/backlash_identifier/<joint>/estimate`` and ``/diagnostics`` from a wait set of its
own (:class:`Replies`; no executor).

Measured, over every command from the first (the first 5 s included): commands answered (a
compensated array with that ``k``), per joint the share of answered arrays whose element
differs from the command in the second half (compensated), latency (the time the reply was
taken less the publish time of the message it answers, the command's or the ping's, on the
player's monotonic clock) of the compensated command and of the pong in the same run, the
node's CPU fraction (``utime + stime`` from ``/proc/<pid>/stat`` from the first command to
the last reply, divided by that wall time; the echo's and the player's over the same time),
the same split per thread of the node and of its child (``/proc/<pid>/task``: CPU and
context switches a second, :func:`thread_costs`) and each joint's largest |parameter error|
of its last estimate against its truth.
``--thread-priority P`` (1-99) runs the node with ``thread_priority: P`` (its message thread
under ``SCHED_FIFO``, identification in a child process, whose CPU is counted with the
node's) and the echo's one thread under ``SCHED_FIFO`` at the same priority, so that the
reference has the same privilege; the player keeps the default scheduler.
Targets (issue 24): every estimate within 0.05, 100 % answered with all six compensated, at
most 0.6 of a core, median and p99 within 1.5x the echo's.

``--blas ROUNDS`` measures instead what one BLAS thread saves the node: the six-joint pipeline
with its live identify thread fed the same data in process at 1 kHz in real time, numpy's
default BLAS threads against one (the node's, :mod:`genbacklash_ros.blas_threads`),
round robin; CPU per thread from ``/proc/self/task``. Printed only.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from _common import ROOT, command_line, machine_description, md_table, write_section

from genbacklash_core.scenarios import OPERATION_BACKLASH, OperationSettings, arm_records, worn
from genbacklash_ros.blas_threads import one_blas_thread

sys.path.insert(0, str(ROOT))
from tests.ros._proc import children

JOINTS = tuple(f"joint_{i + 1}" for i in range(6))
FACTORS = (0.6, 0.8, 1.0, 1.2, 1.5, 2.0)
PING, PONG = "/six_joint/ping", "/six_joint/pong"
TICK_NS = 1_000_000


def echo(lifetime_s: float, thread_priority: int = 0) -> int:
    """The reference: ping -> pong, nothing else (its thread under ``SCHED_FIFO`` at
    ``thread_priority`` when above 0, as the node's message thread)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from std_msgs.msg import Float64MultiArray

    rclpy.init()
    node = rclpy.create_node("six_joint_echo")
    pong = node.create_publisher(Float64MultiArray, PONG, 10)
    node.create_subscription(Float64MultiArray, PING, pong.publish, 2000)
    if thread_priority > 0:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(thread_priority))
    end = time.monotonic() + lifetime_s
    try:
        while rclpy.ok() and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


@dataclass
class Played:
    sent: np.ndarray  # publish time per command, monotonic ns
    ping_sent: np.ndarray  # publish time per ping, monotonic ns
    back: np.ndarray  # compensated array taken, monotonic ns (0: never)
    pong: np.ndarray
    values: np.ndarray  # the compensated arrays received (NaN where none)
    commands: np.ndarray  # the arrays sent
    estimates: dict[str, list[float]]
    status_names: set[str]
    faults: set[str]  # fault names any joint's diagnostics reported
    late: int
    threads: list[ThreadCost]  # the node's and its children's threads over the play
    cpu_s: float  # the node's
    wall_s: float
    player_cpu_s: float  # this process's, over the same wall time
    echo_cpu_s: float


@dataclass(frozen=True)
class ThreadCost:
    """One thread's share of a core and its context switches a second over the play."""

    process: str  # "node" or "node's child"
    tid: int
    main: bool  # the process's main thread (the node's takes the messages)
    name: str  # /proc comm (Python threads of the node are all "python")
    cpu: float
    voluntary: float
    involuntary: float


def _thread_counts(
    pid: int, *, with_children: bool = True
) -> dict[tuple[str, int, int], tuple[str, float, int, int]]:
    """Per thread of ``pid`` (and of its children): (name, CPU seconds, voluntary and
    involuntary context switches) from ``/proc/<pid>/task`` (Linux), keyed by (role, process
    id, thread id)."""
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[tuple[str, int, int], tuple[str, float, int, int]] = {}
    kids = children(pid) if with_children else ()
    for role, each in (("node", pid), *(("node's child", c) for c in kids)):
        for task in Path(f"/proc/{each}/task").glob("[0-9]*"):
            try:
                stat = (task / "stat").read_text()
                status = (task / "status").read_text()
            except OSError:  # the thread ended meanwhile
                continue
            fields = stat.rsplit(")", 1)[1].split()
            name = stat[stat.index("(") + 1 : stat.rindex(")")]
            switches = dict(line.split(":\t") for line in status.splitlines() if ":\t" in line)
            out[(role, each, int(task.name))] = (
                name,
                (int(fields[11]) + int(fields[12])) / tick,
                int(switches["voluntary_ctxt_switches"]),
                int(switches["nonvoluntary_ctxt_switches"]),
            )
    return out


def thread_costs(
    before: dict[tuple[str, int, int], tuple[str, float, int, int]],
    after: dict[tuple[str, int, int], tuple[str, float, int, int]],
    wall_s: float,
) -> list[ThreadCost]:
    """What each thread used between two :func:`_thread_counts`, most CPU first (threads
    that used nothing and hardly switched are left out)."""
    costs = []
    for key, (name, cpu, vol, invol) in after.items():
        _, cpu0, vol0, invol0 = before.get(key, (name, 0.0, 0, 0))
        cost = ThreadCost(
            key[0],
            key[2],
            key[1] == key[2],
            name,
            (cpu - cpu0) / wall_s,
            (vol - vol0) / wall_s,
            (invol - invol0) / wall_s,
        )
        if cost.cpu > 0.0 or cost.voluntary + cost.involuntary >= 10.0:
            costs.append(cost)
    return sorted(costs, key=lambda c: -c.cpu)


def cpu_seconds(pid: int) -> float:
    """``utime + stime`` of a process and of its live children (the node's identify
    process, ``thread_priority``), seconds (Linux ``/proc``)."""
    total = 0
    for each in (pid, *children(pid)):
        try:
            fields = Path(f"/proc/{each}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # a child that ended meanwhile
            continue
        total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


class Replies:
    """The player's subscriptions taken on the player's one thread, between its ticks.

    An rcl wait set of their own (no executor, no second thread): :meth:`until` waits on it
    until a deadline and hands each message taken to its handler with the time it was
    taken (monotonic ns). rclpy's executor cost the player about 0.2 ms of CPU a message,
    and on a thread of its own it took the interpreter lock in turn with the publishing
    thread; the node and the echo then competed with it for the machine's two cores. Both
    replies come through here alike: the echo's pongs are taken before the node's arrays
    in each round, so the order favours the echo if anything.
    """

    def __init__(self, node: Any, handlers: list[tuple[Any, Any]]) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        self._handlers = handlers  # (subscription, handler(msg, taken_ns))
        self._wait_set = _rclpy.WaitSet(len(handlers), 0, 0, 0, 0, 0, node.context.handle)

    def take(self) -> int:
        """Take everything pending (without waiting); the number taken."""
        taken = 0
        for sub, handler in self._handlers:
            handle, msg_type, raw = sub.handle, sub.msg_type, sub.raw
            while (got := handle.take_message(msg_type, raw)) is not None:
                handler(got[0], time.monotonic_ns())
                taken += 1
        return taken

    def until(self, deadline_ns: int) -> None:
        """Take what comes until ``deadline_ns`` (monotonic)."""
        ws = self._wait_set
        while True:
            self.take()
            wait = deadline_ns - time.monotonic_ns()
            if wait <= 0:
                return
            ws.clear_entities()
            for sub, _ in self._handlers:
                ws.add_subscription(sub.handle)
            ws.wait(wait)


def play(u: np.ndarray, y: np.ndarray, node_pid: int, echo_pid: int) -> Played:
    """Publish the arm's commands and readings in real time; what came back."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    n, m = u.shape[1], len(JOINTS)
    rclpy.init()
    node = rclpy.create_node("six_joint_player")
    sent = np.zeros(n, dtype=np.int64)
    ping_sent = np.zeros(n, dtype=np.int64)
    back = np.zeros(n, dtype=np.int64)
    pong = np.zeros(n, dtype=np.int64)
    values = np.full((n, m + 1), np.nan)
    estimates: dict[str, list[float]] = {}
    names: set[str] = set()
    faults: set[str] = set()

    def on_compensated(msg: Any, now: int) -> None:
        k = int(msg.data[m])
        if 0 <= k < n and not back[k]:
            back[k] = now
            values[k] = msg.data

    def on_pong(msg: Any, now: int) -> None:
        k = int(msg.data[0])
        if 0 <= k < n and not pong[k]:
            pong[k] = now

    def on_estimate(joint: str) -> Any:
        def take(msg: Any, now: int) -> None:
            estimates[joint] = list(msg.data)

        return take

    def on_diagnostics(msg: Any, now: int) -> None:
        for status in msg.status:
            names.add(str(status.name))
            for kv in status.values:
                if kv.key == "faults" and kv.value != "none":
                    faults.update(kv.value.split(","))

    def subscribe(msg_type: Any, topic: str, handler: Any, depth: int) -> tuple[Any, Any]:
        # the handler is called by Replies, not by an executor: none spins this node
        return node.create_subscription(msg_type, topic, lambda _: None, depth), handler

    handlers = [
        subscribe(Float64MultiArray, PONG, on_pong, 2000),
        subscribe(Float64MultiArray, "/compensated_command", on_compensated, 2000),
        *(
            subscribe(
                Float64MultiArray,
                f"/backlash_identifier/{joint}/estimate",
                on_estimate(joint),
                10,
            )
            for joint in JOINTS
        ),
        subscribe(DiagnosticArray, "/diagnostics", on_diagnostics, 10),
    ]
    replies = Replies(node, handlers)
    command = node.create_publisher(Float64MultiArray, "/command", 10)
    encoder = node.create_publisher(JointState, "/encoder", qos_profile_sensor_data)
    ping = node.create_publisher(Float64MultiArray, PING, 10)
    commands = np.vstack([u, np.arange(n, dtype=np.float64)]).T
    try:
        deadline = time.monotonic() + 60.0
        while min(command.get_subscription_count(), encoder.get_subscription_count()) < 1 or (
            ping.get_subscription_count() < 1
            or node.count_publishers("/compensated_command") < 1
            or node.count_publishers(PONG) < 1
        ):
            if time.monotonic() > deadline:
                raise RuntimeError("the node's or the echo's endpoints did not match in 60 s")
            replies.until(time.monotonic_ns() + 50_000_000)
        replies.until(time.monotonic_ns() + 1_000_000_000)  # let discovery settle both ways
        rows = commands.tolist()
        readings = y.T.tolist()
        joints = list(JOINTS)
        threads0 = _thread_counts(node_pid)
        cpu0, echo0, start = cpu_seconds(node_pid), cpu_seconds(echo_pid), time.monotonic_ns()
        own0 = time.process_time()
        late = 0
        for k in range(n):
            tick = start + k * TICK_NS
            replies.until(tick)
            if time.monotonic_ns() - tick > TICK_NS:
                late += 1
            sent[k] = time.monotonic_ns()
            command.publish(Float64MultiArray(data=rows[k]))
            reading = JointState(name=joints, position=readings[k])
            reading.header.stamp = node.get_clock().now().to_msg()
            encoder.publish(reading)
            ping_sent[k] = time.monotonic_ns()
            ping.publish(Float64MultiArray(data=[float(k)]))
        # replies in flight (a node behind works off its backlog): until all came or none
        # for 3 s; the node's CPU and the wall time run to the last reply (at least the play)
        quiet_since, last_count = time.monotonic(), -1
        while time.monotonic() - quiet_since < 3.0 and int((back > 0).sum()) < n:
            count = int((back > 0).sum())
            if count != last_count:
                quiet_since, last_count = time.monotonic(), count
            replies.until(time.monotonic_ns() + 50_000_000)
        cpu = cpu_seconds(node_pid) - cpu0
        echo_cpu = cpu_seconds(echo_pid) - echo0
        own = time.process_time() - own0
        threads1 = _thread_counts(node_pid)
        end = max(int(back.max()), int(sent[-1]))
        wall = (end - start) / 1e9
        replies.until(time.monotonic_ns() + 1_500_000_000)  # the last estimates, diagnostics
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return Played(
        sent,
        ping_sent,
        back,
        pong,
        values,
        commands,
        estimates,
        names,
        faults,
        late,
        thread_costs(threads0, threads1, wall),
        cpu,
        wall,
        own,
        echo_cpu,
    )


def pipeline_cost(u: np.ndarray, y: np.ndarray) -> float:
    """CPU seconds per second of data of the node's pipeline alone (no middleware): the same
    messages fed in process to the six-joint pipeline, as fast as it takes them, with the
    synchronous identify workers (every batch identified in line: a thread worker fed faster
    than real time would skip batches and understate the cost)."""
    from genbacklash_ros.node.joints import JointSet
    from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
    from genbacklash_ros.node.multijoint import MultiJointPipeline

    joints = JointSet.from_mapping(
        {"joints": list(JOINTS), "command_indices": list(range(len(JOINTS)))}
    )
    pipe = MultiJointPipeline(joints)
    n = u.shape[1]
    rows = np.vstack([u, np.arange(n, dtype=np.float64)]).T.tolist()
    readings = y.T.tolist()
    t0 = 1_700_000_000 * 1_000_000_000
    cpu0 = time.process_time()
    for k in range(n):
        at = t0 + k * TICK_NS
        pipe.on_command(Float64MultiArray(data=tuple(rows[k])), at)
        reading = JointState(Header(Time.from_ns(at + 100_000)), JOINTS, tuple(readings[k]))
        pipe.on_encoder(reading, at + 200_000)
    pipe.finish(refit=False)
    cpu = time.process_time() - cpu0
    pipe.close()
    return float(cpu / (n * TICK_NS / 1e9))


def _thread_cpu() -> dict[str, float]:
    """CPU seconds (``utime + stime``) of each thread of this process (Linux ``/proc``)."""
    own = os.getpid()
    return {
        str(tid): counts[1]
        for (_, pid, tid), counts in _thread_counts(own, with_children=False).items()
        if pid == own
    }


def paced_threads(u: np.ndarray, y: np.ndarray, one_thread: bool) -> tuple[float, float, float]:
    """The six-joint pipeline with its live identify thread (as the node runs it), fed in
    process at 1 kHz in real time (sleeping to each tick): (process, message thread, other
    threads) CPU per second of data, with one BLAS thread or numpy's default."""
    from threadpoolctl import threadpool_limits

    from genbacklash_ros.node.identify import live_worker
    from genbacklash_ros.node.joints import JointSet
    from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
    from genbacklash_ros.node.multijoint import MultiJointPipeline

    joints = JointSet.from_mapping(
        {"joints": list(JOINTS), "command_indices": list(range(len(JOINTS)))}
    )
    n = u.shape[1]
    rows = np.vstack([u, np.arange(n, dtype=np.float64)]).T.tolist()
    readings = y.T.tolist()
    t0 = 1_700_000_000 * 1_000_000_000
    own = str(threading.get_native_id())
    with threadpool_limits(limits=1 if one_thread else None, user_api="blas"):
        pipe = MultiJointPipeline(joints, worker=live_worker)
        try:
            before, start = _thread_cpu(), time.monotonic_ns()
            for k in range(n):
                tick = start + k * TICK_NS
                while (wait := tick - time.monotonic_ns()) > 0:
                    time.sleep(wait / 1e9)
                at = t0 + k * TICK_NS
                pipe.on_command(Float64MultiArray(data=tuple(rows[k])), at)
                reading = JointState(Header(Time.from_ns(at + 100_000)), JOINTS, tuple(readings[k]))
                pipe.on_encoder(reading, at + 200_000)
            after, wall = _thread_cpu(), (time.monotonic_ns() - start) / 1e9
        finally:
            pipe.close()
    used = {tid: after[tid] - before.get(tid, 0.0) for tid in after}
    total = sum(used.values())
    return total / wall, used.get(own, 0.0) / wall, (total - used.get(own, 0.0)) / wall


def blas_comparison(seconds: float, seed: int, rounds: int) -> str:
    """:func:`paced_threads` with numpy's default BLAS threads and with one, round robin."""
    models = [worn(OPERATION_BACKLASH, f) for f in FACTORS]
    u, y = arm_data(models, seconds, seed)
    rows = []
    for r in range(rounds):
        for one in (False, True):
            load = os.getloadavg()[0]
            proc, msg, other = paced_threads(u, y, one)
            rows.append(
                [
                    str(r + 1),
                    "one" if one else "default",
                    f"{load:.1f}",
                    f"{proc:.3f}",
                    f"{msg:.3f}",
                    f"{other:.3f}",
                ]
            )
    table = md_table(
        [
            "round",
            "BLAS threads",
            "1-min load",
            "process (of a core)",
            "message thread",
            "other threads",
        ],
        rows,
    )
    return f"""`{command_line()}`. Machine: {machine_description()}.

The six-joint pipeline with its live identify thread, fed {seconds:g} s of the arm's data in
process at 1 kHz in real time (no middleware); CPU of each thread from `/proc/self/task`:

{table}
"""


def arm_data(models: list[Any], seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The arm's commands and readings (joints x samples), 1 kHz, no jitter, no loss."""
    settings = OperationSettings(
        duration=seconds,
        command_rate=1000.0,
        encoder_rate=1000.0,
        command_jitter=0.0,
        stamp_jitter=0.0,
        loss=0.0,
    )
    records = arm_records(models, settings, seed)
    u = np.stack([r.command_u for r in records])
    y = np.stack([r.y_all for r in records])
    n = min(u.shape[1], y.shape[1])
    return u[:, :n], y[:, :n]


def latency(sent: np.ndarray, back: np.ndarray) -> tuple[int, float, float, float]:
    """(answered, median ms, p99 ms, max ms) over the answered ones."""
    ok = back > 0
    ms = (back[ok] - sent[ok]) / 1e6
    if not ms.size:
        return 0, float("nan"), float("nan"), float("nan")
    return int(ok.sum()), float(np.median(ms)), float(np.percentile(ms, 99)), float(ms.max())


def run(
    seconds: float,
    seed: int,
    transport: str,
    domain_id: int | None = None,
    thread_priority: int = 0,
) -> str:
    models = [worn(OPERATION_BACKLASH, f) for f in FACTORS]
    u, y = arm_data(models, seconds, seed)
    domain = str(random.randint(201, 231) if domain_id is None else domain_id)
    env = {**os.environ, "ROS_DOMAIN_ID": domain}
    with tempfile.TemporaryDirectory(prefix="six_joint_") as tmp:
        params = Path(tmp) / "six.yaml"
        params.write_text(
            "/**/backlash_identifier:\n  ros__parameters:\n"
            "    command_type: float64_multi_array\n"
            f"    joints: [{', '.join(JOINTS)}]\n"
            f"    command_indices: [{', '.join(str(i) for i in range(len(JOINTS)))}]\n"
            f"    thread_priority: {thread_priority}\n"
        )
        log = Path(tmp) / "node.log"
        node = subprocess.Popen(
            [
                *(sys.executable, "-m", "genbacklash_ros.cli.node", "--transport", transport),
                *("--params-file", str(params)),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log.open("wb"),
        )
        echo_proc = subprocess.Popen(
            [
                *(sys.executable, __file__, "--role", "echo"),
                *("--lifetime", f"{seconds + 120:.0f}"),
                *("--thread-priority", str(thread_priority)),
            ],
            env=env,
        )
        os.environ["ROS_DOMAIN_ID"] = domain
        try:
            played = play(u, y, node.pid, echo_proc.pid)
        finally:
            for proc in (node, echo_proc):
                proc.send_signal(signal.SIGINT)
            code = node.wait(timeout=60)
            echo_proc.wait(timeout=30)
        node_log = log.read_text()
    with one_blas_thread():  # as the node runs
        alone = pipeline_cost(u, y)
    return report(played, models, seconds, seed, transport, code, node_log, alone)


def report(
    p: Played,
    models: list[Any],
    seconds: float,
    seed: int,
    transport: str,
    code: int,
    log: str,
    alone: float,
) -> str:
    n = p.sent.size
    comp = latency(p.sent, p.back)
    ref = latency(p.ping_sent, p.pong)
    first5 = p.sent - p.sent[0] < 5_000_000_000
    comp5 = latency(p.sent[first5], p.back[first5])
    ref5 = latency(p.ping_sent[first5], p.pong[first5])
    half = slice(n // 2, n)
    answered = p.back[half] > 0
    shares = [
        float(np.mean(p.values[half][answered, j] != p.commands[half][answered, j]))
        for j in range(len(JOINTS))
    ]
    passed = bool(np.array_equal(p.values[p.back > 0, -1], p.commands[p.back > 0, -1]))
    errors = {
        j: float(np.max(np.abs(np.array(p.estimates[j]) - mdl.parameters())))
        if j in p.estimates
        else float("nan")
        for j, mdl in zip(JOINTS, models, strict=True)
    }
    cpu = p.cpu_s / p.wall_s
    rows = [
        ["compensated command (node)", f"{comp[0]} / {n}", *(f"{v:.2f}" for v in comp[1:])],
        ["pong (plain rclpy echo)", f"{ref[0]} / {n}", *(f"{v:.2f}" for v in ref[1:])],
        ["node / echo", "", f"{comp[1] / ref[1]:.2f}x", f"{comp[2] / ref[2]:.2f}x", ""],
        ["first 5 s: node", f"{comp5[0]}", *(f"{v:.2f}" for v in comp5[1:])],
        ["first 5 s: echo", f"{ref5[0]}", *(f"{v:.2f}" for v in ref5[1:])],
    ]
    table = md_table(["", "answered", "median ms", "p99 ms", "max ms"], rows)
    joint_rows = [
        [j, f"{FACTORS[i]:g}x", f"{errors[j]:.4f}", f"{100 * shares[i]:.1f} %"]
        for i, j in enumerate(JOINTS)
    ]
    joints_table = md_table(
        ["joint", "dead zones", "max |parameter error|", "elements compensated (2nd half)"],
        joint_rows,
    )
    statuses = sorted(s for s in p.status_names if s.startswith("backlash_identifier"))
    threads_table = md_table(
        [
            "process",
            "thread",
            "name",
            "CPU (of a core)",
            "voluntary switches / s",
            "involuntary / s",
        ],
        [
            [
                t.process,
                "main" if t.main else str(t.tid),
                t.name,
                f"{t.cpu:.3f}",
                f"{t.voluntary:.0f}",
                f"{t.involuntary:.0f}",
            ]
            for t in p.threads
        ],
    )

    def mark(ok: bool) -> str:
        return "met" if ok else "NOT met"

    all_answered = comp[0] == n
    lat_ok = comp[1] <= 1.5 * ref[1] and comp[2] <= 1.5 * ref[2]
    est_ok = all(e < 0.05 for e in errors.values())
    six_ok = all(s > 0.5 for s in shares)
    spread = f"{min(shares) * 100:.0f}-{max(shares) * 100:.0f}"
    return f"""## Six joints through one node ({transport}, issue 24)

`{command_line()}`. Machine: {machine_description()}.

One `genbacklash node --transport {transport}` serving six joints (`joints`,
`command_indices`), fed for {seconds:g} s at 1 kHz (seed {seed}) by an rclpy player: a
7-element Float64MultiArray command (element 6 the sequence number, no joint's), a six-joint
JointState and a ping to a plain rclpy echo at each tick. Every command counts, from the
first (the first 5 s included). Player ticks late by more than 1 ms: {p.late}. Node exit
status {code}{", no traceback" if "Traceback" not in log else ", with a traceback"}.

{table}

{joints_table}

Node CPU: {p.cpu_s:.1f} s over {p.wall_s:.1f} s (first command to last reply) =
**{cpu:.2f} of a core**; over the same time the echo {p.echo_cpu_s / p.wall_s:.2f} and the
player {p.player_cpu_s / p.wall_s:.2f}. The pipeline alone, the same messages fed in process with no
middleware (after the run; CPU time per second of data, every identification in line, one
BLAS thread as in the node):
{alone:.2f} of a core. The element no joint uses came back unchanged in every answered
array: {passed}. Faults the joints' diagnostics reported (their elements pass through
while one is active): {", ".join(sorted(p.faults)) or "none"}. Diagnostics statuses seen:
{", ".join(f"`{s}`" for s in statuses)}.

Where the node's CPU went, per thread over the same time (`/proc/<pid>/task`, the node's
and its child's, the identify process with `thread_priority`; the node's main thread takes
the messages and answers the commands, `dds.*` are Fast DDS's; counted from a moment before
the first command to a moment after the last reply, so the sum may differ a little from the
node's figure above):

{threads_table}

Targets:
- every joint's estimate within 0.05 of its truth: {mark(est_ok)} (largest
  {max(errors.values()):.4f});
- 100 % of the commands answered, all six compensated: {mark(all_answered and six_ok)}
  ({comp[0]} of {n}; each joint's element compensated in {spread} % of the second half's
  arrays);
- at most 0.6 of a core: {mark(cpu <= 0.6)} ({cpu:.2f});
- latency median and p99 within 1.5x of the echo's: {mark(lat_ok)} (median
  {comp[1] / ref[1]:.2f}x, p99 {comp[2] / ref[2]:.2f}x).
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--role", choices=("player", "echo"), default="player")
    parser.add_argument("--lifetime", type=float, default=300.0, help="echo: seconds to live")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--transport", choices=("rclpy", "dds"), default="rclpy")
    parser.add_argument("--quick", action="store_true", help="5 s (a smoke test)")
    parser.add_argument(
        "--domain",
        type=int,
        default=None,
        help="ROS_DOMAIN_ID of the three processes (default: one at random in 201-231)",
    )
    parser.add_argument(
        "--thread-priority",
        type=int,
        default=0,
        metavar="P",
        help="the node's thread_priority (SCHED_FIFO 1-99), and the echo's thread at the same "
        "priority (default 0: the default scheduler for both)",
    )
    parser.add_argument(
        "--blas",
        type=int,
        metavar="ROUNDS",
        default=0,
        help="instead: the pipeline and its identify thread paced at 1 kHz in process, numpy's "
        "default BLAS threads against one, ROUNDS rounds (printed, no section written)",
    )
    args = parser.parse_args(argv)
    if not 0 <= args.thread_priority <= 99:
        parser.error(f"--thread-priority must lie in 0..99, got {args.thread_priority}")
    if args.quick:
        args.seconds = 5.0
    if args.role == "echo":
        return echo(args.lifetime, args.thread_priority)
    if args.blas:
        print(blas_comparison(args.seconds, args.seed, args.blas))
        return 0
    text = run(args.seconds, args.seed, args.transport, args.domain, args.thread_priority)
    print(text)
    write_section(f"six_joint_{args.transport}", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
