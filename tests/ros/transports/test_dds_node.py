"""The DDS node as a real process: a publisher process, the node process, a subscriber here.

The player (``tests/ros/transports/dds_player.py``) plays the paper's Example 1 at 500 Hz over DDS;
the node runs as ``python -m genbacklash_ros.cli.node --transport dds`` with a params file in
``tmp_path`` and a domain id of its own; this process subscribes to its outputs. Then SIGINT:
a clean exit, the final checkpoint on disk, and a second node that warm-starts from it.
"""

from __future__ import annotations

import json
import math
import os
import random
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("cyclonedds", reason="cyclonedds is not installed (pip install .[dds])")

from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from genbacklash_core import paper_example, simulate_backlash
from genbacklash_ros.node.checkpoint import load_checkpoint
from genbacklash_ros.transports.dds_node import DEFAULT_QOS
from genbacklash_ros.transports.dds_types import (
    Float64MultiArray_,
    MultiArrayDimension_,
    MultiArrayLayout_,
)

from ._answer_first import ANSWER_FIRST, recorded
from ._dds import Received, Subscriber, diagnostic_values, start_node, stop_node
from ._player import wait_for

HERE = Path(__file__).parent
TRUTH = paper_example(1).model
RATE_HZ = 500.0
SECONDS = 8.0
# one domain per test session (ROS_DOMAIN_ID range), so parallel runs do not cross-talk
DOMAIN = 1 + (os.getpid() * 7919 + random.randrange(1000)) % 200


def _write_params(path: Path, checkpoint: Path) -> Path:
    path.write_text(
        "backlash_identifier:\n"
        "  ros__parameters:\n"
        "    command_type: float64_multi_array\n"
        "    command_index: 0\n"
        "    joint: j\n"
        f"    checkpoint_file: {checkpoint}\n"
        "    checkpoint_period: 2.0\n"
        "    publish_rate: 10.0\n"
    )
    return path


@dataclass
class Run:
    summary: dict[str, Any]
    got: Received
    returncode: int
    log: str
    checkpoint: Path
    params: Path
    tmp: Path
    seconds: float


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Run]:
    """Node + player + subscriber once; the tests check different parts of the result."""
    tmp = tmp_path_factory.mktemp("dds_node")
    checkpoint = tmp / "estimate.json"
    params = _write_params(tmp / "params.yaml", checkpoint)
    log = tmp / "node.log"
    started = time.monotonic()
    sub = Subscriber(DOMAIN)
    node = start_node(params, log, DOMAIN)
    try:
        player = subprocess.run(
            [
                *(sys.executable, str(HERE / "dds_player.py"), "--domain-id", str(DOMAIN)),
                *("--rate", str(RATE_HZ), "--seconds", str(SECONDS)),
            ],
            capture_output=True,
            timeout=90,
            check=False,
        )
        assert player.returncode == 0, player.stdout.decode() + player.stderr.decode()
        summary = json.loads(player.stdout.decode().strip().splitlines()[-1])
        # the node keeps up: wait until (almost) every command came back
        wait_for(lambda: len(sub.got.compensated) >= summary["sent"], 10)
        returncode = stop_node(node, log)
        wait_for(lambda: False, 1.0)  # the final estimate and diagnostics
    finally:
        if node.poll() is None:
            node.kill()
        sub.close()
    yield Run(
        summary,
        sub.got,
        returncode,
        log.read_text(),
        checkpoint,
        params,
        tmp,
        time.monotonic() - started,
    )


def test_player_reaches_the_rate(run: Run) -> None:
    assert run.summary["rate"] >= 0.9 * RATE_HZ, run.summary


def test_one_compensated_command_per_command(run: Run) -> None:
    sent = run.summary["sent"]
    u = np.array(run.summary["u"])
    seqs = [int(s.data[1]) for _, s in run.got.compensated]
    assert len(seqs) == len(set(seqs)), "a command was compensated twice"
    # reliable QoS end to end: on a loaded machine allow a few losses, never extra ones
    assert len(seqs) >= 0.95 * sent, f"{len(seqs)} of {sent} compensated commands arrived"
    assert set(seqs) <= set(range(sent))
    assert all(len(s.data) == 3 for _, s in run.got.compensated)
    # the other elements are echoed unchanged (the sequence number, the write time)
    values = {int(s.data[1]): s.data[0] for _, s in run.got.compensated}
    assert all(math.isfinite(v) for v in values.values())
    # where the model is known (the last quarter), the compensated commands drive the true
    # backlash to the desired positions: far closer than the raw commands would
    late = [k for k in range(int(0.75 * sent), sent) if k in values]
    assert len(late) > 0.2 * sent
    sent_u = np.array([values[k] for k in late])
    x = simulate_backlash(TRUTH, sent_u, x0=float(u[late[0]]))[20:]
    desired = u[late][20:]
    raw = simulate_backlash(TRUTH, u[late], x0=float(u[late[0]]))[20:]
    compensated_error = float(np.median(np.abs(x - desired)))
    raw_error = float(np.median(np.abs(raw - desired)))
    assert compensated_error < 0.05, (compensated_error, raw_error)
    assert compensated_error < 0.2 * raw_error


def test_compensated_command_latency(run: Run) -> None:
    """Report the loopback latency (write of the command -> compensated command taken here);
    only a loose bound: the machine may be loaded."""
    lat_ms = np.array([(t - s.data[2]) / 1e6 for t, s in run.got.compensated])
    median, p99 = np.percentile(lat_ms, [50, 99])
    print(f"compensated command latency: median {median:.2f} ms, p99 {p99:.2f} ms")
    assert median < 100.0


