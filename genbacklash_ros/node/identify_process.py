"""The identify stage in a process of its own: a message never waits for the identifier.

:class:`~genbacklash_ros.node.identify.ThreadWorker` keeps the identifier off the message
thread, but not off its interpreter lock. On a machine whose cores are full (two cores, a
1 kHz player and an echo beside the node: ``bench/six_joint.py``), the identify thread is
preempted while it holds the lock, and the message thread then waits for it to be scheduled
again: stalls of 8-87 ms, 1.6-4 a second, the whole of the node's p99 tail over a plain
echo's (BENCHMARKS.md, "Six joints through one node"). Lowering the identify thread's
priority makes the wait longer (it is the textbook priority inversion), and a real-time
message thread stalled for half a second on it. The answer has to be outside the lock.

:class:`ProcessWorker` has the same interface as the thread worker
(:class:`~genbacklash_ros.node.identify.IdentifierWorker`) and runs the identifier in a
child process (:class:`IdentifyProcess`, one per node for every joint and restart): the
message thread hands each batch over a socket without waiting (what the socket cannot take
yet waits in the worker's outbox) and takes the results when it next polls. In the child, a
:class:`~genbacklash_ros.node.identify.ThreadWorker` per identifier runs the batches exactly
as it runs them in the node, so what is identified, skipped and refused is the same.

The child is started with ``start_new_session`` (a Ctrl-C in a terminal reaches the node
only, which ends it) and ignores SIGINT; it ends when its socket closes, so it ends with the
node however the node ends, ``kill -9`` included. If it ends first, every batch handed over
since is refused with the reason (an ``identifier_error`` drop in the diagnostics) and the
node keeps answering on its last estimate.

Examples
--------
>>> import numpy as np
>>> from genbacklash_core import WindowedIdentifier
>>> worker = ProcessWorker(WindowedIdentifier(3))
>>> worker.submit(np.zeros(3), np.zeros(3), np.array([True, False, False]))
>>> worker.flush()
>>> [type(r).__name__ for r in worker.poll()], worker.identifier.estimate.samples
(['Identified'], 3)
>>> worker.close()
"""

from __future__ import annotations

import atexit
import os
import pickle
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from genbacklash_core import GenBacklashError, OnlineIdentifier
from genbacklash_ros.node.identify import (
    SWITCH_INTERVAL_S,
    IdentifyThread,
    Refused,
    Result,
    Skipped,
    ThreadWorker,
)

__all__ = ["IdentifyProcess", "ProcessWorker", "process_worker", "serve"]

_HEADER = struct.Struct("!Q")  # each frame: its length, then a pickle
_BUFFER = 4 << 20  # socket buffers asked for (the kernel caps them at net.core.*mem_max)
POLL_NS = 1_000_000
"""The socket is read at most once per this much time while results are awaited: polling
is asked on every message of every joint (thousands a second) and a result a millisecond
later changes nothing."""
MAX_OUTBOX = 64 << 20
"""Bytes kept waiting for a child that takes nothing (stopped, hung); batches beyond are
let go (:class:`~genbacklash_ros.node.identify.Skipped`) and the next one sent breaks the
chain."""
REPLY_TIMEOUT_S = 30.0  # flush, refit, snapshot: the longest wait for the child's reply


@dataclass
class _Channel:
    """What :class:`IdentifyProcess` keeps for one worker: the results come back into it,
    and its counts say what the child still owes."""

    key: int
    results: deque[Result] = field(default_factory=deque)
    awaited: int = 0  # samples handed over and not yet answered
    broken: bool = False  # a batch was let go: the next one sent breaks the chain


def _frame(obj: object) -> bytes:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(len(data)) + data


