"""Checkpoint writes on a background thread, for the live transports.

:func:`~genbacklash_ros.node.checkpoint.save_checkpoint` fsyncs the file and its directory, which
can take tens of milliseconds; a node's message loop should not wait for it.
:class:`BackgroundCheckpointWriter` is a ``checkpoint_writer`` for
:class:`~genbacklash_ros.node.pipeline.BacklashPipeline`: each call hands the checkpoint to a
writer thread and returns at once. Only the newest pending checkpoint is written (an older
one not yet written is superseded). :meth:`BackgroundCheckpointWriter.close` writes what is
pending and stops the thread: call it after ``pipeline.finish()`` so that the final
checkpoint is on disk before the process exits.

Examples
--------
>>> import tempfile, numpy as np
>>> from genbacklash_core import Estimate, Structure, paper_example
>>> from genbacklash_ros.node.checkpoint import Checkpoint, load_checkpoint
>>> est = Estimate(Structure(3), paper_example(1).model.parameters(), np.eye(8), 0.0, 1.0,
...                "converged", 1.0, 9)
>>> with tempfile.TemporaryDirectory() as tmp:
...     writer = BackgroundCheckpointWriter()
...     writer(f"{tmp}/cp.json", Checkpoint(est, 5))
...     writer.close()
...     load_checkpoint(f"{tmp}/cp.json").time_ns, writer.written, writer.errors
(5, 1, 0)
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

from genbacklash_ros.node.checkpoint import Checkpoint, CheckpointError, save_checkpoint

__all__ = ["BackgroundCheckpointWriter"]

_LOG = logging.getLogger("genbacklash.node")


class BackgroundCheckpointWriter:
    """Write checkpoints on a daemon thread; the newest pending one wins.

    Parameters
    ----------
    save : callable
        ``save(path, checkpoint)``; default :func:`~genbacklash_ros.node.checkpoint.save_checkpoint`
        (atomic: temp file, fsync, rename).
    on_error : callable, optional
        Called with the reason when a write fails (default: logged as a warning).

    Attributes
    ----------
    written, errors : int
        Checkpoints written and failed so far.
    """

    def __init__(
        self,
        save: Callable[[Path, Checkpoint], object] = save_checkpoint,
        on_error: Callable[[str], None] | None = None,
    ) -> None:
        self._save = save
        self._on_error = on_error
        self._cond = threading.Condition()
        self._pending: tuple[Path, Checkpoint] | None = None
        self._busy = False
        self._closed = False
        self.written = 0
        self.errors = 0
        self._thread = threading.Thread(target=self._run, name="checkpoint-writer", daemon=True)
        self._thread.start()

    def __call__(self, path: Path | str, checkpoint: Checkpoint) -> None:
        """Queue ``checkpoint`` for ``path`` (returns at once)."""
        with self._cond:
            if self._closed:
                raise CheckpointError("the checkpoint writer is closed")
            self._pending = (Path(path), checkpoint)
            self._cond.notify_all()

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until nothing is pending or being written; False on timeout."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self._pending is None and not self._busy, timeout=timeout
            )

    def close(self, timeout: float | None = 30.0) -> None:
        """Write what is pending, then stop the thread."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._pending is not None or self._closed)
                job = self._pending
                if job is None:  # closed with nothing pending
                    self._cond.notify_all()
                    return
                self._pending = None
                self._busy = True
            path, checkpoint = job
            try:
                self._save(path, checkpoint)
            except (CheckpointError, OSError) as err:
                self.errors += 1
                reason = f"checkpoint not saved: {err}"
                if self._on_error is not None:
                    self._on_error(reason)
                else:
                    _LOG.warning(reason)
            else:
                self.written += 1
            with self._cond:
                self._busy = False
                self._cond.notify_all()
