"""The DDS types serialise to the same CDR bytes as ROS 2 (rosbags' serializer)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

dds = pytest.importorskip(
    "genbacklash_ros.transports.dds_types", reason="cyclonedds is not installed"
)
rosbags_typesys = pytest.importorskip("rosbags.typesys", reason="rosbags is not installed")

STORE = rosbags_typesys.get_typestore(rosbags_typesys.Stores.ROS2_JAZZY)
T = STORE.types


def _time(sec: int, nanosec: int) -> tuple[Any, Any]:
    return dds.Time_(sec, nanosec), T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header(sec: int, nanosec: int, frame: str) -> tuple[Any, Any]:
    ours, theirs = _time(sec, nanosec)
    return dds.Header_(ours, frame), T["std_msgs/msg/Header"](stamp=theirs, frame_id=frame)


def _cases() -> list[tuple[str, Any, Any]]:
    h_ours, h_theirs = _header(1_700_000_000, 123_456_789, "base_link")
    dim = dds.MultiArrayDimension_("m_left_1,c_left", 2, 2)
    t_dim = T["std_msgs/msg/MultiArrayDimension"](label="m_left_1,c_left", size=2, stride=2)
    kv = [dds.KeyValue_("state", "converged"), dds.KeyValue_("c_left", "0.7")]
    t_kv = [T["diagnostic_msgs/msg/KeyValue"](key=k.key, value=k.value) for k in kv]
    status = dds.DiagnosticStatus_(1, "backlash_identifier", "warming up", "joint1", kv)
    t_status = T["diagnostic_msgs/msg/DiagnosticStatus"](
        level=1, name="backlash_identifier", message="warming up", hardware_id="joint1", values=t_kv
    )
    f64 = np.array([0.5, -1.25e-7, 3.0])
    return [
        ("std_msgs/msg/Float64", dds.Float64_(-0.125), T["std_msgs/msg/Float64"](data=-0.125)),
        (
            "std_msgs/msg/Float64MultiArray",
            dds.Float64MultiArray_(dds.MultiArrayLayout_([dim], 0), list(f64)),
            T["std_msgs/msg/Float64MultiArray"](
                layout=T["std_msgs/msg/MultiArrayLayout"](dim=[t_dim], data_offset=0), data=f64
            ),
        ),
        (
            "sensor_msgs/msg/JointState",
            dds.JointState_(h_ours, ["joint1", "joint2"], [0.5, 1.5], [0.1], []),
            T["sensor_msgs/msg/JointState"](
                header=h_theirs,
                name=["joint1", "joint2"],
                position=np.array([0.5, 1.5]),
                velocity=np.array([0.1]),
                effort=np.array([], dtype=np.float64),
            ),
        ),
        (
            "diagnostic_msgs/msg/DiagnosticArray",
            dds.DiagnosticArray_(h_ours, [status]),
            T["diagnostic_msgs/msg/DiagnosticArray"](header=h_theirs, status=[t_status]),
        ),
    ]


@pytest.mark.parametrize(("typename", "ours", "theirs"), _cases(), ids=lambda c: str(c)[:40])
def test_cdr_bytes_equal_ros2(typename: str, ours: Any, theirs: Any) -> None:
    ours_bytes = ours.serialize()
    theirs_bytes = bytes(STORE.serialize_cdr(theirs, typename))
    assert ours_bytes == theirs_bytes
    assert type(ours).deserialize(theirs_bytes) == ours


def test_type_names_follow_the_ros2_mapping() -> None:
    assert dds.JointState_.__idl_typename__ == "sensor_msgs::msg::dds_::JointState_"
    assert dds.dds_topic("/diagnostics") == "rt/diagnostics"


def test_participant_entities_info_bytes_equal_ros2_jazzy() -> None:
    """``ros_discovery_info``'s message with Jazzy's 16-byte gids, byte for byte."""
    gids = [bytes(range(k, k + dds.GID_SIZE)) for k in (0, 16, 32)]
    ours = dds.ParticipantEntitiesInfo_(
        dds.Gid_(list(gids[0])),
        [
            dds.NodeEntitiesInfo_(
                "/arm",
                "backlash_identifier",
                [dds.Gid_(list(gids[1]))],
                [dds.Gid_(list(gids[2])), dds.Gid_(list(gids[0]))],
            )
        ],
    )
    gid = T["rmw_dds_common/msg/Gid"]
    theirs = T["rmw_dds_common/msg/ParticipantEntitiesInfo"](
        gid=gid(data=np.frombuffer(gids[0], np.uint8)),
        node_entities_info_seq=[
            T["rmw_dds_common/msg/NodeEntitiesInfo"](
                node_namespace="/arm",
                node_name="backlash_identifier",
                reader_gid_seq=[gid(data=np.frombuffer(gids[1], np.uint8))],
                writer_gid_seq=[
                    gid(data=np.frombuffer(gids[2], np.uint8)),
                    gid(data=np.frombuffer(gids[0], np.uint8)),
                ],
            )
        ],
    )
    theirs_bytes = bytes(STORE.serialize_cdr(theirs, "rmw_dds_common/msg/ParticipantEntitiesInfo"))
    assert ours.serialize() == theirs_bytes
    back = dds.ParticipantEntitiesInfo_.deserialize(theirs_bytes)
    assert bytes(back.node_entities_info_seq[0].writer_gid_seq[0].data) == gids[2]
