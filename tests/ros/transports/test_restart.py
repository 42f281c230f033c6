"""Restart after a crash: the estimate continues from the last checkpoint.

* In process: a pipeline is dropped mid-run (as a killed node is) and a new one starts from
  its last checkpoint with the data that follow; the identifier is seeded from the checkpoint
  (no cold start), so the first estimate is the checkpointed one within noise and every
  command is compensated from the first one.
* Multi-process: the DDS node (``genbacklash node --transport dds``) runs as its own process,
  a player process publishes a drivetrain at 500 Hz, a subscriber here records the outputs.
  Once checkpoints are written the node is killed with SIGKILL between two checkpoints, the
  checkpoint file must parse, and the node is started again with the same params file while
  the player goes on. The restarted node must say it warm-started, publish first an estimate
  within noise of the checkpoint's, and be back in its pre-kill state within one checkpoint
  period of data time.
* Atomicity: processes saving checkpoints in a loop are killed with SIGKILL at random
  moments; the checkpoint file must load after every kill.
"""

from __future__ import annotations

import importlib.util
import json
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from genbacklash_core import EstimatorState, Structure, paper_example, simulate_backlash
from genbacklash_ros.node.checkpoint import (
    Checkpoint,
    CheckpointError,
    load_checkpoint,
    warm_start,
)
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    Header,
    JointState,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline, Output

from ._dds import Received, Subscriber, diagnostic_values, start_node
from ._player import wait_for

HERE = Path(__file__).parent
TRUTH = paper_example(1).model
MS = 1_000_000
S = 1_000_000_000
PERIOD_S = 2.0  # checkpoint period (data time)

# --------------------------------------------------------------------------- in process


@dataclass(frozen=True)
class Event:
    receive_ns: int
    kind: str  # "command" or "encoder"
    msg: Any


def drivetrain_events(seed: int, seconds: float) -> list[Event]:
    """Example 1 as a drivetrain publishes it: a Float64MultiArray command at 200 Hz with
    jitter (no header: its time is its receive time), a 1 kHz JointState encoder."""
    rng = np.random.default_rng(seed)
    layout = MultiArrayLayout((MultiArrayDimension("joints", 1, 1),))
    period = 5 * MS
    n_cmd = int(seconds * 200)
    cmd_t = np.arange(1, n_cmd + 1) * period + rng.integers(-MS, MS + 1, n_cmd)
    cmd_u = rng.uniform(-2.0, 2.0, n_cmd)
    enc_t = np.arange(1, int(seconds * 1000) + 1, dtype=np.int64) * MS
    held = np.searchsorted(cmd_t, enc_t, side="right") - 1
    enc_t, held = enc_t[held >= 0], held[held >= 0]
    x = simulate_backlash(TRUTH, cmd_u[held])
    y = x + rng.normal(0.0, float(np.std(x)) / 25.0, x.size)
    events = [
        Event(int(t), "command", Float64MultiArray(layout, (float(u),)))
        for t, u in zip(cmd_t, cmd_u, strict=True)
    ]
    events += [
        Event(int(t) + 100_000, "encoder", JointState(Header(Time.from_ns(int(t))), ("j",), (v,)))
        for t, v in zip(enc_t, y.tolist(), strict=True)
    ]
    events.sort(key=lambda e: (e.receive_ns, e.kind))
    return events


def feed(pipe: BacklashPipeline, events: list[Event]) -> list[Output]:
    outputs: list[Output] = []
    for event in events:
        if event.kind == "command":
            outputs += pipe.on_command(event.msg, event.receive_ns)
        else:
            outputs += pipe.on_encoder(event.msg, event.receive_ns)
    return outputs


