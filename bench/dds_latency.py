"""DDS latency: the compensated command back to a separate process at 1 kHz, next to an echo.

    python bench/dds_latency.py [--seconds S] [--rate HZ] [--quick]
                                [--stamps sane|early] [--load] [--worker thread|sync]

Three processes share a DDS domain of their own (an id in 201-231, apart from the tests'):
the node as users run it (``python -m genbacklash_ros.cli.node --transport dds --params-file
params.yaml``, Float64MultiArray commands, a checkpoint file in a temporary directory); a
plain DDS echo (this script with ``--role echo``) that writes every Float64MultiArray taken on
``rt/dds_latency/ping`` back unchanged on ``rt/dds_latency/pong``, with the node's loop
structure (a WaitSet with a ReadCondition, take, write) and no pipeline; and the player (this
process). The player waits until every reader and writer has matched, then at each tick of
the rate (sleeping until the tick's deadline) writes a command ``[u_k, k]`` on ``rt/command``
(ROS 2 default QoS), an encoder reading ``y_k`` on ``rt/encoder`` (sensor-data QoS, header
stamp) and a ping ``[k]``. ``u`` is the paper's Example 1 input (uniform in (-2, 2)) and
``y`` the true backlash's noisy response to it (``simulate_backlash`` through
``PaperExample.generate``, seeded), so the node's identifier converges during the warm-up and
its compensator is active (not pass-through) while latency is measured. A thread of the
player takes ``rt/compensated_command``, ``rt/dds_latency/pong`` and ``rt/diagnostics`` on a
WaitSet; a compensated command is matched to its command by the sequence number ``k`` the
node echoes unchanged (only element 0 is compensated). Latency is the receive time less the
write time, both on the player's monotonic clock: one write, the DDS hop to the other
process, its processing, the hop back. Messages of the warm-up are discarded; a message
written after the warm-up that never comes back is counted as lost. The echo runs at the
same time as the node (same ticks, same machine load), so the ratio node / echo is the
node's own cost on a shared, noisy machine.

Issue 15's failing case: ``--stamps early`` stamps each encoder reading just *before* the
command that produced it is written, so the node sees a one-sample delay its model lacks and
every cold start fails; ``--load`` runs a CPU-bound process (a busy loop) beside the three for
the whole run; ``--worker sync`` runs the node with identification inside the message handler
(the synchronous worker, as before issue 15 item 4) instead of its own thread, so the two are
compared under the same conditions. Besides the latency after the warm-up the section gives
the commands lost over the *whole* run (the cold start is in the warm-up) and the time from
the first command to the first estimate the node publishes.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _common import (
    OUTPUT_DIR,
    ROOT,
    command_line,
    fmt_ratio,
    machine_description,
    md_table,
    write_section,
)

from genbacklash_core import paper_example

try:
    from cyclonedds.core import (
        GuardCondition,
        InstanceState,
        ReadCondition,
        SampleState,
        ViewState,
        WaitSet,
    )
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    from genbacklash_ros.transports.dds_node import DEFAULT_QOS, SENSOR_QOS
    from genbacklash_ros.transports.dds_types import (
        DiagnosticArray_,
        Float64MultiArray_,
        Header_,
        JointState_,
        MultiArrayDimension_,
        MultiArrayLayout_,
        Time_,
    )
except ImportError as err:  # the section says so instead of failing run_all
    DDS_MISSING: str | None = f"cyclonedds is not installed (pip install .[dds]): {err}"
else:
    DDS_MISSING = None

SEED = 7400
PING_TOPIC = "rt/dds_latency/ping"
PONG_TOPIC = "rt/dds_latency/pong"
TARGET_MEDIAN_MS = 2.0
TARGET_P99_MS = 5.0
MATCH_TIMEOUT_S = 30.0
DRAIN_S = 2.0  # wait this long after the last tick for late replies

__all__ = ["LatencyStats", "echo", "latency_stats", "main"]


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class LatencyStats:
    """Round-trip latency of one path over the measured messages.

    Attributes
    ----------
    sent, received, lost : int
        Messages written after the warm-up, of those the replies taken, and the rest.
    median, p90, p99, max : float
        Latency [ms] over the received ones (nan when none).
    """

    sent: int
    received: int
    lost: int
    median: float
    p90: float
    p99: float
    max: float

    def row(self, name: str) -> list[str]:
        """A markdown table row: name, received, lost, the four latencies."""
        return [
            name,
            f"{self.received:,}",
            f"{self.lost:,} ({self.lost / max(self.sent, 1):.2%})",
            *(f"{v:.3f} ms" for v in (self.median, self.p90, self.p99, self.max)),
        ]


def latency_stats(sent_ns: np.ndarray, received_ns: np.ndarray) -> LatencyStats:
    """Statistics of ``received_ns - sent_ns``; a negative ``received_ns`` means lost.

    Parameters
    ----------
    sent_ns, received_ns : numpy.ndarray
        Write and receive times [ns] of the same messages, on one monotonic clock.

    Returns
    -------
    LatencyStats

    Examples
    --------
    >>> s = latency_stats(np.array([0, 10, 20]), np.array([1_000_000, -1, 2_000_020]))
    >>> s.received, s.lost, s.median, s.max
    (2, 1, 1.5, 2.0)
    """
    got = received_ns >= 0
    lat_ms = (received_ns[got] - sent_ns[got]) / 1e6
    if lat_ms.size == 0:
        nan = float("nan")
        return LatencyStats(sent_ns.size, 0, sent_ns.size, nan, nan, nan, nan)
    median, p90, p99 = (float(v) for v in np.percentile(lat_ms, [50, 90, 99]))
    received = int(lat_ms.size)
    return LatencyStats(
        sent_ns.size, received, sent_ns.size - received, median, p90, p99, float(lat_ms.max())
    )


# --------------------------------------------------------------------------- the echo process


def echo(domain_id: int, lifetime_s: float) -> int:
    """Write every Float64MultiArray taken on the ping topic back on the pong topic.

    Runs until SIGINT/SIGTERM or ``lifetime_s`` seconds (a guard in case the player dies).

    Parameters
    ----------
    domain_id : int
        DDS domain.
    lifetime_s : float
        Longest run time [s].

    Returns
    -------
    int
        Exit status (0).
    """
    dp = DomainParticipant(domain_id)
    reader: DataReader[Any] = DataReader(
        dp, Topic(dp, PING_TOPIC, Float64MultiArray_), qos=DEFAULT_QOS
    )
    writer: DataWriter[Any] = DataWriter(
        dp, Topic(dp, PONG_TOPIC, Float64MultiArray_), qos=DEFAULT_QOS
    )
    ready = ReadCondition(reader, SampleState.NotRead | ViewState.Any | InstanceState.Any)
    guard = GuardCondition(dp)
    waitset = WaitSet(dp)
    waitset.attach(ready)
    waitset.attach(guard)
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()
        guard.set(True)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    end = time.monotonic() + lifetime_s
    while not stop.is_set() and time.monotonic() < end:
        waitset.wait(100_000_000)
        for sample in reader.take(512, condition=ready):
            if sample.sample_info.valid_data:
                writer.write(sample)
    return 0


# --------------------------------------------------------------------------- the player


@dataclass
class Replies:
    """What the player's reader thread took: receive times [monotonic ns] by sequence number
    (-1: not yet), the compensated values, and the node's diagnostics with their receive
    times."""

    command_ns: np.ndarray
    ping_ns: np.ndarray
    compensated: np.ndarray
    duplicates: int = 0
    diagnostics: list[tuple[int, Any]] = field(default_factory=list)
    first_estimate_ns: int = -1


class ReplyReader:
    """Readers on the node's compensated command and diagnostics and the echo's pong, taken
    on a thread that waits on a WaitSet and stamps each wake-up with ``time.monotonic_ns``."""

    def __init__(self, dp: Any, n: int) -> None:
        # KEEP_ALL on our side: a late take here must not drop replies (the writers keep
        # the ROS 2 default history)
        qos = Qos(
            Policy.History.KeepAll,
            Policy.Reliability.Reliable(duration(seconds=1)),
            Policy.Durability.Volatile,
        )
        self.replies = Replies(
            np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64), np.full(n, np.nan)
        )
        self.readers: dict[str, Any] = {
            "command": DataReader(
                dp, Topic(dp, "rt/compensated_command", Float64MultiArray_), qos=qos
            ),
            "ping": DataReader(dp, Topic(dp, PONG_TOPIC, Float64MultiArray_), qos=qos),
            "diagnostics": DataReader(dp, Topic(dp, "rt/diagnostics", DiagnosticArray_), qos=qos),
            "estimate": DataReader(
                dp, Topic(dp, "rt/backlash_identifier/estimate", Float64MultiArray_), qos=qos
            ),
        }
        mask = SampleState.NotRead | ViewState.Any | InstanceState.Any
        self._conditions = {k: ReadCondition(r, mask) for k, r in self.readers.items()}
        self._guard = GuardCondition(dp)
        self._waitset = WaitSet(dp)
        for condition in (*self._conditions.values(), self._guard):
            self._waitset.attach(condition)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="replies", daemon=True)
        self._thread.start()

    def matched(self) -> bool:
        """True when the node's and the echo's writers matched our readers."""
        return all(
            self.readers[k].get_subscription_matched_status().current_count >= 1
            for k in ("command", "ping")
        )

    def _run(self) -> None:
        r = self.replies
        while not self._stop.is_set():
            self._waitset.wait(100_000_000)
            # one receive time per wake-up, before any take: neither path is stamped later
            # for the other's deserialisation
            now = time.monotonic_ns()
            for key, reader in self.readers.items():
                for sample in reader.take(512, condition=self._conditions[key]):
                    if not sample.sample_info.valid_data:
                        continue
                    if key == "diagnostics":
                        r.diagnostics.append((now, sample))
                        continue
                    if key == "estimate":
                        if r.first_estimate_ns < 0:
                            r.first_estimate_ns = now
                        continue
                    k = int(sample.data[1] if key == "command" else sample.data[0])
                    times = r.command_ns if key == "command" else r.ping_ns
                    if not 0 <= k < times.size:
                        continue
                    if times[k] >= 0:
                        r.duplicates += 1
                        continue
                    times[k] = now
                    if key == "command":
                        r.compensated[k] = sample.data[0]

    def close(self) -> None:
        """Stop the thread."""
        self._stop.set()
        self._guard.set(True)
        self._thread.join(5)


@dataclass
class Played:
    """What the player wrote: write times [monotonic ns] and deadlines by sequence number,
    and the CPU time [s] each process used over the measured ticks."""

    command_ns: np.ndarray
    ping_ns: np.ndarray
    deadline_ns: np.ndarray
    cpu_s: dict[str, float] = field(default_factory=dict)


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system, all threads) a process has used so far [s]; nan off Linux.

    >>> cpu_seconds(os.getpid()) >= 0.0 or sys.platform != "linux"
    True
    """
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as handle:
            fields = handle.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime


