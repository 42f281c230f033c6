"""Bag IO: round trips through rosbags' MCAP writer and reader, errors, salvage, alignment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.samples import MAX_BRIDGED
from genbacklash_ros.bags.bagio import BagError, BagReader, BagWriter, align, read_aligned
from genbacklash_ros.bags.bagio import reader as bag_reader
from genbacklash_ros.bags.bagio.in_order import chunks_in_order
from genbacklash_ros.bags.rosbags_types import jazzy_typestore
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

T0 = 1_700_000_000_000_000_000


def _messages() -> list[tuple[str, int, object]]:
    out: list[tuple[str, int, object]] = []
    for k in range(50):
        t = T0 + k * 1_000_000
        out.append(("/cmd", t, Float64MultiArray(data=(0.01 * k, -1.0))))
        out.append(("/enc", t + 100, JointState(Header(Time.from_ns(t)), ("a", "b"), (k, 2.0))))
    out.append(("/f", T0 + 5, Float64(0.25)))
    status = DiagnosticStatus(1, "x", "warming up", "hw", (KeyValue("k", "v"),))
    out.append(("/diagnostics", T0 + 7, DiagnosticArray(Header(Time.from_ns(T0)), (status,))))
    return out


def _write(path: Path) -> list[tuple[str, int, object]]:
    msgs = _messages()
    with BagWriter(path) as writer:
        for topic, t, msg in msgs:
            writer.write(topic, t, msg)  # type: ignore[arg-type]
    return sorted(msgs, key=lambda m: m[1])


def test_round_trip_directory_and_bare_mcap(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    expected = _write(bag)
    assert (bag / "metadata.yaml").is_file()
    (mcap,) = bag.glob("*.mcap")
    topics = ["/cmd", "/enc", "/f", "/diagnostics"]
    for source in (bag, mcap):
        with BagReader(source) as reader:
            assert not reader.salvaged
            assert reader.topics["/enc"].count == 50
            assert reader.topics["/cmd"].msgtype == "std_msgs/msg/Float64MultiArray"
            got = [(m.topic, m.log_time_ns, m.message) for m in reader.messages(topics)]
        assert [g[1] for g in got] == sorted(g[1] for g in got)
        assert sorted(got, key=repr) == sorted(expected, key=repr)


def test_topic_selection(tmp_path: Path) -> None:
    _write(tmp_path / "bag")
    with BagReader(tmp_path / "bag") as reader:
        got = list(reader.messages(["/f"]))
    assert [m.message for m in got] == [Float64(0.25)]
    assert got[0].msgtype == "std_msgs/msg/Float64"


def test_missing_and_not_a_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="does not exist"):
        BagReader(tmp_path / "nothing")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"hello world" * 10)
    with pytest.raises(BagError, match="not a readable rosbag2 MCAP bag"):
        BagReader(junk).open()


def test_unknown_topic_lists_the_topics(tmp_path: Path) -> None:
    _write(tmp_path / "bag")
    with BagReader(tmp_path / "bag") as reader, pytest.raises(BagError) as info:
        list(reader.messages(["/nope"]))
    text = str(info.value)
    assert "'/nope' is not in" in text
    assert "/enc (sensor_msgs/msg/JointState, 50)" in text


def test_unsupported_type(tmp_path: Path) -> None:
    store = jazzy_typestore()
    string = store.types["std_msgs/msg/String"](data="hi")
    raw = store.serialize_cdr(string, "std_msgs/msg/String")
    with BagWriter(tmp_path / "bag") as writer:
        writer.write_raw("/s", T0, raw, "std_msgs/msg/String")
    with BagReader(tmp_path / "bag") as reader, pytest.raises(BagError, match="not supported"):
        list(reader.messages(["/s"]))
    with BagReader(tmp_path / "bag") as reader, pytest.raises(BagError, match="not supported"):
        reader.topic("/s", {"sensor_msgs/msg/JointState"})


def test_writer_refuses_an_existing_path(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="exists already"):
        BagWriter(tmp_path)


def test_writer_closes_on_error(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with pytest.raises(RuntimeError), BagWriter(bag) as writer:
        writer.write("/f", T0, Float64(1.0))
        raise RuntimeError("boom")
    with BagReader(bag) as reader:
        assert [m.message for m in reader.messages(["/f"])] == [Float64(1.0)]


def _big_bag(path: Path, n: int = 16_000) -> None:
    with BagWriter(path) as writer:
        for k in range(n):
            t = T0 + k * 1_000_000
            writer.write("/enc", t, JointState(Header(Time.from_ns(t)), ("j",), (float(k),)))


def test_truncated_bag_is_salvaged_then_reported(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _big_bag(bag)
    (mcap,) = bag.glob("*.mcap")
    data = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.85)])  # the first 1 MiB chunk complete
    seen = []
    with BagReader(cut) as reader, pytest.raises(BagError, match="truncated") as info:
        assert reader.salvaged
        for item in reader.messages(["/enc"]):
            seen.append(item.message.position[0])  # type: ignore[union-attr]
    assert "\n" not in str(info.value)
    assert 0 < len(seen) < 16_000
    assert seen == list(range(len(seen)))


def test_truncated_to_nothing(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _big_bag(bag, 10)
    (mcap,) = bag.glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[:20])
    with pytest.raises(BagError, match="holds no complete message"):
        BagReader(cut).open()


def test_align_holds_the_command() -> None:
    s = align(
        np.array([10, 20]), np.array([1.0, 2.0]), np.array([5, 10, 19, 20, 30]), np.arange(5.0)
    )
    assert s.t.tolist() == [10, 19, 20, 30]
    assert s.u.tolist() == [1.0, 1.0, 2.0, 2.0]
    assert s.skipped == 1


def test_align_breaks_where_a_reading_is_missing_or_taken_out() -> None:
    enc_t = np.array([5, 10, 15, 20, 30, 35, 40, 60, 65]) * 1_000_000  # 25, 45..55 lost
    s = align(np.array([10_000_000]), np.array([1.0]), enc_t, np.arange(9.0))
    assert s.skipped == 1 and s.t.tolist() == enc_t[1:].tolist()
    assert np.flatnonzero(s.breaks).tolist() == [0, 3, 6]
    marks = np.zeros(9, dtype=bool)
    marks[2] = True  # a rejected reading before the one at 15 ms
    s = align(np.array([10_000_000]), np.array([1.0]), enc_t, np.arange(9.0), marks=marks)
    assert np.flatnonzero(s.breaks).tolist() == [0, 1, 3, 6]


def copy_without(source: Path, target: Path, topic: str, lost: set[int]) -> None:
    """Copy a bag, leaving out the messages of ``topic`` whose (0-based) number is in
    ``lost``."""
    with BagReader(source) as reader, BagWriter(target) as writer:
        k = 0
        for m in reader.raw_messages(list(reader.topics)):
            if m.topic == topic:
                k += 1
                if k - 1 in lost:
                    continue
            writer.write_raw(m.topic, m.log_time_ns, m.raw, m.msgtype)


def test_read_aligned_breaks_after_lost_encoder_messages(tmp_path: Path) -> None:
    from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, write_example_bag

    write_example_bag(tmp_path / "full", 1, seed=0, n_samples=400)
    lost = {10, 11, 12, 200, 301}
    copy_without(tmp_path / "full", tmp_path / "lossy", ENCODER_TOPIC, lost)
    full = read_aligned(tmp_path / "full", COMMAND_TOPIC, ENCODER_TOPIC, joint=JOINT)
    assert np.flatnonzero(full.breaks).tolist() == [0]
    s = read_aligned(tmp_path / "lossy", COMMAND_TOPIC, ENCODER_TOPIC, joint=JOINT)
    kept = [i for i in range(400) if i not in lost]
    assert np.array_equal(s.y, full.y[kept])
    expected = [k for k, i in enumerate(kept) if k == 0 or i - 1 in lost]
    assert np.flatnonzero(s.breaks).tolist() == expected


def test_read_aligned_breaks_after_rejected_encoder_messages(tmp_path: Path) -> None:
    msgs = _messages()
    bad = {
        (T0 + 20 * 1_000_000): JointState(
            Header(Time.from_ns(T0 + 20 * 1_000_000)), ("x",), (0.0,)
        ),
        (T0 + 30 * 1_000_000): JointState(
            Header(Time.from_ns(T0 + 30 * 1_000_000)), ("a", "b"), (1.0, float("nan"))
        ),
    }
    with BagWriter(tmp_path / "bag") as writer:
        for topic, t, msg in msgs:
            if topic == "/enc" and t - 100 in bad:
                writer.write(topic, t - 50, bad[t - 100])  # rejected, just before the reading
            writer.write(topic, t, msg)  # type: ignore[arg-type]
            if topic == "/enc" and t - 100 == T0 + 40 * 1_000_000:
                writer.write(topic, t + 10, msg)  # type: ignore[arg-type]  # a duplicate
    s = read_aligned(tmp_path / "bag", "/cmd", "/enc", joint="b", command_index=0)
    assert s.y.size == 50
    assert np.flatnonzero(s.breaks).tolist() == [0, 20, 30]


def test_read_aligned(tmp_path: Path) -> None:
    _write(tmp_path / "bag")
    s = read_aligned(tmp_path / "bag", "/cmd", "/enc", joint="b", command_index=0)
    assert s.y.tolist() == [2.0] * 50
    assert np.allclose(s.u, 0.01 * np.arange(50))
    with pytest.raises(BagError, match="not supported"):
        read_aligned(tmp_path / "bag", "/diagnostics", "/enc")


def test_align_bridges_lost_readings_only_along_monotone_commands() -> None:
    """``bridge`` (a backlash alone): a break made by lost readings goes where the commands in
    force over the gap were monotone; across a reversal, after a rejected reading, or over
    a long gap it stays."""
    cmd_t = np.array([0, 30, 60, 90, 120])
    cmd_u = np.array([0.0, 0.5, 1.0, 0.2, 0.3])
    enc_t = np.arange(0, 1000, 10)
    long_gap = 300 + 10 * np.arange(MAX_BRIDGED + 1)  # one reading more than may be bridged
    lost = np.isin(enc_t, [40, 100, 200, 210, 220, 230, *long_gap])
    enc_t = enc_t[~lost]
    enc_y = np.zeros(enc_t.size)
    strict = align(cmd_t, cmd_u, enc_t, enc_y)
    bridged = align(cmd_t, cmd_u, enc_t, enc_y, bridge=True)
    at = {int(t): k for k, t in enumerate(enc_t)}
    after_long = int(long_gap[-1]) + 10
    assert all(strict.breaks[at[t]] for t in (50, 110, 240, after_long))
    assert not bridged.breaks[at[50]]  # 0.5 held over the lost reading at 40
    assert not bridged.breaks[at[110]]  # 0.2 from 90 on: held over 100 (one fall, 1.0 -> 0.2)
    assert not bridged.breaks[at[240]]  # 0.3 held over four lost readings
    assert bridged.breaks[at[after_long]]  # too long a gap
    reversing = align(
        np.array([0, 35, 45]),
        np.array([0.0, 1.0, 0.0]),
        np.array([0, 10, 20, 30, 50]),
        np.zeros(5),
        bridge=True,
    )
    assert reversing.breaks.tolist() == [True, False, False, False, True]  # 0 -> 1 -> 0 at 40
    marked = align(cmd_t, cmd_u, enc_t, enc_y, bridge=True, marks=enc_t == 50)
    assert marked.breaks[at[50]]  # a reading taken out before it: never bridged


REPO_BAGS = Path(__file__).resolve().parents[3] / "bags"


@pytest.mark.parametrize("name", ["drivetrain", "operation", "example1", "example3"])
def test_chunks_in_order_read_as_rosbags_merges_them(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The bundled bags (recorder-like: chunks one after the other in time) are read chunk
    after chunk, and that is the stream rosbags' merging reader gives, for the directory
    and for the bare .mcap file."""
    bag = REPO_BAGS / name
    (mcap,) = bag.glob("*.mcap")
    for source in (bag, mcap):
        with BagReader(source) as reader:
            topics = list(reader.topics)
            assert chunks_in_order(reader._reader, set(topics)) is not None
            chunked = list(reader.raw_messages(topics))
        with monkeypatch.context() as patch:
            patch.setattr(bag_reader, "chunks_in_order", lambda *args: None)
            with BagReader(source) as reader:
                assert list(reader.raw_messages(topics)) == chunked
        with BagReader(source) as reader:
            assert len(chunked) == sum(t.count for t in reader.topics.values())


