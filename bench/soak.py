"""Soak: a million encoder samples of a wearing drivetrain through the message pipeline.

    python bench/soak.py [--samples N] [--quick] [--method windowed|recursive|both]

The node's own code path, message by message: a ``std_msgs/Float64MultiArray`` command at
~200 Hz (0-30 % jitter, held between messages) and a ``sensor_msgs/JointState`` encoder at
1 kHz (header-stamped, received 0-0.3 ms later) go through
:class:`~genbacklash_ros.node.pipeline.BacklashPipeline` (``on_command`` / ``on_encoder``, the
estimate published at 10 Hz, diagnostics at 1 Hz, a checkpoint every 10 s of data time to a
temporary file). The drivetrain is Example 1's general backlash whose dead-zone widths
``c_L``, ``c_R`` widen linearly by ``--wear`` (default 50 %) over the run, SNR 25. The data are
generated in chunks of 5000 samples as they are consumed, so the generator never holds more.

Every 50 000 samples (every 1/20 of a shorter run) it records the resident set size
(``/proc/self/statm``), the peak RSS (``getrusage``), the Python object count, the time spent
inside the pipeline (generation excluded) and the estimate's error against the drifting truth;
it counts divergences (estimates published in state ``diverged``; for the recursive identifier
also its re-initialisations). Each identifier runs in a fresh process.
Memory growth is measured from the record at 10 % of the run (after warm-up) to the end.
"""

from __future__ import annotations

import argparse
import gc
import multiprocessing
import os
import resource
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from _common import command_line, fmt_bytes, machine_description, md_table, write_section

from genbacklash_core import EstimatorState, GeneralBacklash, paper_example, simulate_backlash
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    Header,
    JointState,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline

SEED = 7300
MS = 1_000_000
GEN_CHUNK = 5_000  # samples generated at a time
RECORD_EVERY = 50_000  # samples between two records (at most 1/20 of the run)
COMMAND_HZ = 200.0
JITTER = 0.3  # share of the command period
SNR = 25.0
WARM_UP = 0.1  # share of the run before the memory reference
LAYOUT = MultiArrayLayout((MultiArrayDimension("joints", 2, 2),))
JOINTS = ("drive", "other")


@dataclass(frozen=True)
class Chunk:
    """Messages of one stretch of the run, in receive order, and the truth at its end."""

    events: list[tuple[int, bool, Float64MultiArray | JointState]]  # (receive ns, command?, msg)
    samples: int
    truth: np.ndarray


def worn(base: GeneralBacklash, factor: float) -> GeneralBacklash:
    """``base`` with both dead-zone widths scaled by ``factor``."""
    return GeneralBacklash(base.m_left, base.c_left * factor, base.m_right, base.c_right * factor)


