"""Bad bags (issue 6, item 2): every kind of damage gives a one-line reason and exit 2, no
traceback, and what was processed before the damage is kept in a valid output bag."""

from __future__ import annotations

import random
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from genbacklash_ros.bags.bagio import BagReader, BagWriter
from genbacklash_ros.bags.replay import OUTPUT_TOPICS
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, write_example_bag
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, main
from genbacklash_ros.node.messages import Float64MultiArray

TOPICS = ["--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC, "--joint", JOINT]


@pytest.fixture(scope="module")
def good_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("good") / "ex1"
    write_example_bag(bag, 1, seed=3, n_samples=1200)
    return bag


def _mcap(bag: Path) -> Path:
    (file,) = bag.glob("*.mcap")
    return file


def _flip(start: float, length: int) -> Callable[[Path], None]:
    """Invert ``length`` bytes from the fraction ``start`` of the MCAP file on."""

    def damage(bag: Path) -> None:
        file = _mcap(bag)
        data = bytearray(file.read_bytes())
        at = int(len(data) * start)
        for i in range(at, min(at + length, len(data))):
            data[i] ^= 0xFF
        file.write_bytes(bytes(data))

    return damage


def _truncate(fraction: float) -> Callable[[Path], None]:
    def damage(bag: Path) -> None:
        file = _mcap(bag)
        file.write_bytes(file.read_bytes()[: int(file.stat().st_size * fraction)])

    return damage


def _bad_metadata(bag: Path) -> None:
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n  : :\n")


def _no_metadata(bag: Path) -> None:
    (bag / "metadata.yaml").unlink()


def _no_mcap(bag: Path) -> None:
    _mcap(bag).unlink()


def _empty_mcap(bag: Path) -> None:
    _mcap(bag).write_bytes(b"")


def _random_mcap(bag: Path) -> None:
    _mcap(bag).write_bytes(random.Random(0).randbytes(4000))


# damage -> (words the reason must contain, whether messages before the damage are kept)
DAMAGE: dict[str, tuple[Callable[[Path], None], str, bool]] = {
    "truncated_early": (_truncate(0.05), "truncated", False),
    "truncated_late": (_truncate(0.6), "truncated", True),
    "flipped_early": (_flip(0.02, 100), "corrupt", True),
    "flipped_middle": (_flip(0.5, 64), "corrupt", True),
    "flipped_summary": (_flip(0.995, 40), "recovered", True),
    "bad_metadata": (_bad_metadata, "metadata.yaml", True),
    "no_metadata": (_no_metadata, "metadata", True),
    "no_mcap": (_no_mcap, "missing", False),
    "empty_mcap": (_empty_mcap, "empty", False),
    "random_bytes": (_random_mcap, "not a readable", False),
}


def _replay(bag: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(["replay", str(bag), *TOPICS, "-o", str(out), "--no-progress"])
    return code, capsys.readouterr().err


def _check_one_line(err: str) -> str:
    assert "Traceback" not in err
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1, err  # one line: the reason (nothing else on stderr)
    assert lines[0].startswith("genbacklash replay: error: ")
    return lines[0]


def _check_valid_output(out: Path) -> int:
    """The output bag opens normally and every number the node wrote is finite."""
    with BagReader(out) as reader:
        assert not reader.salvaged
        topics = reader.topics
        kept = topics[ENCODER_TOPIC].count if ENCODER_TOPIC in topics else 0
        outputs = [t for t in OUTPUT_TOPICS.values() if t in topics and topics[t].count]
        for item in reader.messages(outputs):
            msg = item.message
            if isinstance(msg, Float64MultiArray):
                assert np.all(np.isfinite(np.asarray(msg.data, dtype=float)))
    return kept


@pytest.mark.parametrize("name", sorted(DAMAGE))
def test_damaged_bag(
    name: str, good_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    damage, words, kept = DAMAGE[name]
    bag = tmp_path / "bag"
    shutil.copytree(good_bag, bag)
    damage(bag)
    out = tmp_path / "out"
    code, err = _replay(bag, out, capsys)
    assert code == EXIT_BAD_INPUT
    line = _check_one_line(err)
    assert words in line
    if kept:
        assert "kept" in line
        assert _check_valid_output(out) > 0
    elif out.exists():
        _check_valid_output(out)


def test_missing_path_missing_topic_and_not_a_bag(
    good_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, err = _replay(tmp_path / "nowhere", tmp_path / "o1", capsys)
    assert code == EXIT_BAD_INPUT and "does not exist" in _check_one_line(err)
    empty = tmp_path / "empty_dir"
    empty.mkdir()
    code, err = _replay(empty, tmp_path / "o2", capsys)
    assert code == EXIT_BAD_INPUT and "not a readable" in _check_one_line(err)
    code = main(["replay", str(good_bag), "--command", COMMAND_TOPIC, "--encoder", "/joint_states",
                 "-o", str(tmp_path / "o3"), "--no-progress"])  # fmt: skip
    line = _check_one_line(capsys.readouterr().err)
    assert code == EXIT_BAD_INPUT and "'/joint_states' is not in" in line
    assert "/encoder (sensor_msgs/msg/JointState" in line  # says what the bag has
    assert not (tmp_path / "o3").exists()  # nothing was processed: no output


def test_unknown_message_type(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msg = store.types["std_msgs/msg/String"](data="hello")
    raw = bytes(store.serialize_cdr(msg, "std_msgs/msg/String"))
    bag = tmp_path / "strings"
    with BagWriter(bag) as writer:
        writer.add_topic(COMMAND_TOPIC, "std_msgs/msg/String")
        writer.add_topic(ENCODER_TOPIC, "std_msgs/msg/String")
        for k in range(10):
            writer.write_raw(COMMAND_TOPIC, 1_000 + k, raw, "std_msgs/msg/String")
    code, err = _replay(bag, tmp_path / "o", capsys)
    line = _check_one_line(err)
    assert code == EXIT_BAD_INPUT
    assert "std_msgs/msg/String" in line and "not supported" in line
    assert "std_msgs/msg/Float64MultiArray" in line  # says what would work


def test_a_corrupt_message_in_a_good_file(
    good_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A message whose CDR bytes do not decode (a buggy recorder) is skipped, the replay
    goes on, and the end says the bag is corrupt."""
    bag = tmp_path / "one_bad"
    with BagReader(good_bag) as reader, BagWriter(bag) as writer:
        cmd = reader.topics[COMMAND_TOPIC].msgtype
        enc = reader.topics[ENCODER_TOPIC].msgtype
        writer.add_topic(COMMAND_TOPIC, cmd)
        writer.add_topic(ENCODER_TOPIC, enc)
        for k, item in enumerate(reader.messages([COMMAND_TOPIC, ENCODER_TOPIC])):
            raw = item.raw[:9] if k == 1501 else item.raw  # cut one encoder message short
            writer.write_raw(item.topic, item.log_time_ns, raw, item.msgtype)
    out = tmp_path / "out"
    code, err = _replay(bag, out, capsys)
    line = _check_one_line(err)
    assert code == EXIT_BAD_INPUT and "kept" in line
    assert "1 message was not decodable" in line and "/encoder" in line
    assert _check_valid_output(out) == 1200  # nothing lost: every input message is copied


def test_no_traceback_from_a_real_process(good_bag: Path, tmp_path: Path) -> None:
    """The console script itself (not just main()) prints one line and exits 2."""
    bag = tmp_path / "bag"
    shutil.copytree(good_bag, bag)
    _flip(0.02, 100)(bag)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "genbacklash_ros.cli.main",
            "replay",
            str(bag),
            *TOPICS,
            "-o",
            str(tmp_path / "out"),
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == EXIT_BAD_INPUT
    _check_one_line(proc.stderr)
