"""What the multi-process DDS tests share: the node as a process, a subscriber on its outputs.

cyclonedds is imported inside :class:`Subscriber` only, so that this module (collected for
doctests, imported by test modules that also hold in-process tests) imports without it.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class Received:
    """What the subscriber saw: (monotonic receive ns, message) per output topic."""

    compensated: list[tuple[int, Any]] = field(default_factory=list)
    estimates: list[tuple[int, Any]] = field(default_factory=list)
    diagnostics: list[tuple[int, Any]] = field(default_factory=list)


class Subscriber:
    """KEEP_ALL RELIABLE readers on the node's outputs, taken on a thread."""

    def __init__(self, domain: int) -> None:
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.qos import Policy, Qos
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from cyclonedds.util import duration

        from genbacklash_ros.transports.dds_types import DiagnosticArray_, Float64MultiArray_
        from genbacklash_ros.transports.ros_graph import endpoint_qos

        reliable_all = Qos(
            Policy.History.KeepAll,
            Policy.Reliability.Reliable(duration(seconds=1)),
            Policy.Durability.Volatile,
        )
        # with their type hashes, so that ROS 2 processes in a test do not warn about them
        arrays = endpoint_qos(reliable_all, "std_msgs/msg/Float64MultiArray")
        diagnostics = endpoint_qos(reliable_all, "diagnostic_msgs/msg/DiagnosticArray")
        self._wait = duration(milliseconds=50)
        self.got = Received()
        self._stop = threading.Event()
        self.dp = dp = DomainParticipant(domain)
        self._readers = {
            "compensated": DataReader(
                dp, Topic(dp, "rt/compensated_command", Float64MultiArray_), qos=arrays
            ),
            "estimates": DataReader(
                dp,
                Topic(dp, "rt/backlash_identifier/estimate", Float64MultiArray_),
                qos=arrays,
            ),
            "diagnostics": DataReader(
                dp, Topic(dp, "rt/diagnostics", DiagnosticArray_), qos=diagnostics
            ),
        }
        self._waitset = WaitSet(dp)
        mask = SampleState.NotRead | ViewState.Any | InstanceState.Any
        self._conditions = {}
        for key, reader in self._readers.items():
            condition = ReadCondition(reader, mask)
            self._conditions[key] = condition
            self._waitset.attach(condition)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._waitset.wait(self._wait)
            now = time.monotonic_ns()
            for key, reader in self._readers.items():
                for sample in reader.take(1000, condition=self._conditions[key]):
                    if sample.sample_info.valid_data:
                        getattr(self.got, key).append((now, sample))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)


def start_node(
    params: Path, log: Path, domain: int, transport: str = "dds"
) -> subprocess.Popen[bytes]:
    """The node as users run it (the DDS transport unless told), its stderr in ``log``."""
    cmd = [sys.executable, "-m", "genbacklash_ros.cli.node", "--transport", transport]
    cmd += ["--params-file", str(params), "--domain-id", str(domain)]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log.open("wb"))


def stop_node(node: subprocess.Popen[bytes], log: Path) -> int:
    """SIGINT the node and its exit status; fail the test if it does not exit within 30 s."""
    import pytest

    node.send_signal(signal.SIGINT)
    try:
        return node.wait(timeout=30)
    except subprocess.TimeoutExpired:
        node.kill()
        pytest.fail(f"the node did not exit within 30 s of SIGINT:\n{log.read_text()}")


@dataclass
class Played:
    """What a player process reported (its last JSON line), and the node's exit and log."""

    summary: dict[str, Any]
    returncode: int
    log: str
    inspected: Any = None  # what ``inspect`` found in the running node, if asked


def play_against_node(
    tmp: Path,
    transport: str,
    params_yaml: str,
    player: str,
    player_args: list[str],
    timeout: float,
    inspect: Callable[[int], Any] | None = None,
) -> Played:
    """Start the node (``transport``, the params file ``params_yaml``), run ``player`` (a
    script beside this module) on a domain of their own, then (``inspect(pid)`` on the
    node still running, when given) stop the node with SIGINT."""
    from ._ros2 import domain_id

    domain = domain_id()
    log = tmp / "node.log"
    params = tmp / "params.yaml"
    params.write_text(params_yaml)
    node = start_node(params, log, domain, transport)
    here = Path(__file__).parent
    try:
        ran = subprocess.run(
            [sys.executable, str(here / player), "--domain-id", str(domain), *player_args],
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
        assert ran.returncode == 0, ran.stdout + ran.stderr + log.read_text()
        summary = json.loads(ran.stdout.strip().splitlines()[-1])
        inspected = None if inspect is None else inspect(node.pid)
        returncode = stop_node(node, log)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait(10)
    return Played(summary, returncode, log.read_text(), inspected)


def diagnostic_values(diag: Any) -> dict[str, str]:
    """The key/value pairs of a DiagnosticArray's first status."""
    return {kv.key: kv.value for kv in diag.status[0].values}


def match_trial(
    domain: int,
    params: Path,
    log: Path,
    *,
    rate: float,
    seconds: float,
    lead: float = 0.5,
    during: Callable[[], None] | None = None,
    transport: str = "dds",
) -> tuple[dict[str, Any], int]:
    """One run of ``match_player.py`` (rclpy, already publishing) and then the DDS node: the
    player's JSON summary (what was lost after it matched the node) and the node's exit status.
    ``lead``: seconds the player runs before the node is started; ``during``: run on a thread
    once the node is started (joined before returning); ``transport``: the node's."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "PYTHONUNBUFFERED": "1"}
    here = Path(__file__).resolve().parent
    cmd = [sys.executable, str(here / "match_player.py"), "--rate", str(rate)]
    player = subprocess.Popen(
        [*cmd, "--seconds", str(seconds)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    node = None
    try:
        assert player.stdout is not None
        first = player.stdout.readline()
        if first.strip() != "publishing":
            player.kill()
            _, err = player.communicate()
            raise RuntimeError(f"match_player did not start: {first!r} {err[-2000:]}")
        time.sleep(lead)
        node = start_node(params, log, domain, transport)
        aside = threading.Thread(target=during) if during is not None else None
        if aside is not None:
            aside.start()
        out, err = player.communicate(timeout=120)
        if aside is not None:
            aside.join(60)
        lines = out.strip().splitlines()
        if player.returncode != 0 or not lines:
            raise RuntimeError(f"match_player failed ({player.returncode}): {out} {err[-2000:]}")
        summary: dict[str, Any] = json.loads(lines[-1])
        node.send_signal(signal.SIGINT)
        status = node.wait(timeout=30)
        return summary, status
    finally:
        for process in (player, node):
            if process is not None and process.poll() is None:
                process.kill()
                process.wait(10)
