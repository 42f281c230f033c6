"""The compiled MCAP writer (foxglove-sdk behind rosbags' rosbag2 Writer) writes the bag
rosbags' own writer writes: the same metadata.yaml, schemas, channels, messages and summary."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from genbacklash_ros.bags import fast_mcap
from genbacklash_ros.bags.bagio import BagError, BagReader, BagWriter
from genbacklash_ros.node.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    KeyValue,
    Time,
)

pytestmark = pytest.mark.skipif(not fast_mcap.AVAILABLE, reason="foxglove-sdk not installed")


def _write(path: Path, compiled: bool) -> BagWriter:
    rng = np.random.default_rng(3)
    with BagWriter(path, compiled=compiled) as writer:
        writer.add_topic("/encoder", JointState.ros_type)
        for k in range(3000):  # more than one 1 MiB chunk
            t = 1_700_000_000_000_000_000 + k * 1_000_000
            header = Header(Time.from_ns(t), "enc")
            writer.write("/encoder", t + 150_000, JointState(header, ("a", "b"), (k, -k)))
            if k % 10 == 0:
                writer.write("/command", t, Float64MultiArray(data=(float(rng.normal()), 0.5)))
            if k % 1000 == 0:
                status = DiagnosticStatus(
                    level=DiagnosticStatus.WARN, name="n", values=(KeyValue("k", "v"),)
                )
                writer.write("/diagnostics", t, DiagnosticArray(Header(Time.from_ns(t)), (status,)))
        cdr_header = b"\x00\x01\x00\x00"  # little-endian CDR
        writer.write_raw("/x", 5, cdr_header + struct.pack("<d", 2.5), Float64.ros_type)
        writer.set_custom_data("genbacklash.test", '{"a": 1}')
    return writer


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    compiled = tmp_path_factory.mktemp("compiled") / "bag"
    python = tmp_path_factory.mktemp("python") / "bag"
    assert _write(compiled, compiled=True).compiled
    assert not _write(python, compiled=False).compiled
    return compiled, python


def test_same_metadata_and_messages(bags: tuple[Path, Path]) -> None:
    compiled, python = bags
    assert (compiled / "metadata.yaml").read_text() == (python / "metadata.yaml").read_text()
    contents = []
    for path in (compiled, python, compiled / "bag.mcap"):  # a bare .mcap opens too
        with BagReader(path) as reader:
            assert not reader.salvaged
            topics = reader.topics
            contents.append(
                (
                    topics,
                    [(m.topic, m.log_time_ns, m.raw) for m in reader.raw_messages(list(topics))],
                    reader.custom_data,
                )
            )
    assert contents[0] == contents[1] == contents[2]
    assert contents[0][2] == {"genbacklash.test": '{"a": 1}'}
    assert contents[0][0]["/encoder"].count == 3000


def test_same_mcap_records(bags: tuple[Path, Path]) -> None:
    reader_mod = pytest.importorskip("mcap.reader")

    def records(path: Path) -> tuple[object, ...]:
        with (path / "bag.mcap").open("rb") as stream:
            reader = reader_mod.make_reader(stream)
            summary = reader.get_summary()
            assert summary is not None
            schemas = sorted((s.name, s.encoding, s.data) for s in summary.schemas.values())
            channels = sorted(
                (c.topic, c.message_encoding, tuple(sorted(c.metadata.items())))
                for c in summary.channels.values()
            )
            messages = [
                (c.topic, m.log_time, m.publish_time, m.data)
                for _s, c, m in reader.iter_messages(log_time_order=True)
            ]
            stats = summary.statistics
            assert stats is not None
            return (
                reader.get_header().profile,
                schemas,
                channels,
                messages,
                stats.message_count,
                len(summary.chunk_indexes) > 1,
                sorted(m.name for m in reader.iter_metadata()),
            )

    compiled, python = bags
    assert records(compiled) == records(python)
    assert records(compiled)[0] == "ros2"


def test_readable_by_mcap_ros2(bags: tuple[Path, Path]) -> None:
    reader_mod = pytest.importorskip("mcap_ros2.reader")
    compiled, _ = bags
    positions = [
        m.ros_msg.position[0]
        for m in reader_mod.read_ros2_messages(str(compiled / "bag.mcap"), topics=["/encoder"])
    ]
    assert positions == [float(k) for k in range(3000)]


@pytest.mark.parametrize("compiled", [True, False])
def test_write_raw_many_is_write_raw_in_turn(tmp_path: Path, compiled: bool) -> None:
    with BagReader(_write(tmp_path / "src" / "bag", compiled=True).path) as reader:
        topics = reader.topics
        records = [(m.topic, m.log_time_ns, m.raw) for m in reader.raw_messages(list(topics))]
    for name, many in (("one", False), ("many", True)):
        with BagWriter(tmp_path / name / "bag", compiled=compiled if many else False) as w:
            for topic, info in topics.items():
                w.add_topic(topic, info.msgtype)
            if many:
                w.write_raw_many(records[:1000])
                w.write_raw_many([])
                w.write_raw_many(records[1000:])
            else:
                for topic, t, raw in records:
                    w.write_raw(topic, t, raw, topics[topic].msgtype)
        assert w.count == len(records)
    one, many_ = (tmp_path / n / "bag" / "metadata.yaml" for n in ("one", "many"))
    assert one.read_text() == many_.read_text()  # counts, time span, topics
    with BagReader(tmp_path / "many" / "bag") as reader:
        assert [(m.topic, m.log_time_ns, m.raw) for m in reader.raw_messages(list(topics))] == (
            records
        )
    with BagWriter(tmp_path / "x", compiled=compiled) as w, pytest.raises(BagError, match="/nope"):
        w.write_raw_many([("/nope", 1, b"")])
