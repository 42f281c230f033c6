"""ROS 2 message types for plain DDS (cyclonedds), wire-compatible with ROS 2 (GUIDE §5).

ROS 2 maps a message ``pkg/msg/Type`` to the DDS type ``pkg::msg::dds_::Type_`` and a topic
``/name`` to ``rt/name``. Declared as plain (final) ``IdlStruct`` dataclasses these serialise
to the same CDR bytes as ROS 2 and as rosbags' serializer (tested byte for byte); they must not
be marked appendable, which would switch to XCDR2.

This module imports cyclonedds; import it only where the DDS transport is used.

Examples
--------
>>> msg = Float64_(data=1.5)
>>> Float64_.deserialize(msg.serialize()).data
1.5
"""

# No ``from __future__ import annotations``: cyclonedds reads the field types at class creation.

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, bounded_str, float64, int32, sequence, uint8, uint32

__all__ = [
    "GID_SIZE",
    "DiagnosticArray_",
    "DiagnosticStatus_",
    "Float64MultiArray_",
    "Float64_",
    "Gid_",
    "Header_",
    "JointState_",
    "KeyValue_",
    "MultiArrayDimension_",
    "MultiArrayLayout_",
    "NodeEntitiesInfo_",
    "ParticipantEntitiesInfo_",
    "Time_",
    "dds_topic",
]


def dds_topic(ros_topic: str) -> str:
    """The DDS topic name of a ROS 2 topic: ``/a/b`` -> ``rt/a/b``.

    >>> dds_topic("/backlash_identifier/estimate"), dds_topic("command")
    ('rt/backlash_identifier/estimate', 'rt/command')
    """
    return "rt/" + ros_topic.lstrip("/")


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_ = field(default_factory=Time_)
    frame_id: str = ""


@dataclass
class Float64_(IdlStruct, typename="std_msgs::msg::dds_::Float64_"):
    data: float64 = 0.0


@dataclass
class MultiArrayDimension_(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    label: str = ""
    size: uint32 = 0
    stride: uint32 = 0


@dataclass
class MultiArrayLayout_(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    dim: sequence[MultiArrayDimension_] = field(default_factory=list)
    data_offset: uint32 = 0


@dataclass
class Float64MultiArray_(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    layout: MultiArrayLayout_ = field(default_factory=MultiArrayLayout_)
    data: sequence[float64] = field(default_factory=list)


@dataclass
class JointState_(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header_ = field(default_factory=Header_)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class KeyValue_(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus_(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8 = 0  # ROS 2 declares `byte level`; OK=0 WARN=1 ERROR=2 STALE=3
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue_] = field(default_factory=list)


@dataclass
class DiagnosticArray_(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header_ = field(default_factory=Header_)
    status: sequence[DiagnosticStatus_] = field(default_factory=list)


# ---- the ROS 2 graph (rmw_dds_common/msg, Jazzy): what rmw publishes on ``ros_discovery_info``

GID_SIZE = 16
"""Bytes of a Jazzy ``rmw_gid_t`` (``RMW_GID_STORAGE_SIZE``; Humble had 24): a DDS GUID."""


def _zero_gid() -> list[int]:
    return [0] * GID_SIZE


@dataclass
class Gid_(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, GID_SIZE] = field(default_factory=_zero_gid)  # `char[16] data`


@dataclass
class NodeEntitiesInfo_(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: bounded_str[256] = "/"
    node_name: bounded_str[256] = ""
    reader_gid_seq: sequence[Gid_] = field(default_factory=list)
    writer_gid_seq: sequence[Gid_] = field(default_factory=list)


@dataclass
class ParticipantEntitiesInfo_(
    IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
):
    gid: Gid_ = field(default_factory=Gid_)
    node_entities_info_seq: sequence[NodeEntitiesInfo_] = field(default_factory=list)
