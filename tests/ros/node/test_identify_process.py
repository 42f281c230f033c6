"""The identify stage in a child process (genbacklash_ros.node.identify_process): the same
results as the in-process workers, never a wait on submit, and a child that ends with the
node however the node ends."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import WindowedIdentifier, paper_example
from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.node import identify_process
from genbacklash_ros.node.identify import Identified, Refused, Skipped, SyncWorker
from genbacklash_ros.node.identify_process import IdentifyProcess, ProcessWorker
from tests.ros._proc import alive

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="the child's checks read Linux /proc"
)


@pytest.fixture
def process() -> Iterator[IdentifyProcess]:
    proc = IdentifyProcess()
    try:
        yield proc
    finally:
        proc.close()


def _example(n: int = 3000, seed: int = 7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    data = paper_example(1).generate(seed=seed, n_samples=n)
    breaks = np.zeros(n, dtype=bool)
    breaks[0] = True
    return data.u, data.y, breaks


def _refused(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples the identifier refuses at once (not finite): the child's work is then only
    the transport's, which is what the outbox tests are about."""
    breaks = np.zeros(n, dtype=bool)
    breaks[0] = True
    return np.full(n, np.nan), np.full(n, np.nan), breaks


def test_the_child_identifies_what_the_synchronous_worker_does(process: IdentifyProcess) -> None:
    u, y, breaks = _example()
    with one_blas_thread():  # the child runs with one, as the node does
        sync = SyncWorker(WindowedIdentifier(3))
        sync.submit(u, y, breaks)
        expected = sync.poll()
    worker = ProcessWorker(WindowedIdentifier(3), process=process)
    worker.submit(u, y, breaks)
    worker.flush()
    results = worker.poll()
    assert len(results) == 1 and isinstance(results[0], Identified)
    assert isinstance(expected[0], Identified)
    assert results[0].samples == u.size
    np.testing.assert_array_equal(results[0].estimate.parameters, expected[0].estimate.parameters)
    assert results[0].estimate.state is expected[0].estimate.state
    copy = worker.identifier  # a snapshot of the child's
    assert copy.estimate.samples == expected[0].estimate.samples
    refit = worker.refit()
    assert isinstance(refit, Identified) and refit.samples == 0
    worker.close()


def test_results_come_back_without_a_flush(process: IdentifyProcess) -> None:
    u, y, breaks = _example(600)
    worker = ProcessWorker(WindowedIdentifier(3), process=process)
    worker.submit(u, y, breaks)
    deadline = time.monotonic() + 30
    taken: list[object] = []
    while not taken and time.monotonic() < deadline:
        taken = list(worker.poll())
        time.sleep(0.002)
    assert taken and isinstance(taken[0], Identified) and taken[0].samples == 600
    assert worker.poll() == []
    worker.close()


def test_workers_share_one_child_and_keep_their_results_apart(process: IdentifyProcess) -> None:
    first = ProcessWorker(WindowedIdentifier(3), process=process)
    second = ProcessWorker(WindowedIdentifier(2), process=process)
    u, y, breaks = _example(500)
    first.submit(u, y, breaks)
    second.submit(u[:200], y[:200], breaks[:200])
    first.flush()
    second.flush()
    assert [r.samples for r in first.poll()] == [500]
    assert [r.samples for r in second.poll()] == [200]
    assert first.identifier.structure.degree == 3 and second.identifier.structure.degree == 2
    first.close()
    second.close()


def test_submit_never_waits_for_a_stopped_child(process: IdentifyProcess) -> None:
    """What the socket cannot take waits in the outbox: the message thread goes on."""
    worker = ProcessWorker(WindowedIdentifier(3), process=process)
    worker.flush()  # the child is up
    u, y, breaks = _refused(4096)
    os.kill(process.pid, signal.SIGSTOP)
    try:
        start = time.monotonic()
        for _ in range(200):  # 200 batches of 4096 samples: ~20 MB of pickles, past the buffers
            worker.submit(u, y, breaks)
            worker.poll()
        assert time.monotonic() - start < 10.0
    finally:
        os.kill(process.pid, signal.SIGCONT)
    worker.flush()
    results = worker.poll()
    assert sum(r.samples for r in results) == 200 * 4096  # refused or skipped, none lost
    worker.close()