class IdentifyProcess:
    """One child process that identifies for any number of :class:`ProcessWorker`.

    Thread-safe (one lock); the node calls it from its message thread, and from its main
    thread when it shuts down.
    """

    def __init__(self) -> None:
        ours, theirs = socket.socketpair()
        for sock in (ours, theirs):
            for opt in (socket.SO_SNDBUF, socket.SO_RCVBUF):
                sock.setsockopt(socket.SOL_SOCKET, opt, _BUFFER)
        env = dict(os.environ)
        # one BLAS thread, as in the node (genbacklash_ros.blas_threads), from the start
        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env[name] = "1"
        fd = theirs.fileno()
        code = (
            "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
            "from genbacklash_ros.node.identify_process import serve\n"
            f"serve({fd})\n"
        )
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-c", code],
                pass_fds=(fd,),
                start_new_session=True,
                stdin=subprocess.DEVNULL,
                env=env,
            )
        except OSError as err:
            ours.close()
            raise GenBacklashError(f"cannot start the identify process: {err}") from err
        finally:
            theirs.close()
        ours.setblocking(False)
        self._sock = ours
        self._lock = threading.RLock()
        self._out = bytearray()
        self._in = bytearray()
        self._channels: dict[int, _Channel] = {}
        self._next_key = 0
        self._next_token = 0
        self._replies: dict[int, object] = {}
        self._last_pump = 0
        self._dead: str | None = None

    @property
    def pid(self) -> int:
        """The child's process id."""
        return int(self._proc.pid)

    @property
    def dead(self) -> str | None:
        """Why the child no longer identifies (None while it does)."""
        return self._dead

    # -------------------------------------------------------------- workers' calls

    def register(self, identifier: OnlineIdentifier) -> _Channel:
        """Start identifying with ``identifier`` in the child; its results come back into
        the returned channel."""
        with self._lock:
            channel = _Channel(self._next_key)
            self._next_key += 1
            self._channels[channel.key] = channel
            self._send(("new", channel.key, identifier))
            return channel

    def unregister(self, channel: _Channel) -> None:
        with self._lock:
            if self._channels.pop(channel.key, None) is not None:
                self._send(("close", channel.key))
                self._pump()

    def submit(self, channel: _Channel, us: np.ndarray, ys: np.ndarray, b: np.ndarray) -> None:
        with self._lock:
            n = int(us.size)
            if self._dead is not None:
                channel.results.append(Refused(n, f"identifier: {self._dead}"))
                return
            if len(self._out) > MAX_OUTBOX:  # the child takes nothing: let this batch go
                channel.results.append(
                    Skipped(n, f"identify process behind by more than {MAX_OUTBOX} bytes")
                )
                channel.broken = True
                return
            if channel.broken and b.size:  # the batch no longer follows the last one sent
                b = b.copy()
                b[0] = True
                channel.broken = False
            channel.awaited += n
            self._send(("batch", channel.key, us, ys, b))

    def pump_soon(self) -> None:
        """Read what came back, unless the socket was read less than :data:`POLL_NS` ago."""
        now = time.monotonic_ns()
        if now - self._last_pump >= POLL_NS:
            with self._lock:
                self._last_pump = now
                self._pump()

    def call(self, key: int, request: str) -> object:
        """Send ``request`` for worker ``key`` and wait for the child's reply."""
        with self._lock:
            if self._dead is not None:
                raise GenBacklashError(f"identifier: {self._dead}")
            token = self._next_token
            self._next_token += 1
            self._send((request, key, token))
            deadline = time.monotonic() + REPLY_TIMEOUT_S
            while token not in self._replies:
                self._pump()
                if self._dead is not None:
                    raise GenBacklashError(f"identifier: {self._dead}")
                if token in self._replies:
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    raise GenBacklashError(
                        f"the identify process did not answer {request!r} in {REPLY_TIMEOUT_S:g} s"
                    )
                want_write = [self._sock] if self._out else []
                select.select([self._sock], want_write, [], min(left, 0.1))
            return self._replies.pop(token)

    def close(self) -> None:
        """End the child (it ends when its socket closes) and wait for it briefly."""
        with self._lock:
            if self._sock.fileno() < 0:
                return
            self._sock.close()
            if self._dead is None:
                self._dead = "the identify process was closed"
        try:
            self._proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()

    # -------------------------------------------------------------- the socket

    def _send(self, obj: object) -> None:
        if self._dead is not None:
            return
        self._out += _frame(obj)
        self._write()

    def _write(self) -> None:
        out = self._out
        while out:
            try:
                sent = self._sock.send(out)
            except BlockingIOError:
                return
            except OSError as err:
                self._died(self._why_gone(err))
                return
            del out[:sent]

    def _pump(self) -> None:
        if self._dead is not None:
            return
        if self._out:
            self._write()
        sock, buf = self._sock, self._in
        while True:
            try:
                data = sock.recv(1 << 20)
            except BlockingIOError:
                break
            except OSError as err:
                self._died(self._why_gone(err))
                return
            if not data:
                self._died(self._why_gone(None))
                return
            buf += data
        view = 0
        size = _HEADER.size
        while len(buf) - view >= size:
            (length,) = _HEADER.unpack_from(buf, view)
            if len(buf) - view - size < length:
                break
            message = pickle.loads(bytes(buf[view + size : view + size + length]))
            view += size + length
            self._take(message)
        if view:
            del buf[:view]

    def _take(self, message: tuple[Any, ...]) -> None:
        kind = message[0]
        if kind == "result":
            _, key, result = message
            channel = self._channels.get(key)
            if channel is not None:
                channel.awaited -= min(int(result.samples), channel.awaited)
                channel.results.append(result)
        elif kind == "reply":
            _, token, value = message
            self._replies[token] = value

    def _why_gone(self, err: OSError | None) -> str:
        # never waits: this runs on the node's message thread (an exit code not yet reaped
        # is simply not named)
        code = self._proc.poll()
        if code is None:
            return f"the identify process stopped answering ({err or 'its socket closed'})"
        return f"the identify process ended (exit code {code})"

    def _died(self, reason: str) -> None:
        self._dead = reason
        self._out.clear()
        for channel in self._channels.values():
            if channel.awaited:
                channel.results.append(Refused(channel.awaited, f"identifier: {reason}"))
                channel.awaited = 0


