"""The pipeline's batch form (``BacklashPipeline.on_batch``) against its per-message path.

The batch form takes stretches of messages that only need bookkeeping in numpy steps and
every other message through the per-message path; whatever the stream -- clean, or with any
of the faults of test_faults.py -- and however it is cut into batches, it must publish the
same compensated commands, estimates and diagnostics, to the last bit.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core.scenarios import OperationSettings, operation_record
from genbacklash_ros.node.messages import MessageError, read_command, read_encoder
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline, Output
from genbacklash_ros.node.publish import Schedule
from genbacklash_ros.node.sample_rule import EncoderPeriod
from genbacklash_ros.node.silence import SilentStreams
from genbacklash_ros.node.stretch import first_at
from tests.ros.node.test_faults import FAULTS, PARAMS, Event, Fault, Scenario, drivetrain

# (message index, topic, message, stamp): what the node published, in order
Published = list[tuple[int, str, Any, int]]


@dataclass
class Run:
    published: Published = field(default_factory=list)
    sent: dict[int, tuple[int, float]] = field(default_factory=dict)  # index -> (stamp, sent)


def _values(event: Event, params: NodeParameters) -> tuple[int, float] | None:
    """What a transport reads of a message (None: the adapters reject it)."""
    msg = event.message()
    try:
        if event.kind == "command":
            stamp, value = read_command(msg, params.command_type, index=params.command_index)
        else:
            stamp, value = read_encoder(msg, params.encoder_type, joint=params.joint)
    except MessageError:
        return None
    return stamp or 0, value


def _record(run: Run, index: int, outs: list[Output]) -> None:
    for out in outs:
        if out.topic == "compensated_command":
            continue  # the per-message adapters' copy of the sent value
        run.published.append((index, out.topic, out.message, out.stamp_ns))


def per_message(pipe: BacklashPipeline, events: list[Event]) -> Run:
    run = Run()
    for k, event in enumerate(events):
        read = _values(event, pipe.params)
        if read is None:
            outs = (pipe.on_command if event.kind == "command" else pipe.on_encoder)(
                event.message(), event.receive_ns
            )
        elif event.kind == "command":
            taken = pipe.on_command_value(read[0], read[1], event.receive_ns)
            outs = []
            if taken is not None:
                stamp, sent, outs = taken
                run.sent[k] = (stamp, sent)
        else:
            outs = pipe.on_encoder_value(read[0], read[1], event.receive_ns)
        _record(run, k, outs)
    _record(run, len(events), pipe.finish())
    return run


def batched(pipe: BacklashPipeline, events: list[Event], cuts: list[int]) -> Run:
    """``events`` through :meth:`BacklashPipeline.on_batch` in batches ending at ``cuts``
    (a message the adapters reject goes by itself, as a transport would hand it on)."""
    run = Run()
    reads = [_values(event, pipe.params) for event in events]
    bounds = sorted({0, len(events), *(c for c in cuts if 0 < c < len(events))})
    bounds += [k for k, read in enumerate(reads) if read is None]
    bounds += [k + 1 for k, read in enumerate(reads) if read is None]
    bounds = sorted(set(bounds))
    for start, end in itertools.pairwise(bounds):
        if reads[start] is None:
            event = events[start]
            method = pipe.on_command if event.kind == "command" else pipe.on_encoder
            _record(run, start, method(event.message(), event.receive_ns))
            continue
        part = events[start:end]
        out = pipe.on_batch(
            np.array([e.kind == "command" for e in part], dtype=bool),
            np.array([reads[k][0] for k in range(start, end)], dtype=np.int64),  # type: ignore[index]
            np.array([reads[k][1] for k in range(start, end)], dtype=np.float64),  # type: ignore[index]
            np.array([e.receive_ns for e in part], dtype=np.int64),
        )
        for k in np.flatnonzero(out.accepted).tolist():
            run.sent[start + k] = (int(out.stamps[k]), float(out.sent[k]))
        for k, item in out.outputs:
            _record(run, start + k, [item])
    _record(run, len(events), pipe.finish())
    return run


def assert_same(one: BacklashPipeline, two: BacklashPipeline, a: Run, b: Run) -> None:
    assert a.sent == b.sent  # every compensated command, bit for bit
    assert a.published == b.published  # estimates and diagnostics, where and when
    assert one.stats == two.stats
    assert np.array_equal(one.estimate.parameters, two.estimate.parameters)


def scenario_of(fault: Fault, seed: int) -> Scenario:
    scenario = drivetrain(seed, fault.commands)
    scenario.fault_from = round(2.0 * 1e9)
    scenario.fault_to = round((2.0 + fault.seconds) * 1e9)
    fault.events(scenario, np.random.default_rng([seed, 7]))
    return scenario


CLEAN = Fault("clean", "")


@pytest.mark.parametrize("fault", [CLEAN, *FAULTS], ids=["clean", *(f.name for f in FAULTS)])
def test_batches_publish_what_the_per_message_path_publishes(fault: Fault) -> None:
    events = scenario_of(fault, seed=5).events
    one, two = BacklashPipeline(fault.params), BacklashPipeline(fault.params)
    rng = np.random.default_rng(23)
    cuts = np.cumsum(rng.integers(1, 3000, 40)).tolist()
    assert_same(one, two, per_message(one, events), batched(two, events, cuts))


@settings(max_examples=12, deadline=None)
@given(
    fault=st.sampled_from([CLEAN, *FAULTS]),
    seed=st.integers(0, 2**16),
    cuts=st.lists(st.integers(1, 7000), max_size=12),
    in_loop=st.booleans(),
)
def test_batches_cut_anywhere(fault: Fault, seed: int, cuts: list[int], in_loop: bool) -> None:
    events = scenario_of(fault, seed).events[: 2500 + seed % 3000]
    params = fault.params.replace(compensation_in_loop=in_loop)
    one, two = BacklashPipeline(params), BacklashPipeline(params)
    assert_same(one, two, per_message(one, events), batched(two, events, cuts))


def test_an_empty_batch_changes_nothing() -> None:
    pipe = BacklashPipeline(PARAMS)
    none = np.zeros(0, dtype=np.int64)
    out = pipe.on_batch(np.zeros(0, dtype=bool), none, np.zeros(0), none)
    assert out.outputs == [] and out.accepted.size == 0
    assert pipe.stats.commands == pipe.stats.encoder_messages == 0


@settings(max_examples=60, deadline=None)
@given(kinds=st.lists(st.booleans(), max_size=12), first=st.lists(st.booleans(), max_size=4))
def test_silence_many_is_each_in_turn(kinds: list[bool], first: list[bool]) -> None:
    one, two = SilentStreams(), SilentStreams()
    for k, is_cmd in enumerate(first):  # some history first
        for silence in (one, two):
            (silence.command if is_cmd else silence.encoder)(k * 10)
    receive = [1000 + 7 * k for k in range(len(kinds))]
    for is_cmd, t in zip(kinds, receive, strict=True):
        (one.command if is_cmd else one.encoder)(t)

    def seen(mine: bool) -> tuple[int, int, int] | None:
        own = [k for k, is_cmd in enumerate(kinds) if is_cmd is mine]
        after = [k for k in range(own[-1] + 1 if own else 0, len(kinds)) if kinds[k] is not mine]
        if not own and not after:
            return None
        return (receive[own[-1]] if own else -1), len(after), (receive[after[0]] if after else -1)

    two.arrived_many(seen(True), seen(False))
    for name in ("_command", "_encoder"):
        a, b = getattr(one, name), getattr(two, name)
        assert (a.last, a.since, a.others) == (b.last, b.since, b.others)


@given(steps=st.lists(st.integers(-5, 50), max_size=300))
def test_period_add_many_is_add_in_turn(steps: list[int]) -> None:
    one, two = EncoderPeriod(window=25), EncoderPeriod(window=25)
    for step in steps:
        one.add(step)
    two.add_many(steps)
    assert one.value == two.value


@given(
    times=st.lists(st.integers(0, 40), max_size=60),
    due=st.integers(-5, 45),
    start=st.integers(0, 70),
    end=st.integers(0, 70),
)
def test_first_at_is_the_first_late_message(
    times: list[int], due: int, start: int, end: int
) -> None:
    """The first message from ``start`` on (before ``end``) whose time is ``due`` or later,
    the times in any order; ``end`` when none is."""
    array = np.array(times, dtype=np.int64)
    end = min(end, array.size)
    late = np.flatnonzero(array[start:end] >= due)
    assert first_at(array, due, start, end) == (start + int(late[0]) if late.size else end)


def _frozen_encoder_after_a_jump(seed: int, hold_ms: int = 150) -> tuple[list[Event], int]:
    """2.5 s of the clean drivetrain (the estimate converges), then 150 ms of the last
    command held with the encoder steady, then a command far away while the encoder stays
    where it was: a stuck encoder, which only the command in force 20 ms before each
    reading reveals (``hold_ms`` after the steady part begins). Returns the events and the
    index of the jump."""
    events = [e for e in scenario_of(CLEAN, seed).events if e.true_ns < 2_500_000_000]
    last_cmd = next(e for e in reversed(events) if e.kind == "command")
    last_enc = next(e for e in reversed(events) if e.kind == "encoder")
    t0 = max(e.true_ns for e in events)
    tail: list[Event] = []
    for k in range(1, 301):  # 300 ms: commands every 5 ms, readings every 1 ms
        t = t0 + k * 1_000_000
        if k % 5 == 0:
            value = last_cmd.value if k <= hold_ms else last_cmd.value + 1.5
            tail.append(
                Event(
                    t,
                    "command",
                    t,
                    last_cmd.receive_ns + t - last_cmd.true_ns,
                    last_cmd.stamp_ns + t - last_cmd.true_ns,
                    value,
                )
            )
        stamp = last_enc.stamp_ns + t - last_enc.true_ns
        tail.append(Event(t + 1, "encoder", t, stamp + 100_000, stamp, last_enc.value))
    jump = len(events) + next(
        k for k, e in enumerate(tail) if e.kind == "command" and e.value != last_cmd.value
    )
    return events + tail, jump


@pytest.mark.parametrize("hold_ms", range(100, 165, 5))
@pytest.mark.parametrize("offset", [-1, 0, 1])
def test_a_stretch_starting_at_the_command_that_reveals_a_stuck_encoder(
    hold_ms: int, offset: int
) -> None:
    """Wherever the feeds fall, a stretch that starts at (or just before) the jump holds it
    for the readings 20 ms after it."""
    events, jump = _frozen_encoder_after_a_jump(seed=8, hold_ms=hold_ms)
    one, two = BacklashPipeline(PARAMS), BacklashPipeline(PARAMS)
    a = per_message(one, events)
    assert one.stats.dropped["encoder_stuck"] > 0  # the scenario does find the stuck encoder
    assert_same(one, two, a, batched(two, events, [jump + offset]))


def _operation_events(seed: int) -> tuple[np.ndarray, ...]:
    """A drivetrain in operation (moves, dwells with the command held at 100 Hz, a
    quantised 1 kHz encoder losing 2 % of its readings) as ``on_batch`` takes it: kinds,
    header stamps, values, receive times, in the order a node receives them."""
    rec = operation_record(OperationSettings(duration=12.0), seed)
    cmd_t, enc_t = rec.command_t_ns, rec.encoder_t_ns
    receive = np.concatenate([cmd_t, enc_t + 200_000])
    kinds = np.concatenate([np.ones(cmd_t.size, dtype=bool), np.zeros(enc_t.size, dtype=bool)])
    heads = np.concatenate([np.zeros(cmd_t.size, dtype=np.int64), enc_t])
    values = np.concatenate([rec.command_u, rec.encoder_y])
    order = np.lexsort((~kinds, receive))  # a command and a reading at once: the command first
    return kinds[order], heads[order], values[order], receive[order]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_operation_batches_match_and_keep_off_the_per_message_path(seed: int) -> None:
    """On a drivetrain in operation the batch path publishes what the per-message path does
    and sends the same commands; it takes the feeds, the estimate steps that come due at
    commands and a dwell's repeated commands itself, so few messages go one by one."""
    kinds, heads, values, receive = _operation_events(seed)
    params = NodeParameters(command_type="float64", encoder_type="float64")
    one, two = BacklashPipeline(params), BacklashPipeline(params)
    a = Run()
    for k, (is_cmd, head, value, rx) in enumerate(
        zip(kinds.tolist(), heads.tolist(), values.tolist(), receive.tolist(), strict=True)
    ):
        if is_cmd:
            taken = one.on_command_value(head, value, rx)
            outs = []
            if taken is not None:
                stamp, sent, outs = taken
                a.sent[k] = (stamp, sent)
        else:
            outs = one.on_encoder_value(head, value, rx)
        _record(a, k, outs)
    _record(a, kinds.size, one.finish())
    alone = [0]

    def counted(method: Any) -> Any:
        def call(*args: Any) -> Any:
            alone[0] += 1
            return method(*args)

        return call

    two.on_command_value = counted(two.on_command_value)  # type: ignore[method-assign]
    two.on_encoder_value = counted(two.on_encoder_value)  # type: ignore[method-assign]
    b = Run()
    for start in range(0, kinds.size, 4096):
        end = start + 4096
        out = two.on_batch(
            kinds[start:end], heads[start:end], values[start:end], receive[start:end]
        )
        for k in np.flatnonzero(out.accepted).tolist():
            b.sent[start + k] = (int(out.stamps[k]), float(out.sent[k]))
        for k, item in out.outputs:
            _record(b, start + k, [item])
    _record(b, kinds.size, two.finish())
    assert_same(one, two, a, b)
    assert sum(topic == "estimate" for _, topic, _, _ in b.published) > 50
    # before the feeds and estimate steps were taken in stretches, 2.7 % went one by one
    assert alone[0] < 0.01 * kinds.size, alone[0]


def test_a_schedule_copy_looks_ahead_without_moving_the_schedule() -> None:
    clock = Schedule(publish_ns=100, checkpoint_ns=None, feed_ns=1000)
    clock.tick(0)
    ahead = clock.copy()
    assert ahead.tick(150) and ahead.due(150).estimate
    ahead.estimate_done(150)
    ahead.settle()
    assert (ahead.now, ahead.next_due) == (150, 200)
    assert (clock.now, clock.next_due) == (0, 100)  # the original as it was
