"""The DDS node as a ROS 2 graph citizen: type hashes, ``ros_discovery_info``, wiring checks.

What an ``rmw_cyclonedds_cpp`` peer (rclpy, ``ros2`` CLI) needs to see a plain-DDS process as a
ROS 2 node, as rmw_cyclonedds_cpp / rmw_dds_common (Jazzy) do it:

* every endpoint's USER_DATA QoS is ``typehash=RIHS01_<sha256>;``
  (:func:`~genbacklash_ros.transports.type_hash.typehash_user_data`); without it each peer logs
  ``Failed to parse type hash ... from USER_DATA '(null)'`` per topic;
* the participant's USER_DATA is ``enclave=/;`` (rmw adds a participant to its graph with the
  enclave it announces);
* the participant publishes ``rmw_dds_common/msg/ParticipantEntitiesInfo`` on the DDS topic
  ``ros_discovery_info`` (no ``rt/`` prefix; RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 1): its gid and,
  per node, the namespace, the name and the gids of the node's readers and writers. A Jazzy gid
  is the entity's 16-byte DDS GUID (``convert_guid_to_gid``: ``memcpy`` of ``dds_guid_t``), so
  peers match these gids against the endpoints they discover. ``ros2 node list`` and the node
  names in ``ros2 topic info -v`` come from this message.

Before the node creates its readers it lets discovery settle (:func:`await_discovery`): a
newly started cyclonedds participant learns the endpoints of a Fast DDS participant that was
already running up to a second after that participant has matched the new readers, and drops
what it is sent meanwhile (see the function).

And the reverse check for the node's own subscriptions: :class:`PublicationWatch` reads the
``DCPSPublication`` builtin topic and reports publishers of another type on a subscribed topic
(:class:`WiringMismatch`, worded by :mod:`genbacklash_ros.node.wiring`), which DDS would
otherwise never match and nobody would notice.

This module imports cyclonedds; import it only where the DDS transport is used.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import InstanceState
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.topic import Topic

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.wiring import type_mismatch
from genbacklash_ros.transports import dds_types
from genbacklash_ros.transports.type_hash import typehash_user_data

__all__ = [
    "DISCOVERY_MAX_S",
    "DISCOVERY_MIN_S",
    "DISCOVERY_QOS",
    "DISCOVERY_TOPIC",
    "PARTICIPANT_USER_DATA",
    "Discovered",
    "GraphAnnouncer",
    "PublicationWatch",
    "Subscribed",
    "WiringMismatch",
    "await_discovery",
    "endpoint_qos",
    "gid_bytes",
    "node_namespace",
    "participant_entities_info",
    "ros_topic_name",
    "ros_type_name",
]

DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_ROS_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
PARTICIPANT_USER_DATA = b"enclave=/;"
"""The participant's USER_DATA: the default enclave, as ``rmw_create_node`` announces it."""

DISCOVERY_QOS = Qos(
    Policy.Reliability.Reliable(0),
    Policy.Durability.TransientLocal,
    Policy.History.KeepLast(1),
    Policy.Userdata(typehash_user_data(DISCOVERY_ROS_TYPE)),
)
"""rmw's QoS for ``ros_discovery_info``: RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 1 (late joiners
get the last message), with its type hash."""

DISCOVERY_MIN_S = 1.0
"""Shortest wait of :func:`await_discovery`: the participants already running answer a new
participant's announcement within milliseconds on an idle machine; on one at load 13 a Fast DDS
player answered after 0.64 s, past the 0.5 s this was, and the readers created before its
answer lost 29 commands. A participant not heard of by then is taken as not running."""

DISCOVERY_MAX_S = 3.0
"""Longest wait of :func:`await_discovery` (a participant that never announces both a writer
and a reader holds it this long). Fast DDS resends its endpoints at its discovery heartbeat,
once a second."""

_DISCOVERY_POLL_S = 0.01

_T: Any = dds_types  # the IDL classes are runtime descriptors mypy cannot read


def endpoint_qos(qos: Qos, ros_type: str) -> Qos:
    """``qos`` with the USER_DATA a ROS 2 endpoint of ``ros_type`` carries (its type hash)."""
    return Qos(*(p for p in qos if not isinstance(p, Policy.Userdata))) + Qos(
        Policy.Userdata(typehash_user_data(ros_type))
    )


def node_namespace(namespace: str) -> str:
    """The namespace as rcl hands it to rmw: absolute, ``/`` for the root.

    >>> node_namespace(""), node_namespace("arm"), node_namespace("/robot/arm/")
    ('/', '/arm', '/robot/arm')
    """
    inner = namespace.strip().strip("/")
    return "/" + inner


