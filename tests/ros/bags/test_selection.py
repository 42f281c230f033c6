"""A selection that matches nothing stops before any work, saying what the bag holds (issue 22,
deliverable 2): a joint, a command index, a topic, a multi-joint JointState without a joint;
the same check for ``replay``, ``identify``, ``diagnose`` (and the fleet's archive check)."""

from __future__ import annotations

from pathlib import Path

import pytest

from genbacklash_ros.bags.bagio import BagError, BagReader, BagWriter, check_selection, read_aligned
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, main
from genbacklash_ros.fleet.archive import discover
from genbacklash_ros.fleet.job import FleetSettings, check_archive
from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time

T0 = 1_700_000_000_000_000_000
JOINTS = ("shoulder", "elbow", "wrist")


def _arm_bag(path: Path, joints: tuple[str, ...] = JOINTS, width: int = 2) -> Path:
    """A bag of 200 samples: /cmd a Float64MultiArray of ``width`` values, /enc a JointState
    of ``joints``, /joint_cmd a JointState command of the same joints."""
    with BagWriter(path) as writer:
        for k in range(200):
            t = T0 + k * 1_000_000
            u = 0.5 * ((k // 20) % 2) - 0.25
            writer.write("/cmd", t, Float64MultiArray(data=(u,) * width))
            writer.write(
                "/joint_cmd", t, JointState(Header(Time.from_ns(t)), joints, (u,) * len(joints))
            )
            writer.write(
                "/enc",
                t + 100,
                JointState(Header(Time.from_ns(t)), joints, (0.9 * u,) * len(joints)),
            )
    return path


def _error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    prefix = f"genbacklash {command}: error: "
    assert err.startswith(prefix), err
    return err[len(prefix) :]


def test_check_selection_accepts_what_the_bag_holds(tmp_path: Path) -> None:
    bag = _arm_bag(tmp_path / "bag")
    with BagReader(bag) as reader:
        cmd, enc = check_selection(reader, "/cmd", "/enc", joint="elbow", command_index=1)
        assert (cmd.name, enc.name) == ("/cmd", "/enc")
        check_selection(reader, "/joint_cmd", "/enc", joint="wrist")
    single = _arm_bag(tmp_path / "single", joints=("drive",))
    with BagReader(single) as reader:  # one joint: no need to name it
        check_selection(reader, "/cmd", "/enc")


@pytest.mark.parametrize(
    ("topics", "joint", "index", "match"),
    [
        (("/cmd", "/enc"), "Elbow", 0, r"joint 'Elbow' is not in the encoder JointState on "
         r"/enc .* \(did you mean 'elbow'\?\); it holds: shoulder, elbow, wrist"),
        (("/cmd", "/enc"), "", 0, r"holds 3 joints \(shoulder, elbow, wrist\): say which "
         r"with --joint NAME"),
        (("/cmd", "/enc"), "elbow", 2, r"command index 2 is beyond the Float64MultiArray on "
         r"/cmd .*: it holds 2 values \(indices 0 to 1\)"),
        (("/cmd", "/enc"), "elbow", -1, r"command index must be >= 0, got -1"),
        (("/comand", "/enc"), "elbow", 0, r"topic '/comand' is not in .* \(did you mean "
         r"'/command'\?\)|topic '/comand' is not in .*the bag has: /cmd "
         r"\(std_msgs/msg/Float64MultiArray, 200\)"),
        (("/cmd", "/cmd"), "elbow", 0, r"must differ"),
    ],
)  # fmt: skip
def test_check_selection_names_what_the_bag_holds(
    tmp_path: Path, topics: tuple[str, str], joint: str, index: int, match: str
) -> None:
    bag = _arm_bag(tmp_path / "bag")
    with BagReader(bag) as reader, pytest.raises(BagError, match=match):
        check_selection(reader, *topics, joint=joint, command_index=index)


def test_a_joint_the_command_lacks(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag") as writer:
        for k in range(20):
            t = T0 + k * 1_000_000
            writer.write("/jc", t, JointState(Header(Time.from_ns(t)), ("a",), (0.1,)))
            writer.write("/enc", t + 1, JointState(Header(Time.from_ns(t)), ("b",), (0.1,)))
    with (
        BagReader(tmp_path / "bag") as reader,
        pytest.raises(
            BagError, match=r"joint 'b' is not in the command JointState on /jc .* it holds: a"
        ),
    ):
        check_selection(reader, "/jc", "/enc", joint="b")


def test_read_aligned_and_replay_check_first(tmp_path: Path) -> None:
    bag = _arm_bag(tmp_path / "bag")
    with pytest.raises(BagError, match="holds 3 joints"):
        read_aligned(bag, "/cmd", "/enc")
    assert read_aligned(bag, "/cmd", "/enc", joint="wrist", command_index=1).u.size == 200
    with pytest.raises(BagError, match="beyond the Float64MultiArray"):
        replay(bag, tmp_path / "out", command_topic="/cmd", encoder_topic="/enc",
               joint="elbow", command_index=5)  # fmt: skip
    assert not (tmp_path / "out").exists()  # stopped before the output was made


@pytest.mark.parametrize("command", ["replay", "identify", "diagnose"])
@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--joint", "Elbow"], "did you mean 'elbow'"),
        (["--joint", "elbow", "--command-index", "4"], "holds 2 values"),
        ([], "say which with --joint NAME"),
        (["--param", "joint=knee"], "it holds: shoulder, elbow, wrist"),
    ],
)
def test_every_bag_command_stops_with_exit_2(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    extra: list[str],
    words: str,
) -> None:
    bag = _arm_bag(tmp_path / "bag")
    argv = [command, str(bag), "--command", "/cmd", "--encoder", "/enc", *extra]
    if command == "replay":
        argv += ["-o", str(tmp_path / "out"), "--no-progress"]
    assert main(argv) == EXIT_BAD_INPUT
    assert words in _error(capsys, command)
    assert not (tmp_path / "out").exists()


def test_a_missing_topic_lists_the_topics_with_types(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _arm_bag(tmp_path / "bag")
    argv = ["identify", str(bag), "--command", "/x", "--encoder", "/enc", "--joint", "elbow"]
    assert main(argv) == EXIT_BAD_INPUT
    error = _error(capsys, "identify")
    for topic in ("/cmd (std_msgs/msg/Float64MultiArray, 200)",
                  "/enc (sensor_msgs/msg/JointState, 200)",
                  "/joint_cmd (sensor_msgs/msg/JointState, 200)"):  # fmt: skip
        assert topic in error


def test_fleet_archive_without_bags_or_topics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty"
    (empty / "robot").mkdir(parents=True)
    (empty / "robot" / "notes.txt").write_text("x")
    with pytest.raises(Exception, match=r"holds no bags .* it holds 1 file: robot/notes.txt"):
        check_archive(empty, discover(empty), FleetSettings())
    archive = tmp_path / "archive"
    _arm_bag(archive / "robot" / "elbow" / "2024-03-05")
    _arm_bag(archive / "robot" / "wrist" / "2024-03-05")
    bags = discover(archive)
    check_archive(archive, bags, FleetSettings(command_topic="/cmd", encoder_topic="/enc"))
    with pytest.raises(Exception, match=r"no bag of .* holds both --command /command and "
                       r"--encoder /encoder .* 2 readable bags hold: /cmd "
                       r"\(std_msgs/msg/Float64MultiArray, in 2 bags\)"):  # fmt: skip
        check_archive(archive, bags, FleetSettings())
    db = tmp_path / "fleet.db"
    for argv in (
        ["fleet", str(empty), "--db", str(db), "--threads", "--no-progress"],
        ["fleet", str(archive), "--db", str(db), "--threads", "--no-progress"],
    ):
        assert main(argv) == EXIT_BAD_INPUT
        assert "Traceback" not in capsys.readouterr().err
    assert not db.exists()  # stopped before the database and the cluster
