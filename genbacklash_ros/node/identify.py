"""The identify stage: screened samples in, estimates out, on a worker of its own.

The online identifier (:class:`~genbacklash_core.OnlineIdentifier`) is the one costly step of
the node: a refit of the windowed identifier, or a cold start that keeps failing, takes
milliseconds to seconds. A message handler must not wait for it. So the pipeline hands each
screened batch to a *worker* (:meth:`IdentifierWorker.submit`) and, on every message, takes
what the worker has finished since (:meth:`IdentifierWorker.poll`): :class:`Identified`
results carry the identifier's new estimate, :class:`Refused` ones the samples the
identifier could not take (counted as ``identifier_error`` drops), :class:`Skipped` ones the
samples a worker that fell behind let go (``identifier_behind``).

Two workers, one interface:

* :class:`SyncWorker` identifies a batch when it is submitted, so its result is taken at the
  same sample count on every run: bag replay uses it, and its outputs are the same for the
  same bag (replay is the node, fed from a file, at the speed of the file).
* :class:`ThreadWorker` identifies on a thread of its own. Batches queue up while it works;
  it takes every batch queued at once (one ``update_many`` over them, breaks kept), so a
  slow refit makes the next call bigger, not the queue longer. Live transports use it: a
  compensated command then costs the align, screen and compensate steps only, and uses the
  latest estimate the worker has finished. numpy releases the GIL in its heavy linear
  algebra, but per-sample Python does not; the transports keep the interpreter's switch
  interval short (:data:`SWITCH_INTERVAL_S`) so a message waits at most that long for it.

:class:`EstimateInUse` chooses between the identifier's estimate and a checkpoint's (a warm
start), once per result.

Examples
--------
>>> import numpy as np
>>> from genbacklash_core import WindowedIdentifier
>>> worker = SyncWorker(WindowedIdentifier(3))
>>> worker.submit(np.zeros(3), np.zeros(3), np.array([True, False, False]))
>>> [type(r).__name__ for r in worker.poll()]
['Identified']
>>> worker.poll()
[]
"""

from __future__ import annotations

import os
import sys
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeAlias

import numpy as np

from genbacklash_core import Estimate, EstimatorState, GenBacklashError, OnlineIdentifier

__all__ = [
    "IDENTIFY_NICENESS",
    "MAX_BACKLOG",
    "SWITCH_INTERVAL_S",
    "EstimateInUse",
    "Identified",
    "IdentifierWorker",
    "IdentifyThread",
    "Refused",
    "Result",
    "Skipped",
    "SyncWorker",
    "ThreadWorker",
    "live_worker",
    "lower_this_thread",
]

MAX_BACKLOG = 1 << 18  # samples a thread worker keeps queued at most (4.4 min at 1 kHz)

IDENTIFY_NICENESS = 10
"""How much lower the identify thread runs than the message thread (Linux niceness, added to
the process's): the answers come first. On two cores shared with an echo and a 1 kHz player
(bench/six_joint.py, six joints, 2026-11-27) the node's median reply over its first 5 s was
1.7-2.7x a plain echo's with the identify thread at the process's priority and 1.3-1.5x with
it lowered; identification only waits where the cores are full."""


def lower_this_thread(niceness: int = IDENTIFY_NICENESS) -> bool:
    """Lower the calling thread's scheduling priority by ``niceness`` (capped at 19); Linux
    only (elsewhere a thread id is no process id). Whether it was lowered.

    >>> import threading
    >>> done = []
    >>> t = threading.Thread(target=lambda: done.append(lower_this_thread(3)))
    >>> t.start(); t.join()
    >>> done == [sys.platform == "linux"]
    True
    """
    if not sys.platform.startswith("linux"):
        return False
    tid = threading.get_native_id()
    try:
        now = os.getpriority(os.PRIO_PROCESS, tid)
        os.setpriority(os.PRIO_PROCESS, tid, min(19, now + niceness))
    except OSError:
        return False
    return True


SWITCH_INTERVAL_S = 0.0005  # the interpreter's GIL switch interval the live transports set
IDENTIFIER_ERRORS = (GenBacklashError, ArithmeticError, np.linalg.LinAlgError)


@dataclass(frozen=True, slots=True)
class Identified:
    """The identifier took ``samples`` samples; its estimate is now ``estimate``."""

    estimate: Estimate
    from_seed: bool
    samples: int


