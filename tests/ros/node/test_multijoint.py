"""Several joints in one node: the parameters (JointSet) and the multi-joint pipeline.

The arm is simulated with :func:`genbacklash_core.scenarios.arm_records` (three joints, each its
own motion and its own backlash, one clock) and fed as one Float64MultiArray of four elements
(element 1 used by no joint: it must pass through) and one three-joint JointState per reading.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.scenarios import OPERATION_BACKLASH, OperationSettings, arm_records, worn
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, arm_messages
from genbacklash_ros.node.joints import JointSet, load_joint_set
from genbacklash_ros.node.messages import (
    DiagnosticArray,
    Float64MultiArray,
    Header,
    JointState,
    Time,
)
from genbacklash_ros.node.multijoint import MultiJointPipeline, joint_status_name, make_pipeline
from genbacklash_ros.node.parameters import NodeParameters, parse_ros_arguments
from genbacklash_ros.node.pipeline import BacklashPipeline, Output

NAMES = ("shoulder", "elbow", "wrist")
INDICES = (0, 2, 3)
MODELS = (
    OPERATION_BACKLASH,
    worn(OPERATION_BACKLASH, 1.6),
    GeneralBacklash((1.0, 0.02, -0.01), 0.03, (1.0, 0.02, -0.01), 0.025),
)


# --------------------------------------------------------------------------- parameters


def test_joint_set_gives_each_joint_its_parameters_and_overrides() -> None:
    js = JointSet.from_mapping(
        {
            "joints": ["shoulder", "elbow"],
            "command_indices": [3, 1],
            "degree": 2,
            "elbow.degree": 4,
            "elbow.u_max": 1.5,
            "checkpoint_file": "/tmp/arm_{joint}.json",
        }
    )
    assert js.multi and js.names == ("shoulder", "elbow")
    shoulder, elbow = js.per_joint
    assert (shoulder.joint, shoulder.command_index, shoulder.degree) == ("shoulder", 3, 2)
    assert (elbow.joint, elbow.command_index, elbow.degree, elbow.u_max) == ("elbow", 1, 4, 1.5)
    assert shoulder.u_max == np.inf
    assert elbow.checkpoint_file == "/tmp/arm_elbow.json"
    assert JointSet.from_mapping(js.to_mapping()) == js


def test_single_joint_stays_the_default() -> None:
    js = JointSet.from_mapping({"joint": "j", "command_index": 2})
    assert not js.multi
    assert js.per_joint == (NodeParameters(joint="j", command_index=2),)
    assert isinstance(make_pipeline(js), BacklashPipeline)


@pytest.mark.parametrize(
    ("values", "match"),
    [
        ({"joints": ["a", "b"]}, r"'command_indices' must give one element index per joint"),
        ({"joints": ["a", "b"], "command_indices": [0, 0]}, r"one element to two joints"),
        ({"joints": ["a", "a"], "command_indices": [0, 1]}, r"lists a more than once"),
        ({"joints": ["a/b"], "command_indices": [0]}, r"not a joint name"),
        ({"joints": ["a"], "command_indices": [0], "joint": "a"}, r"leave 'joint'"),
        (
            {"joints": ["a"], "command_type": "float64", "command_indices": [0]},
            r"a Float64 command holds one joint",
        ),
        (
            {"joints": ["elbow"], "command_indices": [0], "elbw.degree": 2},
            r"'elbw' is not in 'joints' \(close matches: elbow\)",
        ),
        ({"joints": ["a"], "command_indices": [0], "a.joint": "x"}, r"cannot be set per joint"),
        ({"joints": ["a"], "command_indices": [0], "a.degree": 12}, r"joint 'a': .*degree"),
        ({"joints": ["a"], "command_indices": [0], "a.degre": 2}, r"unknown parameter.*degree"),
        (
            {"joints": ["a", "b"], "command_indices": [0, 1], "checkpoint_file": "x.json"},
            r"checkpoint_file must hold '\{joint\}'",
        ),
        ({"command_indices": [0]}, r"need 'joints'"),
    ],
)
def test_joint_set_refuses_with_the_reason(values: dict[str, object], match: str) -> None:
    with pytest.raises(GenBacklashError, match=match):
        JointSet.from_mapping(values)


def test_params_file_nests_per_joint_overrides(tmp_path: Path) -> None:
    path = tmp_path / "arm.yaml"
    path.write_text(
        "/**/backlash_identifier:\n"
        "  ros__parameters:\n"
        "    joints: [shoulder, elbow]\n"
        "    command_indices: [0, 1]\n"
        "    degree: 2\n"
        "    elbow:\n"
        "      degree: 3\n"
        "      publish_rate: 5\n"
    )
    js = load_joint_set(path, namespace="/arm")
    assert [p.degree for p in js.per_joint] == [2, 3]
    assert js.per_joint[1].publish_rate == 5.0
    path.write_text(
        "backlash_identifier:\n  ros__parameters:\n    joints: [a]\n    command_indices: [0]\n"
        "    b:\n      degree: 2\n"
    )
    with pytest.raises(GenBacklashError, match=r"arm.yaml: parameter 'b.degree'"):
        load_joint_set(path)


def test_minus_p_takes_the_joint_parameters_and_refuses_typos() -> None:
    ok = ["n", "--ros-args", "-p", "joints:=[a,b]", "-p", "a.degree:=2"]
    parse_ros_arguments(ok).check_parameter_names()
    with pytest.raises(GenBacklashError, match=r"unknown parameter 'a.degre'"):
        parse_ros_arguments(["n", "--ros-args", "-p", "a.degre:=2"]).check_parameter_names()


# --------------------------------------------------------------------------- the pipeline


@pytest.fixture(scope="module")
def arm() -> list[tuple[int, str, Float64MultiArray | JointState]]:
    records = arm_records(MODELS, OperationSettings(duration=30.0), seed=5)
    return arm_messages(records, NAMES, INDICES, 4)


def _feed(pipe: MultiJointPipeline | BacklashPipeline, messages: list) -> list[Output]:  # type: ignore[type-arg]
    outputs: list[Output] = []
    for receive_ns, topic, msg in messages:
        if topic == COMMAND_TOPIC:
            outputs += pipe.on_command(msg, receive_ns)
        else:
            outputs += pipe.on_encoder(msg, receive_ns)
    return outputs + pipe.finish()


@pytest.fixture(scope="module")
def fed(
    arm: list[tuple[int, str, Float64MultiArray | JointState]],
) -> tuple[MultiJointPipeline, list[Output]]:
    js = JointSet.from_mapping({"joints": list(NAMES), "command_indices": list(INDICES)})
    pipe = MultiJointPipeline(js)
    return pipe, _feed(pipe, arm)


def test_every_joint_is_identified_near_its_own_truth(
    fed: tuple[MultiJointPipeline, list[Output]],
) -> None:
    pipe, _ = fed
    plays = []
    for name, model in zip(NAMES, MODELS, strict=True):
        est = pipe.pipelines[name].estimate
        assert est.available
        assert np.max(np.abs(est.parameters - model.parameters())) < 0.01, name
        plays.append(est.model.c_left + est.model.c_right)
    assert len({round(p, 3) for p in plays}) == 3  # three different drivetrains told apart


def test_one_compensated_array_per_command_with_the_free_element_passed(
    fed: tuple[MultiJointPipeline, list[Output]],
    arm: list[tuple[int, str, Float64MultiArray | JointState]],
) -> None:
    _, outputs = fed
    commands = [m for _, topic, m in arm if topic == COMMAND_TOPIC]
    sent = [o.message for o in outputs if o.topic == "compensated_command"]
    assert len(sent) == len(commands)
    got = np.array([m.data for m in sent])  # type: ignore[union-attr]
    given = np.array([m.data for m in commands])  # type: ignore[union-attr]
    assert np.array_equal(got[:, 1], given[:, 1])  # element 1: no joint's, passed through
    for k in INDICES:  # every joint's element compensated (it differs once the model is in)
        assert np.mean(got[:, k] != given[:, k]) > 0.3


def test_each_joint_is_exactly_a_single_joint_pipeline(
    fed: tuple[MultiJointPipeline, list[Output]],
    arm: list[tuple[int, str, Float64MultiArray | JointState]],
) -> None:
    """The per-joint logic is the single-joint pipeline's: each joint's element of the
    compensated array equals, to the bit, what a one-joint node on the same stream sends."""
    _, outputs = fed
    got = np.array([o.message.data for o in outputs if o.topic == "compensated_command"])  # type: ignore[union-attr]
    for name, index in zip(NAMES, INDICES, strict=True):
        single = BacklashPipeline(NodeParameters(joint=name, command_index=index))
        alone = _feed(single, arm)
        own = np.array([o.message.data[index] for o in alone if o.topic == "compensated_command"])  # type: ignore[union-attr]
        assert np.array_equal(got[:, index], own), name


def _shuffled(
    messages: list[tuple[int, str, Float64MultiArray | JointState]],
) -> list[tuple[int, str, Float64MultiArray | JointState]]:
    """The readings with their names reordered, missing, repeated or not finite now and
    then (each a new name tuple, then the usual one again)."""
    out: list[tuple[int, str, Float64MultiArray | JointState]] = []
    for k, (receive_ns, topic, msg) in enumerate(messages):
        if isinstance(msg, JointState) and k % 7 == 1:
            names, position = list(msg.name), list(msg.position)
            if k % 4 == 1:
                names, position = names[::-1], position[::-1]
            elif k % 4 == 3:
                names, position = names[1:], position[1:]  # the first joint missing
            if k % 3 == 0:
                names.append(names[0])  # a repeated name: its first position counts
                position.append(position[0] + 1.0)
            elif k % 3 == 1:
                position[-1] = float("nan")
            msg = JointState(msg.header, tuple(names), tuple(position))
        out.append((receive_ns, topic, msg))
    return out


def _multi_and_singles() -> tuple[MultiJointPipeline, list[BacklashPipeline]]:
    """The arm's joints in one pipeline, and each in a single-joint pipeline of its own."""
    js = JointSet.from_mapping({"joints": list(NAMES), "command_indices": list(INDICES)})
    singles = [
        BacklashPipeline(params, status_name=joint_status_name(params.joint))
        for params in js.per_joint
    ]
    return MultiJointPipeline(js), singles


