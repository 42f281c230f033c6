"""A bag's messages read one block ahead in a child process (the reading on a second core).

:class:`PrefetchedMessages` gives what :meth:`BagReader.raw_messages
<genbacklash_ros.bags.bagio.BagReader.raw_messages>` gives (the same messages in the same
order, then the same :class:`~genbacklash_ros.bags.bagio.BagError` at a damage), read by a
child process with its own :class:`~genbacklash_ros.bags.bagio.BagReader` of the same bag
while this process works on the previous block. Each block crosses a
:func:`multiprocessing.Pipe` as one pickle of four columns (topics, log times, types, bytes:
strings repeated are pickled once), taken apart again with :func:`zip`; at most the block
in the pipe and the one being read are ahead (the pipe's writer waits for its reader).

The child is forked (multiprocessing's ``fork``: nothing imported or opened again, it
starts in milliseconds), and only from a process that runs one thread: a fork copies only
the calling thread, and a lock another thread holds stays locked in the child.
:func:`can_prefetch` says whether that holds here; it does not (and the caller reads in
process) with more threads than one (e.g. OpenBLAS's, a progress bar's, a ROS executor's),
in a daemonic process (multiprocessing allows it no children: ``genbacklash fleet``'s
workers), on one CPU, where the OS does not list a process's threads (only Linux's
``/proc`` is read), or when the environment variable ``GENBACKLASH_PREFETCH`` is ``0``.
Nor, unless that variable is ``1``, when no CPU is free: when the 1-minute load average
(this process included) is at least the number of CPUs this process may run on. A child
pays only on a free core (BENCHMARKS.md "Rerun 2026-11-28 (evening), branch prefetch-1": up
to 0.5 s less wall time on a 300 s bag); on a saturated machine it competes with the replay
itself (0.1-0.3 s more wall time, 0.2-0.3 s more CPU).

``spawn`` and ``forkserver`` are not used: their child imports the readers again (~0.25 s
of CPU) and first runs the caller's main script again, which a script without a
``__main__`` guard does not survive.

The child ignores SIGINT (Ctrl-C is the parent's to handle) and ends quietly when the pipe
closes: when the parent closes it (:meth:`PrefetchedMessages.close`) or dies, its next send
fails. It is a daemonic process, so the parent's exit ends it at the latest.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import pickle
import signal
import threading
from collections.abc import Iterator, Sequence
from multiprocessing.connection import Connection
from pathlib import Path

from genbacklash_ros.bags.bagio import BagError, BagReader, RawMessage, RawRecord

__all__ = ["ENV", "PrefetchedMessages", "can_prefetch"]

ENV = "GENBACKLASH_PREFETCH"
"""``0``: read in process wherever :func:`can_prefetch` is asked; ``1``: fork a reading
child wherever that is safe, whatever the load."""

_PIPE_BYTES = 1 << 20  # a block of 8192 messages of ~100 bytes pickled: about 0.9 MB
_STOP_WAIT = 2.0  # seconds the parent waits for the child to end before terminating it


def _threads() -> int | None:
    """Threads of this process, native ones too (None where the OS does not tell)."""
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return None


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _load() -> float:
    """The 1-minute load average (0 where the OS does not tell)."""
    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return 0.0


def can_prefetch() -> bool:
    """Whether a reading child process should be forked here now (see the module's notes)."""
    wish = os.environ.get(ENV, "").strip()
    if wish == "0":
        return False
    cpus = _cpus()
    if multiprocessing.current_process().daemon or cpus < 2:
        return False
    if "fork" not in multiprocessing.get_all_start_methods():
        return False
    if _threads() != 1 or threading.active_count() != 1:
        return False
    return wish == "1" or _load() < cpus


def _widen(conn: Connection) -> None:
    """Make the pipe under ``conn`` hold a whole block where the OS allows (Linux: up to
    ``/proc/sys/fs/pipe-max-size``): a block then crosses in one write and one read, not in
    64 KiB turns of the two processes."""
    try:
        import fcntl

        fcntl.fcntl(conn.fileno(), fcntl.F_SETPIPE_SZ, _PIPE_BYTES)
    except (ImportError, AttributeError, OSError):  # not Linux, or a lower limit: as it is
        pass


def _send_blocks(reader: BagReader, topics: list[str], size: int, conn: Connection) -> None:
    """Blocks of ``size`` messages down ``conn``: ``(columns, None)`` each (the last one
    shorter), then ``(columns, why)`` at a damage (the messages before it in ``columns``,
    ``why`` the error's text or the exception itself) or ``(None, None)`` at the end."""
    stream = reader.raw_messages(topics)
    while True:
        block: list[RawMessage] = []
        why: object = None
        try:
            block.extend(itertools.islice(stream, size))
        except BagError as err:
            why = str(err)
        except Exception as err:  # not a damage: the parent raises it (as in process)
            why = err
        if not block and why is None:
            conn.send_bytes(pickle.dumps((None, None), pickle.HIGHEST_PROTOCOL))
            return
        columns = tuple(zip(*block, strict=True)) if block else ((), (), (), ())
        try:
            data = pickle.dumps((columns, why), pickle.HIGHEST_PROTOCOL)
        except Exception:  # an exception that does not pickle: its text
            data = pickle.dumps((columns, f"{type(why).__name__}: {why}"), pickle.HIGHEST_PROTOCOL)
        conn.send_bytes(data)
        if why is not None:
            return


def _child(path: str, topics: list[str], size: int, conn: Connection, other: Connection) -> None:
    """The child process: read ``path`` and send its blocks until done or the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the parent stops, then the pipe
    other.close()  # the parent's end (a fork copies it): the parent's exit must close it
    try:
        try:
            with BagReader(path) as reader:
                _send_blocks(reader, topics, size, conn)
        except BagError as err:  # the bag does not open here
            conn.send_bytes(pickle.dumps((((), (), (), ()), str(err)), pickle.HIGHEST_PROTOCOL))
    except (BrokenPipeError, ConnectionError, EOFError, OSError):
        pass  # the parent went away: nothing to say
    finally:
        conn.close()


class PrefetchedMessages:
    """The messages of ``BagReader(path).raw_messages(topics)``, read by a child process
    one block ahead of the caller.

    Parameters
    ----------
    path : str or Path
        The bag (opened again in the child).
    topics : sequence of str
        The topics to read (checked by the caller's reader beforehand).
    block : int
        Messages per block the child sends.

    Notes
    -----
    The child is forked at construction (ask :func:`can_prefetch` first). Iterate once,
    and :meth:`close` (also a context manager) in every case: it closes the pipe and waits
    for the child (one that does not end within a few seconds is terminated). Iteration
    yields :data:`~genbacklash_ros.bags.bagio.RawRecord` tuples (equal to the in-process
    reader's :class:`~genbacklash_ros.bags.bagio.RawMessage`\\ s) and raises the same
    :class:`~genbacklash_ros.bags.bagio.BagError` text at a damage, after the messages read
    before it.
    """

    def __init__(self, path: str | Path, topics: Sequence[str], block: int) -> None:
        context = multiprocessing.get_context("fork")
        self._conn, child_end = context.Pipe(duplex=False)
        _widen(self._conn)
        self._process = context.Process(
            target=_child,
            args=(str(path), list(topics), block, child_end, self._conn),
            name="genbacklash-prefetch",
            daemon=True,
        )
        try:
            self._process.start()
        finally:
            child_end.close()  # the child's now: its end (EOF here when the child ends)

    def __enter__(self) -> PrefetchedMessages:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __iter__(self) -> Iterator[RawRecord]:
        # each block's messages by zip, chained in C: no Python frame per message
        return itertools.chain.from_iterable(self._blocks())

    def _blocks(self) -> Iterator[Iterator[RawRecord]]:
        """Each block's messages (then the damage's error, raised when they are taken)."""
        conn = self._conn
        while True:
            try:
                data = conn.recv_bytes()
            except (EOFError, OSError) as err:
                self._process.join(_STOP_WAIT)
                code = self._process.exitcode
                raise BagError(
                    f"the process reading the bag stopped before the end (exit code {code})"
                ) from err
            columns, why = pickle.loads(data)
            if columns is None:
                return
            yield zip(*columns, strict=True)
            if isinstance(why, BaseException):
                raise why
            if why is not None:
                raise BagError(why)

    def close(self) -> None:
        """Close the pipe and wait for the child to end (idempotent)."""
        self._conn.close()
        process = self._process
        if process.pid is None:
            return
        process.join(_STOP_WAIT)
        if process.exitcode is None:  # still reading a block after its send failed: stop it
            process.terminate()
            process.join()