def play(
    domain_id: int, rate: float, n: int, n_warm: int, pids: dict[str, int], early: bool = False
) -> tuple[Played, Replies]:
    """Wait for the matches, then write ``n`` ticks at ``rate`` Hz; the write and reply times.

    Parameters
    ----------
    domain_id : int
        DDS domain.
    rate : float
        Ticks per second.
    n : int
        Ticks (warm-up included).
    n_warm : int
        Warm-up ticks: the CPU time of the processes in ``pids`` is measured from there on.
    pids : dict
        Process ids by name (the player itself is added as ``player``).
    early : bool
        Stamp each encoder reading before its command is written (issue 15's failing case).

    Returns
    -------
    (Played, Replies)
    """
    data = paper_example(1).generate(SEED, n_samples=n)
    u, y = data.u.tolist(), data.y.tolist()
    dp = DomainParticipant(domain_id)
    reader = ReplyReader(dp, n)
    command = DataWriter(dp, Topic(dp, "rt/command", Float64MultiArray_), qos=DEFAULT_QOS)
    encoder = DataWriter(dp, Topic(dp, "rt/encoder", JointState_), qos=SENSOR_QOS)
    ping = DataWriter(dp, Topic(dp, PING_TOPIC, Float64MultiArray_), qos=DEFAULT_QOS)
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while not (
        all(w.get_publication_matched_status().current_count >= 1 for w in (command, encoder, ping))
        and reader.matched()
    ):
        if time.monotonic() > deadline:
            reader.close()
            raise RuntimeError("the node's or the echo's endpoints did not match")
        time.sleep(0.05)
    time.sleep(0.5)  # discovery settles both ways before the first timed write
    cmd_layout = MultiArrayLayout_([MultiArrayDimension_("u,seq", 2, 2)], 0)
    ping_layout = MultiArrayLayout_([MultiArrayDimension_("seq", 1, 1)], 0)
    played = Played(
        np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    )
    pids = {**pids, "player": os.getpid()}
    cpu_start: dict[str, float] = {}
    period_ns = round(1e9 / rate)
    start = time.monotonic_ns() + period_ns
    for k in range(n):
        target = start + k * period_ns
        delay = target - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay / 1e9)
        if k == n_warm:
            cpu_start = {name: cpu_seconds(pid) for name, pid in pids.items()}
        played.deadline_ns[k] = target
        stamp_ns = time.time_ns()  # used when early: the reading stamped before its command
        played.command_ns[k] = time.monotonic_ns()
        command.write(Float64MultiArray_(cmd_layout, [u[k], float(k)]))
        sec, nanosec = divmod(stamp_ns if early else time.time_ns(), 1_000_000_000)
        encoder.write(JointState_(Header_(Time_(sec, nanosec), ""), ["j"], [y[k]], [], []))
        played.ping_ns[k] = time.monotonic_ns()
        ping.write(Float64MultiArray_(ping_layout, [float(k)]))
    played.cpu_s = {name: cpu_seconds(pid) - cpu_start[name] for name, pid in pids.items()}
    drain_end = time.monotonic() + DRAIN_S
    r = reader.replies
    while time.monotonic() < drain_end and (np.any(r.command_ns < 0) or np.any(r.ping_ns < 0)):
        time.sleep(0.05)
    time.sleep(1.2)  # one more /diagnostics
    reader.close()
    return played, r


