"""A progress line on stderr for long work, with and without a terminal.

On a terminal, a tqdm bar (a counter when the total is unknown) that a ticker thread
refreshes every second, so that the elapsed time moves while one long step runs. Without a
terminal (a log file, a pipe, CI) tqdm would write carriage-return updates into one endless
line; instead a plain line such as::

    genbacklash diagnose: round 2: fitting the nominated effects; 15 s

goes to stderr at most every ``every`` seconds (default 5), and a last line with the total
time when the work took longer than that. Work shorter than ``every`` prints nothing
without a terminal.
"""

from __future__ import annotations

import sys
import threading
import time
from types import TracebackType
from typing import Any, TextIO

__all__ = ["Progress"]


class Progress:
    """Progress of one piece of work (see the module notes).

    Parameters
    ----------
    desc : str
        What runs, e.g. ``"genbacklash diagnose"``.
    total : int, optional
        The number of units (:meth:`update`), when known.
    unit : str
        The unit's name (``"msg"``, ``"bag"``).
    enabled : bool
        False: nothing is printed (``--no-progress``, ``--json``).
    every : float
        Seconds between two plain lines without a terminal.
    stream : text file, optional
        Default ``sys.stderr``; a terminal when its ``isatty()`` says so.
    """

    def __init__(
        self,
        desc: str,
        *,
        total: int | None = None,
        unit: str = "it",
        enabled: bool = True,
        every: float = 5.0,
        stream: TextIO | None = None,
        unit_scale: bool = False,
    ) -> None:
        self.desc = desc
        self.total = total
        self.unit = unit
        self.count = 0
        self.stage = ""
        self._every = every
        self._stream = sys.stderr if stream is None else stream
        self._start = time.monotonic()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._bar: Any = None
        self._thread: threading.Thread | None = None
        self._printed = False
        self._tty = False
        if not enabled:
            return
        isatty = getattr(self._stream, "isatty", None)
        self._tty = bool(isatty()) if callable(isatty) else False
        if self._tty:
            from tqdm import tqdm

            self._bar = tqdm(
                total=total,
                desc=desc,
                unit=unit,
                unit_scale=unit_scale,
                leave=False,
                file=self._stream,
                dynamic_ncols=True,
            )
        self._thread = threading.Thread(target=self._tick, name="progress", daemon=True)
        self._thread.start()

    @property
    def enabled(self) -> bool:
        return self._thread is not None

    def update(self, count: int = 1) -> None:
        """``count`` more units done."""
        with self._lock:
            self.count += count
            if self._bar is not None:
                self._bar.update(count)

    def set_stage(self, stage: str) -> None:
        """What runs now (shown after the description)."""
        with self._lock:
            self.stage = stage
            if self._bar is not None:
                self._bar.set_postfix_str(stage, refresh=False)

    def _counted(self) -> str:
        units = {"msg": "messages", "it": "steps"}.get(self.unit, self.unit + "s")
        if self.total:
            return f"{self.count}/{self.total} {units} ({self.count / self.total:.0%})"
        return f"{self.count} {units}" if self.count else ""

    def line(self) -> str:
        """The plain progress line (without a terminal), e.g. ``genbacklash fleet: 5/40
        bags (12%), 35 s`` or ``genbacklash diagnose: round 2: judging; 15 s``."""
        elapsed = f"{time.monotonic() - self._start:.0f} s"
        rest = ", ".join(part for part in (self._counted(), elapsed) if part)
        if self.stage:
            return f"{self.desc}: {self.stage}; {rest}"
        return f"{self.desc}: {rest}"

    def _tick(self) -> None:
        interval = 1.0 if self._tty else self._every
        while not self._stop.wait(interval):
            with self._lock:
                if self._bar is not None:
                    self._bar.refresh()
                else:
                    print(self.line(), file=self._stream, flush=True)
                    self._printed = True

    def close(self, finished: bool = True) -> None:
        """Stop the ticker; remove the bar (terminal) or print the total time (plain lines,
        when any was printed; ``finished`` False: the work stopped on an error)."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join()
        self._thread = None
        if self._bar is not None:
            self._bar.close()
        elif self._printed:
            elapsed = time.monotonic() - self._start
            done = ", ".join(part for part in (self._counted(), f"{elapsed:.0f} s") if part)
            word = "done" if finished else "stopped"
            print(f"{self.desc}: {word} ({done})", file=self._stream, flush=True)

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close(finished=kind is None)
