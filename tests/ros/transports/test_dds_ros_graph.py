"""The DDS node as a ROS 2 graph citizen, seen from plain DDS (no ROS needed).

What rmw_cyclonedds_cpp peers read: the node's ``ros_discovery_info`` announcement (its gids are
the DDS GUIDs of the endpoints discovery reports), each endpoint's USER_DATA type hash, the
participant's enclave; and the node's own check of the publishers on its subscribed topics.
The same against the real rclpy and ``ros2`` CLI: ``test_dds_interop.py``.
"""

from __future__ import annotations

import logging
import os
import random
import threading
import time
import uuid
from typing import Any

import pytest

pytest.importorskip("cyclonedds", reason="cyclonedds is not installed (pip install .[dds])")

from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.messages import (
    DiagnosticArray,
    DiagnosticStatus,
    Header,
    KeyValue,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.transports.dds_node import DEFAULT_QOS, DdsNode, with_wiring
from genbacklash_ros.transports.dds_types import Float64_, ParticipantEntitiesInfo_
from genbacklash_ros.transports.ros_graph import (
    DISCOVERY_QOS,
    DISCOVERY_TOPIC,
    WiringMismatch,
    gid_bytes,
    node_namespace,
    participant_entities_info,
    ros_type_name,
)
from genbacklash_ros.transports.type_hash import typehash_user_data

from ._dds import Subscriber, diagnostic_values
from ._player import wait_for

DOMAIN = 1 + (os.getpid() * 7919 + random.randrange(1000)) % 200
MISMATCH = WiringMismatch(
    "/command",
    "std_msgs/msg/Float64",
    "std_msgs/msg/Float64MultiArray",
    "command_type",
    (("float64", "std_msgs/msg/Float64"), ("joint_state", "sensor_msgs/msg/JointState")),
)


def _userdata(qos: Any) -> bytes | None:
    for policy in qos:
        if isinstance(policy, Policy.Userdata):
            return bytes(policy.data)
    return None


# --------------------------------------------------------------------------- pure parts


def test_wiring_text_names_the_seen_type_and_the_parameter() -> None:
    text = MISMATCH.text()
    assert "/command" in text and "std_msgs/msg/Float64 " in text
    assert "std_msgs/msg/Float64MultiArray" in text
    assert "set parameter command_type to float64" in text
    assert "\n" not in text


def test_wiring_text_lists_the_choices_for_an_unsupported_type() -> None:
    text = WiringMismatch(
        "/encoder", "geometry_msgs/msg/Twist", "sensor_msgs/msg/JointState", "encoder_type"
    ).text()
    assert "geometry_msgs/msg/Twist" in text and "encoder_type" in text
    assert "reads sensor_msgs/msg/JointState or std_msgs/msg/Float64" in text


def test_with_wiring_raises_the_level_and_adds_the_key() -> None:
    status = DiagnosticStatus(DiagnosticStatus.OK, "backlash_identifier", "converged", "j", ())
    diag = DiagnosticArray(Header(), (status,))
    out = with_wiring(diag, (MISMATCH,))
    assert out.status[0].level == DiagnosticStatus.WARN
    assert out.status[0].message.startswith("converged; a publisher of std_msgs/msg/Float64 on")
    assert out.status[0].values[-1] == KeyValue("wiring", MISMATCH.text())
    stale = DiagnosticArray(Header(), (status.__class__(DiagnosticStatus.STALE, "n", "no data"),))
    assert with_wiring(stale, (MISMATCH,)).status[0].level == DiagnosticStatus.STALE
    assert with_wiring(diag, ()) is diag


def test_gids_are_the_16_byte_guids() -> None:
    guid = uuid.uuid4()
    info = participant_entities_info(guid, "backlash_identifier", "arm", [guid], [])
    assert bytes(info.gid.data) == guid.bytes
    node = info.node_entities_info_seq[0]
    assert (node.node_namespace, node.node_name) == ("/arm", "backlash_identifier")
    assert [bytes(g.data) for g in node.reader_gid_seq] == [guid.bytes]
    assert participant_entities_info(guid, "", "", [], []).node_entities_info_seq == []
    assert node_namespace("") == "/"
    with pytest.raises(GenBacklashError, match="a gid has 16 bytes"):
        gid_bytes(bytes(24))  # Humble's size


def test_ros_type_name_of_dds_names() -> None:
    assert ros_type_name("rmw_dds_common::msg::dds_::Gid_") == "rmw_dds_common/msg/Gid"


# --------------------------------------------------------------------------- on the wire


def _take_all(reader: Any, seconds: float, enough: Any) -> list[Any]:
    got: list[Any] = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        got.extend(s for s in reader.take(100) if s.sample_info.valid_data)
        if enough(got):
            break
        time.sleep(0.05)
    return got


def test_node_announces_its_endpoints_with_type_hashes() -> None:
    node = DdsNode(NodeParameters(joint="j"), domain_id=DOMAIN, namespace="arm")
    dp = DomainParticipant(DOMAIN)
    info_reader = DataReader(
        dp, Topic(dp, DISCOVERY_TOPIC, ParticipantEntitiesInfo_), qos=DISCOVERY_QOS
    )
    pubs = BuiltinDataReader(dp, BuiltinTopicDcpsPublication)
    subs = BuiltinDataReader(dp, BuiltinTopicDcpsSubscription)
    parts = BuiltinDataReader(dp, BuiltinTopicDcpsParticipant)

    infos = _take_all(info_reader, 10, lambda got: any(m.node_entities_info_seq for m in got))
    announced = [m for m in infos if m.node_entities_info_seq][-1]
    participant = uuid.UUID(bytes=bytes(announced.gid.data))
    entry = announced.node_entities_info_seq[0]
    assert (entry.node_namespace, entry.node_name) == ("/arm", "backlash_identifier")
    readers = {uuid.UUID(bytes=bytes(g.data)) for g in entry.reader_gid_seq}
    writers = {uuid.UUID(bytes=bytes(g.data)) for g in entry.writer_gid_seq}

    def mine(samples: list[Any]) -> dict[uuid.UUID, Any]:
        return {s.key: s for s in samples if s.participant_key == participant}

    seen_pubs = mine(_take_all(pubs, 10, lambda got: len(mine(got)) >= 4))
    seen_subs = mine(_take_all(subs, 10, lambda got: len(mine(got)) >= 2))
    ros_pubs = {k: s for k, s in seen_pubs.items() if s.topic_name.startswith("rt/")}
    ros_subs = {k: s for k, s in seen_subs.items() if s.topic_name.startswith("rt/")}
    # the gids are the GUIDs that discovery reports for the node's endpoints
    assert set(ros_pubs) == writers
    assert set(ros_subs) == readers
    assert {s.topic_name for s in ros_pubs.values()} == {
        "rt/arm/compensated_command",
        "rt/arm/backlash_identifier/estimate",
        "rt/diagnostics",
    }
    assert {s.topic_name for s in ros_subs.values()} == {"rt/arm/command", "rt/arm/encoder"}
    # every endpoint carries its type hash, the discovery writer too (the builtin-topic reader
    # of the wiring check is not a ROS endpoint: rmw ignores DCPS* topics)
    for sample in [*seen_pubs.values(), *ros_subs.values()]:
        wanted = typehash_user_data(ros_type_name(sample.type_name))
        assert _userdata(sample.qos) == wanted, sample.topic_name
    (discovery,) = [s for s in seen_pubs.values() if s.topic_name == DISCOVERY_TOPIC]
    assert Policy.Durability.TransientLocal in discovery.qos
    assert Policy.History.KeepLast(1) in discovery.qos
    participants = _take_all(parts, 5, lambda got: any(p.key == participant for p in got))
    (me,) = [p for p in participants if p.key == participant]
    assert _userdata(me.qos) == b"enclave=/;"
    del node


def test_a_publisher_of_another_type_is_named_in_the_diagnostics(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A std_msgs/Float64 publisher on /command while the node expects Float64MultiArray:
    DDS never matches them, so no command arrives; the diagnostics say why."""
    node = DdsNode(NodeParameters(joint="j"), domain_id=DOMAIN)
    sub = Subscriber(DOMAIN)
    wrong_dp = DomainParticipant(DOMAIN)
    wrong = DataWriter(wrong_dp, Topic(wrong_dp, "rt/command", Float64_), qos=DEFAULT_QOS)
    thread = threading.Thread(target=node.spin, args=(20.0,), daemon=True)
    with caplog.at_level(logging.WARNING, logger="genbacklash.node"):
        thread.start()
        try:
            wrong.write(Float64_(1.0))

            def wired() -> bool:
                return any("wiring" in diagnostic_values(d) for _, d in sub.got.diagnostics)

            assert wait_for(wired, 10), [diagnostic_values(d) for _, d in sub.got.diagnostics]
        finally:
            node.stop()
            thread.join(10)
            sub.close()
    diag = next(d for _, d in sub.got.diagnostics if "wiring" in diagnostic_values(d))
    text = diagnostic_values(diag)["wiring"]
    assert "std_msgs/msg/Float64 on" in text and "command_type to float64" in text
    assert text in diag.status[0].message
    assert node.stats.received["command"] == 0
    logged = [r.getMessage() for r in caplog.records if "a publisher of" in r.getMessage()]
    assert logged == [text], "the mismatch is logged once"
    # the wrong publisher goes: so does the complaint
    del wrong
    del wrong_dp
    assert wait_for(lambda: node.check_wiring() == (), 10), node.wiring_mismatches


def test_discovery_waits_for_the_writers_of_a_participant_whose_readers_are_known() -> None:
    """Fast DDS announces its writers and its readers separately, and a new cyclonedds
    participant can learn the readers a second before the writers (seen: 247 commands lost by
    readers created in between). A participant whose readers alone are known holds
    ``await_discovery`` until its first writer is announced (here 0.4 s after its reader), not
    only until ``min_s``."""
    from genbacklash_ros.transports.ros_graph import await_discovery

    other = DomainParticipant(DOMAIN)
    _reader = DataReader(other, Topic(other, "rt/graph_test_in", Float64_))
    writers: list[Any] = []

    def announce_a_writer() -> None:
        time.sleep(0.4)
        writers.append(DataWriter(other, Topic(other, "rt/graph_test_out", Float64_)))

    late = threading.Thread(target=announce_a_writer)
    late.start()
    try:
        seen = await_discovery(DomainParticipant(DOMAIN), min_s=0.05, max_s=5.0)
    finally:
        late.join()
    assert seen.incomplete == 0 and seen.participants >= 1
    assert 0.4 <= seen.waited_s < 5.0, seen


def test_discovery_gives_up_on_a_participant_that_never_announces_a_writer() -> None:
    """A participant with readers only holds the wait to ``max_s`` and is counted incomplete."""
    from genbacklash_ros.transports.ros_graph import await_discovery

    other = DomainParticipant(DOMAIN)
    _reader = DataReader(other, Topic(other, "rt/graph_test_only_in", Float64_))
    seen = await_discovery(DomainParticipant(DOMAIN), min_s=0.05, max_s=0.6)
    assert seen.incomplete >= 1 and seen.waited_s >= 0.6, seen