# --------------------------------------------------------------------------- processes


def _domain_id() -> int:
    """A domain for this run: 201-231 (the DDS node tests use 1-200), by process id."""
    return 201 + os.getpid() % 31


def _write_params(path: Path) -> Path:
    path.write_text(
        "backlash_identifier:\n"
        "  ros__parameters:\n"
        "    command_type: float64_multi_array\n"
        "    command_index: 0\n"
        "    joint: j\n"
        f"    checkpoint_file: {path.parent / 'estimate.json'}\n",
        encoding="utf-8",
    )
    return path


def _stop(process: subprocess.Popen[bytes], name: str) -> int:
    process.send_signal(signal.SIGINT)
    try:
        return process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        print(f"{name} did not exit within 30 s of SIGINT: killed", file=sys.stderr)
        return process.wait()


@dataclass
class Run:
    """One benchmark run: what was played, what came back, the node's log and exit status."""

    played: Played
    replies: Replies
    warmup: int
    node_status: int
    echo_status: int
    node_log: str
    seconds: float
    early: bool = False
    load: bool = False
    worker: str = "thread"


# the node as users run it, with one change for --worker sync: the transport's worker factory
# replaced by the synchronous one (identification inside the message handler, as before)
_NODE_SYNC = (
    "import sys; import genbacklash_ros.transports.dds_node as m; "
    "from genbacklash_ros.node.identify import SyncWorker; m.live_worker = SyncWorker; "
    "from genbacklash_ros.cli.node import main; sys.exit(main(sys.argv[1:]))"
)
_BUSY = "while True: pass"  # the CPU-bound process beside the node (--load)