def test_estimates_approach_the_truth(run: Run) -> None:
    estimates = run.got.estimates
    assert len(estimates) >= 10
    label = estimates[-1][1].layout.dim[0].label
    assert label == ",".join(TRUTH.parameter_names) or label.startswith("m_left_1")
    last = np.array(estimates[-1][1].data)
    error = np.max(np.abs(last - TRUTH.parameters()))
    assert error < 0.1, f"max |parameter error| {error:.3f}: {last}"


def test_diagnostics_arrive(run: Run) -> None:
    diags = [s for _, s in run.got.diagnostics]
    assert len(diags) >= 3
    assert all(d.status[0].name == "backlash_identifier" for d in diags)
    values = diagnostic_values(diags[-1])
    assert values["state"] in ("converged", "converging")
    assert int(values["compensated_commands"]) >= 0.95 * run.summary["sent"]


def test_clean_exit_and_atomic_checkpoint(run: Run) -> None:
    assert run.returncode == 0, run.log
    assert "SIGINT: shutting down" in run.log
    assert "Traceback" not in run.log
    saved = load_checkpoint(run.checkpoint)
    assert np.max(np.abs(saved.estimate.parameters - TRUTH.parameters())) < 0.1
    leftovers = [p.name for p in run.tmp.iterdir() if p.name.endswith(".tmp")]
    assert leftovers == [], "a temporary checkpoint file was left behind"
    print(f"multi-process run took {run.seconds:.1f} s")


def test_restarts_from_the_checkpoint(run: Run) -> None:
    """A new node warm-starts from the checkpoint: before any data its diagnostics (STALE)
    carry the checkpoint's parameters, and its first command is already compensated."""
    saved = load_checkpoint(run.checkpoint)
    log = run.tmp / "node2.log"
    sub = Subscriber(DOMAIN)
    node = start_node(run.params, log, DOMAIN)
    try:
        assert wait_for(lambda: len(sub.got.diagnostics) >= 1, 20), log.read_text()
        diag = sub.got.diagnostics[-1][1]
        values = diagnostic_values(diag)
        assert diag.status[0].level == 3  # STALE: no data yet
        assert values["estimate_source"] == "checkpoint"
        assert "warm start from checkpoint" in values["warm_start"]
        for name, value in zip(saved.estimate.names, saved.estimate.parameters, strict=True):
            assert float(values[name]) == pytest.approx(value, rel=1e-6, abs=1e-9)
        # a command: compensated with the checkpoint's model at once
        dp = sub.dp
        writer = DataWriter(dp, Topic(dp, "rt/command", Float64MultiArray_), qos=DEFAULT_QOS)
        wait_for(lambda: writer.get_publication_matched_status().current_count >= 1, 10)
        time.sleep(0.3)
        layout = MultiArrayLayout_([MultiArrayDimension_("u", 3, 3)], 0)
        for k, u in enumerate((0.5, 1.0, 1.5)):
            writer.write(Float64MultiArray_(layout, [u, float(k), 0.0]))
            time.sleep(0.01)
        assert wait_for(lambda: len(sub.got.compensated) >= 3, 10), log.read_text()
        sent = [s.data[0] for _, s in sub.got.compensated]
        assert sent != [0.5, 1.0, 1.5], "the commands passed through uncompensated"
        assert stop_node(node, log) == 0, log.read_text()
    finally:
        if node.poll() is None:
            node.kill()
        sub.close()


def test_a_stalled_loop_loses_no_command() -> None:
    """Commands that arrive while the loop is busy wait in the reader (READER_DEPTH), instead of
    being overwritten after ROS 2's 10: here the loop has not started while 300 arrive."""
    from genbacklash_ros.node.parameters import NodeParameters
    from genbacklash_ros.transports.dds_node import READER_DEPTH, DdsNode

    sent = 300
    assert sent < READER_DEPTH
    node = DdsNode(NodeParameters(joint="j"), domain_id=DOMAIN)
    sub = Subscriber(DOMAIN)
    dp = sub.dp
    writer = DataWriter(dp, Topic(dp, "rt/command", Float64MultiArray_), qos=DEFAULT_QOS)
    try:
        assert wait_for(lambda: writer.get_publication_matched_status().current_count >= 1, 10)
        layout = MultiArrayLayout_([MultiArrayDimension_("u", 3, 3)], 0)
        for k in range(sent):
            writer.write(Float64MultiArray_(layout, [0.01 * k, float(k), 0.0]))
        time.sleep(0.5)  # all delivered and acknowledged into the reader's history
        node.spin(0.5)
        assert node.stats.received["command"] == sent
        assert wait_for(lambda: len(sub.got.compensated) >= sent, 10), len(sub.got.compensated)
    finally:
        sub.close()


def test_the_compensated_command_is_published_before_the_periodic_outputs_are_built(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A command at which a diagnostics report comes due: its compensated command is
    written before the report is built (the pipeline's ``answer``, then ``periodic``), so
    building the estimates and reports never delays the answer."""
    from genbacklash_ros.node.messages import Float64MultiArray
    from genbacklash_ros.node.parameters import NodeParameters
    from genbacklash_ros.transports.dds_node import DdsNode, _Event

    node = DdsNode(NodeParameters(joint="j"), domain_id=DOMAIN, clock=lambda: 10**15)
    events, publish = recorded(node.pipeline)
    pending = [
        _Event(1_000_000, 1, "command", Float64MultiArray(data=(0.1, 0.0))),
        _Event(1_200_000_000, 2, "command", Float64MultiArray(data=(0.2, 0.0))),
    ]

    def take(kind: str, out: list[_Event]) -> None:
        if kind == "command":
            out.extend(pending)
            pending.clear()

    monkeypatch.setattr(node, "_take", take)
    monkeypatch.setattr(node, "_publish", publish)
    try:
        assert node._process_available()
        assert events == ANSWER_FIRST
    finally:
        node.stop()
        node.spin()
