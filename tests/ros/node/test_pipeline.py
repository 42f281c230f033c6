"""The message-level pipeline on synthetic streams of the paper's Example 1."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import (
    Estimate,
    EstimatorState,
    GeneralBacklash,
    Structure,
    paper_example,
    simulate_backlash,
)
from genbacklash_core.measured import TrackingVerdict
from genbacklash_ros.node.checkpoint import Checkpoint, load_checkpoint, save_checkpoint
from genbacklash_ros.node.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    MultiArrayDimension,
    MultiArrayLayout,
    Time,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline, Output

MS = 1_000_000
TRUTH = paper_example(1).model
LAYOUT = MultiArrayLayout((MultiArrayDimension("joints", 2, 2),))


@dataclass(frozen=True)
class Event:
    receive_ns: int
    kind: str  # "command" or "encoder"
    msg: Any


def example1_events(
    seed: int,
    seconds: float,
    *,
    command_hz: float = 200.0,
    jitter: float = 0.3,
    snr: float = 25.0,
) -> list[Event]:
    """Example 1 as a drivetrain would publish it.

    The command is a Float64MultiArray ``[other joint, drive]`` at ``command_hz`` with
    jitter (its time is its receive time: it has no header); the encoder a 1 kHz JointState
    ``[other, drive]`` with header stamps, received 0-0.3 ms later. The drivetrain holds each
    command until the next, as the pipeline assumes.
    """
    rng = np.random.default_rng(seed)
    period = round(1e9 / command_hz)
    n_cmd = int(seconds * command_hz)
    spread = int(jitter * period)
    cmd_t = np.arange(1, n_cmd + 1) * period + rng.integers(-spread, spread + 1, n_cmd)
    cmd_u = rng.uniform(-2.0, 2.0, n_cmd)
    enc_t = np.arange(1, int(seconds * 1000) + 1, dtype=np.int64) * MS
    held = np.searchsorted(cmd_t, enc_t, side="right") - 1
    enc_t, held = enc_t[held >= 0], held[held >= 0]
    x = simulate_backlash(TRUTH, cmd_u[held])
    y = x + rng.normal(0.0, float(np.std(x)) / snr, x.size)
    events = [
        Event(int(t), "command", Float64MultiArray(LAYOUT, (0.25, float(u))))
        for t, u in zip(cmd_t, cmd_u, strict=True)
    ]
    for t, v in zip(enc_t, y, strict=True):
        msg = JointState(Header(Time.from_ns(int(t))), ("other", "drive"), (-1.0, float(v)))
        events.append(Event(int(t) + int(rng.integers(0, 300_000)), "encoder", msg))
    events.sort(key=lambda e: (e.receive_ns, e.kind))
    return events


def run(pipe: BacklashPipeline, events: list[Event], finish: bool = True) -> list[Output]:
    outputs: list[Output] = []
    for event in events:
        if event.kind == "command":
            outputs += pipe.on_command(event.msg, event.receive_ns)
        else:
            outputs += pipe.on_encoder(event.msg, event.receive_ns)
    if finish:
        outputs += pipe.finish()
    return outputs


def numbers_in(msg: Any) -> Iterator[float]:
    """Every number an output carries (diagnostic values parsed where they are numbers)."""
    if isinstance(msg, Float64):
        yield msg.data
    elif isinstance(msg, Float64MultiArray):
        yield from msg.data
    elif isinstance(msg, JointState):
        yield from (*msg.position, *msg.velocity, *msg.effort)
    elif isinstance(msg, DiagnosticArray):
        for status in msg.status:
            for kv in status.values:
                assert kv.value.lower() not in ("nan", "inf", "-inf"), kv
                try:
                    yield float(kv.value)
                except ValueError:
                    pass


def assert_all_finite(outputs: list[Output]) -> None:
    for out in outputs:
        assert all(math.isfinite(v) for v in numbers_in(out.message)), out


# the streams' plant answers a command at once (no servo): every reading is a sample, no
# settling rule (genbacklash_core.settling, tested in tests/core/test_settling.py)
PARAMS = NodeParameters(joint="drive", command_index=1, settle_time=0.0)


# --------------------------------------------------------------------------- identification


@pytest.fixture(scope="module")
def example1() -> list[Event]:
    return example1_events(seed=11, seconds=8.0)


@pytest.mark.parametrize("method", ["windowed", "recursive"])
def test_example1_streams_reach_the_known_parameters(example1: list[Event], method: str) -> None:
    pipe = BacklashPipeline(PARAMS.replace(method=method))
    outputs = run(pipe, example1)
    est = pipe.estimate
    assert est.state in (EstimatorState.CONVERGED, EstimatorState.CONVERGING)
    assert np.max(np.abs(est.parameters - TRUTH.parameters())) < 0.05
    stats = pipe.stats
    encoders = sum(e.kind == "encoder" for e in example1)
    assert stats.encoder_messages == encoders and stats.samples == encoders
    assert sum(stats.dropped.values()) == 0
    assert_all_finite(outputs)
    topics = Counter(o.topic for o in outputs)
    assert 7 * 10 <= topics["estimate"] <= 8 * 10 + 1  # 10 Hz once an estimate exists
    assert 8 <= topics["diagnostics"] <= 9  # 1 Hz of data time, and the final one
    last = [o for o in outputs if o.topic == "estimate"][-1]
    assert isinstance(last.message, Float64MultiArray)
    assert last.message.layout.dim[0].label == ",".join(Structure(3).names())
    assert last.estimate is est


def test_one_compensated_command_per_command_stamped_like_it(example1: list[Event]) -> None:
    pipe = BacklashPipeline(PARAMS)
    outputs = run(pipe, example1)
    commands = [e for e in example1 if e.kind == "command"]
    compensated = [o for o in outputs if o.topic == "compensated_command"]
    assert len(compensated) == len(commands)
    for event, out in zip(commands, compensated, strict=True):
        assert out.stamp_ns == event.receive_ns  # no header: the receive time is its time
        assert isinstance(out.message, Float64MultiArray)
        assert out.message.layout == LAYOUT and out.message.data[0] == 0.25  # other joint
    # once converged the commands are compensated: they cross the gap at reversals
    sent = np.array([o.message.data[1] for o in compensated])
    raw = np.array([e.msg.data[1] for e in commands])
    assert np.allclose(sent[:50], raw[:50])  # warming up: pass-through
    assert np.max(np.abs(sent[-200:] - raw[-200:])) > 0.5


def test_joint_state_commands_keep_their_header() -> None:
    pipe = BacklashPipeline(NodeParameters(command_type="joint_state", joint="a"))
    msg = JointState(Header(Time(4, 5), "base"), ("b", "a"), (1.0, 0.5), (0.1, 0.2), ())
    (out,) = pipe.on_command(msg, receive_ns=9 * 10**9)
    assert out.stamp_ns == 4_000_000_005
    assert isinstance(out.message, JointState) and out.message.header == msg.header
    assert out.message.position == (1.0, 0.5) and out.message.velocity == (0.1, 0.2)


def test_replay_is_deterministic(example1: list[Event]) -> None:
    first = run(BacklashPipeline(PARAMS), example1[:3000])
    second = run(BacklashPipeline(PARAMS), example1[:3000])
    assert [(o.topic, o.message, o.stamp_ns) for o in first] == [
        (o.topic, o.message, o.stamp_ns) for o in second
    ]


def _spy_diagnostics(pipe: BacklashPipeline) -> list[int]:
    """The data times at which ``pipe`` builds a diagnostics report, as it builds them."""
    built: list[int] = []
    original = pipe.diagnostics

    def diagnostics(stamp_ns: int, *, stale: bool = False) -> Output:
        built.append(stamp_ns)
        return original(stamp_ns, stale=stale)

    pipe.diagnostics = diagnostics  # type: ignore[method-assign]
    return built


def test_the_answer_comes_before_the_periodic_outputs_are_built() -> None:
    """``answer`` returns the compensated command alone and builds no estimate or
    diagnostics; ``periodic`` right after makes them: message by message exactly
    ``on_command``'s outputs, so a live transport can publish the answer first and change
    nothing else. Commands at 1 kHz, each just before its reading, as an arm's controller
    sends them: the commands move the data clock, so the periodic outputs come due at
    commands."""
    events = example1_events(seed=3, seconds=4.0, command_hz=1000.0, jitter=0.0)
    pipe, same = BacklashPipeline(PARAMS), BacklashPipeline(PARAMS)
    built = _spy_diagnostics(pipe)
    due_at_commands: Counter[str] = Counter()

    def key(outputs: list[Output]) -> list[tuple[str, Any, int]]:
        return [(o.topic, o.message, o.stamp_ns) for o in outputs]

    for event in events:
        if event.kind == "command":
            answer = pipe.answer(event.msg, event.receive_ns)
            assert built == [] and answer is not None
            due = pipe.periodic()
            due_at_commands.update(o.topic for o in due)
            got = [answer, *due]
            assert key(got) == key(same.on_command(event.msg, event.receive_ns))
        else:
            got = pipe.on_encoder(event.msg, event.receive_ns)
            assert key(got) == key(same.on_encoder(event.msg, event.receive_ns))
        built.clear()
    assert key(pipe.finish()) == key(same.finish())
    assert due_at_commands["estimate"] >= 20 and due_at_commands["diagnostics"] >= 3


def test_periodic_outputs_not_taken_come_with_the_next_reading() -> None:
    """An answer whose ``periodic`` was not called: its periodic step runs before the next
    message moves the pipeline on, and its outputs come first in that call's."""
    pipe = BacklashPipeline(NodeParameters(command_type="float64"))
    assert pipe.answer(Float64(0.1), receive_ns=1 * MS) is not None
    assert pipe.periodic() == []  # the first message starts the data clock: nothing due
    reading = JointState(Header(Time.from_ns(2 * MS)), ("j",), (0.1,))
    assert pipe.on_encoder(reading, receive_ns=2 * MS) == []
    assert pipe.answer(Float64(0.2), receive_ns=1200 * MS) is not None  # a report is due
    later = JointState(Header(Time.from_ns(1201 * MS)), ("j",), (0.2,))
    outputs = pipe.on_encoder(later, receive_ns=1201 * MS)
    assert [o.topic for o in outputs] == ["diagnostics"]
    assert outputs[0].stamp_ns == 1200 * MS  # the command's step, on the command's time
    assert pipe.periodic() == []
    # also when the next message is one the adapters refuse
    assert pipe.answer(Float64(0.3), receive_ns=2400 * MS) is not None
    refused = JointState(Header(Time.from_ns(2401 * MS)), ("j",), ())  # no position
    outputs = pipe.on_encoder(refused, receive_ns=2401 * MS)
    assert [(o.topic, o.stamp_ns) for o in outputs] == [("diagnostics", 2400 * MS)]
    assert pipe.stats.dropped["encoder_invalid"] == 1