@dataclass(frozen=True, slots=True)
class Refused:
    """The identifier raised on ``samples`` samples (what it kept of them is unknown: the
    next sample handed to it breaks the chain)."""

    samples: int
    reason: str


@dataclass(frozen=True, slots=True)
class Skipped:
    """A worker that fell more than :data:`MAX_BACKLOG` samples behind let ``samples`` of
    the oldest go (the next sample breaks the chain)."""

    samples: int
    reason: str


Result: TypeAlias = Identified | Refused | Skipped


class IdentifierWorker(Protocol):
    """Where the identify stage runs (see the module notes)."""

    @property
    def identifier(self) -> OnlineIdentifier:
        """The online identifier (its methods are the worker's to call while it runs)."""
        ...

    def submit(self, us: np.ndarray, ys: np.ndarray, breaks: np.ndarray) -> None:
        """Hand over a batch of samples (``breaks[0]`` refers to the last one before)."""
        ...

    def poll(self) -> list[Result]:
        """The results finished since the last call, oldest first (never waits)."""
        ...

    def flush(self) -> None:
        """Wait until every batch handed over is identified."""
        ...

    def refit(self) -> Result | None:
        """Flush, then refit the identifier on what it holds (None when it cannot refit)."""
        ...

    def close(self) -> None:
        """Stop the worker (what is queued is not identified)."""
        ...


class _Identify:
    """The identifier and the one rule both workers share: after a refused batch, the next
    sample breaks the chain."""

    def __init__(self, identifier: OnlineIdentifier) -> None:
        self.identifier = identifier
        self._broken = False

    def update(self, us: np.ndarray, ys: np.ndarray, breaks: np.ndarray) -> Result:
        if self._broken and breaks.size:
            breaks = breaks.copy()
            breaks[0] = True
        ident = self.identifier
        try:
            ident.update_many(us, ys, breaks=breaks)
        except IDENTIFIER_ERRORS as err:
            self._broken = True
            return Refused(int(us.size), f"identifier: {err}")
        self._broken = False
        return Identified(ident.estimate, ident.from_seed, int(us.size))

    def skipped(self) -> None:
        self._broken = True

    def refit(self) -> Result | None:
        ident = self.identifier
        refit_now = getattr(ident, "refit", None)
        if not callable(refit_now):
            return None
        try:
            refit_now()
        except IDENTIFIER_ERRORS as err:
            return Refused(1, f"identifier: {err}")
        return Identified(ident.estimate, ident.from_seed, 0)


class SyncWorker:
    """Identifies each batch as it is handed over (deterministic: bag replay, tests).

    Parameters
    ----------
    identifier : OnlineIdentifier
    """

    def __init__(self, identifier: OnlineIdentifier) -> None:
        self._run = _Identify(identifier)
        self._results: list[Result] = []

    @property
    def identifier(self) -> OnlineIdentifier:
        """The online identifier."""
        return self._run.identifier

    def submit(self, us: np.ndarray, ys: np.ndarray, breaks: np.ndarray) -> None:
        """Identify the batch now."""
        self._results.append(self._run.update(us, ys, breaks))

    def poll(self) -> list[Result]:
        """The results since the last call."""
        results, self._results = self._results, []
        return results

    def flush(self) -> None:
        """Nothing is ever pending."""

    def refit(self) -> Result | None:
        """Refit now."""
        return self._run.refit()

    def close(self) -> None:
        """Nothing to stop."""


