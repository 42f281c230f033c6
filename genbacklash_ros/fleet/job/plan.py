"""A bag planned before it is analysed (:func:`inspect_bag`, a :class:`BagPlan`: its content
hash, drivetrain and time), and the archive checked first (:func:`check_archive`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from genbacklash_core import (
    GenBacklashError,
)
from genbacklash_ros.bags.bagio import (
    COMMAND_MSGTYPES,
    ENCODER_MSGTYPES,
    BagError,
    BagReader,
)
from genbacklash_ros.fleet.archive import (
    ArchiveBag,
    bag_start_ns,
    content_hash,
    metadata_identity,
)
from genbacklash_ros.node.messages import JointState

from .settings import FleetSettings


@dataclass(frozen=True)
class BagPlan:
    """A bag, planned (:func:`inspect_bag`).

    Attributes
    ----------
    bag : ArchiveBag
    bag_hash : str
        :func:`~genbacklash_ros.fleet.archive.content_hash` (``""`` when the bag cannot be
        read at all; ``reason`` says why).
    robot : str
    joints : tuple of (str, int)
        Each joint's name (resolved: never ``""`` when the encoder could be read) and command
        element.
    recorded_ns : int or None
        The bag's time (ns since the epoch, UTC); None when neither path nor bag gives one.
    time_source : str or None
        ``"name"``, ``"directory"`` (the path) or ``"metadata"`` (the bag's first message).
    reason : str
        Why the bag could not be inspected ("" when it could).
    """

    bag: ArchiveBag
    bag_hash: str
    robot: str
    joints: tuple[tuple[str, int], ...]
    recorded_ns: int | None
    time_source: str | None
    reason: str = ""


def _first_joint(path: Path, topic: str) -> str:
    """The first joint name of the encoder's first JointState (the topic's name for a
    ``std_msgs/Float64`` encoder); ``""`` when it cannot be read."""
    try:
        with BagReader(path) as reader:
            for item in reader.messages([topic]):
                message = item.message
                if isinstance(message, JointState):
                    return message.name[0] if message.name else ""
                return topic
    except GenBacklashError:
        return ""
    return ""


def _what_is_there(root: Path, limit: int = 5) -> str:
    """A few of the entries under ``root`` (what an archive without bags holds)."""
    found: list[str] = []
    total = 0
    try:
        for path in sorted(root.rglob("*")):
            if path.is_file() and not any(part.startswith(".") for part in path.parts):
                total += 1
                if len(found) < limit:
                    found.append(path.relative_to(root).as_posix())
    except OSError:
        pass
    if not total:
        return "it holds no files"
    more = f" and {total - limit} more" if total > limit else ""
    return f"it holds {total} file{'' if total == 1 else 's'}: {', '.join(found)}{more}"


def check_archive(archive: str | Path, bags: list[ArchiveBag], settings: FleetSettings) -> None:
    """Stop before any work when the archive holds no bag, or no bag with both topics.

    The bags are opened in order until one holds ``settings.command_topic`` and
    ``settings.encoder_topic`` with supported types (the check of
    :meth:`~genbacklash_ros.bags.bagio.BagReader.topic`; usually the first bag). When none
    does, :class:`~genbacklash_core.GenBacklashError` names the topics (and types) the bags
    hold, or why none could be read. A bag that lacks them among others that have them is
    the row ``unreadable``, as before.
    """
    root = Path(archive)
    if not bags:
        raise GenBacklashError(
            f"{archive} holds no bags (rosbag2 directories with metadata.yaml, or .mcap "
            f"files); {_what_is_there(root)}"
        )
    held: dict[tuple[str, str], int] = {}
    first_error = ""
    readable = 0
    for bag in bags:
        try:
            with BagReader(bag.path) as reader:
                readable += 1
                for info in reader.topics.values():
                    held[info.name, info.msgtype] = held.get((info.name, info.msgtype), 0) + 1
                reader.topic(settings.command_topic, COMMAND_MSGTYPES)
                reader.topic(settings.encoder_topic, ENCODER_MSGTYPES)
                return
        except BagError as err:
            first_error = first_error or str(err)
    n = len(bags)
    if not readable:
        raise GenBacklashError(
            f"none of the {n} bag{'' if n == 1 else 's'} of {archive} can be read "
            f"(first: {first_error})"
        )
    topics = ", ".join(
        f"{name} ({msgtype}, in {count} bag{'' if count == 1 else 's'})"
        for (name, msgtype), count in sorted(held.items())
    )
    raise GenBacklashError(
        f"no bag of {archive} holds both --command {settings.command_topic} and --encoder "
        f"{settings.encoder_topic} of a supported type; the {readable} readable "
        f"{'bag holds' if readable == 1 else 'bags hold'}: {topics or 'no topics'}"
    )


def inspect_bag(bag: ArchiveBag, settings: FleetSettings) -> BagPlan:
    """The hash, drivetrain and time of ``bag`` (see :mod:`genbacklash_ros.fleet.archive`)."""
    try:
        digest = content_hash(bag.path)
    except OSError as err:
        return BagPlan(
            bag, "", bag.identity.robot, (), bag.identity.time_ns, bag.identity.time_source,
            f"cannot read {bag.relpath}: {err.strerror or err}",
        )  # fmt: skip
    try:
        with BagReader(bag.path) as reader:
            custom = reader.custom_data
    except GenBacklashError:
        custom = None
    robot, joint = metadata_identity(custom)
    robot = robot or bag.identity.robot
    joint = joint or bag.identity.joint
    time_ns, source = bag.identity.time_ns, bag.identity.time_source
    if time_ns is None:
        time_ns = bag_start_ns(bag.path)
        source = "metadata" if time_ns is not None else None
    joints = []
    for request in settings.requests(joint):
        name = request.name or _first_joint(bag.path, settings.encoder_topic)
        joints.append((name, settings.command_index(request)))
    return BagPlan(bag, digest, robot, tuple(joints), time_ns, source)
