"""Replay in blocks (the fast path) against replay message by message, on the bundled bags,
and the output bag read back by rosbags and by mcap-ros2-support's decoder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    OperationSettings,
    arm_records,
    operation_record,
    worn,
)
from genbacklash_ros.bags.bagio import BagReader, BagWriter
from genbacklash_ros.bags.replay import OUTPUT_TOPICS, ReplayResult, replay
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    START_NS,
    write_arm_bag,
)
from genbacklash_ros.node.messages import Float64, Header, JointState, Time

BAGS = Path(__file__).resolve().parents[3] / "bags"
BUNDLED = {  # bag -> model to replay it with (bags/README.md)
    "operation": "backlash",
    "drivetrain": "backlash",
    "example1": "backlash",
    "example3": "cascade",
}


def _replay(bag: str, out: Path, batched: bool) -> ReplayResult:
    return replay(
        BAGS / bag,
        out,
        command_topic=COMMAND_TOPIC,
        encoder_topic=ENCODER_TOPIC,
        joint=JOINT,
        model=BUNDLED[bag],
        batched=batched,
    )


def _records(out: Path) -> list[tuple[str, int, bytes]]:
    with BagReader(out) as reader:
        topics = list(reader.topics)
        return [(m.topic, m.log_time_ns, m.raw) for m in reader.raw_messages(topics)]


def _same(fast: ReplayResult, slow: ReplayResult, tmp_path: Path) -> None:
    """The block path published what the per-message path did, to the bit."""
    assert fast.error == slow.error == ""
    one, two = fast.history, slow.history
    assert one.command_sent == two.command_sent  # every compensated command, exactly
    assert one.command_t == two.command_t and one.command_raw == two.command_raw
    assert one.estimate_t == two.estimate_t
    assert len(one.estimates) == len(two.estimates) > 0
    for a, b in zip(one.estimates, two.estimates, strict=True):
        assert np.array_equal(a.parameters, b.parameters)
        assert np.array_equal(a.covariance, b.covariance)
    assert np.array_equal(fast.estimate.parameters, slow.estimate.parameters)
    assert fast.stats == slow.stats
    assert (one.encoder_t, one.encoder_y) == (two.encoder_t, two.encoder_y)
    # the output bags hold the same records, byte for byte
    assert _records(tmp_path / "fast") == _records(tmp_path / "slow")


@pytest.mark.parametrize("bag", sorted(BUNDLED))
def test_blocks_give_the_per_message_estimates_and_commands(bag: str, tmp_path: Path) -> None:
    fast = _replay(bag, tmp_path / "fast", batched=True)
    slow = _replay(bag, tmp_path / "slow", batched=False)
    _same(fast, slow, tmp_path)


def _write_float64_bag(path: Path, seconds: float, seed: int) -> None:
    """Float64 commands at 100 Hz and a one-joint JointState at 1 kHz stamped and logged
    0.2 ms after each 1 ms tick (so 0.2 ms after each command), none lost (issue 24's
    other bag shape; bench/_replay_shapes.py)."""
    cfg = OperationSettings(duration=seconds, loss=0.0, stamp_jitter=0.0, command_jitter=0.0)
    rec = operation_record(cfg, seed)
    cmd_log = START_NS + rec.command_t_ns
    enc_log = START_NS + rec.sample_t_ns + 200_000
    events = sorted(
        [(int(t), 0, i) for i, t in enumerate(cmd_log)]
        + [(int(t), 1, i) for i, t in enumerate(enc_log)]
    )
    with BagWriter(path) as writer:
        writer.add_topic(COMMAND_TOPIC, Float64.ros_type)
        writer.add_topic(ENCODER_TOPIC, JointState.ros_type)
        for log, kind, i in events:
            if kind == 0:
                writer.write(COMMAND_TOPIC, log, Float64(float(rec.command_u[i])))
            else:
                stamp = Header(Time.from_ns(log), "encoder")
                writer.write(
                    ENCODER_TOPIC, log, JointState(stamp, (JOINT,), (float(rec.y_all[i]),))
                )


@pytest.mark.parametrize("shape", ["float64", "arm6"])
def test_blocks_equal_messages_on_other_bag_shapes(shape: str, tmp_path: Path) -> None:
    """Float64 commands with a reading 0.2 ms after each, none lost; and one joint of a
    six-joint arm (a six-element command, a six-joint JointState)."""
    bag = tmp_path / "bag"
    selection: dict[str, object] = {"joint": JOINT}
    if shape == "float64":
        _write_float64_bag(bag, 20.0, seed=24)
    else:
        models = [worn(OPERATION_BACKLASH, 1.0 + 0.2 * k) for k in range(6)]
        records = arm_records(models, OperationSettings(duration=20.0), seed=24)
        names = tuple(f"joint_{k + 1}" for k in range(6))
        write_arm_bag(bag, records, names, tuple(range(6)), 6)
        selection = {"joint": "joint_3", "command_index": 2}
    results = [
        replay(
            bag,
            tmp_path / name,
            command_topic=COMMAND_TOPIC,
            encoder_topic=ENCODER_TOPIC,
            batched=batched,
            **selection,  # type: ignore[arg-type]
        )
        for name, batched in (("fast", True), ("slow", False))
    ]
    assert results[0].stats.compensated > 1500
    _same(*results, tmp_path)


def test_output_reads_back_with_rosbags_and_mcap_ros2(tmp_path: Path) -> None:
    decoder = pytest.importorskip("mcap_ros2.decoder")
    mcap_reader = pytest.importorskip("mcap.reader")
    result = _replay("operation", tmp_path / "out", batched=True)
    sent = result.history.command_sent
    comp = OUTPUT_TOPICS["compensated_command"]
    # rosbags (our BagReader decodes with its deserializer)
    with BagReader(tmp_path / "out") as reader:
        assert not reader.salvaged
        counts = {name: info.count for name, info in reader.topics.items()}
        decoded = [m.message.data[0] for m in reader.messages([comp])]  # type: ignore[union-attr,index]
        inputs = sum(1 for _ in reader.raw_messages([COMMAND_TOPIC, ENCODER_TOPIC]))
    assert decoded == sent
    assert inputs == result.messages_in
    assert sum(counts.values()) == result.messages_out
    # mcap-ros2-support: the schemas are ROS 2 message definitions it decodes
    (mcap_file,) = (tmp_path / "out").glob("*.mcap")
    seen: dict[str, int] = {}
    values: list[float] = []
    with mcap_file.open("rb") as stream:
        reader_ = mcap_reader.make_reader(stream, decoder_factories=[decoder.DecoderFactory()])
        assert reader_.get_header().profile == "ros2"
        for schema, channel, _message, ros_msg in reader_.iter_decoded_messages():
            assert schema is not None and schema.encoding == "ros2msg"
            assert channel.message_encoding == "cdr"
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if channel.topic == comp:
                values.append(ros_msg.data[0])
            elif channel.topic == OUTPUT_TOPICS["estimate"]:
                assert ros_msg.layout.dim[0].label.startswith("m_left_1,")
            elif channel.topic == OUTPUT_TOPICS["diagnostics"]:
                assert ros_msg.status[0].name
    assert seen == counts
    assert values == sent