def _side_by_side(
    multi: MultiJointPipeline,
    singles: list[BacklashPipeline],
    topic: str,
    msg: Float64MultiArray | JointState,
    receive_ns: int,
    *,
    answer_only: bool = False,
) -> tuple[list[Output], list[list[Output]]]:
    """One message to the multi-joint pipeline and to each joint's single-joint pipeline
    (``answer_only``: a command's ``answer`` alone, its periodic step left to the next
    message); asserts each joint's outputs but the compensated command are the single
    one's, in joint order. Returns both."""
    alone: list[list[Output]]
    if topic == COMMAND_TOPIC and answer_only:
        answer = multi.answer(msg, receive_ns)
        got = [] if answer is None else [answer]
        alone = [[] for _ in singles]
        for single in singles:
            single.answer(msg, receive_ns)
    elif topic == COMMAND_TOPIC:
        got = multi.on_command(msg, receive_ns)
        alone = [single.on_command(msg, receive_ns) for single in singles]
    else:
        got = multi.on_encoder(msg, receive_ns)
        alone = [single.on_encoder(msg, receive_ns) for single in singles]
    expected = [
        (o.topic, name, o.message, o.stamp_ns)
        for name, outputs in zip(NAMES, alone, strict=True)
        for o in outputs
        if o.topic != "compensated_command"
    ]
    assert [(o.topic, o.joint, o.message, o.stamp_ns) for o in got if o.joint] == expected
    return got, alone