def run(
    rate: float,
    warmup_s: float,
    seconds: float,
    domain_id: int,
    *,
    early: bool = False,
    load: bool = False,
    worker: str = "thread",
) -> Run:
    """Start the node and the echo, play, stop both; everything measured."""
    n_warm = round(warmup_s * rate)
    n = n_warm + round(seconds * rate)
    lifetime = n / rate + MATCH_TIMEOUT_S + 60.0
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="dds_latency_") as tmp:
        params = _write_params(Path(tmp) / "params.yaml")
        log_path = Path(tmp) / "node.log"
        node_cmd = [sys.executable, *(["-c", _NODE_SYNC] if worker == "sync" else ["-m"])]
        node_cmd += ["genbacklash_ros.cli.node"] if worker != "sync" else []
        node_cmd += ["--transport", "dds"]
        node_cmd += ["--params-file", str(params), "--domain-id", str(domain_id)]
        node_cmd += ["--duration", f"{lifetime:.0f}"]
        echo_cmd = [sys.executable, str(Path(__file__).resolve()), "--role", "echo"]
        echo_cmd += ["--domain-id", str(domain_id), "--lifetime", f"{lifetime:.0f}"]
        with log_path.open("wb") as log:
            node = subprocess.Popen(node_cmd, stdout=subprocess.DEVNULL, stderr=log, env=env)
            echo_proc = subprocess.Popen(echo_cmd, env=env, cwd=ROOT)
            busy = subprocess.Popen([sys.executable, "-c", _BUSY]) if load else None
            try:
                pids = {"node": node.pid, "echo": echo_proc.pid}
                played, replies = play(domain_id, rate, n, n_warm, pids, early)
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()
                node_status = _stop(node, "the node")
                echo_status = _stop(echo_proc, "the echo")
        node_log = log_path.read_text(encoding="utf-8", errors="replace")
    return Run(
        played,
        replies,
        n_warm,
        node_status,
        echo_status,
        node_log,
        time.perf_counter() - started,
        early,
        load,
        worker,
    )


