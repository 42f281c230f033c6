"""The message-level pipeline on synthetic streams of the paper's Example 1."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Iterator
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
from genbacklash_ros.checkpoint import Checkpoint, load_checkpoint, save_checkpoint
from genbacklash_ros.messages import (
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
from genbacklash_ros.parameters import NodeParameters
from genbacklash_ros.pipeline import BacklashPipeline, Output

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


PARAMS = NodeParameters(joint="drive", command_index=1)


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


# --------------------------------------------------------------------------- compensation


def closed_loop(in_loop: bool, seed: int = 0, seconds: float = 8.0) -> tuple[float, float]:
    """The drivetrain driven by the compensated command; the identifier in the loop.

    Returns the largest parameter error and the RMS tracking error of the last 400 commands.
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
    return error, float(np.sqrt(np.mean(np.square(errors[-400:]))))


def test_in_loop_identification_follows_the_compensated_command() -> None:
    error, tracking = closed_loop(in_loop=True)
    assert error < 0.05 and tracking < 0.05


def test_raw_command_identification_fails_when_the_compensator_drives_the_plant() -> None:
    # the documented reason for compensation_in_loop: the raw command is not the plant input
    error, tracking = closed_loop(in_loop=False)
    assert error > 0.1 and tracking > 0.2


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

    def spy(u: Any, y: Any) -> Estimate:
        fed.append(np.array(u))
        return real(u, y)

    monkeypatch.setattr(pipe.identifier, "update_many", spy)
    outputs = run(pipe, example1[:1200])
    raw = {e.msg.data[1] for e in example1[:1200] if e.kind == "command"}
    sent = {o.message.data[1] for o in outputs if o.topic == "compensated_command"}  # type: ignore[union-attr]
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
    monkeypatch.setattr(pipe.identifier, "update_many", lambda u, y: fed.append((list(u), list(y))))
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
    assert len(pipe._cmd_t) <= 4097  # commands of the last 0.1 s, trimmed in bulk
    pipe.on_encoder(Float64(0.0), 10_000 * MS)
    pipe.finish()
    assert pipe.stats.samples == 1


def test_samples_wait_for_their_command_or_the_timeout(monkeypatch: pytest.MonkeyPatch) -> None:
    pipe = BacklashPipeline(NodeParameters(command_type="float64", encoder_type="float64"), batch=1)
    fed: list[float] = []
    monkeypatch.setattr(pipe.identifier, "update_many", lambda u, y: fed.extend(list(y)))
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
