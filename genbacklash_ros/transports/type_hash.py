"""ROS 2 type hashes (REP-2016, ``RIHS01``) of the message types the DDS transport uses.

Since Iron every ROS 2 endpoint announces ``typehash=RIHS01_<sha256 hex>;`` in its DDS USER_DATA
QoS; an ``rmw_cyclonedds_cpp`` peer that discovers an endpoint without it logs
``Failed to parse type hash ... from USER_DATA '(null)'`` once per topic.

The hash is computed here the way ``rosidl_generator_type_description`` computes it: the type
description (the type's fields as ``type_description_interfaces/msg/Field`` records, plus the
descriptions of every type it references, sorted by name) is written as canonical JSON
(``json.dumps`` with ``", "`` and ``": "`` separators, keys in message order, no default
values) and hashed with SHA-256. The fields come from :data:`MESSAGE_FIELDS`, the field lines
of each ``.msg`` file (constants and comments left out: they are not part of the description).
The table is checked against a ROS 2 installation's generated ``share/<pkg>/msg/<Type>.json``
type descriptions and hashes by ``tests/ros/transports/test_dds_type_hash.py`` whenever one is
sourced. Computing from the definitions rather than storing hash strings keeps the table
reviewable against the ``.msg`` files and makes a wrong entry fail on the field that is wrong.

This module is pure Python (no cyclonedds, no ROS).

Examples
--------
>>> type_hash("std_msgs/msg/Float64")
'RIHS01_705ba9c3d1a09df43737eb67095534de36fd426c0587779bda2bc51fe790182a'
>>> typehash_user_data("std_msgs/msg/Float64")[:16]
b'typehash=RIHS01_'
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

from genbacklash_core import GenBacklashError

__all__ = [
    "MESSAGE_FIELDS",
    "FieldDescription",
    "TypeHashError",
    "field_descriptions",
    "type_description",
    "type_hash",
    "typehash_user_data",
]

MESSAGE_FIELDS: Mapping[str, tuple[str, ...]] = {
    "builtin_interfaces/msg/Time": ("int32 sec", "uint32 nanosec"),
    "std_msgs/msg/Header": ("builtin_interfaces/Time stamp", "string frame_id"),
    "std_msgs/msg/Float64": ("float64 data",),
    "std_msgs/msg/MultiArrayDimension": ("string label", "uint32 size", "uint32 stride"),
    "std_msgs/msg/MultiArrayLayout": ("MultiArrayDimension[] dim", "uint32 data_offset"),
    "std_msgs/msg/Float64MultiArray": ("MultiArrayLayout layout", "float64[] data"),
    "sensor_msgs/msg/JointState": (
        "std_msgs/Header header",
        "string[] name",
        "float64[] position",
        "float64[] velocity",
        "float64[] effort",
    ),
    "diagnostic_msgs/msg/KeyValue": ("string key", "string value"),
    "diagnostic_msgs/msg/DiagnosticStatus": (
        "byte level",
        "string name",
        "string message",
        "string hardware_id",
        "KeyValue[] values",
    ),
    "diagnostic_msgs/msg/DiagnosticArray": ("std_msgs/Header header", "DiagnosticStatus[] status"),
    "rmw_dds_common/msg/Gid": ("char[16] data",),
    "rmw_dds_common/msg/NodeEntitiesInfo": (
        "string<=256 node_namespace",
        "string<=256 node_name",
        "Gid[] reader_gid_seq",
        "Gid[] writer_gid_seq",
    ),
    "rmw_dds_common/msg/ParticipantEntitiesInfo": (
        "Gid gid",
        "NodeEntitiesInfo[] node_entities_info_seq",
    ),
}
"""ROS type name -> its ``.msg`` field lines (Jazzy), for every type the DDS transport uses."""

# type_description_interfaces/msg/FieldType ids of the .msg primitives (char and byte as rosidl
# maps them to IDL: char -> uint8, byte -> octet)
_PRIMITIVE_IDS = {
    "int8": 2,
    "uint8": 3,
    "char": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "bool": 15,
    "byte": 16,
    "string": 17,
    "wstring": 18,
}
_NESTED_ID = 1
_BOUNDED_STRING_ID = {"string": 21, "wstring": 22}
_ARRAY, _BOUNDED_SEQUENCE, _UNBOUNDED_SEQUENCE = 48, 96, 144  # added to the element's id
_FIELD_LINE = re.compile(
    r"^(?P<base>[A-Za-z][\w/]*)(?:<=(?P<strcap>\d+))?"
    r"(?P<suffix>\[\]|\[\d+\]|\[<=\d+\])?\s+(?P<name>[a-z]\w*)$"
)
RIHS01_PREFIX = "RIHS01_"


class TypeHashError(GenBacklashError):
    """A type without a definition here, or a field line that cannot be read."""


@dataclass(frozen=True)
class FieldDescription:
    """One ``type_description_interfaces/msg/Field`` (without its default value, which the
    hash leaves out)."""

    name: str
    type_id: int
    capacity: int = 0
    string_capacity: int = 0
    nested_type_name: str = ""

    def as_dict(self) -> dict[str, Any]:
        """The field as the canonical JSON has it (key order matters for the hash)."""
        return {
            "name": self.name,
            "type": {
                "type_id": self.type_id,
                "capacity": self.capacity,
                "string_capacity": self.string_capacity,
                "nested_type_name": self.nested_type_name,
            },
        }


def _parse_field(line: str, package: str) -> FieldDescription:
    match = _FIELD_LINE.match(line.strip())
    if match is None:
        raise TypeHashError(f"cannot read the field line {line!r}")
    base, strcap, suffix, name = match["base"], match["strcap"], match["suffix"], match["name"]
    nested = ""
    if base in _PRIMITIVE_IDS:
        type_id = _PRIMITIVE_IDS[base]
        string_capacity = 0
        if strcap is not None:
            if base not in _BOUNDED_STRING_ID:
                raise TypeHashError(f"only strings take a bound (<=N): {line!r}")
            type_id, string_capacity = _BOUNDED_STRING_ID[base], int(strcap)
    else:
        if strcap is not None:
            raise TypeHashError(f"only strings take a bound (<=N): {line!r}")
        pkg, _, short = base.rpartition("/")
        nested = f"{pkg or package}/msg/{short}"
        type_id, string_capacity = _NESTED_ID, 0
    capacity = 0
    if suffix == "[]":
        type_id += _UNBOUNDED_SEQUENCE
    elif suffix and suffix.startswith("[<="):
        type_id += _BOUNDED_SEQUENCE
        capacity = int(suffix[3:-1])
    elif suffix:
        type_id += _ARRAY
        capacity = int(suffix[1:-1])
    return FieldDescription(name, type_id, capacity, string_capacity, nested)


def field_descriptions(ros_type: str) -> tuple[FieldDescription, ...]:
    """The fields of ``ros_type`` (``pkg/msg/Type``) from :data:`MESSAGE_FIELDS`.

    >>> [f.type_id for f in field_descriptions("std_msgs/msg/Float64MultiArray")]
    [1, 155]
    """
    try:
        lines = MESSAGE_FIELDS[ros_type]
    except KeyError:
        known = ", ".join(sorted(MESSAGE_FIELDS))
        raise TypeHashError(f"no type description for {ros_type!r}; known: {known}") from None
    package = ros_type.split("/", 1)[0]
    return tuple(_parse_field(line, package) for line in lines)


def _referenced(ros_type: str) -> list[str]:
    seen: set[str] = set()
    queue = [f.nested_type_name for f in field_descriptions(ros_type) if f.nested_type_name]
    while queue:
        name = queue.pop()
        if name not in seen:
            seen.add(name)
            queue.extend(f.nested_type_name for f in field_descriptions(name) if f.nested_type_name)
    return sorted(seen)


def _description(ros_type: str) -> dict[str, Any]:
    return {
        "type_name": ros_type,
        "fields": [f.as_dict() for f in field_descriptions(ros_type)],
    }


def type_description(ros_type: str) -> dict[str, Any]:
    """The hashed form of ``type_description_interfaces/msg/TypeDescription`` for ``ros_type``:
    ``{"type_description": ..., "referenced_type_descriptions": [...]}``, referenced types
    sorted by name, fields without default values.
    """
    return {
        "type_description": _description(ros_type),
        "referenced_type_descriptions": [_description(name) for name in _referenced(ros_type)],
    }


@cache
def type_hash(ros_type: str) -> str:
    """The REP-2016 type hash ``RIHS01_<sha256 hex>`` of ``ros_type`` (``pkg/msg/Type``)."""
    canonical = json.dumps(
        type_description(ros_type),
        ensure_ascii=True,
        allow_nan=False,
        indent=None,
        separators=(", ", ": "),
        sort_keys=False,
    )
    return RIHS01_PREFIX + hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def typehash_user_data(ros_type: str) -> bytes:
    """The USER_DATA QoS value a ROS 2 endpoint of ``ros_type`` carries:
    ``b"typehash=RIHS01_...;"`` (``rmw_dds_common::encode_type_hash_for_user_data_qos``)."""
    return f"typehash={type_hash(ros_type)};".encode("ascii")