# --------------------------------------------------------------------------- report


def _last_diagnostics(replies: Replies, until_ns: int) -> tuple[dict[str, str], str]:
    """Values and message of the node's last /diagnostics taken before ``until_ns``."""
    for stamp, sample in reversed(replies.diagnostics):
        if stamp <= until_ns and sample.status:
            status = sample.status[0]
            levels = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
            message = f"{levels.get(int(status.level), status.level)}: {status.message}"
            return {kv.key: kv.value for kv in status.values}, message
    return {}, "none"


def _plot(result: Run, rate: float, path: Path) -> None:
    w = result.warmup
    p = result.played
    r = result.replies
    t0 = p.deadline_ns[w]
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for name, sent, got, color in (
        ("echo (reference)", p.ping_ns[w:], r.ping_ns[w:], "0.6"),
        ("node: compensated command", p.command_ns[w:], r.command_ns[w:], "C0"),
    ):
        ok = got >= 0
        ax.plot(
            (sent[ok] - t0) / 1e9, (got[ok] - sent[ok]) / 1e6, ".", ms=1.5, color=color, label=name
        )
    ax.axhline(TARGET_P99_MS, color="C3", lw=0.8, ls="--", label="p99 target")
    ax.axhline(TARGET_MEDIAN_MS, color="C1", lw=0.8, ls="--", label="median target")
    ax.set_yscale("log")
    ax.set_xlabel("time since the warm-up [s]")
    ax.set_ylabel("round trip [ms]")
    ax.legend(fontsize=7, markerscale=6, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=4)
    fig.tight_layout()
    OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(result: Run, rate: float) -> str:
    """The markdown section for one run."""
    w = result.warmup
    p, r = result.played, result.replies
    ours = latency_stats(p.command_ns[w:], r.command_ns[w:])
    ref = latency_stats(p.ping_ns[w:], r.ping_ns[w:])
    whole = latency_stats(p.command_ns, r.command_ns)
    first_s = (
        (r.first_estimate_ns - p.command_ns[0]) / 1e9 if r.first_estimate_ns >= 0 else math.inf
    )
    setting = (
        f"Encoder readings stamped {'before' if result.early else 'after'} their commands"
        f"{' (issue 15: they look delayed by one sample)' if result.early else ''}; "
        f"{'a CPU-bound process beside it' if result.load else 'no extra load'}; "
        f"identification {'on its own thread' if result.worker == 'thread' else 'in the handler'}."
    )
    measured = p.command_ns.size - w
    span_s = (p.command_ns[-1] - p.command_ns[w]) / 1e9
    achieved = (measured - 1) / span_s if span_s > 0 else float("nan")
    late_ms = (p.command_ns[w:] - p.deadline_ns[w:]) / 1e6
    late_ticks = int(np.count_nonzero(late_ms > 1e3 / rate))
    u = paper_example(1).generate(SEED, n_samples=p.command_ns.size).u[w:]
    comp = r.compensated[w:]
    got = np.isfinite(comp)
    altered = int(np.count_nonzero(np.abs(comp[got] - u[got]) > 1e-9))
    diag, diag_message = _last_diagnostics(r, int(p.command_ns[-1]))
    cpu_us = {name: 1e6 * cpu / measured for name, cpu in p.cpu_s.items()}
    cpu_text = ", ".join(f"{name} {us:.0f} µs" for name, us in cpu_us.items())
    ratio_row = [
        "ratio node / echo",
        "",
        "",
        *(
            fmt_ratio(a / b) if b > 0 else "n/a"
            for a, b in (
                (ours.median, ref.median),
                (ours.p90, ref.p90),
                (ours.p99, ref.p99),
                (ours.max, ref.max),
            )
        ),
    ]
    table = md_table(
        [
            "path (round trip, player's monotonic clock)",
            "replies",
            "lost",
            "median",
            "p90",
            "p99",
            "max",
        ],
        [
            ours.row("node: command -> compensated_command"),
            ref.row("plain DDS echo: ping -> pong (reference)"),
            ratio_row,
        ],
    )
    plot_path = OUTPUT_DIR / "dds_latency.png"
    _plot(result, rate, plot_path)

    def mark(ok: bool) -> str:
        return "met" if ok else "**not met**"

    rate_ok = achieved >= 0.98 * rate and ours.lost <= 0.001 * ours.sent
    intro = __doc__.split("\n", 4)[4].strip()
    return f"""## DDS latency

{intro} Machine: {machine_description()}. Run time {result.seconds:.0f} s.

{setting} Over the whole run, warm-up included: {whole.lost:,} of {whole.sent:,} commands
lost ({whole.lost / max(whole.sent, 1):.2%}); first estimate {first_s:.2f} s after the first
command.

{measured:,} ticks measured after a warm-up of {w:,} ticks ({w / rate:.1f} s); target rate
{rate:g} Hz, achieved {achieved:.1f} Hz (ticks written more than one period after their
deadline: {late_ticks}; write lateness p99 {np.percentile(late_ms, 99):.3f} ms, max
{late_ms.max():.3f} ms). Duplicate replies: {r.duplicates}. CPU time per tick over the
measured ticks (all threads, from `/proc`; it grows too when the other logical core is
busy): {cpu_text} (the node takes a command and an encoder reading and writes a compensated
command, the echo takes and writes one ping, the player writes three messages and takes two).

{table}

Compensator active while measured: {altered:,} of {int(np.count_nonzero(got)):,} compensated
commands differ from their command (the others were passed through). The node's last
/diagnostics before the last tick: state `{diag.get("identifier_state", "n/a")}`, confidence
{diag.get("identifier_confidence", "n/a")}, compensation weight
{diag.get("compensation_weight", "n/a")}, {diag.get("commands", "n/a")} commands,
{diag.get("identifier_samples", "n/a")} samples identified; message "{diag_message[:300]}".
The node exited with status {result.node_status} on SIGINT (the echo: {result.echo_status}).

![DDS round trip](bench/output/dds_latency.png)

Command: `{command_line()}`

Targets (compensated command back to a separate process at {rate:g} Hz):
* median <= {TARGET_MEDIAN_MS:g} ms: {mark(ours.median <= TARGET_MEDIAN_MS)} ({ours.median:.3f} ms;
  the echo {ref.median:.3f} ms)
* p99 <= {TARGET_P99_MS:g} ms: {mark(ours.p99 <= TARGET_P99_MS)} ({ours.p99:.3f} ms; the echo
  {ref.p99:.3f} ms)
* at {rate:g} Hz without losses: {mark(rate_ok)} (achieved {achieved:.1f} Hz, {ours.lost} lost)
"""