def test_a_child_that_takes_nothing_costs_a_bounded_outbox(
    process: IdentifyProcess, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Past MAX_OUTBOX the batches are let go (Skipped), and the next one sent breaks the
    chain; every sample is accounted for."""
    monkeypatch.setattr(identify_process, "MAX_OUTBOX", 1 << 20)
    worker = ProcessWorker(WindowedIdentifier(3), process=process)
    worker.flush()
    u, y, breaks = _refused(4096)
    follows = np.zeros_like(breaks)
    os.kill(process.pid, signal.SIGSTOP)
    try:
        for _ in range(400):  # ~28 MB: past the socket buffers and the 1 MB outbox
            worker.submit(u, y, follows)
        skipped = [r for r in worker.poll() if isinstance(r, Skipped)]
        assert skipped and "identify process behind" in skipped[0].reason
        assert worker._channel.broken
    finally:
        os.kill(process.pid, signal.SIGCONT)
    worker.flush()  # the outbox drained
    worker.submit(u, y, follows)  # sent, with its first sample breaking the chain
    assert not worker._channel.broken
    worker.flush()
    results = skipped + worker.poll()
    assert sum(r.samples for r in results) == 401 * 4096


def test_a_child_that_dies_refuses_what_was_handed_over(process: IdentifyProcess) -> None:
    worker = ProcessWorker(WindowedIdentifier(3), process=process)
    worker.flush()
    os.kill(process.pid, signal.SIGSTOP)
    u, y, breaks = _example(300)
    worker.submit(u, y, breaks)
    os.kill(process.pid, signal.SIGKILL)
    deadline = time.monotonic() + 10
    results: list[object] = []
    while not results and time.monotonic() < deadline:
        results = list(worker.poll())
        time.sleep(0.005)
    assert len(results) == 1 and isinstance(results[0], Refused)
    assert results[0].samples == 300 and "identify process ended" in results[0].reason
    worker.submit(u, y, breaks)  # after: refused at once
    later = worker.poll()
    assert isinstance(later[0], Refused) and later[0].samples == 300
    assert isinstance(worker.refit(), Refused)
    worker.flush()  # returns
    assert worker.identifier.estimate.samples == 0  # the identifier it started from
    worker.close()


def test_the_child_ignores_an_interrupt(process: IdentifyProcess) -> None:
    worker = ProcessWorker(WindowedIdentifier(3), process=process)
    worker.flush()
    os.kill(process.pid, signal.SIGINT)
    u, y, breaks = _example(300)
    worker.submit(u, y, breaks)
    worker.flush()
    assert [type(r) for r in worker.poll()] == [Identified]
    worker.close()


def test_closing_ends_the_child_cleanly() -> None:
    proc = IdentifyProcess()
    worker = ProcessWorker(WindowedIdentifier(3), process=proc)
    worker.flush()
    pid = proc.pid
    proc.close()
    assert proc._proc.returncode == 0
    assert not alive(pid)
    assert proc.dead is not None


@pytest.mark.parametrize("how", ["kill -9", "exit"])
def test_the_child_ends_with_its_node(how: str, tmp_path: Path) -> None:
    """A node killed with SIGKILL, or one that exits without closing anything, leaves no
    identify process behind."""
    script = textwrap.dedent(
        f"""
        import os, signal, sys, time
        from genbacklash_core import WindowedIdentifier
        from genbacklash_ros.node.identify_process import ProcessWorker
        worker = ProcessWorker(WindowedIdentifier(3))
        worker.flush()
        print(worker._process.pid, flush=True)
        if {how == "kill -9"!r}:
            os.kill(os.getpid(), signal.SIGKILL)
        os._exit(0)
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    child = int(out.stdout.split()[0])
    deadline = time.monotonic() + 10
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(child), f"the identify process {child} outlived its node ({how})"
    assert "Traceback" not in out.stderr