def test_every_joint_gives_what_its_single_joint_pipeline_gives(
    arm: list[tuple[int, str, Float64MultiArray | JointState]],
) -> None:
    """Message by message, each joint's compensated element, estimates and diagnostics are
    a single-joint pipeline's on the same stream, to the bit, the readings' names reordered,
    missing, repeated or not finite now and then (one look-up per name tuple)."""
    messages = _shuffled(arm[: len(arm) // 2])
    multi, singles = _multi_and_singles()
    compared = 0
    for receive_ns, topic, msg in messages:
        got, alone = _side_by_side(multi, singles, topic, msg, receive_ns)
        compared += sum(o.topic != "compensated_command" for outputs in alone for o in outputs)
        for index, outputs in zip(INDICES, alone, strict=True):
            answers = [o.message for o in outputs if o.topic == "compensated_command"]
            if answers:
                assert got[0].message.data[index] == answers[0].data[index]  # type: ignore[union-attr]
    assert compared > 100
    for name, single in zip(NAMES, singles, strict=True):
        assert multi.pipelines[name].stats == single.stats
    assert multi.pipelines[NAMES[0]].stats.dropped["encoder_invalid"] > 0  # missing
    assert multi.pipelines[NAMES[-1]].stats.dropped["encoder_invalid"] > 0  # not finite


def _one_joint_silent(
    messages: list[tuple[int, str, Float64MultiArray | JointState]],
) -> list[tuple[int, str, Float64MultiArray | JointState]]:
    """The wrist's command element cut off from 2 to 5 s (the array too short for index 3)
    and the elbow's reading left out from 6 to 9 s: each joint silent on one stream for 3 s
    while the others read every message."""
    start = messages[0][0]
    out: list[tuple[int, str, Float64MultiArray | JointState]] = []
    for receive_ns, topic, msg in messages:
        at = (receive_ns - start) / 1e9
        if isinstance(msg, Float64MultiArray) and 2.0 <= at < 5.0:
            msg = Float64MultiArray(msg.layout, msg.data[:3])
        elif isinstance(msg, JointState) and 6.0 <= at < 9.0:
            keep = [k for k, name in enumerate(msg.name) if name != "elbow"]
            names = tuple(msg.name[k] for k in keep)
            msg = JointState(msg.header, names, tuple(msg.position[k] for k in keep))
        out.append((receive_ns, topic, msg))
    return out


@pytest.mark.parametrize("answer_only", [False, True])
def test_a_joint_that_cannot_read_a_stream_reports_its_own_silence(
    arm: list[tuple[int, str, Float64MultiArray | JointState]], answer_only: bool
) -> None:
    """A joint that cannot read a stream's messages (its command element cut off, its reading
    left out) reports its own silence and the others none: every joint's outputs a
    single-joint pipeline's, message by message, also when a command's periodic step waits
    for the next message (``answer`` alone). (Written for branch joint4-1, which shared one
    silence watch between the joints; the watch stayed per joint, the test guards it.)"""
    messages = _one_joint_silent(arm[: len(arm) // 3])
    multi, singles = _multi_and_singles()
    silent: dict[str, set[str]] = {name: set() for name in NAMES}
    for receive_ns, topic, msg in messages:
        got, _ = _side_by_side(multi, singles, topic, msg, receive_ns, answer_only=answer_only)
        for o in got:
            if o.topic == "diagnostics":
                assert isinstance(o.message, DiagnosticArray)
                for key in o.message.status[0].values:
                    if key.key.endswith("_silent_s"):
                        silent[o.joint].add(key.key)
    assert silent == {
        "shoulder": set(),
        "elbow": {"encoder_silent_s"},
        "wrist": {"command_silent_s"},
    }
    for name, single in zip(NAMES, singles, strict=True):
        assert multi.pipelines[name].stats == single.stats


def test_the_answer_comes_before_any_joint_builds_its_periodic_outputs(
    fed: tuple[MultiJointPipeline, list[Output]],
    arm: list[tuple[int, str, Float64MultiArray | JointState]],
) -> None:
    """``answer`` (the one compensated array) builds no joint's estimate or diagnostics;
    ``periodic`` right after makes them: together exactly ``on_command``'s outputs, so the
    live transports publish the array first and nothing else changes."""
    _, expected = fed
    js = JointSet.from_mapping({"joints": list(NAMES), "command_indices": list(INDICES)})
    pipe = MultiJointPipeline(js)
    built: list[str] = []
    for name, joint_pipe in pipe.pipelines.items():
        original = joint_pipe.diagnostics

        def spy(stamp_ns: int, *, stale: bool = False, _name: str = name, _orig=original):  # type: ignore[no-untyped-def]
            built.append(_name)
            return _orig(stamp_ns, stale=stale)

        joint_pipe.diagnostics = spy  # type: ignore[method-assign]
    outputs: list[Output] = []
    reports_at_commands = 0
    for receive_ns, topic, msg in arm:
        if topic == COMMAND_TOPIC:
            answer = pipe.answer(msg, receive_ns)  # type: ignore[arg-type]
            assert built == [] and answer is not None
            due = pipe.periodic()
            reports_at_commands += sum(o.topic == "diagnostics" for o in due)
            outputs += [answer, *due]
        else:
            outputs += pipe.on_encoder(msg, receive_ns)
        built.clear()
    outputs += pipe.finish()
    assert reports_at_commands >= len(NAMES) * 10  # every joint's, at commands, each second
    assert [(o.topic, o.joint, o.message, o.stamp_ns) for o in outputs] == [
        (o.topic, o.joint, o.message, o.stamp_ns) for o in expected
    ]


def test_estimates_and_diagnostics_are_per_joint(
    fed: tuple[MultiJointPipeline, list[Output]],
) -> None:
    pipe, outputs = fed
    estimates = [o for o in outputs if o.topic == "estimate"]
    assert {o.joint for o in estimates} == set(NAMES)
    for o in estimates:
        assert o.estimate is not None
    names = set()
    for o in outputs:
        if o.topic == "diagnostics":
            assert isinstance(o.message, DiagnosticArray)
            assert [s.name for s in o.message.status] == [f"backlash_identifier: {o.joint}"]
            assert o.message.status[0].hardware_id == o.joint
            names.add(o.message.status[0].name)
    assert names == {f"backlash_identifier: {n}" for n in NAMES}
    stale = pipe.diagnostics(1, stale=True).message
    assert isinstance(stale, DiagnosticArray)
    assert [s.name.rsplit(" ", 1)[-1] for s in stale.status] == list(NAMES)


def test_a_joint_missing_from_a_message_passes_only_its_own_element() -> None:
    js = JointSet.from_mapping({"joints": ["a", "b"], "command_indices": [0, 5]})
    pipe = MultiJointPipeline(js)
    out = pipe.on_command(Float64MultiArray(data=(0.3, 0.4)), 1_000_000)
    assert out[0].message.data == (0.3, 0.4)  # b's index is beyond: a's element taken
    assert pipe.pipelines["b"].stats.dropped["command_invalid"] == 1
    assert pipe.pipelines["a"].stats.commands == 1
    reading = JointState(Header(Time.from_ns(2_000_000)), ("a",), (0.1,))
    pipe.on_encoder(reading, 2_100_000)
    assert pipe.pipelines["a"].stats.encoder_messages == 1
    assert pipe.pipelines["b"].stats.dropped["encoder_invalid"] == 1
    assert pipe.on_command(JointState(name=("a",), position=(0.1,)), 3_000_000) == []  # type: ignore[arg-type]
    assert pipe.pipelines["a"].stats.dropped["command_invalid"] == 1
    # a NaN anywhere in the array: every joint drops it (the echo would publish it)
    assert pipe.on_command(Float64MultiArray(data=(0.3, float("nan"))), 4_000_000) == []
    assert pipe.pipelines["a"].stats.dropped["command_invalid"] == 2
    # a NaN position drops only its joint's reading
    both = JointState(Header(Time.from_ns(5_000_000)), ("b", "a"), (float("nan"), 0.2))
    pipe.on_encoder(both, 5_100_000)
    assert pipe.pipelines["a"].stats.encoder_messages == 2
    assert pipe.pipelines["b"].stats.dropped["encoder_invalid"] == 2
    pipe.close()


def test_a_joint_state_command_is_compensated_joint_by_joint(
    arm: list[tuple[int, str, Float64MultiArray | JointState]],
) -> None:
    """A JointState command: each listed joint's position compensated, by name, in one
    message; a joint the node does not serve passes through; no command_indices."""
    js = JointSet.from_mapping({"joints": ["wrist", "shoulder"], "command_type": "joint_state"})
    pipe = MultiJointPipeline(js)
    names = ("shoulder", "gripper", "elbow", "wrist")
    sent = []
    for receive_ns, topic, msg in arm:
        if topic == COMMAND_TOPIC:
            assert isinstance(msg, Float64MultiArray)
            positions = (msg.data[0], msg.data[1], msg.data[2], msg.data[3])
            command = JointState(Header(Time.from_ns(receive_ns)), names, positions)
            out = pipe.on_command(command, receive_ns)
            assert out[0].topic == "compensated_command"
            reply = out[0].message
            assert isinstance(reply, JointState) and reply.name == names
            sent.append((positions, reply.position))
        else:
            pipe.on_encoder(msg, receive_ns)
    pipe.close()
    given = np.array([s[0] for s in sent])
    got = np.array([s[1] for s in sent])
    assert np.array_equal(got[:, 1:3], given[:, 1:3])  # gripper, elbow: not served
    for k in (0, 3):  # shoulder, wrist compensated once their models are in
        assert np.mean(got[:, k] != given[:, k]) > 0.3
    assert pipe.pipelines["wrist"].estimate.available