def gid_bytes(guid: uuid.UUID | bytes) -> list[int]:
    """A Jazzy ``rmw_gid_t`` payload (16 bytes) from a DDS GUID (cyclonedds' ``entity.guid``)."""
    data = guid.bytes if isinstance(guid, uuid.UUID) else bytes(guid)
    if len(data) != dds_types.GID_SIZE:
        raise GenBacklashError(
            f"a gid has {dds_types.GID_SIZE} bytes (a DDS GUID), got {len(data)} bytes"
        )
    return list(data)


def participant_entities_info(
    participant: uuid.UUID,
    node_name: str,
    namespace: str,
    readers: Iterable[uuid.UUID],
    writers: Iterable[uuid.UUID],
) -> Any:
    """The ``ParticipantEntitiesInfo`` wire object announcing one node (empty ``node_name``:
    none, as rmw publishes when its last node goes)."""
    nodes = []
    if node_name:
        nodes.append(
            _T.NodeEntitiesInfo_(
                node_namespace(namespace),
                node_name,
                [_T.Gid_(gid_bytes(g)) for g in readers],
                [_T.Gid_(gid_bytes(g)) for g in writers],
            )
        )
    return _T.ParticipantEntitiesInfo_(_T.Gid_(gid_bytes(participant)), nodes)


class GraphAnnouncer:
    """Publishes a node's entities on ``ros_discovery_info`` for one participant.

    Parameters
    ----------
    participant : DomainParticipant
        Created with USER_DATA :data:`PARTICIPANT_USER_DATA`.
    node_name, namespace : str
        The node as ``ros2 node list`` should show it.
    """

    def __init__(self, participant: DomainParticipant, node_name: str, namespace: str) -> None:
        self._participant = participant
        self.node_name = node_name
        self.namespace = node_namespace(namespace)
        topic = Topic(participant, DISCOVERY_TOPIC, _T.ParticipantEntitiesInfo_)
        self._writer: DataWriter[Any] = DataWriter(participant, topic, qos=DISCOVERY_QOS)
        self.published = 0

    def announce(self, readers: Iterable[Any], writers: Iterable[Any]) -> None:
        """Publish the node with these DataReaders and DataWriters."""
        message = participant_entities_info(
            self._participant.guid,
            self.node_name,
            self.namespace,
            (r.guid for r in readers),
            (w.guid for w in writers),
        )
        self._writer.write(message)
        self.published += 1

    def withdraw(self) -> None:
        """Publish the participant without nodes (the node is going away)."""
        self._writer.write(participant_entities_info(self._participant.guid, "", "", (), ()))
        self.published += 1


def ros_type_name(dds_type: str) -> str:
    """``pkg::msg::dds_::Type_`` -> ``pkg/msg/Type``; other names unchanged.

    >>> ros_type_name("std_msgs::msg::dds_::Float64_"), ros_type_name("MyType")
    ('std_msgs/msg/Float64', 'MyType')
    """
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_type


def ros_topic_name(dds_topic: str) -> str:
    """``rt/a/b`` -> ``/a/b``; other names unchanged.

    >>> ros_topic_name("rt/command"), ros_topic_name("ros_discovery_info")
    ('/command', 'ros_discovery_info')
    """
    return "/" + dds_topic[3:] if dds_topic.startswith("rt/") else dds_topic


@dataclass(frozen=True)
class WiringMismatch:
    """A discovered publisher whose type differs from the node's subscription on its topic."""

    topic: str
    seen_type: str
    expected_type: str
    parameter: str
    choices: tuple[tuple[str, str], ...] = ()

    def text(self) -> str:
        """The line the rclpy node writes too.

        See :func:`~genbacklash_ros.node.wiring.type_mismatch`.
        """
        return type_mismatch(self.topic, self.seen_type, self.expected_type, self.parameter)


@dataclass(frozen=True)
class Subscribed:
    """What the node subscribes on one DDS topic, and the parameter that selects its type."""

    dds_type: str
    parameter: str
    choices: tuple[tuple[str, str], ...] = ()