# --------------------------------------------------------------------------- compensation


def closed_loop(
    in_loop: bool, seed: int = 0, seconds: float = 8.0
) -> tuple[float, float, TrackingVerdict]:
    """The drivetrain driven by the compensated command; the identifier in the loop.

    Returns the largest parameter error, the RMS tracking error of the last 400 commands and
    the measured tracking's verdict.
    """
    rng = np.random.default_rng(seed)
    params = NodeParameters(
        command_type="float64", encoder_type="float64", compensation_in_loop=in_loop
    )
    pipe = BacklashPipeline(params)
    period = 5 * MS
    n_cmd = int(seconds * 200)
    cmd_t = np.arange(1, n_cmd + 1) * period + rng.integers(-period // 4, period // 4, n_cmd)
    wanted = rng.uniform(-1.6, 1.6, n_cmd)
    enc_t = np.arange(1, int(seconds * 1000) + 1) * MS
    events = sorted([(int(t), 0, k) for k, t in enumerate(cmd_t)] + [(int(t), 1, 0) for t in enc_t])
    x = 0.0
    errors = []
    for t, kind, k in events:
        if kind == 0:
            (out,) = pipe.on_command(Float64(float(wanted[k])), t)
            u = out.message.data  # type: ignore[union-attr]
            left, right = float(TRUTH.left([u])[0]), float(TRUTH.right([u])[0])
            x = min(max(x, min(left, right)), max(left, right))  # the play operator, eq. (20)
            errors.append(x - wanted[k])
        else:
            pipe.on_encoder(Float64(x + float(rng.normal(0.0, 0.02))), t)
    pipe.finish()
    error = float(np.max(np.abs(pipe.estimate.parameters - TRUTH.parameters())))
    return error, float(np.sqrt(np.mean(np.square(errors[-400:])))), pipe.measured


def test_in_loop_identification_follows_the_compensated_command() -> None:
    # the measured tracking's 3 s baseline and 3 s trial come first: 12 s leave 6 s at full
    error, tracking, measured = closed_loop(in_loop=True, seconds=12.0)
    assert error < 0.05 and tracking < 0.05
    assert measured.state == "on" and measured.ratio < 0.3, measured.reason


def test_raw_command_identification_fails_when_the_compensator_drives_the_plant() -> None:
    # the documented reason for compensation_in_loop: the raw command is not the plant input
    error, tracking, measured = closed_loop(in_loop=False)
    assert error > 0.1 and tracking > 0.2
    # not in the loop, the measured tracking only watches (its trust stays 1)
    assert measured.state == "watching" and measured.trust == 1.0, measured.reason


def converged_checkpoint(path: Path, model: GeneralBacklash = TRUTH) -> Path:
    est = Estimate(
        Structure(3), model.parameters(), np.eye(8) * 1e-6, 0.02, 0.6, "converged", 0.9, 1000
    )
    return save_checkpoint(path, est, 10**9)


@pytest.mark.parametrize("in_loop", [False, True])
def test_identifier_input_is_the_raw_or_the_sent_command(
    tmp_path: Path, example1: list[Event], in_loop: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = converged_checkpoint(tmp_path / "c.json")
    params = PARAMS.replace(checkpoint_file=str(path), compensation_in_loop=in_loop)
    pipe = BacklashPipeline(params)
    fed: list[np.ndarray] = []
    real = pipe.identifier.update_many

    def spy(u: Any, y: Any, breaks: Any = None) -> Estimate:
        fed.append(np.array(u))
        return real(u, y, breaks=breaks)

    monkeypatch.setattr(pipe.identifier, "update_many", spy)
    outputs = run(pipe, example1[:1200])
    raw = {e.msg.data[1] for e in example1[:1200] if e.kind == "command"}
    sent = {o.message.data[1] for o in outputs if o.topic == "compensated_command"}  # type: ignore[union-attr]
    if in_loop:
        # the measured tracking holds the checkpoint's model off until it has measured the
        # tracking without it (harm is judged against that baseline)
        assert not raw.isdisjoint(sent)
    else:
        assert raw.isdisjoint(sent)  # the checkpoint's model compensates from the first command
    used = set(np.concatenate(fed).tolist())
    assert used <= (sent if in_loop else raw)


def test_pass_through_when_compensation_is_off(example1: list[Event]) -> None:
    pipe = BacklashPipeline(PARAMS.replace(compensate=False))
    outputs = run(pipe, example1[:4000])
    commands = [e.msg for e in example1[:4000] if e.kind == "command"]
    assert [o.message for o in outputs if o.topic == "compensated_command"] == commands


def test_output_limits_hold_while_warming_up_and_after() -> None:
    pipe = BacklashPipeline(PARAMS.replace(u_min=-0.5, u_max=0.5, max_rate=0.3))
    outputs = run(pipe, example1_events(seed=2, seconds=4.0))
    sent = np.array([o.message.data[1] for o in outputs if o.topic == "compensated_command"])  # type: ignore[union-attr]
    assert sent.min() >= -0.5 and sent.max() <= 0.5
    assert np.max(np.abs(np.diff(sent))) <= 0.3 + 1e-12


# --------------------------------------------------------------------------- alignment


def test_fixed_grid_sampling(example1: list[Event]) -> None:
    pipe = BacklashPipeline(PARAMS.replace(sample_period=0.002))
    run(pipe, example1)
    assert pipe.stats.samples == pytest.approx(8.0 / 0.002, abs=3)
    assert np.max(np.abs(pipe.estimate.parameters - TRUTH.parameters())) < 0.05


def test_receive_time_ignores_header_stamps() -> None:
    pipe = BacklashPipeline(PARAMS.replace(stamp_source="receive"))
    pipe.on_command(Float64MultiArray(LAYOUT, (0.0, 0.5)), 1 * MS)
    for k in range(5):  # headers all equal: duplicates by header, fine by receive time
        pipe.on_encoder(JointState(Header(Time(7)), ("other", "drive"), (0.0, 0.1)), (2 + k) * MS)
    pipe.finish()
    assert pipe.stats.encoder_messages == 5 and pipe.stats.samples == 5


def test_zero_header_stamps_fall_back_to_receive_time() -> None:
    pipe = BacklashPipeline(PARAMS)
    pipe.on_command(Float64MultiArray(LAYOUT, (0.0, 0.5)), 1 * MS)
    for k in range(3):
        pipe.on_encoder(JointState(Header(), ("other", "drive"), (0.0, 0.1)), (2 + k) * MS)
    assert pipe.stats.encoder_messages == 3


def test_command_is_held_until_the_next_one(monkeypatch: pytest.MonkeyPatch) -> None:
    pipe = BacklashPipeline(NodeParameters(command_type="float64", encoder_type="float64"))
    fed: list[tuple[list[float], list[float]]] = []
    monkeypatch.setattr(
        pipe.identifier, "update_many", lambda u, y, breaks=None: fed.append((list(u), list(y)))
    )
    pipe.on_encoder(Float64(9.0), 1 * MS)  # before any command: skipped, counted quietly
    pipe.on_command(Float64(1.0), 2 * MS)
    for t in (3, 4):
        pipe.on_encoder(Float64(float(t)), t * MS)
    pipe.on_command(Float64(2.0), 4 * MS)  # same time as the encoder at 4 ms: it applies
    pipe.on_encoder(Float64(5.0), 5 * MS)
    pipe.on_command(Float64(3.0), 7 * MS)  # after the last encoder reading
    pipe.finish()
    assert fed and [v for u, _ in fed for v in u] == [1.0, 2.0, 2.0]
    assert [v for _, y in fed for v in y] == [3.0, 4.0, 5.0]
    assert pipe.stats.dropped["before_first_command"] == 1


def test_command_history_stays_bounded_without_encoder_data() -> None:
    pipe = BacklashPipeline(NodeParameters(command_type="float64", encoder_type="float64"))
    for k in range(10_000):
        pipe.on_command(Float64(math.sin(k / 50)), (k + 1) * MS)
    assert len(pipe._align.cmd_t) <= 4097  # commands of the last 0.1 s, trimmed in bulk
    pipe.on_encoder(Float64(0.0), 10_000 * MS)
    pipe.finish()
    assert pipe.stats.samples == 1


def test_samples_wait_for_their_command_or_the_timeout(monkeypatch: pytest.MonkeyPatch) -> None:
    pipe = BacklashPipeline(NodeParameters(command_type="float64", encoder_type="float64"), batch=1)
    fed: list[float] = []
    monkeypatch.setattr(
        pipe.identifier, "update_many", lambda u, y, breaks=None: fed.extend(list(y))
    )
    pipe.on_command(Float64(1.0), 1 * MS)
    pipe.on_encoder(Float64(0.5), 2 * MS)
    pipe.on_encoder(Float64(0.6), 3 * MS)
    assert fed == []  # a command stamped before 2 ms may still come
    pipe.on_command(Float64(1.5), 2 * MS + 500_000)
    assert fed == []  # fed at the next feed, not at the command
    pipe.on_encoder(Float64(0.7), 4 * MS)
    assert fed == [0.5]
    pipe.on_encoder(Float64(0.8), 200 * MS)  # 0.1 s on: the held command is taken
    assert fed == [0.5, 0.6, 0.7]


# --------------------------------------------------------------------------- bad input


def test_bad_messages_are_counted_not_raised() -> None:
    pipe = BacklashPipeline(PARAMS)
    good = Float64MultiArray(LAYOUT, (0.0, 0.5))
    assert pipe.on_command(good, 10 * MS)
    bad_commands = [
        (Float64(1.0), "expected a Float64MultiArray, got Float64"),
        (Float64MultiArray(LAYOUT, (0.0,)), "command_index 1 is out of range"),
        (Float64MultiArray(LAYOUT, (0.0, math.nan)), "not finite"),
        (Float64MultiArray(LAYOUT, (math.inf, 0.1)), "not finite"),
        ("not a message", "expected a Float64MultiArray, got str"),
    ]
    for k, (msg, _) in enumerate(bad_commands):
        assert pipe.on_command(msg, (11 + k) * MS) == []  # type: ignore[arg-type]
    assert pipe.on_command(good, 10 * MS) == []  # duplicate time
    assert pipe.on_command(good, 5 * MS) == []  # out of order
    enc = ("other", "drive")
    bad_encoders: list[Any] = [
        JointState(Header(Time.from_ns(20 * MS)), ("other",), (0.0,)),  # joint missing
        JointState(Header(Time.from_ns(21 * MS)), enc, (0.0, math.nan)),
        JointState(Header(Time.from_ns(22 * MS)), enc, (0.0,)),  # mismatched
        Float64(0.3),
        None,
    ]
    pipe.on_encoder(JointState(Header(Time.from_ns(30 * MS)), enc, (0.0, 0.1)), 31 * MS)
    for msg in bad_encoders:
        assert pipe.on_encoder(msg, 32 * MS) == []
    assert (
        pipe.on_encoder(JointState(Header(Time.from_ns(30 * MS)), enc, (0.0, 0.1)), 33 * MS) == []
    )
    assert (
        pipe.on_encoder(JointState(Header(Time.from_ns(29 * MS)), enc, (0.0, 0.1)), 34 * MS) == []
    )
    assert pipe.stats.encoder_messages == 1
    dropped = pipe.stats.dropped
    assert dropped["command_invalid"] == len(bad_commands)
    assert dropped["command_duplicate"] == 1 and dropped["command_out_of_order"] == 1
    assert dropped["encoder_invalid"] == len(bad_encoders)
    assert dropped["encoder_duplicate"] == 1 and dropped["encoder_out_of_order"] == 1
    assert "not after the previous" in pipe.stats.last_problem
    # the next report is a WARN naming the reasons
    outputs = pipe.on_encoder(
        JointState(Header(Time.from_ns(1_100 * MS)), enc, (0.0, 0.1)), 1_100 * MS
    )
    (diag,) = [o for o in outputs if o.topic == "diagnostics"]
    status = diag.message.status[0]  # type: ignore[union-attr]
    assert status.level == DiagnosticStatus.WARN
    assert "dropped since the last report" in status.message
    assert "5 encoder invalid (last: encoder: expected a JointState with a header" in (
        status.message
    )
    assert "command out of order" in status.message
    values = {kv.key: kv.value for kv in status.values}
    assert values["dropped_encoder_invalid"] == str(len(bad_encoders))
    # a report without new drops says nothing about them
    quiet = pipe.diagnostics(1_200 * MS).message.status[0]  # type: ignore[union-attr]
    assert "dropped" not in quiet.message


ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True, width=32)


@st.composite
def message_streams(draw: st.DrawFn) -> list[Event]:
    events: list[Event] = []
    for _ in range(draw(st.integers(0, 60))):
        kind = draw(st.sampled_from(["command", "encoder"]))
        t = draw(st.integers(0, 3 * 10**9))
        if kind == "command":
            data = tuple(draw(st.lists(ANY_FLOAT, max_size=3)))
            msg: Any = draw(
                st.sampled_from([Float64MultiArray(LAYOUT, data), Float64(data[0] if data else 0)])
            )
        else:
            names = tuple(draw(st.lists(st.sampled_from(["other", "drive"]), max_size=2)))
            position = tuple(draw(st.lists(ANY_FLOAT, max_size=2)))
            stamp = draw(st.integers(0, 3 * 10**9))
            msg = JointState(Header(Time.from_ns(stamp)), names, position)
        events.append(Event(t, kind, msg))
    return events


@settings(max_examples=40, deadline=None)
@given(events=message_streams(), in_loop=st.booleans())
def test_fuzz_pipeline_never_raises_nor_emits_non_finite(
    events: list[Event], in_loop: bool
) -> None:
    pipe = BacklashPipeline(PARAMS.replace(compensation_in_loop=in_loop))
    outputs = run(pipe, events)
    assert_all_finite(outputs)
    stats = pipe.stats
    commands = sum(e.kind == "command" for e in events)
    dropped_commands = sum(n for k, n in stats.dropped.items() if k.startswith("command_"))
    assert stats.commands + dropped_commands == commands


# --------------------------------------------------------------------------- checkpoints


def test_checkpoints_on_the_data_clock_and_warm_start(tmp_path: Path) -> None:
    path = tmp_path / "estimate.json"
    saved: list[Checkpoint] = []

    def writer(target: Path, checkpoint: Checkpoint) -> None:
        saved.append(checkpoint)
        save_checkpoint(target, checkpoint)

    params = PARAMS.replace(checkpoint_file=str(path), checkpoint_period=1.0)
    events = example1_events(seed=5, seconds=5.0)
    run(BacklashPipeline(params, checkpoint_writer=writer), events)
    times = [c.time_ns for c in saved]
    assert len(saved) >= 4 and times == sorted(times)
    periodic = times[:-1]  # and a last one at finish
    assert all(b - a >= 10**9 for a, b in itertools.pairwise(periodic))
    assert load_checkpoint(path).time_ns == times[-1]  # the last one, at finish
    # a new node warm-starts: compensates and publishes from its first messages
    pipe = BacklashPipeline(params)
    assert pipe.using_checkpoint and "warm start" in pipe.warm_start_note
    first = run(pipe, events[:400], finish=False)
    sent = [o.message.data[1] for o in first if o.topic == "compensated_command"]  # type: ignore[union-attr]
    raw = [e.msg.data[1] for e in events[:400] if e.kind == "command"]
    assert not np.allclose(sent, raw)
    assert any(o.topic == "estimate" for o in first)
    diag = pipe.diagnostics(500 * MS).message.status[0]  # type: ignore[union-attr]
    assert "checkpoint" in diag.message
    assert {kv.key: kv.value for kv in diag.values}["estimate_source"] == "checkpoint"


def test_corrupt_checkpoint_starts_cold_and_warns(tmp_path: Path) -> None:
    path = tmp_path / "estimate.json"
    path.write_text('{"format": "genbacklash-checkpoint", "version": 1')
    pipe = BacklashPipeline(PARAMS.replace(checkpoint_file=str(path)))
    assert not pipe.using_checkpoint and "is corrupt" in pipe.warm_start_note
    diag = pipe.diagnostics(0).message.status[0]  # type: ignore[union-attr]
    assert diag.level == DiagnosticStatus.WARN and "starting cold" in diag.message


def test_checkpoint_write_failure_is_reported(tmp_path: Path) -> None:
    def broken(target: Path, checkpoint: Checkpoint) -> None:
        raise OSError(13, "Permission denied")

    params = PARAMS.replace(checkpoint_file=str(tmp_path / "c.json"), checkpoint_period=0.5)
    pipe = BacklashPipeline(params, checkpoint_writer=broken)
    outputs = run(pipe, example1_events(seed=6, seconds=3.0))
    assert pipe.stats.checkpoint_errors >= 1 and pipe.stats.checkpoints == 0
    warned = [
        o.message.status[0]  # type: ignore[union-attr]
        for o in outputs
        if o.topic == "diagnostics" and "checkpoint not saved" in o.message.status[0].message  # type: ignore[union-attr]
    ]
    assert warned and all(s.level >= DiagnosticStatus.WARN for s in warned)


# --------------------------------------------------------------------------- lifecycle


def test_finish_feeds_everything_and_reports() -> None:
    pipe = BacklashPipeline(PARAMS)
    assert pipe.finish() == []  # no data: nothing to say
    events = example1_events(seed=3, seconds=2.0)
    outputs = run(pipe, events, finish=False)
    assert pipe.stats.samples < pipe.stats.encoder_messages  # the latest are pending
    final = pipe.finish()
    assert [o.topic for o in final] == ["estimate", "diagnostics"]
    assert pipe.stats.samples == pipe.stats.encoder_messages
    assert final[0].stamp_ns == max(o.stamp_ns for o in outputs + final)


def test_set_params_restarts_only_when_needed() -> None:
    pipe = BacklashPipeline(PARAMS)
    run(pipe, example1_events(seed=4, seconds=2.0), finish=False)
    identifier = pipe.identifier
    pipe.set_params(pipe.params.replace(u_max=0.1, gate_low=0.0))
    assert pipe.identifier is identifier
    out = pipe.on_command(Float64MultiArray(LAYOUT, (0.0, 1.9)), 10**10)[0]
    assert out.topic == "compensated_command" and out.message.data[1] <= 0.1  # type: ignore[union-attr]
    pipe.set_params(pipe.params.replace(degree=2))
    assert pipe.identifier is not identifier and pipe.identifier.structure.degree == 2
    assert not pipe.estimate.available


# --------------------------------------------------------------------------- the sample rule

FLOATS = NodeParameters(command_type="float64", encoder_type="float64", settle_time=0.0)


class Recorder:
    """Stands in for the identifier's ``update_many``: what each feed gave it (and, with
    ``inner``, passes it on to the real one)."""

    def __init__(self, inner: Any = None) -> None:
        self.feeds: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.inner = inner

    def __call__(self, u: Any, y: Any, breaks: Any = None) -> Any:
        assert breaks is not None, "the pipeline always says which samples follow"
        b = np.asarray(breaks)
        assert b.dtype == np.bool_ and b.shape == np.shape(u) == np.shape(y)
        self.feeds.append((np.array(u), np.array(y), b.copy()))
        return None if self.inner is None else self.inner(u, y, breaks=breaks)

    @property
    def y(self) -> np.ndarray:
        return np.concatenate([y for _, y, _ in self.feeds])

    @property
    def breaks(self) -> np.ndarray:
        return np.concatenate([b for _, _, b in self.feeds])


def recording(
    pipe: BacklashPipeline, monkeypatch: pytest.MonkeyPatch, *, through: bool = False
) -> Recorder:
    recorder = Recorder(pipe.identifier.update_many if through else None)
    monkeypatch.setattr(pipe.identifier, "update_many", recorder)
    return recorder


def smooth(i: int) -> float:
    """A command that reverses every 22 samples."""
    return math.sin(i / 7.0)


def zigzag(i: int) -> float:
    """A command that reverses at every sample: no lost reading lies along a monotone path,
    so none is bridged (the strict sample rule)."""
    return 0.5 * (-1.0) ** i + 0.001 * i


def send(
    pipe: BacklashPipeline,
    stamps: Any,
    lost: set[int] | frozenset[int] = frozenset(),
    command: Callable[[int], float] = smooth,
) -> None:
    """Float64 streams (a message's time is its receive time): at each stamp a command,
    then reading ``i`` with the value ``i`` unless ``i`` is lost."""
    for i, t in enumerate(np.asarray(stamps, dtype=np.int64).tolist()):
        pipe.on_command(Float64(command(i)), t)
        if i not in lost:
            pipe.on_encoder(Float64(float(i)), t)


def after_losses(n: int, lost: set[int]) -> list[int]:
    """Where the fed readings (``0..n-1`` less ``lost``) break: the first, and each that
    follows a lost one."""
    kept = [i for i in range(n) if i not in lost]
    return [k for k, i in enumerate(kept) if k == 0 or i - 1 in lost]


def test_lost_readings_break_the_chain_exactly_after_each_loss(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pipe = BacklashPipeline(FLOATS)
    rec = recording(pipe, monkeypatch)
    lost = {40, 41, 100, 163, 300, 301, 302, 303, 450}
    send(pipe, np.arange(1, 601) * MS, lost, zigzag)
    pipe.finish()
    assert rec.y.tolist() == [float(i) for i in range(600) if i not in lost]
    assert np.flatnonzero(rec.breaks).tolist() == after_losses(600, lost)
    assert len(rec.feeds) > 5  # the link from one feed to the next was exercised


@pytest.mark.parametrize("model", ["backlash", "cascade"])
def test_lost_readings_along_monotone_commands_are_bridged_for_a_backlash_alone(
    monkeypatch: pytest.MonkeyPatch, model: str
) -> None:
    """A backlash alone is rate independent: readings lost while the command rose or fell
    (or held) hide nothing, so the chain goes on; across a reversal it breaks. The cascade
    keeps the strict rule."""
    pipe = BacklashPipeline(FLOATS.replace(model=model))
    rec = recording(pipe, monkeypatch)
    # sin(i / 7) turns near i = 11, 33, 55, 77, 99, 121: 32 and 33 lost straddle the turn
    lost = {20, 32, 33, 60, 61, 62, 100}
    send(pipe, np.arange(1, 201) * MS, lost)
    pipe.finish()
    kept = [i for i in range(200) if i not in lost]
    where = {i: k for k, i in enumerate(kept)}
    if model == "cascade":
        assert np.flatnonzero(rec.breaks).tolist() == after_losses(200, lost)
    else:
        assert np.flatnonzero(rec.breaks).tolist() == [0, where[34]]


@pytest.mark.parametrize("kind", ["intervals", "stamps"])
def test_jittered_stamps_do_not_break(monkeypatch: pytest.MonkeyPatch, kind: str) -> None:
    """Each interval within +-0.3 period of the period (or each stamp within +-0.2 period of
    its grid point, so each interval within +-0.4) keeps neighbours neighbours."""
    rng = np.random.default_rng(3)
    n = 2000
    if kind == "intervals":
        stamps = MS + np.cumsum(np.round(MS * rng.uniform(0.7, 1.3, n))).astype(np.int64)
    else:
        stamps = (np.arange(1, n + 1) * MS + rng.uniform(-0.2, 0.2, n) * MS).astype(np.int64)
    pipe = BacklashPipeline(FLOATS)
    rec = recording(pipe, monkeypatch)
    send(pipe, stamps)
    pipe.finish()
    assert rec.y.size == n
    assert np.flatnonzero(rec.breaks).tolist() == [0]


def test_each_feed_links_to_the_last_sample_of_the_previous_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pipe = BacklashPipeline(FLOATS, batch=10)
    rec = recording(pipe, monkeypatch)
    send(pipe, np.arange(1, 101) * MS, {10}, zigzag)  # the first reading of the second feed
    pipe.finish()
    links = []
    for (_, y_prev, _), (_, y, b) in itertools.pairwise(rec.feeds):
        assert bool(b[0]) == (y[0] - y_prev[-1] != 1.0)
        links.append(bool(b[0]))
        assert not b[1:].any()
    assert links[0] and not all(links)  # one across the loss, the others linked


def test_rejected_readings_break_but_duplicates_and_late_ones_do_not(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pipe = BacklashPipeline(FLOATS)
    rec = recording(pipe, monkeypatch)
    values = []
    for i in range(1, 61):
        t = i * MS
        pipe.on_command(Float64(0.1 * i), t)
        if i == 20:
            pipe.on_encoder(Float64(math.nan), t - MS // 2)  # an invalid reading between two
        if i == 30:
            pipe.on_encoder(Float64(float(i)), t)
            pipe.on_encoder(Float64(float(i)), t)  # a duplicate
            values.append(i)
            continue
        if i == 40:
            continue  # reading 40 comes late, after 41 ...
        pipe.on_encoder(Float64(float(i)), t)
        values.append(i)
        if i == 41:
            pipe.on_encoder(Float64(40.0), 40 * MS)  # ... and is dropped as out of order
    pipe.reject("encoder", "bytes that do not decode")  # a transport's rejection
    pipe.on_command(Float64(0.0), 61 * MS)
    pipe.on_encoder(Float64(61.0), 61 * MS)
    values.append(61)
    pipe.finish()
    dropped = pipe.stats.dropped
    assert (dropped["encoder_invalid"], dropped["encoder_duplicate"]) == (2, 1)
    assert dropped["encoder_out_of_order"] == 1
    assert rec.y.tolist() == [float(v) for v in values]
    # the reading after the invalid one and the one after the transport's rejection; the gap
    # reading 40 left is bridged (the command rose over it: a backlash alone is rate
    # independent), which the cascade's strict rule does not do
    assert [values[k] for k in np.flatnonzero(rec.breaks)] == [1, 20, 61]


def test_a_clock_reanchor_breaks_the_chain(monkeypatch: pytest.MonkeyPatch) -> None:
    pipe = BacklashPipeline(FLOATS)
    rec = recording(pipe, monkeypatch)
    send(pipe, np.arange(2001, 2301) * MS)
    # the clock jumps 1 s back: the first two messages of each stream are dropped as out of
    # order, the third re-anchors alignment (REANCHOR_COUNT)
    for i, t in enumerate(range(1301, 1401)):
        pipe.on_command(Float64(0.5), t * MS)
        pipe.on_encoder(Float64(1000.0 + i), t * MS)
    pipe.finish()
    assert pipe.stats.dropped["encoder_out_of_order"] == 2
    first_new = rec.y.tolist().index(1002.0)
    assert np.flatnonzero(rec.breaks).tolist() == [0, first_new]
    assert rec.y.size == 300 + 98


def test_a_spike_screened_out_breaks_the_chain(monkeypatch: pytest.MonkeyPatch) -> None:
    events = example1_events(seed=11, seconds=4.0)
    readings = [e for e in events if e.kind == "encoder"]
    spike = next(e for e in readings if e.msg.header.stamp.to_ns() == 3000 * MS)
    after = readings[readings.index(spike) + 1].msg.position[1]
    position = (spike.msg.position[0], spike.msg.position[1] + 3.0)
    events[events.index(spike)] = Event(
        spike.receive_ns, "encoder", JointState(spike.msg.header, spike.msg.name, position)
    )
    pipe = BacklashPipeline(PARAMS)
    rec = recording(pipe, monkeypatch, through=True)  # the real identifier judges spikes
    run(pipe, events)
    assert pipe.stats.dropped["encoder_spike"] == 1
    assert position[1] not in rec.y.tolist()
    assert np.flatnonzero(rec.breaks).tolist() == [0, rec.y.tolist().index(after)]


def test_readings_of_a_stuck_encoder_taken_out_break_the_chain(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pipe = BacklashPipeline(FLOATS)
    rec = recording(pipe, monkeypatch)
    send(pipe, np.arange(1, 101) * MS)
    pipe._feed(final=True)
    for i in range(100, 110):  # pending, then found stuck: the last five are taken out
        pipe.on_command(Float64(0.0), (i + 1) * MS)
        pipe.on_encoder(Float64(float(i)), (i + 1) * MS)
    assert pipe._align.discard_after(105 * MS) == 5
    send(pipe, np.arange(111, 121) * MS)  # values 0..9 again: told apart by their order
    pipe.finish()
    assert rec.y.size == 100 + 5 + 10
    assert np.flatnonzero(rec.breaks).tolist() == [0, 105]


def test_grid_samples_break_where_they_hold_a_stale_reading(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """On the grid (sample_period = the encoder's period) a lost reading leaves a grid point
    holding the reading before it again: that one breaks, and so does the next."""
    pipe = BacklashPipeline(FLOATS.replace(sample_period=0.001))
    rec = recording(pipe, monkeypatch)
    lost = {50, 120, 121}
    send(pipe, np.arange(1, 301) * MS + MS // 2, lost)  # half a period off the grid
    pipe.finish()
    y = rec.y
    assert np.array_equal(rec.breaks[1:], np.diff(y) != 1.0)
    assert rec.breaks[0]
    # the first; 49 held twice, then 51; 119 held three times, then 122
    assert np.count_nonzero(rec.breaks) == 1 + 2 + 3


@pytest.mark.parametrize("method", ["windowed", "recursive"])
def test_a_stream_losing_30pct_of_its_readings_is_identified_without_bias(method: str) -> None:
    """A command per encoder period (so each lost reading hides an input): paired across
    the losses the gaps read about 0.1 too small; with the sample rule they do not."""
    events = example1_events(seed=11, seconds=8.0, command_hz=1000.0, jitter=0.0)
    rng = np.random.default_rng(5)
    lossy = [e for e in events if e.kind == "command" or rng.random() >= 0.3]
    pipe = BacklashPipeline(PARAMS.replace(method=method))
    run(pipe, lossy)
    assert np.max(np.abs(pipe.estimate.parameters - TRUTH.parameters())) < 0.02


def _coasting_stream(seed: int, seconds: float, *, bunched: bool) -> tuple[list[Event], float]:
    """Commands (100 Hz) and readings (500 Hz) of a load that coasts across the play
    (``c`` each side) at the end of every move, where the play operator leaves it at the
    near contact; with ``bunched`` a third of the command periods have their last two
    readings stamped 0.05 period apart (a publisher that fell behind and caught up). The
    events (in stamp order) and the play."""
    from genbacklash_core.scenarios import OperationSettings, operation_commands

    c = 0.03
    cfg = OperationSettings(duration=seconds, phases=(("operation", seconds),))
    values, _ = operation_commands(np.random.default_rng(seed), cfg)
    state, moving = float(values[0]), 0.0
    loads = np.empty(values.size)
    for k, u in enumerate(values):
        step = u - values[k - 1] if k else 0.0
        state = min(max(state, u - c), u + c)
        if step == 0.0 and moving:
            state = u + c if moving > 0 else u - c  # the move ended: the load coasts on
        moving = step
        loads[k] = state
    events = [Event(k * 10 * MS, "command", Float64(float(u))) for k, u in enumerate(values)]
    rng = np.random.default_rng(seed + 100)
    for k in range(values.size):
        late = bunched and rng.random() < 1 / 3
        for i, at in enumerate((2, 4, 6, 8)):
            stamp = (k * 10 + at) * MS
            if late and i == 2:
                stamp += 19 * MS // 10  # published with the next one
            events.append(Event(stamp, "encoder", Float64(float(loads[k]))))
    events.sort(key=lambda e: (e.receive_ns, e.kind != "command"))
    return events, 2 * c


@pytest.mark.parametrize("seed", [0, 1])
def test_readings_stamped_early_do_not_hide_a_coasting_load_from_the_guard(seed: int) -> None:
    """The guard judges a load that coasts into the play the same whether a driver stamps
    its readings on time or bunches some of them when it catches up: the free run restarts
    only where readings were lost (screen.Screened.restarts). Restarted at every early
    stamp it re-anchored on the coasted load and let compensation through (BENCHMARKS.md,
    the live demo, branch coast2-1)."""
    ratios = []
    for bunched in (False, True):
        events, play = _coasting_stream(seed, 30.0, bunched=bunched)
        pipe = BacklashPipeline(
            NodeParameters.from_mapping({"command_type": "float64", "encoder_type": "float64"})
        )
        for event in events:
            if event.kind == "command":
                pipe.on_command(event.msg, event.receive_ns)
            else:
                pipe.on_encoder(event.msg, event.receive_ns)
        pipe.finish(refit=False)
        est = pipe.estimate
        assert (
            est.model is not None and abs(est.model.c_left + est.model.c_right - play) < 0.2 * play
        )
        ratios.append(pipe.guard.ratio)
    regular, bunched_ratio = ratios
    assert regular > 1.0  # the model cannot describe the coasting load: the guard holds off
    assert bunched_ratio == pytest.approx(regular, rel=0.1)
    assert pipe.guard.state == "off"
