"""Start-up latency: the rclpy node's compensated commands from the first one on, beside an echo.

    python bench/startup_latency.py [--quick] [--runs N] [--seconds S] [--rate HZ]

Per run, on a DDS domain of its own: ``genbacklash node --transport rclpy`` (the ROS 2 wheels,
Fast DDS) as its own process with the shipped parameters (``config/params.yaml``) and a
checkpoint file, a plain rclpy echo (``bench/ros_latency.py --role echo``) and the player (this
process, rclpy; ``ros_latency.play``): once both have matched its endpoints it publishes at
each tick a ``Float64MultiArray`` command ``[u_k, k]``, the ``JointState`` reading ``y_k`` stamped
after it and a ping ``[k]`` (the paper's Example 1, seeded). Latency is the reply's receive time
less the command's publish time on the player's clock, for the compensated command and for the
echo's pong of the same tick, *from the first command on*: the node starts cold (no checkpoint),
so its first estimate, its first refits and its first checkpoint fall in the first seconds.
Reported per run and pooled: median, p99 and max for the first 5 s after the first command and
for the rest, the node / echo ratios, and the longest run of consecutive late replies (a
stall). Writes ``bench/output/startup_latency.md``. Default 3 runs of 15 s at 1 kHz
(``--quick``: 1 run of 8 s).

The same first seconds in process, where another process's load cannot blur them: the node's
pipeline with its live identify worker, fed 15 s of 1 kHz commands and readings (ticks late by
an exponential 0.4 ms on average, 30 % of the readings lost, as
``tests/ros/node/test_startup.py``), the message thread's own CPU time per message
(``thread_time``) and per second of data, with the guard judging each new estimate in one scan
(now) and stretch by stretch between the breaks (before the fix; the guard's per-stretch path,
kept for branches that are not finite, forced).
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from _common import ROOT, command_line, machine_description, md_table, write_section
from ros_latency import Played, paper_feed, play

from genbacklash_core import OnlineIdentifier, paper_example
from genbacklash_core import guard as guard_module

sys.path.insert(0, str(ROOT))
from tests.ros.transports._ros2 import domain_id, rclpy_missing

FIRST_S = 5.0  # the start-up window, from the first command
STALL_MS = 100.0  # a reply this late is part of a stall


@dataclass(frozen=True)
class Window:
    """Latencies (ms) of the replies received in one window, and the replies lost there."""

    node: np.ndarray
    echo: np.ndarray
    lost_node: int
    lost_echo: int


def windows(played: Played, rate: float) -> tuple[Window, Window]:
    """The first :data:`FIRST_S` seconds after the first command, and the rest."""
    sent = played.sent_ns
    first = np.arange(sent.size) < int(FIRST_S * rate)
    out = []
    for part in (first, ~first):
        node_back, echo_back = played.command_back_ns[part], played.ping_back_ns[part]
        s = sent[part]
        out.append(
            Window(
                (node_back[node_back > 0] - s[node_back > 0]) / 1e6,
                (echo_back[echo_back > 0] - s[echo_back > 0]) / 1e6,
                int((node_back == 0).sum()),
                int((echo_back == 0).sum()),
            )
        )
    return out[0], out[1]


def longest_stall_ms(played: Played) -> float:
    """The longest stretch of commands whose compensated command came :data:`STALL_MS` or more
    late (or never), in ms of send time."""
    late = (played.command_back_ns == 0) | (
        played.command_back_ns - played.sent_ns >= STALL_MS * 1e6
    )
    best = 0.0
    start = -1
    for i, is_late in enumerate(late.tolist()):
        if is_late and start < 0:
            start = i
        if (not is_late or i == late.size - 1) and start >= 0:
            end = i if is_late else i - 1
            best = max(best, (played.sent_ns[end] - played.sent_ns[start]) / 1e6 + STALL_MS)
            start = -1
    return best


def run_once(rate: float, seconds: float) -> tuple[Played, int]:
    """Start the node and the echo, play ``seconds`` of commands from the first one, stop them."""
    domain = domain_id()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    with tempfile.TemporaryDirectory(prefix="startup_latency_") as tmp_name:
        tmp = Path(tmp_name)
        params = tmp / "params.yaml"
        text = (ROOT / "config" / "params.yaml").read_text()
        params.write_text(
            text.replace('checkpoint_file: ""', f'checkpoint_file: "{tmp / "ckpt.json"}"')
        )
        script = Path(sys.executable).with_name("genbacklash")
        node = subprocess.Popen(
            [str(script), "node", "--transport", "rclpy", "--params-file", str(params)],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=(tmp / "node.log").open("wb"),
        )
        echo_cmd = [sys.executable, str(Path(__file__).with_name("ros_latency.py"))]
        echo = subprocess.Popen(
            [*echo_cmd, "--role", "echo", "--lifetime", f"{seconds + 120:.0f}"],
            env=env,
        )
        try:
            n = int(seconds * rate)
            played = play(paper_feed(rate, 0, n))
        finally:
            node.send_signal(signal.SIGINT)
            echo.send_signal(signal.SIGINT)
            status = node.wait(timeout=60)
            echo.wait(timeout=30)
    return played, status


def in_process(seconds: float, per_stretch: bool) -> np.ndarray:
    """Message-thread CPU seconds per command tick (command + reading) of the live pipeline."""
    from genbacklash_ros.node.identify import ThreadWorker, live_worker
    from genbacklash_ros.node.messages import (
        Float64MultiArray,
        Header,
        JointState,
        MultiArrayLayout,
        Time,
    )
    from genbacklash_ros.node.parameters import NodeParameters
    from genbacklash_ros.node.pipeline import BacklashPipeline

    workers: list[ThreadWorker] = []

    def worker(identifier: OnlineIdentifier) -> ThreadWorker:
        workers.append(live_worker(identifier))
        return workers[-1]

    real_free_run = guard_module.free_run
    if per_stretch:

        def whole_batch_refused(*args: object, **kwargs: object) -> np.ndarray:
            if len(args) > 3 and not np.any(args[3]):  # one stretch: run it
                return real_free_run(*args, **kwargs)  # type: ignore[arg-type]
            raise guard_module.GenBacklashError("per stretch")

        guard_module.free_run = whole_batch_refused  # type: ignore[assignment]
    try:
        pipe = BacklashPipeline(NodeParameters(command_type="float64_multi_array"), worker=worker)
        n = int(seconds * 1000)
        data = paper_example(1).generate(1, n_samples=n)
        rng = np.random.default_rng(7)
        late = rng.exponential(400_000, n).astype(np.int64)
        lost = rng.random(n) < 0.3
        cost = np.zeros(n)
        for k in range(n):
            t = k * 1_000_000 + 1_000_000_000 + int(late[k])
            start = time.thread_time()
            pipe.on_command(Float64MultiArray(MultiArrayLayout(), (float(data.u[k]), k)), t)
            if not lost[k]:
                stamp = Time.from_ns(t + 200_000)
                pipe.on_encoder(JointState(Header(stamp), ("j",), (float(data.y[k]),)), t + 200_000)
            cost[k] = time.thread_time() - start
            if k % 100 == 99:
                workers[0].flush()
        pipe.close()
    finally:
        guard_module.free_run = real_free_run
    return cost


def in_process_rows(seconds: float) -> list[list[object]]:
    rows: list[list[object]] = []
    for label, per_stretch in (("stretch by stretch (before)", True), ("one scan (now)", False)):
        cost = in_process(seconds, per_stretch) * 1e3
        first, rest = cost[: int(FIRST_S * 1000)], cost[int(FIRST_S * 1000) :]
        for window, part in (("first 5 s", first), ("rest", rest)):
            rows.append(
                [
                    label,
                    window,
                    f"{part.sum() / 1e3 / (part.size / 1000):.3f}",
                    f"{np.percentile(part, 99):.2f}",
                    f"{part.max():.1f}",
                    int((part > 10.0).sum()),
                ]
            )
    return rows


def pct(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else float("nan")


def describe(window: Window) -> list[object]:
    node, echo = window.node, window.echo
    return [
        f"{pct(node, 50):.2f} / {pct(echo, 50):.2f}",
        f"{pct(node, 99):.1f} / {pct(echo, 99):.1f}",
        f"{node.max() if node.size else float('nan'):.0f} / "
        f"{echo.max() if echo.size else float('nan'):.0f}",
        f"{pct(node, 50) / pct(echo, 50):.2f}x / {pct(node, 99) / pct(echo, 99):.2f}x",
        f"{window.lost_node} / {window.lost_echo}",
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1 run of 8 s")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--rate", type=float, default=1000.0)
    args = parser.parse_args(argv)
    if reason := rclpy_missing():
        write_section("startup_latency", f"## Start-up latency (issue 24)\n\nSkipped: {reason}.")
        return 0
    if args.quick:
        args.runs, args.seconds = 1, 8.0
    started = time.perf_counter()
    load = os.getloadavg()[0]
    rows: list[list[object]] = []
    pooled: dict[str, list[np.ndarray]] = {"first_node": [], "first_echo": [], "rest_node": []}
    pooled["rest_echo"] = []
    for run in range(args.runs):
        played, status = run_once(args.rate, args.seconds)
        first, rest = windows(played, args.rate)
        stall = longest_stall_ms(played)
        for label, window in (("first 5 s", first), ("rest", rest)):
            rows.append([run + 1, label, *describe(window), f"{stall:.0f}", status])
        pooled["first_node"].append(first.node)
        pooled["first_echo"].append(first.echo)
        pooled["rest_node"].append(rest.node)
        pooled["rest_echo"].append(rest.echo)
        print(rows[-2], rows[-1], sep="\n", flush=True)
    for label, key in (("first 5 s", "first"), ("rest", "rest")):
        window = Window(
            np.concatenate(pooled[f"{key}_node"]), np.concatenate(pooled[f"{key}_echo"]), 0, 0
        )
        rows.append(["all", label, *describe(window)[:4], "", "", ""])
    process_table = md_table(
        [
            "guard's judgement",
            "window",
            "message-thread CPU per second of data (s)",
            "p99 per tick (ms)",
            "max per tick (ms)",
            "ticks over 10 ms",
        ],
        in_process_rows(args.seconds),
    )
    print(process_table)
    seconds = time.perf_counter() - started
    table = md_table(
        [
            "run",
            "window",
            "median node / echo (ms)",
            "p99 node / echo (ms)",
            "max node / echo (ms)",
            "node / echo: median, p99",
            "lost node / echo",
            f"longest stall (replies >= {STALL_MS:.0f} ms late)",
            "node exit",
        ],
        rows,
    )
    print(table)
    write_section(
        "startup_latency",
        f"""## Start-up latency (issue 24)

`{command_line()}`. Machine: {machine_description()}; 1-min load average {load:.1f} at the
start. Run time {seconds:.0f} s.

`genbacklash node --transport rclpy` (shipped parameters, a checkpoint file, a cold start), a
plain rclpy echo and an rclpy player in three processes; {args.rate:.0f} Hz commands
(`Float64MultiArray`), readings (`JointState`) and pings from the player for
{args.seconds:g} s; latency from the first command on, the first {FIRST_S:g} s apart.

{table}

In process (the pipeline and its live worker, {args.seconds:g} s of 1 kHz data, jittered
ticks, 30 % of the readings lost; CPU time of the message thread only):

{process_table}

Target (issue 24): compensated-command latency, median and p99, within 1.5x of the echo's in
the same run, the first 5 s after the first command included; no stall.
""",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
