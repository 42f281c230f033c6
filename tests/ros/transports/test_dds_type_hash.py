"""REP-2016 type hashes: the rules here, and the table against a ROS 2 installation's own.

Each type's description and hash are compared with the ``share/<pkg>/msg/<Type>.json`` that
``rosidl_generator_type_description`` wrote when the message package was built, found on
``AMENT_PREFIX_PATH``: the ROS 2 wheels of the ``ros`` extra ship them (tests/ros/conftest.py
points ``AMENT_PREFIX_PATH`` at the environment), as does a sourced ROS 2 installation; where
neither is there those tests skip with the reason.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from genbacklash_ros.transports.type_hash import (
    MESSAGE_FIELDS,
    TypeHashError,
    field_descriptions,
    type_description,
    type_hash,
    typehash_user_data,
)


def _installed(ros_type: str) -> dict[str, Any] | None:
    """The generated type description JSON of ``ros_type`` on ``AMENT_PREFIX_PATH``, if any."""
    package, _, name = ros_type.split("/")
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        path = Path(prefix) / "share" / package / "msg" / f"{name}.json"
        if prefix and path.is_file():
            data: dict[str, Any] = json.loads(path.read_text())
            return data
    return None


def _without_defaults(description: dict[str, Any]) -> dict[str, Any]:
    def strip(td: dict[str, Any]) -> dict[str, Any]:
        fields = [{k: v for k, v in f.items() if k != "default_value"} for f in td["fields"]]
        return {"type_name": td["type_name"], "fields": fields}

    return {
        "type_description": strip(description["type_description"]),
        "referenced_type_descriptions": [
            strip(td) for td in description["referenced_type_descriptions"]
        ],
    }


@pytest.mark.parametrize("ros_type", sorted(MESSAGE_FIELDS))
def test_matches_the_installed_ros2_type_description(ros_type: str) -> None:
    installed = _installed(ros_type)
    if installed is None:
        pytest.skip(
            f"no {ros_type} type description JSON on AMENT_PREFIX_PATH (the ROS 2 wheels of "
            "the ros extra, pip install -e '.[ros]', ship it): cannot compare with the real hash"
        )
    assert type_description(ros_type) == _without_defaults(installed["type_description_msg"])
    assert type_hash(ros_type) == installed["type_hashes"][0]["hash_string"]


def test_every_wire_type_has_a_description_with_its_field_names() -> None:
    dds_convert = pytest.importorskip(
        "genbacklash_ros.transports.dds_convert", reason="cyclonedds is not installed"
    )
    from dataclasses import fields

    for ros_type, wire in dds_convert.DDS_TYPES.items():
        names = [f.name for f in field_descriptions(ros_type)]
        assert names == [f.name for f in fields(wire)], ros_type


def test_user_data_is_the_rmw_key_value_form() -> None:
    data = typehash_user_data("sensor_msgs/msg/JointState")
    key, _, value = data.decode("ascii").partition("=")
    assert key == "typehash"
    assert value.endswith(";")
    assert value[:-1] == type_hash("sensor_msgs/msg/JointState")
    assert len(value[:-1]) == len("RIHS01_") + 64


def test_referenced_types_are_included_and_sorted() -> None:
    refs = type_description("diagnostic_msgs/msg/DiagnosticArray")["referenced_type_descriptions"]
    names = [r["type_name"] for r in refs]
    assert names == sorted(names)
    # nested twice over: DiagnosticArray -> Header -> Time
    assert "builtin_interfaces/msg/Time" in names
    assert "diagnostic_msgs/msg/KeyValue" in names


def test_a_referenced_type_changes_the_hash(monkeypatch: pytest.MonkeyPatch) -> None:
    before = type_hash("std_msgs/msg/Float64MultiArray")
    table = dict(MESSAGE_FIELDS)
    table["std_msgs/msg/MultiArrayDimension"] = ("string label", "uint32 size")
    monkeypatch.setattr("genbacklash_ros.transports.type_hash.MESSAGE_FIELDS", table)
    type_hash.cache_clear()
    try:
        assert type_hash("std_msgs/msg/Float64MultiArray") != before
    finally:
        type_hash.cache_clear()


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("float64", "cannot read the field line"),
        ("float64<=3 x", "only strings take a bound"),
        ("Header<=3 x", "only strings take a bound"),
        ("float64[x] data", "cannot read the field line"),
    ],
)
def test_bad_field_lines_are_refused(
    monkeypatch: pytest.MonkeyPatch, line: str, message: str
) -> None:
    monkeypatch.setattr(
        "genbacklash_ros.transports.type_hash.MESSAGE_FIELDS", {"pkg/msg/Bad": (line,)}
    )
    with pytest.raises(TypeHashError, match=message):
        field_descriptions("pkg/msg/Bad")


def test_unknown_type_is_refused_with_the_known_ones() -> None:
    with pytest.raises(TypeHashError, match=r"no type description for 'geometry_msgs/msg/Twist'"):
        type_hash("geometry_msgs/msg/Twist")
