"""The rclpy node in process, against the real rclpy (ROS 2 Jazzy's wheels from PyPI, the ``ros``
extra in ``dev``, under Fast DDS; or a sourced ROS 2 installation: GUIDE §5).

Each test makes its own rclpy context on a DDS domain of its own. Skipped, with the reason,
where rclpy does not import (neither the ros extra installed nor a ROS 2 sourced).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from genbacklash_ros.cli.node import choose_transport, ros2_main

from ._answer_first import ANSWER_FIRST, recorded
from ._ros2 import domain_id, params_file, rclpy_missing

needs_rclpy = pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")


def test_without_rclpy_the_cli_says_so(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Where rclpy does not import, the node's entry points say how to get it: run here with
    rclpy hidden (``import rclpy`` raises), so it runs whether or not rclpy is installed."""
    pytest.importorskip("cyclonedds", reason="auto falls back to dds: needs the dds extra")
    monkeypatch.setitem(sys.modules, "rclpy", None)
    with pytest.raises(
        Exception, match=r"rclpy cannot be imported: pip install 'genbacklash\[ros\]'"
    ):
        choose_transport("rclpy")
    assert choose_transport("auto") == "dds"
    assert ros2_main() == 2
    err = capsys.readouterr().err
    assert "pip install 'genbacklash[ros]'" in err
    assert "genbacklash node --transport dds" in err


@pytest.fixture
def ros_args(ros_init: Callable[..., None]) -> list[str]:
    ros_init()
    return []


@needs_rclpy
def test_descriptors_carry_ranges_and_descriptions() -> None:
    from genbacklash_ros.node.parameters import PARAMETER_SPECS
    from genbacklash_ros.transports import rclpy_node

    by_name = {s.name: s for s in PARAMETER_SPECS}
    degree = rclpy_node.descriptor(by_name["degree"])
    assert degree.integer_range[0].from_value == 1 and degree.integer_range[0].to_value == 9
    gate = rclpy_node.descriptor(by_name["gate_low"])
    assert gate.floating_point_range[0].to_value == 1.0
    assert rclpy_node.descriptor(by_name["command_type"]).read_only
    assert rclpy_node.descriptor(by_name["thread_priority"]).read_only  # chosen at start
    assert all(rclpy_node.descriptor(s).description for s in PARAMETER_SPECS)


@needs_rclpy
def test_destroy_node_is_clean(ros_args: list[str]) -> None:
    """rclpy's ``Node`` keeps its publishers in ``self._publishers``; the node must not
    shadow it, or every ``destroy_node()`` (each shutdown) ends in a KeyError."""
    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    own = {p.topic_name for p in node.publishers}
    assert {"/compensated_command", "/backlash_identifier/estimate", "/diagnostics"} <= own
    node.finish()
    node.destroy_node()  # raised KeyError: 0
    assert not list(node.publishers)


