"""The identify stage off the message path (issue 15 item 4).

No timing here: a stand-in identifier that blocks inside ``update_many`` until the test lets
it go shows that, with the thread worker, every command is answered while a refit is under
way (with the synchronous worker the first feed would never return), that the batches handed
over meanwhile reach the identifier in one call (no queue grows), and that the estimate is
taken up once it is ready. Replay's determinism is in tests/ros/bags/test_replay.py.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any

import numpy as np
import pytest

from genbacklash_core import Estimate, EstimatorState, GenBacklashError, Structure, paper_example
from genbacklash_ros.node.identify import (
    Identified,
    IdentifyThread,
    Refused,
    Skipped,
    SyncWorker,
    ThreadWorker,
)
from genbacklash_ros.node.messages import Float64
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline, Output

MS = 1_000_000
TRUTH = paper_example(1).model
FLOATS = NodeParameters(command_type="float64", encoder_type="float64")
WAIT_S = 30.0  # a safety net only: the tests never wait this long unless they fail


class GatedIdentifier:
    """An online identifier whose ``update_many`` blocks until :attr:`gate` is set (a refit
    that takes as long as the test wants); then its estimate is the truth, converged."""

    def __init__(self, fail: bool = False) -> None:
        self.gate = threading.Event()
        self.entered = threading.Event()
        self.calls: list[tuple[int, bool]] = []  # (samples, breaks[0]) per call
        self.fail = fail
        self._estimate = Estimate.empty(Structure(3))

    @property
    def estimate(self) -> Estimate:
        return self._estimate

    @property
    def from_seed(self) -> bool:
        return False

    def update_many(self, u: Any, y: Any, breaks: Any = None) -> Estimate:
        self.entered.set()
        assert self.gate.wait(WAIT_S), "the test never opened the gate"
        self.calls.append((int(np.size(u)), bool(np.asarray(breaks)[0])))
        if self.fail and len(self.calls) == 1:
            raise GenBacklashError("singular regression")
        structure = Structure(3)
        self._estimate = Estimate(
            structure,
            TRUTH.parameters(),
            np.eye(8) * 1e-8,
            0.01,
            1.0,
            EstimatorState.CONVERGED,
            1.0,
            sum(n for n, _ in self.calls),
        )
        return self._estimate


def drive(pipe: BacklashPipeline, start: int, stop: int) -> list[Output]:
    """A 1 kHz command and encoder stream (the command a slow sine, the reading follows)."""
    outputs: list[Output] = []
    for k in range(start, stop):
        u = 1.5 * np.sin(k / 300.0)
        outputs += pipe.on_command(Float64(float(u)), k * MS)
        outputs += pipe.on_encoder(Float64(float(u) * 0.5), k * MS)
    return outputs


def sent(outputs: list[Output]) -> list[float]:
    return [o.message.data for o in outputs if o.topic == "compensated_command"]  # type: ignore[union-attr]


def test_a_blocked_refit_does_not_hold_up_compensated_commands() -> None:
    ident = GatedIdentifier()
    pipe = BacklashPipeline(FLOATS, worker=lambda _: ThreadWorker(ident))  # type: ignore[arg-type]
    try:
        outputs = drive(pipe, 1, 201)  # the first batches handed over
        # the worker thread takes the first batch when the scheduler runs it (no timing
        # assumed); from then on it blocks, and the handlers go on without it
        assert ident.entered.wait(WAIT_S), "the worker never started the first batch"
        outputs += drive(pipe, 201, 2001)  # 2 s in all: ~30 batches handed over
        assert ident.entered.is_set() and not ident.gate.is_set()  # still in the first call
        assert len(sent(outputs)) == 2000  # every command answered meanwhile
        assert not pipe.estimate.available  # nothing adopted before it is ready
        ident.gate.set()
        pipe.finish(refit=False)
        # the first batch, then everything queued meanwhile in one call (no queue grew), then
        # perhaps finish's last samples on their own
        assert 2 <= len(ident.calls) <= 3 and ident.calls[1][0] > 20 * 64
        assert pipe.stats.samples == sum(n for n, _ in ident.calls)
        assert pipe.estimate.state is EstimatorState.CONVERGED
        later = sent(drive(pipe, 2001, 2101))
        raw = [1.5 * np.sin(k / 300.0) for k in range(2001, 2101)]
        assert not np.allclose(later, raw)  # compensated with the adopted model
    finally:
        ident.gate.set()
        pipe.close()


def test_the_synchronous_worker_identifies_before_the_handler_returns() -> None:
    """The reference the thread worker is compared with (and replay's worker)."""
    ident = GatedIdentifier()
    ident.gate.set()
    pipe = BacklashPipeline(FLOATS, worker=lambda _: SyncWorker(ident))  # type: ignore[arg-type]
    drive(pipe, 1, 200)
    assert ident.calls and pipe.stats.samples == sum(n for n, _ in ident.calls)
    assert pipe.estimate.state is EstimatorState.CONVERGED


@pytest.mark.parametrize("worker", [SyncWorker, ThreadWorker])
def test_after_a_refused_batch_the_next_sample_breaks(worker: Any) -> None:
    ident = GatedIdentifier(fail=True)
    ident.gate.set()
    run = worker(ident)
    try:
        follows = np.zeros(5, dtype=bool)
        run.submit(np.zeros(5), np.zeros(5), follows)
        run.flush()
        run.submit(np.zeros(5), np.zeros(5), follows)
        run.flush()
        results = run.poll()
        assert [type(r) for r in results] == [Refused, Identified]
        assert isinstance(results[0], Refused) and "singular" in results[0].reason
        assert ident.calls == [(5, False), (5, True)]
    finally:
        run.close()


def test_a_worker_far_behind_lets_the_oldest_batches_go() -> None:
    ident = GatedIdentifier()
    run = ThreadWorker(ident, max_backlog=130)
    try:
        follows = np.zeros(40, dtype=bool)
        run.submit(np.zeros(40), np.zeros(40), follows)
        assert ident.entered.wait(WAIT_S)  # the worker holds the first batch
        for _ in range(4):  # 160 samples queued behind it: the oldest 40 go
            run.submit(np.zeros(40), np.zeros(40), follows)
        ident.gate.set()
        run.flush()
        results = run.poll()
        assert [type(r) for r in results] == [Skipped, Identified, Identified]
        assert results[0].samples == 40
        assert ident.calls == [(40, False), (120, True)]  # the gap breaks the chain
    finally:
        ident.gate.set()
        run.close()


class Boom(GatedIdentifier):
    """Raises what no identifier should (a bug), on its first call."""

    def update_many(self, u: Any, y: Any, breaks: Any = None) -> Estimate:
        if not self.calls:
            self.calls.append((int(np.size(u)), True))
            raise RuntimeError("a bug")
        return super().update_many(u, y, breaks)


def test_workers_on_one_thread_take_turns_and_a_bug_in_one_stops_none() -> None:
    """Six joints' live workers share one thread (a cold start of six, each on its own
    thread, starved the message thread of the interpreter lock): while one worker's
    identifier is busy the other's batch waits for its turn; an exception from one
    identifier is that worker's Refused result, and the thread goes on for both."""
    thread = IdentifyThread("test-identify")
    slow, broken = GatedIdentifier(), Boom()
    first = ThreadWorker(slow, thread=thread)
    second = ThreadWorker(broken, thread=thread)
    try:
        ones = np.ones(4)
        first.submit(ones, ones, np.array([True, False, False, False]))
        assert slow.entered.wait(WAIT_S)
        second.submit(ones, ones, np.array([True, False, False, False]))
        assert not second.poll() and broken.calls == []  # waits for its turn
        slow.gate.set()
        first.flush()
        second.flush()
        (done,) = first.poll()
        (refused,) = second.poll()
        assert isinstance(done, Identified) and done.samples == 4
        assert isinstance(refused, Refused) and "RuntimeError: a bug" in refused.reason
        broken.gate.set()
        second.submit(ones, ones, np.array([False, False, False, False]))
        second.flush()
        (after,) = second.poll()
        assert isinstance(after, Identified)
        assert broken.calls[-1] == (4, True)  # the refused batch broke the chain
        assert first._thread is second._thread and thread.thread.is_alive()
    finally:
        first.close(wait=True)
        second.close(wait=True)
        thread.close()


def test_pipeline_rejects_a_worker_that_is_not_callable() -> None:
    with pytest.raises(GenBacklashError, match="worker must make"):
        BacklashPipeline(FLOATS, worker=3)  # type: ignore[arg-type]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread niceness is Linux's")
def test_the_identify_thread_runs_below_the_message_thread() -> None:
    """The answers come first: the identify thread's niceness is the process's plus
    IDENTIFY_NICENESS (capped at 19); the calling (message) thread keeps its own."""
    import os

    from genbacklash_ros.node.identify import IDENTIFY_NICENESS

    process = os.getpriority(os.PRIO_PROCESS, 0)
    thread = IdentifyThread("test-nice")
    try:
        tid = thread.thread.native_id
        assert tid is not None

        def lowered() -> bool:
            return os.getpriority(os.PRIO_PROCESS, tid) == min(19, process + IDENTIFY_NICENESS)

        deadline = time.monotonic() + WAIT_S
        while not lowered() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert lowered()
        assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == process
    finally:
        thread.close()
