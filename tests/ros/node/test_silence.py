"""A stream that stays silent while the other arrives (issue 15 item 5, the timing half).

The 2 s are measured on the receive clock (a bag's log time in replay): a silent stream has no
stamps of its own.
"""

from __future__ import annotations

from genbacklash_ros.node.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Header,
    JointState,
    Time,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline, Output
from genbacklash_ros.node.silence import SILENT_STREAM_NS

MS = 1_000_000
FLOATS = NodeParameters(command_type="float64", encoder_type="float64")


def reports(outputs: list[Output]) -> list[tuple[int, int, str, dict[str, str]]]:
    """(time, level, message, values) of each diagnostics output."""
    out = []
    for o in outputs:
        if o.topic == "diagnostics":
            assert isinstance(o.message, DiagnosticArray)
            status = o.message.status[0]
            values = {kv.key: kv.value for kv in status.values}
            out.append((o.stamp_ns, status.level, status.message, values))
    return out


def test_encoder_without_commands_says_the_command_is_silent() -> None:
    pipe = BacklashPipeline(FLOATS)
    outputs: list[Output] = []
    for k in range(1, 3501):  # 3.5 s of a 1 kHz encoder, no command at all
        outputs += pipe.on_encoder(Float64(0.001 * k), k * MS)
    seen = reports(outputs)
    quiet = [r for r in seen if r[0] < MS + SILENT_STREAM_NS]
    loud = [r for r in seen if r[0] >= MS + SILENT_STREAM_NS]
    assert quiet and loud
    assert all("no command" not in message for _, _, message, _ in quiet)
    for _, level, message, values in loud:
        assert level >= DiagnosticStatus.WARN
        assert "no command for" in message and "command_type = float64" in message
        assert float(values["command_silent_s"]) >= SILENT_STREAM_NS / 1e9
    assert "encoder messages arrived" in loud[-1][2]


def test_commands_without_encoder_say_the_encoder_is_silent() -> None:
    pipe = BacklashPipeline(FLOATS)
    outputs: list[Output] = []
    for k in range(1, 401):  # 4 s of 100 Hz commands, no encoder
        outputs += pipe.on_command(Float64(0.1), k * 10 * MS)
    last = reports(outputs)[-1]
    assert last[1] == DiagnosticStatus.ERROR
    assert "no encoder for" in last[2] and "encoder_type = float64" in last[2]
    assert "command messages arrived" in last[2]


def test_a_stream_that_comes_back_is_no_longer_silent() -> None:
    pipe = BacklashPipeline(FLOATS)
    outputs: list[Output] = []
    for k in range(1, 3001):
        outputs += pipe.on_encoder(Float64(0.001 * k), k * MS)
    assert "no command for" in reports(outputs)[-1][2]
    outputs = []
    for k in range(3001, 5001):  # now both come
        if k % 10 == 0:
            outputs += pipe.on_command(Float64(0.1), k * MS)
        outputs += pipe.on_encoder(Float64(0.001 * k), k * MS)
    last = reports(outputs)[-1]
    assert "no command" not in last[2] and "command_silent_s" not in last[3]


def test_silence_is_measured_on_the_receive_clock_not_the_stamps() -> None:
    """Commands a second apart on the receive clock are not silent, whatever the encoder's
    header stamps say (here they run ten times faster)."""
    pipe = BacklashPipeline(NodeParameters(command_type="float64", encoder_type="joint_state"))
    outputs: list[Output] = []
    for k in range(1, 5001):
        receive = k * MS
        if k % 1000 == 0:
            outputs += pipe.on_command(Float64(0.1), receive)
        stamp = Time.from_ns(10 * receive)
        outputs += pipe.on_encoder(JointState(Header(stamp), ("j",), (0.001 * k,)), receive)
    assert reports(outputs)
    assert all("no command" not in message for _, _, message, _ in reports(outputs))