def drivetrain(n_samples: int, wear: float, seed: int = SEED) -> Iterator[Chunk]:
    """The wearing drivetrain as message chunks of ``GEN_CHUNK`` encoder samples.

    Commands at nominal times ``k / COMMAND_HZ`` with up to ``JITTER`` of a period either side
    (so they stay in order); each encoder sample at ``t`` sees the latest command at or
    before ``t`` (zero-order hold, as the pipeline assumes); the gap factor grows linearly
    with the sample index, in blocks of 50 samples.
    """
    rng = np.random.default_rng(seed)
    base = paper_example(1).backlash
    period = round(1e9 / COMMAND_HZ)
    spread = int(JITTER * period)
    x_prev = 0.0
    last_t, last_u = -1, 0.0  # the command holding before the chunk (none yet: 0)
    next_k = 1  # next command index
    scale: float | None = None  # noise std, from the first chunk's clean output
    for start in range(0, n_samples, GEN_CHUNK):
        stop = min(start + GEN_CHUNK, n_samples)
        enc_t = np.arange(start + 1, stop + 1, dtype=np.int64) * MS
        last_k = int(enc_t[-1] // period)  # commands with nominal time up to the chunk end
        ks = np.arange(next_k, last_k + 1, dtype=np.int64)
        next_k = last_k + 1
        cmd_t = ks * period + rng.integers(-spread, spread + 1, ks.size)
        cmd_u = rng.uniform(-2.0, 2.0, ks.size)
        all_t = np.concatenate([[last_t], cmd_t])
        all_u = np.concatenate([[last_u], cmd_u])
        held = all_u[np.searchsorted(all_t, enc_t, side="right") - 1]
        clean = np.empty(enc_t.size)
        for b in range(0, enc_t.size, 50):
            factor = 1.0 + wear * (start + b + 25) / n_samples
            part = simulate_backlash(worn(base, factor), held[b : b + 50], x_prev)
            clean[b : b + 50] = part
            x_prev = float(part[-1])
        if scale is None:
            scale = float(np.std(clean)) / SNR
        y = clean + rng.normal(0.0, scale, enc_t.size)
        delay = rng.integers(0, 300_000, enc_t.size)
        events: list[tuple[int, bool, Float64MultiArray | JointState]] = [
            (int(t), True, Float64MultiArray(LAYOUT, (float(u), 0.25)))
            for t, u in zip(cmd_t.tolist(), cmd_u.tolist(), strict=True)
        ]
        events += [
            (t + d, False, JointState(Header(Time.from_ns(t)), JOINTS, (v, -1.0)))
            for t, d, v in zip(enc_t.tolist(), delay.tolist(), y.tolist(), strict=True)
        ]
        events.sort(key=lambda e: e[0])
        if ks.size:
            last_t, last_u = int(cmd_t[-1]), float(cmd_u[-1])
        truth = worn(base, 1.0 + wear * stop / n_samples).parameters()
        yield Chunk(events, stop - start, truth)


def rss_bytes() -> int:
    """Resident set size now (Linux ``/proc/self/statm``)."""
    with open("/proc/self/statm", encoding="ascii") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def peak_rss_bytes() -> int:
    """Peak resident set size of this process (``ru_maxrss``, KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


@dataclass
class Record:
    samples: int
    rss: int
    peak: int
    objects: int
    seconds: float  # inside the pipeline since the previous record
    error: float  # max |parameter error| against the truth now
    state: str


@dataclass
class Soak:
    method: str
    samples: int
    records: list[Record] = field(default_factory=list)
    divergences: int = 0  # estimates published in state "diverged" (transitions into it)
    restarts: int = 0  # recursive: re-initialisations
    states: dict[str, int] = field(default_factory=dict)
    checkpoints: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    messages: int = 0
    seconds: float = 0.0


def run(method: str, n_samples: int, wear: float) -> Soak:
    """Feed the drivetrain through a pipeline message by message; the records."""
    result = Soak(method, n_samples)
    with tempfile.TemporaryDirectory() as tmp:
        params = NodeParameters(
            command_type="float64_multi_array",
            command_index=0,
            joint="drive",
            method=method,  # type: ignore[arg-type]
            checkpoint_file=str(Path(tmp) / "estimate.json"),
            checkpoint_period=10.0,
            publish_rate=10.0,
        )
        pipe = BacklashPipeline(params)
        on_command, on_encoder = pipe.on_command, pipe.on_encoder
        done = 0
        since = 0.0
        diverged = False
        every = max(GEN_CHUNK, min(RECORD_EVERY, n_samples // 20) // GEN_CHUNK * GEN_CHUNK)
        gc.collect()
        for chunk in drivetrain(n_samples, wear):
            t0 = time.perf_counter()
            for receive_ns, is_command, msg in chunk.events:
                outputs = on_command(msg, receive_ns) if is_command else on_encoder(msg, receive_ns)
                for out in outputs:
                    if out.topic != "estimate" or out.estimate is None:
                        continue
                    state = out.estimate.state
                    result.states[state.value] = result.states.get(state.value, 0) + 1
                    if state is EstimatorState.DIVERGED and not diverged:
                        result.divergences += 1
                    diverged = state is EstimatorState.DIVERGED
            elapsed = time.perf_counter() - t0
            since += elapsed
            result.seconds += elapsed
            result.messages += len(chunk.events)
            done += chunk.samples
            if done % every == 0 or done == n_samples:
                est = pipe.estimate
                error = (
                    float(np.max(np.abs(est.parameters - chunk.truth)))
                    if est.available
                    else float("nan")
                )
                result.records.append(
                    Record(
                        done,
                        rss_bytes(),
                        peak_rss_bytes(),
                        len(gc.get_objects()),
                        since,
                        error,
                        est.state.value,
                    )
                )
                since = 0.0
                print(
                    f"{method}: {done:,} samples, RSS {fmt_bytes(result.records[-1].rss)}, "
                    f"error {error:.4f}, {est.state.value}",
                    file=sys.stderr,
                    flush=True,
                )
        pipe.finish()
        stats = pipe.stats
        result.checkpoints = stats.checkpoints
        result.dropped = {k: v for k, v in stats.dropped.items() if v}
        restarts = getattr(pipe.identifier, "restarts", 0)
        result.restarts = int(restarts)
    return result


def quarter_rate(records: list[Record], first: bool) -> float:
    """Seconds in the pipeline per 1e5 samples over the first or last quarter of the run."""
    n = records[-1].samples
    low, high = (0, n / 4) if first else (3 * n / 4, n)
    seconds = 0.0
    samples = 0
    previous = 0
    for r in records:  # each record covers the samples since the previous one
        if low < r.samples <= high:
            seconds += r.seconds
            samples += r.samples - previous
        previous = r.samples
    return 1e5 * seconds / samples if samples else float("nan")


def report(results: list[Soak], wear: float, total: float) -> tuple[str, bool]:
    rows = []
    ok = True
    details = []
    for res in results:
        records = res.records
        n = res.samples
        reference = next(r for r in records if r.samples >= WARM_UP * n)
        end = records[-1]
        growth = (end.rss - reference.rss) / reference.rss
        peak = max(r.peak for r in records)
        first_q, last_q = quarter_rate(records, True), quarter_rate(records, False)
        passed = growth < 0.05 and res.divergences == 0
        ok &= passed
        rows.append(
            [
                res.method,
                f"{n:,}",
                fmt_bytes(peak),
                f"{fmt_bytes(reference.rss)} at {reference.samples:,}",
                fmt_bytes(end.rss),
                f"{100 * growth:+.2f} %",
                f"{end.objects - reference.objects:+,}",
                f"{first_q:.2f} s / {last_q:.2f} s",
                f"{end.error:.4f}",
                f"{np.nanmedian([r.error for r in records if r.samples >= reference.samples]):.4f}",
                f"{res.divergences} ({res.restarts} re-initialisations)"
                if res.method == "recursive"
                else str(res.divergences),
            ]
        )
        trace = md_table(
            ["samples", "RSS", "objects", "pipeline s since previous", "max error", "state"],
            [
                [
                    f"{r.samples:,}",
                    fmt_bytes(r.rss),
                    f"{r.objects:,}",
                    f"{r.seconds:.2f}",
                    f"{r.error:.4f}",
                    r.state,
                ]
                for r in records
            ],
        )
        states = ", ".join(f"{k}: {v}" for k, v in sorted(res.states.items()))
        dropped = ", ".join(f"{k}: {v}" for k, v in res.dropped.items()) or "none"
        details.append(
            f"""<details><summary>{res.method}: every record</summary>

{res.messages:,} messages, {1e6 * res.seconds / res.messages:.1f} µs per message in the
pipeline on average; {res.checkpoints} checkpoints written; dropped: {dropped};
published estimates by state: {states}.

{trace}

</details>"""
        )
    table = md_table(
        [
            "identifier",
            "encoder samples",
            "peak RSS",
            "RSS after warm-up",
            "RSS at the end",
            "growth",
            "Python objects (end - warm-up)",
            "pipeline time per 1e5 samples, first / last quarter",
            "max abs error at the end",
            "median of it after warm-up",
            "divergences",
        ],
        rows,
    )
    verdict = "met" if ok else "**not met**"
    text = f"""## Soak

{__doc__.split(chr(10), 3)[3].strip()}

Wear {100 * wear:.0f} % over the run. Machine: {machine_description()}. Total {total:.0f} s.

{table}

Target: memory growth < 5 % after warm-up, no divergence: {verdict}.
The error is against the truth at the end of the run; the estimate lags the drift by about
half a window (windowed) or ``1 / (1 - forgetting)`` samples (recursive).

{chr(10).join(details)}

Command: `{command_line()}`
"""
    return text, ok


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1_000_000, help="encoder samples")
    parser.add_argument("--quick", action="store_true", help="100 000 samples (smoke test)")
    parser.add_argument("--wear", type=float, default=0.5, help="relative gap growth")
    parser.add_argument(
        "--method", choices=("windowed", "recursive", "both"), default="both", help="identifier"
    )
    args = parser.parse_args()
    n = 100_000 if args.quick else args.samples
    if n < 20 * GEN_CHUNK:
        parser.error(f"--samples must be at least {20 * GEN_CHUNK}")
    methods = ["windowed", "recursive"] if args.method == "both" else [args.method]
    started = time.perf_counter()
    results = []
    for method in methods:  # each in a fresh process: its own memory and peak RSS
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
            results.append(pool.submit(run, method, n, args.wear).result())
    text, _ = report(results, args.wear, time.perf_counter() - started)
    write_section("soak", text)


if __name__ == "__main__":
    main()
