"""Signal trials against a node process fed at 1 kHz (``test_shutdown.py``, ``bench/shutdown.py``).

One :class:`Feeder` process (``feeder.py``: rclpy, Fast DDS) publishes commands and readings
at 1 kHz on its own DDS domain for the whole run; each :func:`trial` starts ``genbacklash node``
as the user would, waits until the feeder sees it subscribed on both topics, waits a moment,
sends one signal or two, and returns the exit status and stderr.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from tests.ros._proc import alive, children

HERE = Path(__file__).resolve().parent

KINDS = ("SIGINT", "SIGTERM", "SIGINT+SIGINT", "SIGTERM+SIGINT")

PARAMS = "backlash_identifier:\n  ros__parameters:\n    joint: j\n    publish_rate: 10.0\n"


def node_command(transport: str, params: Path) -> list[str]:
    """``genbacklash node`` of this environment (the console script, else ``-m``)."""
    script = Path(sys.executable).with_name("genbacklash")
    head = [str(script)] if script.is_file() else [sys.executable, "-m", "genbacklash_ros.cli.main"]
    return [*head, "node", "--transport", transport, "--params-file", str(params)]


class Feeder:
    """``feeder.py`` at ``rate`` Hz on domain ``domain``, and the listener count it reports."""

    def __init__(self, domain: int, rate: float = 1000.0) -> None:
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONUNBUFFERED": "1"}
        self.env = env
        self.listeners: frozenset[str] = frozenset()
        self._changed = threading.Condition()
        self.proc = subprocess.Popen(
            [sys.executable, str(HERE / "feeder.py"), "--rate", str(rate)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=env,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("listeners"):
                with self._changed:
                    self.listeners = frozenset(
                        line.removeprefix("listeners").strip().split(",")
                    ) - {""}
                    self._changed.notify_all()

    def wait_for_new(self, before: frozenset[str], timeout: float) -> bool:
        """Wait until a participant not in ``before`` listens; False on timeout."""
        with self._changed:
            return self._changed.wait_for(lambda: bool(self.listeners - before), timeout)

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


@dataclass(frozen=True)
class Outcome:
    kind: str
    delay_s: float  # from the node listening to the first signal
    gap_s: float  # between the two signals (0 for one)
    returncode: int
    stderr: str
    left: tuple[int, ...] = ()  # the node's child processes still running 5 s after it ended
    children: int = 0  # the node's child processes when the first signal was sent

    @property
    def clean(self) -> bool:
        return self.returncode == 0 and "Traceback" not in self.stderr and not self.left

    def describe(self) -> str:
        return (
            f"{self.kind} {self.delay_s * 1e3:.0f} ms after listening"
            + (f", second after {self.gap_s * 1e3:.0f} ms" if "+" in self.kind else "")
            + f": exit {self.returncode}"
            + (f", child processes left running: {self.left}" if self.left else "")
            + f"\n{self.stderr[-2000:]}"
        )


def trial(
    feeder: Feeder, transport: str, params: Path, kind: str, delay_s: float, gap_s: float
) -> Outcome:
    """Start the node, wait until it is fed, then ``delay_s`` more, and send ``kind``."""
    before = feeder.listeners
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(
            node_command(transport, params),
            stdout=subprocess.DEVNULL,
            stderr=err,
            env=feeder.env,
        )
        try:
            if not feeder.wait_for_new(before, 30.0):
                raise RuntimeError(f"the node did not subscribe within 30 s (exit {proc.poll()})")
            time.sleep(delay_s)
            kids = children(proc.pid)  # an identify process (thread_priority) must end too
            first, _, second = kind.partition("+")
            proc.send_signal(signal.Signals[first])
            if second:
                time.sleep(gap_s)
                proc.send_signal(signal.Signals[second])
            returncode = proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        deadline = time.monotonic() + 5.0
        while any(alive(k) for k in kids) and time.monotonic() < deadline:
            time.sleep(0.05)
        left = tuple(k for k in kids if alive(k))
        err.seek(0)
        return Outcome(
            kind, delay_s, gap_s if second else 0.0, returncode, err.read(), left, len(kids)
        )


def write_params(directory: Path, thread_priority: int = 0) -> Path:
    """The node's params file (``thread_priority`` above 0: its message thread real-time,
    identification in a child process)."""
    path = directory / f"shutdown_params_{thread_priority}.yaml"
    extra = f"    thread_priority: {thread_priority}\n" if thread_priority else ""
    path.write_text(PARAMS + extra)
    return path
