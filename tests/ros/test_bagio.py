"""Bag IO: round trips through rosbags' MCAP writer and reader, errors, salvage, alignment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_ros.bagio import BagError, BagReader, BagWriter, align, read_aligned
from genbacklash_ros.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    KeyValue,
    Time,
)
from genbacklash_ros.rosbags_types import jazzy_typestore

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


def test_read_aligned(tmp_path: Path) -> None:
    _write(tmp_path / "bag")
    s = read_aligned(tmp_path / "bag", "/cmd", "/enc", joint="b", command_index=0)
    assert s.y.tolist() == [2.0] * 50
    assert np.allclose(s.u, 0.01 * np.arange(50))
    with pytest.raises(BagError, match="not supported"):
        read_aligned(tmp_path / "bag", "/diagnostics", "/enc")