class ProcessWorker:
    """Identifies in a child process (see the module notes); the interface of
    :class:`~genbacklash_ros.node.identify.ThreadWorker`.

    Parameters
    ----------
    identifier : OnlineIdentifier
        Sent to the child (pickled); this process keeps no live copy.
    process : IdentifyProcess, optional
        Shared with other workers; default the process's one (:func:`shared_process`).
    """

    def __init__(self, identifier: OnlineIdentifier, *, process: IdentifyProcess | None = None):
        self._process = shared_process() if process is None else process
        self._initial = identifier
        self._closed = False
        self._channel = self._process.register(identifier)

    @property
    def identifier(self) -> OnlineIdentifier:
        """A copy of the child's identifier as it is once everything handed over is
        identified (it waits for that); the identifier it started from when the child is
        gone. Changing the copy changes nothing in the child."""
        if self._closed or self._process.dead is not None:
            return self._initial
        return cast(OnlineIdentifier, self._process.call(self._channel.key, "snapshot"))

    def submit(self, us: np.ndarray, ys: np.ndarray, breaks: np.ndarray) -> None:
        """Hand the batch over (never waits for the identifier)."""
        self._process.submit(self._channel, us, ys, breaks)

    def poll(self) -> list[Result]:
        """The results that came back since the last call (never waits)."""
        if self._channel.awaited:
            self._process.pump_soon()
        results = self._channel.results
        if not results:
            return []
        out: list[Result] = []
        while results:
            out.append(results.popleft())
        return out

    def flush(self) -> None:
        """Wait until everything handed over is identified (its results come with the next
        :meth:`poll`)."""
        if self._closed or self._process.dead is not None:
            return
        try:
            self._process.call(self._channel.key, "flush")
        except GenBacklashError:
            return  # the child is gone: what was awaited is refused (see poll)

    def refit(self) -> Result | None:
        """Flush, then refit the child's identifier on what it holds."""
        if self._closed:
            return None
        try:
            reply = self._process.call(self._channel.key, "refit")
        except GenBacklashError as err:
            return Refused(1, str(err))
        return cast("Result | None", reply)

    def close(self, *, wait: bool = False) -> None:
        """Stop identifying (what is queued in the child is not identified)."""
        if self._closed:
            return
        self._closed = True
        self._process.unregister(self._channel)


_SHARED: IdentifyProcess | None = None
_SHARED_LOCK = threading.Lock()


def shared_process() -> IdentifyProcess:
    """The process's one :class:`IdentifyProcess` (started on first use; a new one if the
    last has ended; closed when the interpreter exits)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is None or _SHARED.dead is not None:
            _SHARED = IdentifyProcess()
            atexit.register(_SHARED.close)
        return _SHARED


def process_worker(identifier: OnlineIdentifier) -> ProcessWorker:
    """The worker of a live transport that identifies in a child process: a
    :class:`ProcessWorker` on the process's one :class:`IdentifyProcess`."""
    return ProcessWorker(identifier)


# ------------------------------------------------------------------ the child


def _read_exactly(sock: socket.socket, n: int) -> bytes | None:
    chunks = bytearray()
    while len(chunks) < n:
        data = sock.recv(n - len(chunks))
        if not data:
            return None
        chunks += data
    return bytes(chunks)


def serve(fd: int) -> None:
    """The child's main loop: take requests on the socket ``fd`` until it closes."""
    from genbacklash_ros.blas_threads import one_blas_thread

    sock = socket.socket(fileno=fd)
    sock.setblocking(True)
    lock = threading.Lock()

    def send(obj: object) -> None:
        data = _frame(obj)
        with lock:
            try:
                sock.sendall(data)
            except OSError:
                pass  # the node is gone; the receive loop ends on its own

    def sender(key: int) -> Callable[[Result], None]:
        return lambda result: send(("result", key, result))

    sys.setswitchinterval(SWITCH_INTERVAL_S)  # replies and batches are taken between fits
    thread = IdentifyThread("genbacklash-identify-child")
    workers: dict[int, ThreadWorker] = {}
    with one_blas_thread():
        while True:
            try:
                header = _read_exactly(sock, _HEADER.size)
                if header is None:
                    break
                body = _read_exactly(sock, _HEADER.unpack(header)[0])
            except OSError:
                break
            if body is None:
                break
            message = pickle.loads(body)
            kind, key = message[0], message[1]
            if kind == "new":
                # each result goes back the moment it is made
                workers[key] = ThreadWorker(message[2], thread=thread, on_result=sender(key))
            elif kind == "batch":
                workers[key].submit(message[2], message[3], message[4])
            elif kind == "close":
                worker = workers.pop(key, None)
                if worker is not None:
                    worker.close()
            elif kind in ("flush", "snapshot", "refit"):
                token = message[2]
                worker = workers[key]
                if kind == "refit":
                    value: object = worker.refit()
                else:
                    worker.flush()
                    value = worker.identifier if kind == "snapshot" else None
                send(("reply", token, value))
    thread.close()
    for worker in workers.values():
        worker.close()
    sock.close()


if __name__ == "__main__":  # pragma: no cover - started by IdentifyProcess with -c
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    serve(int(sys.argv[1]))