class PublicationWatch:
    """Watches discovered publications (``DCPSPublication``) on the node's subscribed topics.

    Parameters
    ----------
    participant : DomainParticipant
    subscribed : mapping
        DDS topic name (``rt/command``) -> :class:`Subscribed`.
    """

    def __init__(self, participant: DomainParticipant, subscribed: Mapping[str, Subscribed]):
        self._subscribed = dict(subscribed)
        self._reader = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
        self._mismatches: dict[uuid.UUID, WiringMismatch] = {}

    @property
    def mismatches(self) -> tuple[WiringMismatch, ...]:
        """The distinct mismatches of the publications alive now."""
        return tuple(dict.fromkeys(self._mismatches.values()))

    def poll(self) -> list[WiringMismatch]:
        """Take what discovery reported since the last call; the mismatches that are new."""
        before = set(self._mismatches.values())
        while True:
            samples = self._reader.take(64)
            for sample in samples:
                self._note(sample)
            if len(samples) < 64:
                break
        return [m for m in self.mismatches if m not in before]

    def _note(self, sample: Any) -> None:
        info = sample.sample_info
        key = getattr(sample, "key", None)
        if key is None:
            return
        if info.instance_state != InstanceState.Alive or not info.valid_data:
            self._mismatches.pop(key, None)
            return
        wanted = self._subscribed.get(sample.topic_name)
        if wanted is None or sample.type_name == wanted.dds_type:
            return
        self._mismatches[key] = WiringMismatch(
            ros_topic_name(sample.topic_name),
            ros_type_name(sample.type_name),
            ros_type_name(wanted.dds_type),
            wanted.parameter,
            wanted.choices,
        )


@dataclass(frozen=True)
class Discovered:
    """What :func:`await_discovery` saw: the other participants, how many of them had not
    announced both a writer and a reader when it returned (0 unless it timed out), and how long
    it waited."""

    participants: int
    incomplete: int
    waited_s: float


def await_discovery(
    participant: DomainParticipant,
    *,
    min_s: float = DISCOVERY_MIN_S,
    max_s: float = DISCOVERY_MAX_S,
    stop: Callable[[], bool] = lambda: False,
) -> Discovered:
    """Wait until this new participant knows the writers and readers of every participant it
    discovered.

    Call it before creating the readers. A Fast DDS participant (rclpy from the ROS 2 wheels)
    that is already running hears the new participant's announcement, sends its own and, at
    once, a heartbeat for its endpoint announcements. cyclonedds often takes that heartbeat
    before it has taken the announcement, drops it, and its first acknowledgement does not
    make Fast DDS resend; so it learns Fast DDS's writers only at Fast DDS's next discovery
    heartbeat, a second later. Fast DDS meanwhile has learnt the new readers, counts them as
    matched and sends them its samples, which cyclonedds drops (their writer is unknown to it):
    a publisher that starts writing when its subscription count rises lost its first 0.02-1 s
    of messages. Readers created once the writers are known are matched from both sides at once.

    Fast DDS announces its writers and its readers on two separate discovery writers, each with
    its own heartbeat, so the race above can lose either announcement alone: a participant
    whose readers are known is not yet one whose writers are (seen: the readers of a running
    rclpy publisher known 0.1 s after the start, its writers 1.1 s after, and 247 commands lost
    by readers created at 0.6 s). Every ROS 2 participant has both (rmw's
    ``ros_discovery_info`` writer and reader, besides its nodes' endpoints), so both are
    awaited.

    Returns after at least ``min_s`` seconds, once every other participant discovered has
    announced at least one writer and one reader, or after ``max_s``, or when ``stop()`` is
    true.
    """
    start = time.monotonic()
    own = participant.guid
    readers = {
        "participants": BuiltinDataReader(participant, BuiltinTopicDcpsParticipant),
        "publications": BuiltinDataReader(participant, BuiltinTopicDcpsPublication),
        "subscriptions": BuiltinDataReader(participant, BuiltinTopicDcpsSubscription),
    }
    participants: set[uuid.UUID] = set()
    announced: dict[str, set[uuid.UUID]] = {"publications": set(), "subscriptions": set()}
    try:
        while True:
            for kind, reader in readers.items():
                for sample in reader.take(256):
                    if not sample.sample_info.valid_data:
                        continue
                    if kind == "participants":
                        participants.add(sample.key)
                    else:
                        announced[kind].add(sample.participant_key)
            complete = announced["publications"] & announced["subscriptions"]
            waiting = participants - complete - {own}
            waited = time.monotonic() - start
            if (waited >= min_s and not waiting) or waited >= max_s or stop():
                return Discovered(len(participants - {own}), len(waiting), waited)
            time.sleep(_DISCOVERY_POLL_S)
    finally:
        readers.clear()  # cyclonedds deletes an entity with its last Python reference
