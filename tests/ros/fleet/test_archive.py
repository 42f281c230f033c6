"""Archive discovery: the path rule, metadata overrides, content hashes."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.bagio import BagWriter
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, command_message
from genbacklash_ros.fleet.archive import (
    JOINT_KEY,
    ROBOT_KEY,
    bag_start_ns,
    content_hash,
    discover,
    parse_timestamp,
    path_identity,
)
from genbacklash_ros.fleet.job import FleetSettings, JointRequest, inspect_bag
from genbacklash_ros.node.messages import Float64MultiArray

DAY = 86_400 * 10**9
T0 = parse_timestamp("2024-03-05")


def _bag(path: Path, custom: dict[str, str] | None = None, start_ns: int = 10**18) -> Path:
    with BagWriter(path) as writer:
        for key, value in (custom or {}).items():
            writer.set_custom_data(key, value)
        writer.add_topic(COMMAND_TOPIC, Float64MultiArray.ros_type)
        writer.write(COMMAND_TOPIC, start_ns, command_message((0.1,)))
        writer.write(COMMAND_TOPIC, start_ns + 10**6, command_message((0.2,)))
    return path


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("2024-03-05", T0),
        ("20240305", T0),
        ("run_2024-03-05T08-30-15", T0 + (8 * 3600 + 30 * 60 + 15) * 10**9),
        ("2024-03-05 08:30:15.mcap", T0 + (8 * 3600 + 30 * 60 + 15) * 10**9),
        ("rosbag2_2024_03_05-08_30_15", T0 + (8 * 3600 + 30 * 60 + 15) * 10**9),  # ros2 bag's
        ("2024-03_05", None),  # mixed separators
        ("2024-02-30", None),  # no such day
        ("2024-13-01", None),
        ("robot-07", None),
        ("123456789", None),
    ],
)
def test_parse_timestamp(text: str, expected: int | None) -> None:
    assert parse_timestamp(text) == expected


def test_path_rule_name_then_directory_then_none() -> None:
    named = path_identity(("r1", "elbow", "2024-03-04"), "2024-03-05T00-00-00.mcap", "arch")
    assert named == ("r1", "elbow", T0, "name")
    in_dir = path_identity(("r1", "2024-03-05", "elbow"), "take1", "arch")
    assert in_dir == ("r1", "elbow", T0, "directory")  # the date directory is not a name
    bare = path_identity((), "take1.mcap", "arch")
    assert bare == ("arch", None, None, None)


def test_discover_finds_bags_not_inside_them(tmp_path: Path) -> None:
    root = tmp_path / "arch"
    _bag(root / "r1" / "elbow" / "2024-03-05")
    _bag(root / "r2" / "2024-03-06" / "d")
    (root / "r2" / "notes.txt").write_text("not a bag")
    shutil.copy(next((root / "r1" / "elbow" / "2024-03-05").glob("*.mcap")), root / "r3.mcap")
    _bag(root / ".hidden" / "x")
    found = discover(root)
    assert [b.relpath for b in found] == ["r1/elbow/2024-03-05", "r2/2024-03-06/d", "r3.mcap"]
    # the .mcap inside the rosbag2 directory is part of that bag, not a bag of its own
    assert found[1].identity == ("r2", None, T0 + DAY, "directory")  # no joint directory
    assert found[2].identity.robot == "arch"


def test_discover_rejects_a_file(tmp_path: Path) -> None:
    with pytest.raises(GenBacklashError, match="is not a directory"):
        discover(tmp_path / "missing")


def test_metadata_overrides_path_and_gives_time(tmp_path: Path) -> None:
    root = tmp_path / "arch"
    start = 1_700_000_000 * 10**9
    _bag(root / "misc" / "take1", {ROBOT_KEY: "robot-9", JOINT_KEY: "knee"}, start_ns=start)
    (bag,) = discover(root)
    assert bag.identity == ("misc", None, None, None)
    plan = inspect_bag(bag, FleetSettings(joints=(JointRequest("hip", 1),)))
    assert (plan.robot, plan.joints) == ("robot-9", (("knee", 0),))  # the metadata's joint
    assert (plan.recorded_ns, plan.time_source) == (start, "metadata")
    assert bag_start_ns(bag.path) == start


def test_joint_requests_when_the_bag_names_none(tmp_path: Path) -> None:
    (bag,) = discover(_bag(tmp_path / "arch" / "r1" / "2024-03-05").parent.parent)
    settings = FleetSettings(joints=(JointRequest("hip", 1), JointRequest("knee")))
    plan = inspect_bag(bag, settings)
    assert plan.joints == (("hip", 1), ("knee", 0))


def test_content_hash_follows_content_not_place(tmp_path: Path) -> None:
    a = _bag(tmp_path / "a")
    b = tmp_path / "elsewhere" / "b"
    shutil.copytree(a, b)
    assert content_hash(a) == content_hash(b)
    mcap = next(b.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes() + b"\0")
    assert content_hash(a) != content_hash(b)
