"""Replay throughput: encoder messages per second through ``genbacklash replay``, end to end.

    python bench/replay.py [--quick]

Issue 4's target: replay >= 100k encoder messages/s end to end (read, decode, align, estimate,
compensate, write). A drivetrain bag (JointState encoder at 1 kHz, Float64MultiArray commands
at 100-1000 Hz, a wearing gap) is replayed by :func:`genbacklash_ros.bags.replay.replay`, and in
the same run, round-robin, against two references on the same bag:

* **decode-all replay**: the same pipeline fed our message objects, every message decoded by
  rosbags' deserializer and converted by our adapters, the outputs serialized by rosbags (how
  replay worked before the CDR fast path);
* **IO floor**: only reading the input messages' bytes with rosbags and writing as many
  messages to an output bag as the replay writes (copy + outputs): no decoding, no pipeline.
  Nothing built on rosbags' pure-Python MCAP reader and writer can be faster than this.

Also timed alone: the pipeline on pre-decoded values (no IO), to show where the time goes.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import command_line, machine_description, md_table, parse_args, write_section

from genbacklash_ros.bags.bagio import BagReader, BagWriter, align
from genbacklash_ros.bags.replay import OUTPUT_TOPICS, replay
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, write_drivetrain_bag
from genbacklash_ros.node.checkpoint import warm_start
from genbacklash_ros.node.messages import read_command, read_encoder
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BATCH_SAMPLES, BacklashPipeline

SEED = 4400
REPEATS = 3


def run_replay(bag: Path, out: Path) -> tuple[float, int, int]:
    """Ours: seconds, encoder messages, messages written."""
    shutil.rmtree(out, ignore_errors=True)
    started = time.perf_counter()
    result = replay(bag, out, command_topic=COMMAND_TOPIC, encoder_topic=ENCODER_TOPIC)
    seconds = time.perf_counter() - started
    assert result.error == "", result.error
    return seconds, result.stats.encoder_messages, result.messages_out


def run_decode_all(bag: Path, out: Path) -> float:
    """The pipeline fed decoded message objects; outputs serialized by rosbags."""
    shutil.rmtree(out, ignore_errors=True)
    started = time.perf_counter()
    with BagReader(bag) as reader, BagWriter(out) as writer:
        cmd = reader.topic(COMMAND_TOPIC)
        enc = reader.topic(ENCODER_TOPIC)
        params = NodeParameters(command_type="float64_multi_array", encoder_type="joint_state")
        pipe = BacklashPipeline(params.replace(joint="drive_joint"))
        writer.add_topic(COMMAND_TOPIC, cmd.msgtype)
        writer.add_topic(ENCODER_TOPIC, enc.msgtype)
        for item in reader.messages([COMMAND_TOPIC, ENCODER_TOPIC]):
            writer.write_raw(item.topic, item.log_time_ns, item.raw, item.msgtype)
            if item.topic == COMMAND_TOPIC:
                outs = pipe.on_command(item.message, item.log_time_ns)  # type: ignore[arg-type]
            else:
                outs = pipe.on_encoder(item.message, item.log_time_ns)
            for o in outs:
                writer.write(OUTPUT_TOPICS[o.topic], item.log_time_ns, o.message)
        for o in pipe.finish():
            writer.write(OUTPUT_TOPICS[o.topic], item.log_time_ns, o.message)
    return time.perf_counter() - started


def run_io_floor(bag: Path, out: Path, n_written: int) -> float:
    """Read the input's bytes and write ``n_written`` messages: rosbags' MCAP IO alone."""
    shutil.rmtree(out, ignore_errors=True)
    started = time.perf_counter()
    with BagReader(bag) as reader, BagWriter(out) as writer:
        items = reader.raw_messages([COMMAND_TOPIC, ENCODER_TOPIC])
        written = 0
        for topic, log_time, msgtype, raw in items:
            writer.write_raw(topic, log_time, raw, msgtype)
            written += 1
            if written % 4 == 0 and written < n_written:  # the outputs' share, as raw copies
                writer.write_raw("/out", log_time, raw, msgtype)
                written += 1
        while written < n_written:
            writer.write_raw("/out", log_time, raw, msgtype)
            written += 1
    return time.perf_counter() - started


Event = tuple[bool, int | None, float, int]


def decoded_events(bag: Path) -> list[Event]:
    """``(is_command, header stamp, value, log time)`` of every message, decoded once."""
    events: list[Event] = []
    with BagReader(bag) as reader:
        for item in reader.messages([COMMAND_TOPIC, ENCODER_TOPIC]):
            if item.topic == COMMAND_TOPIC:
                stamp, value = read_command(item.message, "float64_multi_array")
                events.append((True, stamp, value, item.log_time_ns))
            else:
                stamp, value = read_encoder(item.message, "joint_state", joint="drive_joint")
                events.append((False, stamp, value, item.log_time_ns))
    return events


def run_pipeline_only(events: list[Event]) -> float:
    """The pipeline on values decoded beforehand (no IO, no decoding)."""
    params = NodeParameters(command_type="float64_multi_array", joint="drive_joint")
    started = time.perf_counter()
    pipe = BacklashPipeline(params)
    for is_cmd, stamp, value, log_time in events:
        if is_cmd:
            pipe.on_command_value(stamp, value, log_time)
        else:
            pipe.on_encoder_value(stamp, value, log_time)
    pipe.finish()
    return time.perf_counter() - started


def aligned_samples(events: list[Event]) -> tuple[np.ndarray, np.ndarray]:
    """``(u, y)``: each encoder reading with the command holding at its time (the pipeline's
    zero-order hold, :func:`~genbacklash_ros.bags.bagio.align`, without its fault checks)."""
    commands = [e for e in events if e[0]]
    readings = [e for e in events if not e[0]]
    series = align(
        np.array([e[3] for e in commands], dtype=np.int64),
        np.array([e[2] for e in commands]),
        np.array([e[3] for e in readings], dtype=np.int64),
        np.array([e[2] for e in readings]),
    )
    return series.u, series.y


WARMUP_SAMPLES = 5000  # the identifier's warm-up (cold starts) is over well before this


def run_identifier_only(samples: tuple[np.ndarray, np.ndarray], method: str) -> tuple[float, float]:
    """The node's online identifier (default settings) alone on aligned samples, fed in the
    pipeline's batches: the estimation's own floor, with no IO, alignment or compensation.
    Seconds for the whole record and for the samples after the first ``WARMUP_SAMPLES``
    (the steady state, without the warm-up's cold starts)."""
    u, y = samples
    params = NodeParameters(command_type="float64_multi_array", method=method)
    started = time.perf_counter()
    warmed = started
    identifier = warm_start(params).identifier
    for start in range(0, u.size, BATCH_SAMPLES):
        if start == WARMUP_SAMPLES // BATCH_SAMPLES * BATCH_SAMPLES:
            warmed = time.perf_counter()
        identifier.update_many(u[start : start + BATCH_SAMPLES], y[start : start + BATCH_SAMPLES])
    ended = time.perf_counter()
    return ended - started, ended - warmed


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    duration = 10.0 if args.quick else 60.0
    machine = machine_description()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        bag = root / "drivetrain"
        write_drivetrain_bag(bag, seed=SEED, duration=duration)
        events = decoded_events(bag)
        samples = aligned_samples(events)
        rows: dict[str, list[float]] = {
            "ours": [],
            "decode": [],
            "floor": [],
            "pipe": [],
            "windowed": [],
            "windowed_steady": [],
            "recursive": [],
            "recursive_steady": [],
        }
        n_enc = n_out = 0
        for k in range(REPEATS):  # round-robin: load bursts hit all alike
            print(f"replay round {k + 1}/{REPEATS}", file=sys.stderr, flush=True)
            seconds, n_enc, n_out = run_replay(bag, root / "ours")
            rows["ours"].append(seconds)
            rows["decode"].append(run_decode_all(bag, root / "decode"))
            rows["floor"].append(run_io_floor(bag, root / "floor", n_out))
            rows["pipe"].append(run_pipeline_only(events))
            for method in ("windowed", "recursive"):
                whole, steady = run_identifier_only(samples, method)
                rows[method].append(whole)
                rows[f"{method}_steady"].append(steady)
        with BagReader(bag) as reader:
            n_cmd = reader.topics[COMMAND_TOPIC].count
    best = {key: min(values) for key, values in rows.items()}
    rate = {key: n_enc / value for key, value in best.items()}
    n_steady = samples[0].size - WARMUP_SAMPLES // BATCH_SAMPLES * BATCH_SAMPLES
    for method in ("windowed", "recursive"):
        rate[f"{method}_steady"] = n_steady / best[f"{method}_steady"]
    warmup = {m: best[m] - best[f"{m}_steady"] for m in ("windowed", "recursive")}
    table = md_table(
        ["path", "best of 3 (s)", "encoder msgs/s", "ours / it (time)"],
        [
            ["genbacklash replay (ours)", f"{best['ours']:.3f}", f"{rate['ours']:,.0f}", "1"],
            [
                "decode-all replay (before the CDR fast path)",
                f"{best['decode']:.3f}",
                f"{rate['decode']:,.0f}",
                f"{best['ours'] / best['decode']:.2f}",
            ],
            [
                "IO floor: rosbags read + write only",
                f"{best['floor']:.3f}",
                f"{rate['floor']:,.0f}",
                f"{best['ours'] / best['floor']:.2f}",
            ],
            [
                "pipeline alone on decoded values (no IO)",
                f"{best['pipe']:.3f}",
                f"{rate['pipe']:,.0f}",
                f"{best['ours'] / best['pipe']:.2f}",
            ],
            *(
                [
                    f"{method} identifier alone (default settings, aligned samples)",
                    f"{best[method]:.3f}",
                    f"{rate[method]:,.0f}",
                    f"{best['ours'] / best[method]:.2f}",
                ]
                for method in ("windowed", "recursive")
            ),
            *(
                [
                    f"{method} identifier alone, after the first {WARMUP_SAMPLES:,} samples",
                    f"{best[f'{method}_steady']:.3f}",
                    f"{rate[f'{method}_steady']:,.0f}",
                    "",
                ]
                for method in ("windowed", "recursive")
            ),
        ],
    )
    verdict = "met" if rate["ours"] >= 100_000 else "NOT met"
    slow = [
        name
        for key, name in (
            ("floor", "the rosbags IO alone"),
            ("windowed", "the default (windowed) estimation with its warm-up"),
        )
        if rate[key] < 100_000
    ]
    floors = (
        f"On this machine {' and '.join(slow)} already {'take' if len(slow) > 1 else 'takes'} "
        "more than the 10 us per encoder message the target allows, so no tuning of the "
        "replay itself can meet it."
        if slow
        else "Each stage alone fits in the 10 us per encoder message the target allows."
    )
    text = f"""## Replay throughput (issue 4)

`{command_line()}`. Machine: {machine}.

A {duration:.0f} s drivetrain bag (seed {SEED}): {n_enc:,} JointState encoder messages at
1 kHz, {n_cmd:,} Float64MultiArray commands at 100-1000 Hz with jitter; the replay writes
{n_out:,} messages (the inputs copied plus compensated commands, estimates and diagnostics).
Each path ran {REPEATS} times round-robin; best time shown. Rates are encoder messages per
second of wall time, end to end (open, read, decode, align, estimate, compensate, write,
close).

{table}

Target >= 100,000 encoder messages/s: **{verdict}** ({rate["ours"]:,.0f}/s). Against the
decode-all replay the CDR fast path is {best["decode"] / best["ours"]:.1f}x faster. The IO
floor - rosbags' pure-Python MCAP reader and writer with no decoding and no pipeline at all -
runs at {rate["floor"]:,.0f} encoder messages/s on this bag; the pipeline alone (online
identifier included) at {rate["pipe"]:,.0f}/s. The online identifier by itself - the core's
numpy estimation at its default settings, fed the aligned samples in the pipeline's
64-sample batches, nothing else - takes {rate["windowed"]:,.0f} samples/s (windowed, the
default method) and {rate["recursive"]:,.0f}/s (recursive) over the record. Of that, the
warm-up costs {warmup["windowed"]:.2f} s (windowed: its cold starts, the paper's batch
iteration with output-error refinement on the first few hundred samples, each 0.1-0.3 s)
and {warmup["recursive"]:.2f} s (recursive); after it the identifiers run at
{rate["windowed_steady"]:,.0f} and {rate["recursive_steady"]:,.0f} samples/s. {floors}
"""
    write_section("replay", text)
    print(text)


if __name__ == "__main__":
    main()