class IdentifyThread:
    """One daemon thread that runs the batches of any number of :class:`ThreadWorker`, one
    worker's at a time, in the order they became ready (round robin under load).

    A live node of several joints has one worker per joint; each on a thread of its own, six
    of them busy in a cold start (the first seconds, when every refit is costly) took the
    interpreter lock in turn with the message thread, which then ran one switch interval in
    seven and fell seconds behind. On one thread they take it in turn with the message thread
    only. :func:`live_worker` puts every live worker of the process on one.
    """

    def __init__(self, name: str = "genbacklash-identify") -> None:
        self._cond = threading.Condition()
        self._ready: deque[ThreadWorker] = deque()
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    @property
    def thread(self) -> threading.Thread:
        return self._thread

    def wake(self, worker: ThreadWorker) -> None:
        """``worker`` has batches queued: run them when its turn comes."""
        with self._cond:
            if worker not in self._ready:
                self._ready.append(worker)
            self._cond.notify()

    def close(self) -> None:
        """End the thread after the batch it may be running."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def _loop(self) -> None:
        lower_this_thread()  # the message thread's answers come first
        cond = self._cond
        while True:
            with cond:
                cond.wait_for(lambda: self._closed or bool(self._ready))
                if self._closed:
                    return
                worker = self._ready.popleft()
            worker._work()


class ThreadWorker:
    """Identifies on a daemon thread (live transports): a thread of its own, or ``thread``,
    an :class:`IdentifyThread` it shares with other workers.

    Parameters
    ----------
    identifier : OnlineIdentifier
        Called from the worker's thread only, while the worker runs.
    max_backlog : int
        Samples kept queued at most; the oldest batches go beyond it (:class:`Skipped`).
    thread : IdentifyThread, optional
        Shared with other workers (closed with them by its owner); default one of its own,
        closed with the worker.
    on_result : callable, optional
        Called with each result, on the thread that made it, instead of keeping it for
        :meth:`poll` (an identify process sends it back at once:
        :mod:`~genbacklash_ros.node.identify_process`). A batch's result is handed over
        before the worker reports itself idle, so it comes before :meth:`flush` returns.

    Examples
    --------
    >>> import numpy as np
    >>> from genbacklash_core import WindowedIdentifier
    >>> worker = ThreadWorker(WindowedIdentifier(3))
    >>> worker.submit(np.zeros(3), np.zeros(3), np.array([True, False, False]))
    >>> worker.flush()
    >>> [r.samples for r in worker.poll()]
    [3]
    >>> worker.close()
    """

    def __init__(
        self,
        identifier: OnlineIdentifier,
        *,
        max_backlog: int = MAX_BACKLOG,
        thread: IdentifyThread | None = None,
        on_result: Callable[[Result], None] | None = None,
    ) -> None:
        if isinstance(max_backlog, bool) or not isinstance(max_backlog, int) or max_backlog < 1:
            raise GenBacklashError(f"max_backlog must be a whole number >= 1, got {max_backlog!r}")
        self._run = _Identify(identifier)
        self._max = max_backlog
        self._queue: deque[tuple[np.ndarray, np.ndarray, np.ndarray]] = deque()
        self._queued = 0  # samples in the queue
        self._busy = False
        self._stop = False
        self._results: deque[Result] = deque()
        self._emit = self._results.append if on_result is None else on_result
        self._cond = threading.Condition()
        self._own = thread is None
        self._thread = IdentifyThread() if thread is None else thread

    @property
    def identifier(self) -> OnlineIdentifier:
        """The online identifier (the worker thread's while it runs)."""
        return self._run.identifier

    def submit(self, us: np.ndarray, ys: np.ndarray, breaks: np.ndarray) -> None:
        """Queue the batch (never waits for the identifier)."""
        with self._cond:
            self._queue.append((us, ys, breaks))
            self._queued += int(us.size)
            skipped = 0
            while self._queued > self._max and len(self._queue) > 1:
                old = self._queue.popleft()
                skipped += int(old[0].size)
                self._queued -= int(old[0].size)
            if skipped:
                self._run.skipped()
                self._emit(Skipped(skipped, f"identifier more than {self._max} samples behind"))
                # the oldest kept batch no longer follows what the identifier saw last
                us0, ys0, b0 = self._queue[0]
                b0 = b0.copy()
                b0[0] = True
                self._queue[0] = (us0, ys0, b0)
        self._thread.wake(self)

    def poll(self) -> list[Result]:
        """The results since the last call (a deque's pops: no lock, no wait)."""
        results = self._results
        out: list[Result] = []
        while results:
            out.append(results.popleft())
        return out

    def flush(self) -> None:
        """Wait until the queue is empty and the identifier idle."""
        with self._cond:
            self._cond.wait_for(lambda: self._stop or (not self._queue and not self._busy))

    def refit(self) -> Result | None:
        """Flush, then refit on the caller's thread (the worker waits meanwhile)."""
        with self._cond:
            self._cond.wait_for(lambda: self._stop or (not self._queue and not self._busy))
            self._busy = True  # nothing is submitted meanwhile: the handler is the caller
        try:
            return self._run.refit()
        finally:
            with self._cond:
                self._busy = False
                self._cond.notify_all()

    def close(self, *, wait: bool = False) -> None:
        """Stop identifying (what is queued is not identified); the call to the identifier
        it may be in finishes (``wait``: wait for that; a restart does not)."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._own:
            self._thread.close()
        if wait and self._thread.thread is not threading.current_thread():
            with self._cond:
                self._cond.wait_for(lambda: not self._busy)

    def _work(self) -> None:
        """Identify everything queued, in one call (on the worker's thread)."""
        cond = self._cond
        with cond:
            if self._stop or not self._queue:
                return
            batches = list(self._queue)
            self._queue.clear()
            self._queued = 0
            self._busy = True
        try:
            if len(batches) == 1:
                us, ys, breaks = batches[0]
            else:
                us = np.concatenate([b[0] for b in batches])
                ys = np.concatenate([b[1] for b in batches])
                breaks = np.concatenate([b[2] for b in batches])
            try:
                result: Result = self._run.update(us, ys, breaks)
            except Exception as err:  # a bug: refused, and the (shared) thread goes on
                self._run.skipped()
                result = Refused(int(us.size), f"identifier: {type(err).__name__}: {err}")
            with cond:
                self._emit(result)
        finally:
            with cond:
                self._busy = False
                cond.notify_all()


_LIVE_THREAD: IdentifyThread | None = None
_LIVE_LOCK = threading.Lock()


def live_worker(identifier: OnlineIdentifier) -> ThreadWorker:
    """The worker of a live transport: a :class:`ThreadWorker` on the process's one live
    :class:`IdentifyThread` (every joint's, every restart's), with the interpreter's GIL
    switch interval at most :data:`SWITCH_INTERVAL_S` (process-wide), so that a message
    handler waiting for the GIL while the worker runs per-sample Python waits at most that
    long (the default, 5 ms, would be half the latency budget).

    >>> from genbacklash_core import WindowedIdentifier
    >>> worker = live_worker(WindowedIdentifier(3))
    >>> sys.getswitchinterval() <= SWITCH_INTERVAL_S
    True
    >>> live_worker(WindowedIdentifier(2))._thread is worker._thread  # one thread for all
    True
    >>> worker.close()
    """
    global _LIVE_THREAD
    if sys.getswitchinterval() > SWITCH_INTERVAL_S:
        sys.setswitchinterval(SWITCH_INTERVAL_S)
    with _LIVE_LOCK:
        if _LIVE_THREAD is None:
            _LIVE_THREAD = IdentifyThread("genbacklash-identify-live")
        thread = _LIVE_THREAD
    return ThreadWorker(identifier, thread=thread)


class EstimateInUse:
    """The estimate the node uses: the identifier's, or a checkpoint's (``prior``) until
    the identifier's own has converged or is at least as confident.

    Decided once per result (:meth:`adopt`): between results the identifier's estimate does
    not change.

    >>> from genbacklash_core import Structure
    >>> use = EstimateInUse(Estimate.empty(Structure(3)), prior=None, from_seed=False)
    >>> use.current.available, use.using_checkpoint
    (False, False)
    """

    __slots__ = ("_from_seed", "_own", "_prior", "current")

    def __init__(self, own: Estimate, prior: Estimate | None, from_seed: bool) -> None:
        self._prior = prior
        self.adopt(own, from_seed)

    def adopt(self, own: Estimate, from_seed: bool) -> None:
        """The identifier's estimate is now ``own`` (``from_seed``: still leaning on the
        checkpoint it was seeded from)."""
        self._own = own
        self._from_seed = from_seed
        prior = self._prior
        if prior is not None and (
            own.available
            and (own.state is EstimatorState.CONVERGED or own.confidence >= prior.confidence)
        ):
            self._prior = prior = None  # the identifier's estimate from now on
        self.current: Estimate = own if prior is None else prior

    @property
    def own(self) -> Estimate:
        """The identifier's latest estimate."""
        return self._own

    @property
    def on_prior(self) -> bool:
        """True while the checkpoint's estimate stands in for the identifier's."""
        return self._prior is not None

    @property
    def using_checkpoint(self) -> bool:
        """True while the estimate rests on the checkpoint: it stands in for the
        identifier's, or the identifier continues from it and still leans on it."""
        return self._prior is not None or self._from_seed