@pytest.mark.parametrize("method", ["windowed", "recursive"])
def test_a_dropped_pipeline_resumes_from_its_checkpoint(tmp_path: Path, method: str) -> None:
    path = tmp_path / "estimate.json"
    params = NodeParameters(
        command_type="float64_multi_array",
        command_index=0,
        joint="j",
        method=method,  # type: ignore[arg-type]
        checkpoint_file=str(path),
        checkpoint_period=PERIOD_S,
    )
    # 22 s: after the restart the identifier needs as many informative rows as the checkpoint
    # stands for (its window, 1500 rows; ~180 commands/s here) before it stops leaning on it
    events = drivetrain_events(11, 22.0)
    kill, back = int(9.3 * S), int(10.5 * S)  # killed mid-period, back 1.2 s later
    first = BacklashPipeline(params)
    before = feed(first, [e for e in events if e.receive_ns < kill])  # then: gone, no finish()
    saved = load_checkpoint(path)
    assert saved.time_ns == 8 * S and saved.estimate.state is EstimatorState.CONVERGED
    pre_kill = [o for o in before if o.topic == "diagnostics"][-1].estimate
    assert pre_kill is not None

    second = BacklashPipeline(params)
    assert second.identifier.from_seed and second.using_checkpoint
    assert "the identifier continues from its estimate" in second.warm_start_note
    after = [e for e in events if e.receive_ns >= back]
    outputs = feed(second, after)
    # the first estimate published is the checkpoint's within noise, already converged
    estimates = [o.estimate for o in outputs if o.topic == "estimate"]
    assert estimates[0] is not None
    std = saved.estimate.std()
    jump = np.abs(estimates[0].parameters - saved.estimate.parameters)
    assert np.all(jump <= 3.0 * std), jump / std
    assert estimates[0].state is pre_kill.state is EstimatorState.CONVERGED
    # no warm-up: converged while the window refills from the checkpoint, accurate throughout
    stamps = [o.stamp_ns for o in outputs if o.topic == "estimate"]
    early = [e for e, t in zip(estimates, stamps, strict=True) if t < back + int(PERIOD_S * S)]
    assert early and all(e is not None and e.state is EstimatorState.CONVERGED for e in early)
    assert all(e is not None and e.state is not EstimatorState.WARMING_UP for e in estimates)
    worst = max(np.max(np.abs(e.parameters - TRUTH.parameters())) for e in estimates if e)
    assert worst < 0.05
    # every command is compensated from the first one: no pass-through window
    raw = [e.msg.data[0] for e in after if e.kind == "command"]
    sent = [o.message.data[0] for o in outputs if o.topic == "compensated_command"]  # type: ignore[union-attr]
    assert len(sent) == len(raw) and all(abs(a - b) > 1e-9 for a, b in zip(sent, raw, strict=True))
    # the diagnostics say where the estimate comes from
    diagnostics = [o.message.status[0] for o in outputs if o.topic == "diagnostics"]  # type: ignore[union-attr]
    assert diagnostics[0].message.startswith("continuing from the checkpoint's estimate")
    sources = [{kv.key: kv.value for kv in d.values}["estimate_source"] for d in diagnostics]
    assert sources[0] == "checkpoint" and sources[-1] == "identifier"


def test_a_restarted_pipeline_stopped_before_any_sample(tmp_path: Path) -> None:
    """Started from a checkpoint and stopped again before data: the checkpoint stands."""
    path = tmp_path / "estimate.json"
    params = NodeParameters(
        command_type="float64_multi_array", command_index=0, joint="j", checkpoint_file=str(path)
    )
    events = drivetrain_events(12, 4.0)
    first = BacklashPipeline(params)
    feed(first, events)
    first.finish()
    saved = load_checkpoint(path).estimate
    second = BacklashPipeline(params)
    feed(second, [e for e in events if e.kind == "command"][:3])  # commands only
    outputs = second.finish()
    final = [o.estimate for o in outputs if o.topic == "estimate"]
    assert final and final[0] is not None
    assert np.array_equal(final[0].parameters, saved.parameters)
    assert np.array_equal(load_checkpoint(path).estimate.parameters, saved.parameters)


# --------------------------------------------------------------------------- atomicity

_SAVER = """
import sys, numpy as np
from genbacklash_core import Estimate, Structure, paper_example
from genbacklash_ros.node.checkpoint import save_checkpoint
path, start = sys.argv[1], int(sys.argv[2])
p = paper_example(1).model.parameters()
rng = np.random.default_rng(start)
k = start
while True:
    a = rng.normal(size=(8, 8)) * 1e-3
    est = Estimate(Structure(3), p + rng.normal(0, 1e-3, 8), a @ a.T, 0.02, 0.5,
                   "converged", 0.9, k, "x" * int(rng.integers(0, 20000)))
    save_checkpoint(path, est, k)
    if k == start:
        print("ready", flush=True)
    k += 1
"""