def test_chunks_out_of_order_go_through_rosbags_merge(tmp_path: Path) -> None:
    """A file whose chunks overlap in time (written out of order) is read through rosbags'
    merge, in log-time order."""
    store = jazzy_typestore()
    raw = bytes(
        store.serialize_cdr(store.types["std_msgs/msg/Float64"](data=1.5), "std_msgs/msg/Float64")
    )
    times = [T0 + k for k in range(20_000, 40_000)] + [T0 + k for k in range(20_000)]
    with BagWriter(tmp_path / "bag") as writer:  # ~1.7 MB: chunks of 1 MiB overlap in time
        writer.add_topic("/x", "std_msgs/msg/Float64")
        writer.write_raw_many([("/x", t, raw) for t in times])
    with BagReader(tmp_path / "bag") as reader:
        assert chunks_in_order(reader._reader, {"/x"}) is None
        got = [m.log_time_ns for m in reader.raw_messages(["/x"])]
    assert got == sorted(times)


@pytest.mark.parametrize("compiled", [True, False])
def test_write_messages_copies_what_was_read(tmp_path: Path, compiled: bool) -> None:
    with BagReader(REPO_BAGS / "drivetrain") as reader:
        topics = reader.topics
        read = list(reader.raw_messages(list(topics)))
    with BagWriter(tmp_path / "copy", compiled=compiled) as writer:
        for topic, info in topics.items():
            writer.add_topic(topic, info.msgtype)
        writer.write_messages(read[:100])
        writer.write_messages([])
        writer.write_messages(read[100:])
    assert writer.count == len(read)
    with BagReader(tmp_path / "copy") as reader:
        assert list(reader.raw_messages(list(topics))) == read
        assert {t: i.count for t, i in reader.topics.items()} == {
            t: i.count for t, i in topics.items()
        }