# --------------------------------------------------------------------------- main


def parse(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line: ``--seconds``, ``--rate``, ``--warmup``, ``--quick``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    parser.add_argument(
        "--seconds", type=float, default=None, help="measured seconds (default 15, quick 4)"
    )
    parser.add_argument("--rate", type=float, default=1000.0, help="ticks per second (1000)")
    parser.add_argument(
        "--warmup", type=float, default=None, help="discarded seconds first (default 3, quick 2)"
    )
    parser.add_argument("--domain-id", type=int, default=None, help="DDS domain (default 201-231)")
    parser.add_argument(
        "--stamps",
        choices=("sane", "early"),
        default="sane",
        help="early: each reading stamped before its command (issue 15's failing case)",
    )
    parser.add_argument("--load", action="store_true", help="a CPU-bound process beside it")
    parser.add_argument(
        "--worker",
        choices=("thread", "sync"),
        default="thread",
        help="sync: identification inside the handler (as before issue 15 item 4)",
    )
    parser.add_argument(
        "--role", choices=("player", "echo"), default="player", help=argparse.SUPPRESS
    )
    parser.add_argument("--lifetime", type=float, default=600.0, help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark (or, with ``--role echo``, the echo process)."""
    args = parse(argv)
    domain_id = _domain_id() if args.domain_id is None else args.domain_id
    if args.role == "echo":
        return echo(domain_id, args.lifetime)
    if DDS_MISSING is not None:
        write_section("dds_latency", f"## DDS latency\n\nSkipped: {DDS_MISSING}.")
        return 0
    seconds = args.seconds if args.seconds is not None else (4.0 if args.quick else 15.0)
    warmup = args.warmup if args.warmup is not None else (2.0 if args.quick else 3.0)
    result = run(
        args.rate,
        warmup,
        seconds,
        domain_id,
        early=args.stamps == "early",
        load=args.load,
        worker=args.worker,
    )
    if result.node_status != 0 or "Traceback" in result.node_log:
        print(result.node_log, file=sys.stderr)
    text = report(result, args.rate)
    write_section("dds_latency", text)
    whole = latency_stats(result.played.command_ns, result.replies.command_ns)
    first = result.replies.first_estimate_ns
    summary = {
        "setting": {"stamps": args.stamps, "load": args.load, "worker": args.worker},
        "whole_run": {"sent": whole.sent, "lost": whole.lost},
        "first_estimate_s": (first - int(result.played.command_ns[0])) / 1e9
        if first >= 0
        else None,
        "node": asdict(
            latency_stats(
                result.played.command_ns[result.warmup :],
                result.replies.command_ns[result.warmup :],
            )
        ),
        "echo": asdict(
            latency_stats(
                result.played.ping_ns[result.warmup :], result.replies.ping_ns[result.warmup :]
            )
        ),
    }
    print(json.dumps(summary), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
