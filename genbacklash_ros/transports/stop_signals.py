"""SIGINT and SIGTERM as a request to stop: a flag, never an exception.

Both transports run their loop until :attr:`StopSignals.requested`; the handler only counts the
signal, sets the flag and calls ``on_stop`` (e.g. :meth:`DdsNode.stop`, which wakes its wait).
Nothing is raised, so no signal can land as a ``KeyboardInterrupt`` inside the middleware (rclpy
turned one raised in its message take into ``RuntimeError: Unable to convert call argument``
and exit 1) or in the node's finishing (final refit, checkpoint).

When the node returns, :meth:`StopSignals.release` either gives the previous handlers back (the
node run inside a longer-lived process, e.g. a test) or, for the process's own entry point,
leaves both signals ignored: the interpreter's shutdown (middleware destructors, which take a
while) then cannot be cut by a late Ctrl-C either. Python restores the default action of a
signal with a Python handler at shutdown, but not of an ignored one; a handler restored before
returning brought back ``KeyboardInterrupt`` and ended the process by SIGINT (exit -2/130) when a
second Ctrl-C came 5-250 ms after the first.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from types import FrameType
from typing import Any

__all__ = ["STOP_SIGNALS", "StopSignals"]

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """SIGINT/SIGTERM handlers that only ask for a stop (see the module docstring).

    Parameters
    ----------
    on_stop : callable, optional
        Called (in the main thread, from the handler) at the first signal; may also be set
        later with :meth:`on_stop`. Exceptions from it are swallowed: a handler never raises.

    Examples
    --------
    >>> import os
    >>> stop = StopSignals().install()
    >>> os.kill(os.getpid(), signal.SIGTERM); stop.requested, stop.count, stop.first.name
    (True, 1, 'SIGTERM')
    >>> stop.release(exiting=False)
    """

    def __init__(self, on_stop: Callable[[], None] | None = None) -> None:
        self.count = 0
        self.first: signal.Signals | None = None  # the signal that asked for the stop
        self._event = threading.Event()
        self._on_stop = on_stop
        self._previous: dict[int, Any] = {}

    def install(self) -> StopSignals:
        """Handle SIGINT and SIGTERM from now on (main thread only); returns self."""
        for sig in STOP_SIGNALS:
            self._previous.setdefault(sig, signal.signal(sig, self._handle))
        return self

    def on_stop(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` at the first signal, or now when one has already come."""
        self._on_stop = callback
        if self.requested:
            self._call(callback)

    @property
    def requested(self) -> bool:
        """True once a SIGINT or SIGTERM came (or :meth:`request` was called)."""
        return self._event.is_set()

    def request(self) -> None:
        """Ask for the stop as a signal would (from any thread)."""
        if not self._event.is_set():
            self._event.set()
            if self._on_stop is not None:
                self._call(self._on_stop)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for the stop request (from another thread); True when it came."""
        return self._event.wait(timeout)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.count += 1
        if self.first is None and not self.requested:
            self.first = signal.Signals(signum)
        self.request()

    @staticmethod
    def _call(callback: Callable[[], None]) -> None:
        try:
            callback()
        except Exception:  # never raise out of a signal handler
            pass

    def release(self, *, exiting: bool) -> None:
        """Stop handling the signals: ignore them from now on when the process is
        ``exiting`` (its entry point returns next), else restore the previous handlers."""
        previous, self._previous = self._previous, {}
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_IGN if exiting else handler)