@needs_rclpy
def test_subscriptions_keep_a_deep_history_with_ros_default_matching(ros_args: list[str]) -> None:
    """A depth of 10 lost 2 % of a 1 kHz command stream while a loaded machine descheduled
    the process; the subscriptions keep READER_DEPTH samples, with ROS 2's reliability and
    durability (so peers match as before)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

    from genbacklash_ros.node.wiring import READER_DEPTH
    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    try:
        subs = {s.topic_name: s.qos_profile for s in node.subscriptions}
        command, encoder = subs["/command"], subs["/encoder"]
        assert command.depth == encoder.depth == READER_DEPTH
        assert command.reliability == QoSProfile(depth=1).reliability
        assert command.reliability == ReliabilityPolicy.RELIABLE
        assert encoder.reliability == qos_profile_sensor_data.reliability
        assert encoder.durability == qos_profile_sensor_data.durability
    finally:
        node.finish()
        node.destroy_node()


@needs_rclpy
def test_node_rejects_bad_parameters_with_the_reason(ros_args: list[str]) -> None:
    from rclpy.parameter import Parameter

    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    try:
        result = node.set_parameters([Parameter("degree", value=12)])[0]
        assert not result.successful and "degree" in result.reason
        result = node.set_parameters([Parameter("publish_rate", value=5.0)])[0]
        assert result.successful
        assert node.get_parameter("publish_rate").value == 5.0
    finally:
        node.finish()
        node.destroy_node()


@needs_rclpy
def test_the_compensated_command_is_published_before_the_periodic_outputs_are_built(
    ros_args: list[str],
) -> None:
    """A command at which a diagnostics report comes due: its compensated command is
    published before the report is built (the pipeline's ``answer``, then ``periodic``),
    so building the estimates and reports never delays the answer."""
    from std_msgs.msg import Float64MultiArray

    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    events, publish = recorded(node._pipeline)
    node._publish = publish  # type: ignore[method-assign]
    try:
        for value, ms in ((0.1, 1), (0.2, 1_200)):
            info = {"source_timestamp": ms * 1_000_000}
            node._on_command(Float64MultiArray(data=[value, 0.0]), info)
        assert events == ANSWER_FIRST
    finally:
        node.finish()
        node.destroy_node()


@needs_rclpy
def test_a_raw_command_is_answered_with_its_own_bytes_compensated(ros_args: list[str]) -> None:
    """The raw subscriptions (CDR bytes): the compensated command goes out as the command's
    bytes with the compensated element written in, the same message the object path
    publishes, and before the periodic outputs are built; a command whose layout the codec
    has not learnt, or bytes that do not decode, take rclpy's own way."""
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    from genbacklash_ros.bags.rosbags_types import jazzy_typestore, to_rosbags
    from genbacklash_ros.node.messages import compensated_command
    from genbacklash_ros.node.pipeline import Output
    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    events, publish = recorded(node._pipeline)
    node._publish = publish  # type: ignore[method-assign]
    raw_sent: list[bytes] = []

    class Recorder:
        def publish(self, payload: bytes) -> None:
            events.append(("published", "compensated_command (bytes)"))
            raw_sent.append(payload)

    node._outputs["compensated_command"] = Recorder()
    real_answer = node._pipeline.answer

    def answer(msg: Any, receive_ns: int) -> Output | None:  # compensation: element 0 -> 0.777
        out = real_answer(msg, receive_ns)
        assert out is not None
        changed = compensated_command(msg, 0.777, "float64_multi_array", index=0)
        return Output(out.topic, changed, out.stamp_ns)

    node._pipeline.answer = answer  # type: ignore[method-assign]
    try:
        command = Float64MultiArray(data=[0.1, -0.5])
        command.layout.dim = [MultiArrayDimension(label="j", size=2, stride=2)]
        store = jazzy_typestore()
        for k, ms in enumerate((1, 2, 1_200)):
            command.data = [0.1 * (k + 1), -0.5]
            # the bytes as they come off the wire (rosbags writes them alike: zero padding);
            # rclpy's serialize_message leaves junk in the padding and after the end
            ours = rclpy_node.from_ros(
                deserialize_message(serialize_message(command), type(command))
            )
            raw = bytes(store.serialize_cdr(to_rosbags(ours, store), ours.ros_type))
            node._on_command(raw, {"source_timestamp": ms * 1_000_000})
        assert len(raw_sent) == 3
        back = deserialize_message(raw_sent[-1], Float64MultiArray)
        assert list(back.data) == [0.777, -0.5]
        assert [(d.label, d.size, d.stride) for d in back.layout.dim] == [("j", 2, 2)]
        assert node._command_codec.fast >= 1  # the later commands by their learnt layout
        # answered before the report that came due at 1.2 s was built
        assert events.index(("built", "diagnostics")) > 2
        assert events[:3] == [("published", "compensated_command (bytes)")] * 3
        # bytes of another layout than the one learnt (here junk in the 4 padding bytes
        # before the doubles, as a middleware's buffer may hold): decoded and published by
        # rclpy. (rclpy's serialize_message leaves such junk only now and then: not used.)
        junk = bytearray(raw)
        assert junk[32:36] == b"\0\0\0\0"
        junk[32:36] = b"d\0\0\0"
        node._on_command(bytes(junk), {"source_timestamp": 1_250_000_000})
        assert len(raw_sent) == 3 and events[-1] == ("published", "compensated_command")
        # a command that is not bytes (a node someone drives with objects) goes the same way
        node._on_command(command, {"source_timestamp": 1_300_000_000})
        assert events[-1] == ("published", "compensated_command")
        with pytest.raises(Exception, match="does not decode"):
            node._command_codec.decode(raw[:7])
        # bytes that do not decode at all: counted as an invalid command, nothing published
        published = len(events)
        node._on_command(raw[:7], {"source_timestamp": 1_350_000_000})
        assert node._pipeline.stats.dropped.get("command_invalid") == 1
        assert ("published", "compensated_command") not in events[published:]
    finally:
        node.finish()
        node.destroy_node()


@needs_rclpy
def test_message_conversion_round_trip() -> None:
    from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
    from genbacklash_ros.transports import rclpy_node

    for msg in (
        Float64MultiArray(data=(0.5, 1.5)),
        JointState(Header(Time(3, 4), "f"), ("a",), (0.1,), (), ()),
    ):
        assert rclpy_node.from_ros(rclpy_node.to_ros(msg)) == msg


@needs_rclpy
def test_the_shipped_params_file_applies_under_a_namespace(
    tmp_path: Path, ros_init: Callable[..., None]
) -> None:
    """rcl reads a `backlash_identifier:` key as `/backlash_identifier`: under a namespace the
    node ran on its defaults without a word."""
    from genbacklash_ros.transports import rclpy_node

    ros_init(
        "--params-file", str(params_file(tmp_path / "params.yaml", degree=2)), "-r", "__ns:=/arm"
    )
    node = rclpy_node.BacklashIdentifierNode()
    try:
        assert node.get_fully_qualified_name() == "/arm/backlash_identifier"
        assert node.get_parameter("degree").value == 2
    finally:
        node.destroy_node()


@needs_rclpy
def test_a_whole_number_is_taken_for_a_double(
    tmp_path: Path, ros_init: Callable[..., None]
) -> None:
    """`publish_rate: 10` in a params file and `ros2 param set ... publish_rate 5` (an
    integer): rclpy typed the parameter from its default and raised
    InvalidParameterTypeException (a traceback) for the first, refused the second."""
    from rclpy.parameter import Parameter

    from genbacklash_ros.transports import rclpy_node

    ros_init("--params-file", str(params_file(tmp_path / "params.yaml", publish_rate=10, u_max=3)))
    node = rclpy_node.BacklashIdentifierNode()
    try:
        for name, value in (("publish_rate", 10.0), ("u_max", 3.0)):
            param = node.get_parameter(name)
            assert param.type_ == Parameter.Type.DOUBLE and param.value == value
        result = node.set_parameters([Parameter("publish_rate", value=5)])[0]
        assert result.successful, result.reason
        assert node.get_parameter("publish_rate").value == 5.0
        assert node._params.publish_rate == 5.0
        # a whole number for an integer parameter stays one; a double there is refused
        assert not node.set_parameters([Parameter("degree", value=2.0)])[0].successful
    finally:
        node.destroy_node()


def _run_main(args: list[str], capfd: pytest.CaptureFixture[str]) -> tuple[int, str]:
    from genbacklash_ros.transports import rclpy_node

    status = rclpy_node.main(["backlash_identifier", *args])
    return status, capfd.readouterr().err


@needs_rclpy
@pytest.mark.parametrize(
    ("values", "reason"),
    [
        ({"degree": 12}, "parameter 'degree' must lie in [1, 9], got 12"),
        ({"publish_rate": 0}, "parameter 'publish_rate' must lie in [0.01, 1000], got 0"),
        ({"gate_low": 0.9}, "parameter 'gate_low' (0.9) must not exceed 'gate_high' (0.5)"),
        ({"method": "kalman"}, "parameter 'method' must be one of 'windowed', 'recursive'"),
    ],
)
def test_a_bad_params_file_is_one_line_the_same_for_both_transports(
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    values: dict[str, object],
    reason: str,
) -> None:
    from genbacklash_ros.cli.main import main as genbacklash

    path = params_file(tmp_path / "params.yaml", **values)
    status, err = _run_main(["--ros-args", "--params-file", str(path)], capfd)
    assert status == 2
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert reason in err
    rclpy_line = err.strip().removeprefix("backlash_identifier: error: ")
    # the DDS transport refuses the same file with the same reason
    pytest.importorskip("cyclonedds", reason="the DDS half needs cyclonedds (the dds extra)")
    assert genbacklash(["node", "--transport", "dds", "--params-file", str(path)]) == 2
    assert capfd.readouterr().err.strip() == f"genbacklash node: error: {rclpy_line}"


@needs_rclpy
def test_a_bad_command_line_parameter_is_one_line(capfd: pytest.CaptureFixture[str]) -> None:
    status, err = _run_main(["--ros-args", "-p", "forgetting:=2.0"], capfd)
    assert status == 2 and "Traceback" not in err
    assert err.strip() == (
        "backlash_identifier: error: parameter 'forgetting' must lie in [0.5, 1], got 2.0"
    )


@needs_rclpy
@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["-p", "degre:=2"], "-p: unknown parameter 'degre' (close matches: degree)"),
        (
            ["-p", "backlash_identifier:windw:=50"],
            "-p: unknown parameter 'windw' (close matches: window)",
        ),
        (
            ["--params-file", "{misspelt}"],
            "params file {misspelt}: unknown parameter(s) 'publish_rat' "
            "(close matches: publish_rate)",
        ),
    ],
)
def test_an_unknown_parameter_name_is_refused_with_the_close_matches(
    tmp_path: Path, args: list[str], line: str
) -> None:
    """``backlash_identifier --ros-args -p degre:=2`` ran with the default degree, saying
    nothing; a misspelt name in a params file listed every name of the node (issue 24)."""
    misspelt = tmp_path / "p.yaml"
    misspelt.write_text("/**/backlash_identifier:\n  ros__parameters:\n    publish_rat: 5.0\n")
    args = [a.format(misspelt=misspelt) for a in args]
    script = Path(sys.executable).with_name("backlash_identifier")
    assert script.is_file(), "the backlash_identifier script is installed with the package"
    command = [str(script)]
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id())}
    try:
        done = subprocess.run(
            [*command, "--ros-args", *args], capture_output=True, text=True, env=env, timeout=20
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{args}: the node started and ran")
    assert done.returncode == 2
    assert done.stderr.strip() == f"backlash_identifier: error: {line.format(misspelt=misspelt)}"


@needs_rclpy
@pytest.mark.parametrize(
    ("low", "high", "goal"),
    [
        ("gate_low", "gate_high", (0.7, 0.9)),
        ("gate_low", "gate_high", (0.05, 0.1)),
        ("u_min", "u_max", (5.0, 6.0)),
        ("u_min", "u_max", (-6.0, -5.0)),
    ],
)
def test_ros2_param_set_moves_a_pair_in_either_order(
    ros_args: list[str], low: str, high: str, goal: tuple[float, float]
) -> None:
    """`ros2 param set` sends one parameter per request: the callback checked the pair per
    parameter, so one of the two orders was refused."""
    from rclpy.parameter import Parameter

    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    try:
        start = (0.2, 0.5) if low == "gate_low" else (-1.0, 1.0)
        both = [Parameter(low, value=start[0]), Parameter(high, value=start[1])]
        assert node.set_parameters_atomically(both).successful
        for order in ((low, high), (high, low)):
            for name in order:
                value = goal[(low, high).index(name)]
                result = node.set_parameters([Parameter(name, value=value)])[0]
                assert result.successful, (order, result.reason)
                assert node.get_parameter(name).value == value
            assert (getattr(node._params, low), getattr(node._params, high)) == goal
            assert node._pending == ()
            for name in reversed(order):  # back to the start, in the other order
                value = start[(low, high).index(name)]
                assert node.set_parameters([Parameter(name, value=value)])[0].successful
            assert (getattr(node._params, low), getattr(node._params, high)) == start
        # in between, the node runs on the last consistent pair and says so
        assert node.set_parameters([Parameter(low, value=start[1] + 0.1)])[0].successful
        assert (getattr(node._params, low), getattr(node._params, high)) == start
        assert len(node._pending) == 1 and "until the pair is consistent" in node._pending[0]
        # a value invalid on its own is still refused with the reason
        if low == "gate_low":
            result = node.set_parameters([Parameter(high, value=1.5)])[0]
            # (the descriptor's range, checked by rclpy itself: its one-line reason)
            assert not result.successful and "gate_high out of range" in result.reason
    finally:
        node.destroy_node()


# A publisher of std_msgs/Float64 on /command, in a process of its own: Fast DDS (the wheels'
# RMW) refuses a second type on a topic within one process ("create_publisher() called for
# existing topic name rt/command with incompatible type"), as two ROS 2 nodes do not share one.
# It says "ready" once the publisher exists and runs until its stdin closes.
_WRONG_TYPE_PUBLISHER = """
import sys
import rclpy
from std_msgs.msg import Float64
rclpy.init(domain_id=int(sys.argv[1]))
node = rclpy.create_node("wrong_type_publisher")
node.create_publisher(Float64, "/command", 10)
print("ready", flush=True)
sys.stdin.read()
node.destroy_node()
rclpy.try_shutdown()
"""


@needs_rclpy
def test_pending_pair_and_wiring_are_in_the_diagnostics(ros_args: list[str]) -> None:
    """A publisher of std_msgs/Float64 on /command (another process) while the node
    subscribes Float64MultiArray: 0 commands, and the diagnostics name the type and
    command_type."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor

    from genbacklash_ros.transports import rclpy_node

    node = rclpy_node.BacklashIdentifierNode()
    peer = rclpy.create_node("diagnostics_listener")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(peer)
    domain = rclpy.get_default_context().get_domain_id()
    wrong = subprocess.Popen(
        [sys.executable, "-c", _WRONG_TYPE_PUBLISHER, str(domain)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert node.check_wiring() == ()
        assert wrong.stdout is not None and wrong.stdout.readline().strip() == "ready", (
            wrong.communicate(timeout=30)
        )
        deadline = time.monotonic() + 15.0
        while not node.check_wiring():
            assert time.monotonic() < deadline, "discovery did not show the publisher"
            executor.spin_once(timeout_sec=0.05)
        (line,) = node._wiring
        assert "std_msgs/msg/Float64 on /command" in line
        assert "std_msgs/msg/Float64MultiArray" in line
        assert "set parameter command_type to float64" in line
        received: list[Any] = []
        peer.create_subscription(DiagnosticArray, "/diagnostics", received.append, 10)
        deadline = time.monotonic() + 10.0
        while not received:
            assert time.monotonic() < deadline, "no /diagnostics"
            node._on_tick()  # the 1 Hz tick, without waiting for it
            executor.spin_once(timeout_sec=0.1)
        status = received[-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert values["wiring"] == line and line in status.message
        assert status.level >= bytes([1])
        assert values["parameters_pending"] == "ok"
        assert values["commands"] == "0"  # the Float64 messages never reach the node
    finally:
        _, err = wrong.communicate(timeout=30)  # closes its stdin: it ends
        executor.shutdown()
        peer.destroy_node()
        node.destroy_node()
    assert wrong.returncode == 0, err


@needs_rclpy
def test_a_second_sigint_during_the_final_refit_is_ignored(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C on `ros2 launch` reaches the node twice (the terminal's process group, then
    launch); the second landed in finish() and ended in a KeyboardInterrupt traceback
    without the final checkpoint. Here: a SIGINT ends the spin, and two more arrive while
    the pipeline finishes."""
    from genbacklash_ros.node.checkpoint_writer import BackgroundCheckpointWriter
    from genbacklash_ros.node.pipeline import BacklashPipeline
    from genbacklash_ros.transports import rclpy_node

    events: list[str] = []
    real_finish = BacklashPipeline.finish
    real_close = BackgroundCheckpointWriter.close

    def finish(self: BacklashPipeline, **kwargs: Any) -> Any:
        events.append("finish")
        for _ in range(2):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler runs here
        out = real_finish(self, **kwargs)
        events.append("refit done")
        return out

    def close(self: BackgroundCheckpointWriter) -> None:
        real_close(self)
        events.append("checkpoints closed")

    monkeypatch.setattr(BacklashPipeline, "finish", finish)
    monkeypatch.setattr(BackgroundCheckpointWriter, "close", close)
    before = signal.getsignal(signal.SIGINT)  # (SIG_IGN in a background job)
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        status = rclpy_node.main(
            ["backlash_identifier", "--ros-args", "-p", f"checkpoint_file:={tmp_path}/c.json"]
        )
    except KeyboardInterrupt:  # (caught: pytest would end the whole session)
        pytest.fail(f"KeyboardInterrupt escaped main() after {events}")
    finally:
        timer.cancel()
    err = capfd.readouterr().err
    assert status == 0
    assert events == ["finish", "refit done", "checkpoints closed"]
    assert "Traceback" not in err and "2 more interrupt(s) ignored while finishing" in err
    assert signal.getsignal(signal.SIGINT) == before  # restored


@needs_rclpy
def test_several_joints_topics_and_parameters(
    ros_init: Callable[..., None], tmp_path: Path
) -> None:
    """With ``joints``: one estimate topic per joint (no ``~/estimate``), the joint lists
    read-only, a ``<joint>.<name>`` set at start settable at run time for that joint only,
    and a change that makes the joints inconsistent held (parameters_pending) until resolved."""
    from rclpy.parameter import Parameter

    from genbacklash_ros.node.multijoint import MultiJointPipeline
    from genbacklash_ros.transports import rclpy_node

    arm = tmp_path / "arm.yaml"
    arm.write_text(
        "/**/backlash_identifier:\n  ros__parameters:\n"
        "    joints: [a, b]\n    command_indices: [1, 0]\n    b:\n      degree: 2\n"
    )
    ros_init("--params-file", str(arm))
    node = rclpy_node.BacklashIdentifierNode()
    try:
        own = {p.topic_name for p in node.publishers}
        assert {"/backlash_identifier/a/estimate", "/backlash_identifier/b/estimate"} <= own
        assert "/backlash_identifier/estimate" not in own
        assert [s.topic_name for s in node.subscriptions].count("/encoder") == 1
        pipe = node._pipeline
        assert isinstance(pipe, MultiJointPipeline)
        assert [p.params.degree for p in pipe.pipelines.values()] == [3, 2]
        assert list(node.get_parameter("joints").value) == ["a", "b"]
        result = node.set_parameters([Parameter("joints", value=["a"])])[0]
        assert not result.successful  # read-only
        result = node.set_parameters([Parameter("b.degree", value=12)])[0]
        assert not result.successful and "degree" in result.reason
        assert node.set_parameters([Parameter("b.degree", value=4)])[0].successful
        assert [p.params.degree for p in pipe.pipelines.values()] == [3, 4]
        assert node.set_parameters([Parameter("publish_rate", value=2)])[0].successful
        assert [p.params.publish_rate for p in pipe.pipelines.values()] == [2.0, 2.0]
        # gate_low above gate_high: held, and said, until gate_high follows
        assert node.set_parameters([Parameter("gate_low", value=0.7)])[0].successful
        assert pipe.pipelines["a"].params.gate_low == 0.2 and node._pending
        assert node.set_parameters([Parameter("gate_high", value=0.9)])[0].successful
        assert pipe.pipelines["a"].params.gate_low == 0.7 and not node._pending
    finally:
        node.finish()
        node.destroy_node()