def test_a_writer_killed_mid_save_never_leaves_a_broken_file(tmp_path: Path) -> None:
    """SIGKILL a process saving checkpoints in a tight loop, many times: the file always
    loads, and only ever moves forward."""
    path = tmp_path / "estimate.json"
    rng = random.Random(5)
    last = -1
    leftovers = 0
    kills = 12
    for round_ in range(kills):
        start = round_ * 1_000_000
        child = subprocess.Popen(
            [sys.executable, "-c", _SAVER, str(path), str(start)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        try:
            assert child.stdout is not None
            line = child.stdout.readline()
            assert line.strip() == b"ready", child.stderr.read() if child.stderr else b""
            time.sleep(rng.uniform(0.0, 0.05))
            os.kill(child.pid, signal.SIGKILL)
            child.wait(timeout=30)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        assert child.returncode == -signal.SIGKILL
        saved = load_checkpoint(path)  # never half-written
        assert saved.time_ns >= start > last
        assert saved.estimate.structure == Structure(3)
        last = saved.time_ns
        for leftover in tmp_path.glob(".estimate.json.*.tmp"):  # this kill was mid-write
            leftovers += 1
            leftover.unlink()
    print(f"{kills} kills; {leftovers} left a temporary file behind (killed mid-write)")
    # a node starting again removes what a killed writer left, and warm-starts
    (tmp_path / ".estimate.json.stale.tmp").write_text('{"format": "genbacklash-che')
    start_again = warm_start(NodeParameters(checkpoint_file=str(path)))
    assert list(tmp_path.glob("*.tmp")) == []
    assert start_again.seeded


# --------------------------------------------------------------------------- multi-process

needs_dds = pytest.mark.skipif(
    importlib.util.find_spec("cyclonedds") is None,
    reason="cyclonedds is not installed (pip install .[dds])",
)
RATE_HZ = 500.0
PLAYER_SECONDS = 20.0
# a domain of this test session's own (ROS_DOMAIN_ID range), apart from test_dds_node's
DOMAIN = 1 + (os.getpid() * 7919 + 97 + random.randrange(1000)) % 200


def _stamp_ns(diag: Any) -> int:
    stamp = diag.header.stamp
    return int(stamp.sec) * S + int(stamp.nanosec)


def _checkpoint_ready(path: Path) -> Checkpoint | None:
    try:
        saved = load_checkpoint(path)
    except CheckpointError:
        return None
    return saved if saved.estimate.state is EstimatorState.CONVERGED else None


@dataclass
class Restart:
    got: Received
    summary: dict[str, Any]
    saved: Checkpoint  # the checkpoint file right after the kill
    kill_mono_ns: int  # when the first node was killed (monotonic)
    killed_at_ns: int  # the first node's data time then (wall clock)
    first_log: str
    second_log: str
    second_returncode: int
    mono_to_wall: int  # add to a monotonic time for the wall-clock time


@pytest.fixture(scope="module")
def restart(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Restart]:
    tmp = tmp_path_factory.mktemp("restart")
    checkpoint = tmp / "estimate.json"
    params = tmp / "params.yaml"
    params.write_text(
        "backlash_identifier:\n"
        "  ros__parameters:\n"
        "    command_type: float64_multi_array\n"
        "    command_index: 0\n"
        "    joint: j\n"
        f"    checkpoint_file: {checkpoint}\n"
        f"    checkpoint_period: {PERIOD_S}\n"
        "    publish_rate: 10.0\n"
    )
    logs = tmp / "node1.log", tmp / "node2.log"
    mono_to_wall = time.time_ns() - time.monotonic_ns()
    sub = Subscriber(DOMAIN)
    first = start_node(params, logs[0], DOMAIN)
    second: subprocess.Popen[bytes] | None = None
    player = subprocess.Popen(
        [
            *(sys.executable, str(HERE / "dds_player.py"), "--domain-id", str(DOMAIN)),
            *("--rate", str(RATE_HZ), "--seconds", str(PLAYER_SECONDS), "--clock", "wall"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        # run until a converged estimate is checkpointed, and one more period on top
        assert wait_for(lambda: _checkpoint_ready(checkpoint) is not None, 30), logs[0].read_text()
        ready = _checkpoint_ready(checkpoint)
        assert ready is not None
        assert wait_for(lambda: load_checkpoint(checkpoint).time_ns > ready.time_ns, 10)
        time.sleep(0.6 * PERIOD_S)  # between two checkpoints
        killed_at_ns = time.time_ns()
        os.kill(first.pid, signal.SIGKILL)
        first.wait(timeout=10)
        kill_mono_ns = time.monotonic_ns()
        assert first.returncode == -signal.SIGKILL
        saved = load_checkpoint(checkpoint)  # parses: never half-written
        second = start_node(params, logs[1], DOMAIN)
        out, err = player.communicate(timeout=90)
        assert player.returncode == 0, out.decode() + err.decode()
        summary = json.loads(out.decode().strip().splitlines()[-1])
        time.sleep(1.0)  # the last outputs
        second.send_signal(signal.SIGINT)
        returncode = second.wait(timeout=30)
        time.sleep(0.5)
    finally:
        for proc in (first, second, player):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
        sub.close()
    yield Restart(
        sub.got,
        summary,
        saved,
        kill_mono_ns,
        killed_at_ns,
        logs[0].read_text(),
        logs[1].read_text(),
        returncode,
        mono_to_wall,
    )


def _after_kill(restart: Restart, items: list[tuple[int, Any]]) -> list[Any]:
    return [m for t, m in items if t > restart.kill_mono_ns]


def _before_kill(restart: Restart, items: list[tuple[int, Any]]) -> list[Any]:
    return [m for t, m in items if t < restart.kill_mono_ns]


@needs_dds
def test_the_player_kept_the_rate(restart: Restart) -> None:
    assert restart.summary["rate"] >= 0.9 * RATE_HZ, restart.summary["rate"]


@needs_dds
def test_the_killed_node_left_a_valid_checkpoint(restart: Restart) -> None:
    saved = restart.saved
    assert saved.estimate.state is EstimatorState.CONVERGED
    assert np.max(np.abs(saved.estimate.parameters - TRUTH.parameters())) < 0.1
    lost = (restart.killed_at_ns - saved.time_ns) / S
    assert 0.0 < lost < PERIOD_S + 0.5, lost  # at most one period of data time is lost
    assert "Traceback" not in restart.first_log


@needs_dds
def test_the_restarted_node_says_it_warm_started(restart: Restart) -> None:
    diags = _after_kill(restart, restart.got.diagnostics)
    assert diags, restart.second_log
    values = diagnostic_values(diags[0])
    assert "warm start from checkpoint" in values["warm_start"]
    assert "the identifier continues from its estimate" in values["warm_start"]
    assert values["estimate_source"] == "checkpoint"
    # the checkpoint's parameters (within noise: data may have arrived before the report)
    saved = restart.saved.estimate
    reported = np.array([float(values[name]) for name in saved.names])
    assert np.all(np.abs(reported - saved.parameters) <= 3.0 * saved.std())
    assert values["state"] == saved.state.value
    assert restart.second_returncode == 0, restart.second_log
    assert "Traceback" not in restart.second_log


@needs_dds
def test_the_first_estimate_after_the_restart_continues_the_checkpoint(restart: Restart) -> None:
    saved = restart.saved.estimate
    before = _before_kill(restart, restart.got.estimates)
    after = _after_kill(restart, restart.got.estimates)
    assert before and after
    first = np.array(after[0].data)
    jump = np.abs(first - saved.parameters)
    std = saved.std()
    last_before = np.array(before[-1].data)
    print(
        f"restart: estimate jump vs checkpoint max {jump.max():.4f} "
        f"({np.max(jump / std):.2f} std); vs the last estimate before the kill "
        f"{np.max(np.abs(first - last_before)):.4f}"
    )
    assert np.all(jump <= 4.0 * std), jump / std
    assert jump.max() < 0.03


@needs_dds
def test_back_in_the_pre_kill_state_within_one_checkpoint_period(restart: Restart) -> None:
    """Data time from the restarted node's first command to its first report of the state
    it had before the kill (and a converged estimate close to the truth)."""
    before = [d for d in _before_kill(restart, restart.got.diagnostics) if d.status[0].level != 3]
    pre_kill_state = diagnostic_values(before[-1])["state"]
    # the restarted node's first command (its data time: the player's write time)
    commands = _after_kill(restart, restart.got.compensated)
    first_data_ns = min(int(c.data[2]) for c in commands)
    reports = [d for d in _after_kill(restart, restart.got.diagnostics) if d.status[0].level != 3]
    back = next(d for d in reports if diagnostic_values(d)["state"] == pre_kill_state)
    resumed_s = (_stamp_ns(back) - first_data_ns) / S
    estimates = [(t, m) for t, m in restart.got.estimates if t > restart.kill_mono_ns]
    error = np.max(np.abs(np.array(estimates[0][1].data) - TRUTH.parameters()))
    first_estimate_s = (estimates[0][0] + restart.mono_to_wall - first_data_ns) / S
    down_s = (first_data_ns - restart.killed_at_ns) / S
    lost_s = (restart.killed_at_ns - restart.saved.time_ns) / S
    print(
        f"restart: node down {down_s:.2f} s (checkpoint {lost_s:.2f} s old at the kill); "
        f"pre-kill state {pre_kill_state!r} reported {resumed_s:.3f} s of data time after the "
        f"first command (checkpoint period {PERIOD_S} s); first estimate received "
        f"{first_estimate_s:.3f} s after the first command, max error {error:.4f}"
    )
    assert resumed_s <= PERIOD_S
    assert error < 0.1
    # the first commands are compensated at once: no pass-through after the restart
    u = np.array(restart.summary["u"])
    first_sent = sorted(commands, key=lambda c: c.data[1])[:20]
    assert all(abs(c.data[0] - u[int(c.data[1])]) > 1e-9 for c in first_sent)
