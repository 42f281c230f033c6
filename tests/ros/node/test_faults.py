"""Fault injection: the pipeline (and the replay) survive bad data and say so (issue 6).

Each scenario is Example 1 as a drivetrain publishes it (commands at ~200 Hz with jitter,
a 1 kHz JointState encoder at SNR 25): a clean warm-up until the estimate has converged,
one injected fault from ``T_FAULT``, then clean data again. For every fault:

(a) nothing raises; (b) no output carries a non-finite number; (c) the estimates published
during the fault stay within 0.1 of the truth; (d) once the fault is seen the compensated command
is the raw command (within the output limits) and a WARN/ERROR ``/diagnostics`` report
names the fault; (e) afterwards the reports return to OK, the commands are compensated
again and the final estimate is within 0.1 of the truth.

Default node parameters except ``joint`` (so that a wrong joint name is a fault) and, for
the saturated command, output limits of +-2.5 (a command cannot saturate without limits).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from genbacklash_core import paper_example, simulate_backlash
from genbacklash_ros.bags.bagio import BagReader, BagWriter
from genbacklash_ros.bags.replay import OUTPUT_TOPICS, replay
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
from genbacklash_ros.node.pipeline import FAULT_HOLD_NS, BacklashPipeline, Output

MS = 1_000_000
S = 1_000_000_000
TRUTH = paper_example(1).model
JOINT = "drive_joint"
OTHER = "wheel_joint"
LAYOUT = MultiArrayLayout((MultiArrayDimension("joints", 2, 2),))
PARAMS = NodeParameters(joint=JOINT)
START = 1_700_000_000 * S  # a plausible wall-clock time
T_FAULT = 2.0  # s into the record: the warm-up has converged by then
DURATION = 6.0


# --------------------------------------------------------------------------- the driver


@dataclass
class Event:
    """One message as it reaches the node.

    ``arrival`` orders the events (the real receive time); ``receive_ns`` is what the
    node's clock says then and ``stamp_ns`` the header stamp (both moved by clock jumps);
    ``true_ns`` is the sample time in the simulation, for the checks.
    """

    arrival: int
    kind: str  # "command" or "encoder"
    true_ns: int
    receive_ns: int
    stamp_ns: int
    value: float
    msg: Any = None  # built from stamp and value unless a fault set it

    def message(self) -> Any:
        if self.msg is not None:
            return self.msg
        if self.kind == "command":
            return Float64MultiArray(LAYOUT, (self.value, 0.25))
        header = Header(Time.from_ns(self.stamp_ns), "encoder")
        return JointState(header, (JOINT, OTHER), (self.value, -1.0))


@dataclass
class Scenario:
    """The message stream of one run and what the checks need to know."""

    events: list[Event]
    fault_from: int  # true time window of the fault
    fault_to: int
    raw: dict[int, float] = field(default_factory=dict)  # command true time -> raw value


def drivetrain(seed: int, command_fault: Callable[[np.ndarray, np.ndarray], None]) -> Scenario:
    """Example 1 at 1 kHz with commands at ~200 Hz; ``command_fault(t, u)`` edits the
    commands in place before the plant sees them (it holds its last finite command)."""
    rng = np.random.default_rng(seed)
    n_cmd = int(DURATION * 200)
    cmd_t = np.arange(1, n_cmd + 1) * 5 * MS + rng.integers(-1_500_000, 1_500_000, n_cmd)
    cmd_u = rng.uniform(-2.0, 2.0, n_cmd)
    command_fault(cmd_t, cmd_u)
    finite = np.isfinite(cmd_u)
    held_u = cmd_u[np.maximum.accumulate(np.where(finite, np.arange(n_cmd), 0))]
    enc_t = np.arange(1, int(DURATION * 1000) + 1, dtype=np.int64) * MS
    k = np.searchsorted(cmd_t, enc_t, side="right") - 1
    enc_t, k = enc_t[k >= 0], k[k >= 0]
    x = simulate_backlash(paper_example(1).backlash, held_u[k])
    sigma = float(np.std(x[enc_t < T_FAULT * S])) / 25.0  # SNR 25 (the warm-up's)
    y = x + rng.normal(0.0, sigma, x.size)
    events = [
        Event(int(t), "command", int(t), START + int(t), START + int(t), float(u))
        for t, u in zip(cmd_t, cmd_u, strict=True)
    ]
    late = rng.integers(0, 300_000, enc_t.size)  # the encoder is received 0-0.3 ms later
    for t, v, d in zip(enc_t, y, late, strict=True):
        events.append(Event(int(t + d), "encoder", int(t), START + int(t + d), START + int(t), v))
    events.sort(key=lambda e: (e.arrival, e.kind))
    raw = {int(t): float(u) for t, u in zip(cmd_t, cmd_u, strict=True)}
    return Scenario(events, 0, 0, raw)


@dataclass
class Record:
    """What the node published, each output with the true time of the event behind it."""

    commands: list[tuple[int, float, float]] = field(default_factory=list)  # t, raw, sent
    outputs: list[tuple[int, Output]] = field(default_factory=list)
    final: list[Output] = field(default_factory=list)

    def reports(self) -> Iterator[tuple[int, DiagnosticStatus]]:
        for t, out in self.outputs:
            if isinstance(out.message, DiagnosticArray):
                yield t, out.message.status[0]

    def estimates(self) -> Iterator[tuple[int, np.ndarray]]:
        for t, out in self.outputs:
            if out.topic == "estimate":
                assert isinstance(out.message, Float64MultiArray)
                yield t, np.array(out.message.data)


def drive(pipe: BacklashPipeline, scenario: Scenario) -> Record:
    record = Record()
    for event in scenario.events:
        msg = event.message()
        if event.kind == "command":
            outs = pipe.on_command(msg, event.receive_ns)
            if outs and outs[0].topic == "compensated_command":
                sent = outs[0].message
                assert isinstance(sent, Float64MultiArray)
                record.commands.append((event.true_ns, event.value, sent.data[0]))
        else:
            outs = pipe.on_encoder(msg, event.receive_ns)
        record.outputs += [(event.true_ns, out) for out in outs]
    record.final = pipe.finish()
    last = scenario.events[-1].true_ns
    record.outputs += [(last, out) for out in record.final]
    return record


def numbers_in(out: Output) -> Iterator[float]:
    """Every number an output carries: message data, diagnostic values that parse as
    numbers, and the standard deviations of the estimate behind it."""
    msg = out.message
    if isinstance(msg, Float64):
        yield msg.data
    elif isinstance(msg, Float64MultiArray):
        yield from msg.data
    elif isinstance(msg, JointState):
        yield from (*msg.position, *msg.velocity, *msg.effort)
    elif isinstance(msg, DiagnosticArray):
        for status in msg.status:
            for kv in status.values:
                assert kv.value.strip().lower() not in ("nan", "inf", "-inf", "+inf"), kv
                try:
                    yield float(kv.value)
                except ValueError:
                    pass
    if out.estimate is not None and out.estimate.available:
        yield from out.estimate.std().tolist()
        yield out.estimate.residual


# --------------------------------------------------------------------------- the faults


def _window(scenario: Scenario, kind: str | None = None) -> list[Event]:
    lo, hi = scenario.fault_from, scenario.fault_to
    return [e for e in scenario.events if lo <= e.true_ns < hi and kind in (None, e.kind)]


def _encoder_values(values: Callable[[int, float], float]) -> Callable[[Scenario, Any], None]:
    def apply(scenario: Scenario, rng: Any) -> None:
        for i, event in enumerate(_window(scenario, "encoder")):
            event.value = values(i, event.value)

    return apply


def _encoder_messages(make: Callable[[Event], Any]) -> Callable[[Scenario, Any], None]:
    def apply(scenario: Scenario, rng: Any) -> None:
        for event in _window(scenario, "encoder"):
            event.msg = make(event)

    return apply


def _drop_encoder(share: float) -> Callable[[Scenario, Any], None]:
    def apply(scenario: Scenario, rng: np.random.Generator) -> None:
        gone = {id(e) for e in _window(scenario, "encoder") if rng.random() < share}
        scenario.events = [e for e in scenario.events if id(e) not in gone]

    return apply


def _out_of_order(scenario: Scenario, rng: Any) -> None:
    for event in _window(scenario, "encoder")[::10]:
        event.arrival += 3 * MS  # every tenth reading arrives after three later ones
    scenario.events.sort(key=lambda e: (e.arrival, e.kind))


def _duplicates(scenario: Scenario, rng: Any) -> None:
    copies = [replace(e, arrival=e.arrival + 1) for e in _window(scenario)]
    scenario.events = sorted(scenario.events + copies, key=lambda e: (e.arrival, e.kind))


def _clock_jump(seconds: float) -> Callable[[Scenario, Any], None]:
    def apply(scenario: Scenario, rng: Any) -> None:
        shift = round(seconds * S)
        for event in scenario.events:
            if event.arrival >= scenario.fault_from:
                event.receive_ns += shift
                event.stamp_ns += shift

    return apply


def _spikes(scenario: Scenario, rng: np.random.Generator) -> None:
    for event in _window(scenario, "encoder"):
        if rng.random() < 0.03:
            event.value += float(rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 3.0))


def _stuck(scenario: Scenario, rng: Any) -> None:
    before = [e for e in scenario.events if e.kind == "encoder"]
    frozen = [e.value for e in before if e.true_ns < scenario.fault_from][-1]
    for event in _window(scenario, "encoder"):
        event.value = frozen


def _no_command_fault(t: np.ndarray, u: np.ndarray) -> None:
    pass


@dataclass(frozen=True)
class Fault:
    """One injected fault: what it does, how long, what the node must say.

    ``detect`` is the time the node may take to notice (its commands may still be
    compensated); ``expect`` a regular expression for the report naming it.
    """

    name: str
    expect: str
    level: int = DiagnosticStatus.WARN
    seconds: float = 0.6
    detect: float = 0.01
    events: Callable[[Scenario, Any], None] = lambda scenario, rng: None
    commands: Callable[[np.ndarray, np.ndarray], None] = _no_command_fault
    params: NodeParameters = PARAMS


def _in_window(seconds: float, edit: Callable[[np.ndarray, np.ndarray], None]) -> Any:
    def apply(t: np.ndarray, u: np.ndarray) -> None:
        inside = (t >= T_FAULT * S) & (t < (T_FAULT + seconds) * S)
        edit(inside, u)

    return apply


def _nan_commands(inside: np.ndarray, u: np.ndarray) -> None:
    idx = np.flatnonzero(inside)[::2]
    u[idx] = np.resize([math.nan, math.inf, -math.inf], idx.size)


def _saturate(inside: np.ndarray, u: np.ndarray) -> None:
    u[inside] = 3.0


_BAD = (math.nan, math.inf, -math.inf)
ERROR = DiagnosticStatus.ERROR

FAULTS = [
    Fault(
        "nonfinite_encoder",
        r"encoder silent for .*not finite",
        ERROR,
        events=_encoder_values(lambda i, v: _BAD[i % 3]),
    ),
    Fault(
        "nonfinite_command",
        r"command invalid \(last: .*not finite",
        commands=_in_window(0.6, _nan_commands),
    ),
    Fault(
        "empty_joint_state",
        r"encoder invalid \(last: encoder: JointState has no positions",
        ERROR,
        events=_encoder_messages(
            lambda e: JointState(Header(Time.from_ns(e.stamp_ns)), (JOINT,), ())
        ),
    ),
    Fault(
        "mismatched_joint_state",
        r"JointState has 2 names but 1 positions",
        ERROR,
        events=_encoder_messages(
            lambda e: JointState(Header(Time.from_ns(e.stamp_ns)), (JOINT, OTHER), (e.value,))
        ),
    ),
    Fault(
        "wrong_joint_name",
        r"joint 'drive_joint' is not in the JointState names \['wheel_joint', 'arm_joint'\]",
        ERROR,
        events=_encoder_messages(
            lambda e: JointState(
                Header(Time.from_ns(e.stamp_ns)), (OTHER, "arm_joint"), (e.value, 0.0)
            )
        ),
    ),
    Fault("out_of_order", r"encoder out of order \(last: encoder time", events=_out_of_order),
    Fault("duplicates", r"(?=.*encoder duplicate).*command duplicate", events=_duplicates),
    Fault(
        "random_drops_30pct",
        r"encoder lost [23]\d% of its readings",
        seconds=1.0,
        detect=0.5,
        events=_drop_encoder(0.3),
    ),
    Fault("burst_drop", r"encoder silent for 0\.[6-9]\d* s", ERROR, 0.8, 0.11, _drop_encoder(1.0)),
    Fault(
        "clock_jump_back",
        r"clock jumped back 2\.00\d s .*re-anchored",
        seconds=0.3,
        events=_clock_jump(-2.0),
    ),
    Fault(
        "clock_jump_forward",
        r"clock jumped forward 2\.00\d s",
        seconds=0.3,
        events=_clock_jump(2.0),
    ),
    Fault(
        "encoder_spikes",
        r"encoder spike \(last: encoder reading",
        seconds=1.0,
        detect=0.25,
        events=_spikes,
    ),
    Fault("stuck_encoder", r"encoder stuck at .* for", ERROR, 1.0, 0.15, _stuck),
    Fault(
        "saturated_command",
        r"command saturated at limit u_max = 2\.5",
        seconds=0.8,
        detect=0.21,
        commands=_in_window(0.8, _saturate),
        params=PARAMS.replace(u_min=-2.5, u_max=2.5),
    ),
]


def run_fault(fault: Fault, seed: int) -> tuple[Scenario, Record, BacklashPipeline]:
    scenario = drivetrain(seed, fault.commands)
    scenario.fault_from = round(T_FAULT * S)
    scenario.fault_to = round((T_FAULT + fault.seconds) * S)
    fault.events(scenario, np.random.default_rng([seed, 7]))
    pipe = BacklashPipeline(fault.params)
    return scenario, drive(pipe, scenario), pipe


@pytest.mark.parametrize("fault", FAULTS, ids=[f.name for f in FAULTS])
def test_fault_is_survived_reported_and_cleared(fault: Fault) -> None:
    scenario, record, pipe = run_fault(fault, seed=5)  # (a) nothing raised
    t0, t1 = scenario.fault_from, scenario.fault_to
    truth = TRUTH.parameters()
    # (b) no output carries a non-finite number
    bad = [out for _, out in record.outputs if not all(map(math.isfinite, numbers_in(out)))]
    assert not bad, bad[:1]
    # the estimate had converged before the fault, and no fault was seen
    before = [p for t, p in record.estimates() if t < t0]
    assert np.max(np.abs(before[-1] - truth)) < 0.1
    clean = [s for t, s in record.reports() if t < t0]
    assert clean and all(s.level == DiagnosticStatus.OK for s in clean)
    # (c) estimates stay near the truth during the fault and the hold after it
    during = [p for t, p in record.estimates() if t0 <= t < t1 + FAULT_HOLD_NS]
    assert during and max(float(np.max(np.abs(p - truth))) for p in during) < 0.1
    # (d) pass-through (within the limits) once the fault is seen ...
    low, high = fault.params.u_min, fault.params.u_max
    seen = [(raw, sent) for t, raw, sent in record.commands if t0 + fault.detect * S <= t < t1]
    assert seen
    for raw, sent in seen:
        assert sent == min(max(raw, low), high), (raw, sent)
    # ... and a WARN/ERROR report that names it
    named = [
        s for t, s in record.reports() if t0 <= t <= t1 + S and re.search(fault.expect, s.message)
    ]
    assert named, [s.message for t, s in record.reports() if t0 <= t <= t1 + S]
    assert max(s.level for s in named) == fault.level
    assert all(s.level >= DiagnosticStatus.WARN for s in named)
    # (e) OK again once it cleared, compensating, close to the truth (the final report
    # may say no_excitation when the refit at the end had only a few new samples)
    after = [s for t, s in record.reports() if t >= t1 + 2 * S]
    periodic, final = after[:-1], after[-1]
    assert periodic and all(s.level == DiagnosticStatus.OK for s in periodic), [
        s.message for s in after if s.level
    ]
    assert {kv.key: kv.value for kv in final.values}["faults"] == "none", final.message
    later = [(raw, sent) for t, raw, sent in record.commands if t >= t1 + S]
    assert np.mean([abs(sent - raw) > 1e-9 for raw, sent in later]) > 0.5
    assert np.max(np.abs(pipe.estimate.parameters - truth)) < 0.1


# --------------------------------------------------------------------------- replay path


def test_replay_of_a_bag_with_faults(tmp_path: Path) -> None:
    """NaN readings, a burst of lost encoder messages and an out-of-order stamp in a bag."""
    bag, out = tmp_path / "faulty", tmp_path / "out"
    scenario = drivetrain(3, _no_command_fault)
    encoders = [e for e in scenario.events if e.kind == "encoder"]
    for e in encoders:
        if 2_000 * MS <= e.true_ns < 2_200 * MS:
            e.value = math.nan  # 0.2 s of NaN readings
    lost = {id(e) for e in encoders if 3_000 * MS <= e.true_ns < 3_500 * MS}  # 0.5 s lost
    late = next(e for e in encoders if e.true_ns == 4_000 * MS)
    late.stamp_ns -= 5 * MS  # one reading stamped before its predecessor
    with BagWriter(bag) as writer:
        writer.add_topic("/command", Float64MultiArray.ros_type)
        writer.add_topic("/encoder", JointState.ros_type)
        for e in scenario.events:
            if id(e) not in lost:
                writer.write(f"/{e.kind}", e.receive_ns, e.message())
    result = replay(bag, out, command_topic="/command", encoder_topic="/encoder", joint=JOINT)
    assert result.error == ""
    assert np.max(np.abs(result.estimate.parameters - TRUTH.parameters())) < 0.1
    values: dict[str, list[float]] = {"compensated_command": [], "estimate": []}
    statuses: list[tuple[int, DiagnosticStatus]] = []
    with BagReader(out) as reader:
        for item in reader.messages(list(OUTPUT_TOPICS.values())):
            msg = item.message
            if isinstance(msg, DiagnosticArray):
                statuses.append((item.log_time_ns - START, msg.status[0]))
            else:
                assert isinstance(msg, Float64MultiArray)
                key = (
                    "estimate" if item.topic == OUTPUT_TOPICS["estimate"] else "compensated_command"
                )
                values[key].extend(msg.data)
    commands = sum(e.kind == "command" for e in scenario.events)
    assert len(values["compensated_command"]) == 2 * commands  # [drive, other joint]
    assert values["estimate"] and all(map(math.isfinite, [x for vs in values.values() for x in vs]))
    warned = " | ".join(s.message for _, s in statuses if s.level >= DiagnosticStatus.WARN)
    assert "not finite" in warned
    assert re.search(r"encoder silent for 0\.[45]\d* s", warned)
    assert "encoder out of order" in warned and "0.004 s back" in warned
    # OK again from 1 s after the last fault; the final report lists no fault
    assert all(s.level == DiagnosticStatus.OK for t, s in statuses[:-1] if t > 5 * S)
    assert {kv.key: kv.value for kv in statuses[-1][1].values}["faults"] == "none"
