"""Archive discovery: which bags a fleet archive holds, whose drivetrain each is, and when.

A fleet archive is a directory tree of bags. :func:`discover` walks it and returns one
:class:`ArchiveBag` per bag, in path order:

* a **bag** is a directory holding ``metadata.yaml`` (a rosbag2 bag; not descended into), or
  a file whose name ends in ``.mcap`` outside such a directory (a bare MCAP file);
* anything else (other files, hidden entries whose name starts with ``.``) is ignored.

**The drivetrain and the time** (the documented rule). For a bag at
``ARCHIVE/c_1/.../c_k/NAME``:

1. *Time*: the first timestamp in ``NAME`` (its suffix stripped), else in the nearest of
   ``c_k ... c_1`` that holds one, else the bag's own start time (its first message, read from
   the bag's metadata by :func:`bag_start_ns`). A timestamp is ``YYYY-MM-DD``, ``YYYY_MM_DD``
   or ``YYYYMMDD``, optionally followed by ``T``, ``_``, ``-`` or a space and
   ``HH-MM-SS``, ``HH:MM:SS``, ``HH_MM_SS`` or ``HHMMSS`` (so ``ros2 bag record``'s default
   ``rosbag2_2024_03_05-08_30_15`` is one), and is read as UTC.
2. *Robot and joint*: the components ``c_1 ... c_k`` that are not a bare date (a component
   that is nothing but a timestamp) name the drivetrain: the first is the **robot**, the
   second, when there is one, the **joint** (the ``JointState`` joint name to analyse). With
   no such component the robot is ``ARCHIVE``'s own name.
3. The bag's metadata wins over the path where it says: ``custom_data`` keys
   :data:`ROBOT_KEY` and :data:`JOINT_KEY` (rosbag2 ``metadata.yaml`` or the MCAP file's
   embedded rosbag2 metadata) set the robot and the joint.
4. A bag whose path and metadata name no joint is analysed for the joints given on the
   command line (``--joint``), else for the node parameter ``joint`` (empty: the first joint
   of the encoder messages, recorded under its name).

Examples
--------
>>> parse_timestamp("2024-03-05T08-30-00")
1709627400000000000
>>> parse_timestamp("run_20240305_083000.mcap") == parse_timestamp("2024-03-05 08:30:00")
True
>>> parse_timestamp("robot-07") is None
True
>>> path_identity(("robot-07", "elbow", "2024-03-05"), "2024-03-05T08-30-00", "fleet")
PathIdentity(robot='robot-07', joint='elbow', time_ns=1709627400000000000, time_source='name')
>>> path_identity((), "run.mcap", "fleet")
PathIdentity(robot='fleet', joint=None, time_ns=None, time_source=None)
"""

from __future__ import annotations

import calendar
import hashlib
import os
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from genbacklash_core import GenBacklashError

__all__ = [
    "JOINT_KEY",
    "ROBOT_KEY",
    "ArchiveBag",
    "PathIdentity",
    "bag_start_ns",
    "content_hash",
    "discover",
    "parse_timestamp",
    "path_identity",
    "recorded_duration_ns",
]

ROBOT_KEY = "genbacklash.robot"
"""``custom_data`` key naming the robot a bag was recorded on (overrides the path)."""
JOINT_KEY = "genbacklash.joint"
"""``custom_data`` key naming the joint to analyse (overrides the path)."""

_TIMESTAMP = re.compile(
    r"(?<!\d)(?P<y>\d{4})(?P<sep>[-_]?)(?P<mo>\d{2})(?P=sep)(?P<d>\d{2})"
    r"(?:[T_\- ](?P<h>\d{2})([-:_]?)(?P<mi>\d{2})\6(?P<s>\d{2}))?(?!\d)"
)
_HASH_BLOCK = 1 << 20


def parse_timestamp(text: str) -> int | None:
    """The first timestamp in ``text`` as ns since the epoch (UTC), or None.

    ``YYYY-MM-DD`` / ``YYYY_MM_DD`` / ``YYYYMMDD``, optionally ``[T_- ]HH[-:_]MM[-:_]SS``
    (one separator throughout each part); impossible dates
    (month 13, day 32, hour 25) are not timestamps.
    """
    for match in _TIMESTAMP.finditer(text):
        year, month, day = int(match["y"]), int(match["mo"]), int(match["d"])
        hour = int(match["h"] or 0)
        minute = int(match["mi"] or 0)
        second = int(match["s"] or 0)
        if not (1 <= month <= 12 and 1 <= day <= 31 and hour < 24 and minute < 60 and second < 61):
            continue
        if day > calendar.monthrange(year, month)[1]:
            continue
        seconds = calendar.timegm((year, month, day, hour, minute, second, 0, 0, 0))
        return seconds * 1_000_000_000
    return None


def _is_timestamp_only(component: str) -> bool:
    """A directory component that is nothing but a timestamp (``2024-03-05``)."""
    match = _TIMESTAMP.fullmatch(component)
    return match is not None and parse_timestamp(component) is not None


class PathIdentity(NamedTuple):
    """What the path says: robot, joint (None: not said), time (None) and where it came from
    (``"name"``, ``"directory"``; None)."""

    robot: str
    joint: str | None
    time_ns: int | None
    time_source: str | None


def _stem(name: str) -> str:
    return name[: -len(".mcap")] if name.lower().endswith(".mcap") else name


def path_identity(parents: tuple[str, ...], name: str, archive_name: str) -> PathIdentity:
    """Rules 1 and 2 of the module notes for the bag ``name`` under the directories
    ``parents`` (relative to the archive, outermost first)."""
    time_ns = parse_timestamp(_stem(name))
    source: str | None = "name" if time_ns is not None else None
    if time_ns is None:
        for component in reversed(parents):
            time_ns = parse_timestamp(component)
            if time_ns is not None:
                source = "directory"
                break
    names = [c for c in parents if not _is_timestamp_only(c)]
    robot = names[0] if names else archive_name
    joint = names[1] if len(names) > 1 else None
    return PathIdentity(robot, joint, time_ns, source)


@dataclass(frozen=True)
class ArchiveBag:
    """One bag of an archive, as the path describes it.

    Attributes
    ----------
    path : Path
        The bag (a rosbag2 directory or an ``.mcap`` file), absolute.
    relpath : str
        Its path relative to the archive, with ``/`` separators (the database's ``bag_path``).
    identity : PathIdentity
        Robot, joint, time from the path (rules 1-2); the metadata may override robot and joint.
    """

    path: Path
    relpath: str
    identity: PathIdentity


def _walk(root: Path) -> Iterator[Path]:
    """Bags under ``root`` in sorted order (rosbag2 directories are not descended into)."""
    try:
        entries = sorted(os.scandir(root), key=lambda e: e.name)
    except OSError as err:
        raise GenBacklashError(f"cannot list {root}: {err.strerror or err}") from err
    for entry in entries:
        if entry.name.startswith("."):
            continue
        path = Path(entry.path)
        if entry.is_dir(follow_symlinks=True):
            if (path / "metadata.yaml").is_file():
                yield path
            else:
                yield from _walk(path)
        elif entry.name.lower().endswith(".mcap"):
            yield path


def discover(archive: str | Path) -> list[ArchiveBag]:
    """Every bag under ``archive`` (see the module notes), in sorted path order.

    Raises :class:`~genbacklash_core.GenBacklashError` when ``archive`` is not a directory.
    A directory with no bag gives an empty list.
    """
    root = Path(archive).resolve()
    if not root.is_dir():
        raise GenBacklashError(
            f"{archive} is not a directory; give the root of a tree of bags (rosbag2 "
            "directories or .mcap files)"
        )
    if (root / "metadata.yaml").is_file():  # the archive is itself one bag
        return [ArchiveBag(root, root.name, path_identity((), root.name, root.parent.name))]
    bags = []
    for path in _walk(root):
        rel = path.relative_to(root)
        identity = path_identity(rel.parts[:-1], rel.name, root.name)
        bags.append(ArchiveBag(path, rel.as_posix(), identity))
    return bags


def content_hash(path: str | Path) -> str:
    """SHA-256 (hex) of a bag's content: a file's bytes, or a rosbag2 directory's files
    (each relative name, its size and its bytes, in sorted order; the directory's own name
    and the files' times do not count, so a copy of a bag has the same hash).

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     a = Path(tmp, "a.mcap"); _ = a.write_bytes(b"mcap")
    ...     b = Path(tmp, "b.mcap"); _ = b.write_bytes(b"mcap")
    ...     content_hash(a) == content_hash(b)
    True
    """
    root = Path(path)
    digest = hashlib.sha256()
    files = sorted(p for p in root.rglob("*") if p.is_file()) if root.is_dir() else [root]
    for file in files:
        name = file.relative_to(root).as_posix() if root.is_dir() else ""
        digest.update(f"{name}\0{file.stat().st_size}\0".encode())
        with open(file, "rb") as handle:
            while block := handle.read(_HASH_BLOCK):
                digest.update(block)
    return digest.hexdigest()


def bag_start_ns(path: str | Path) -> int | None:
    """The log time of a bag's first message (its metadata), or None when it cannot be read."""
    from rosbags.highlevel import AnyReader

    from genbacklash_ros.bags.rosbags_types import jazzy_typestore

    try:
        reader = AnyReader([Path(path)], default_typestore=jazzy_typestore())
        reader.open()
    except Exception:  # unreadable: the analysis reports why
        return None
    try:
        start = int(reader.start_time)
        return start if reader.message_count else None
    except Exception:
        return None
    finally:
        reader.close()


def recorded_duration_ns(path: str | Path) -> int | None:
    """How long the recording was by its rosbag2 ``metadata.yaml`` (a bag directory's; the
    recorder writes it apart from the ``.mcap``, so it survives a cut file), or None where
    there is none (a bare ``.mcap``: its own copy sits at the end of the file, lost with a
    cut) or it cannot be read."""
    import yaml

    meta = Path(path) / "metadata.yaml"
    try:
        info = yaml.safe_load(meta.read_text(encoding="utf-8"))
        value = info["rosbag2_bagfile_information"]["duration"]["nanoseconds"]
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError):
        return None
    return int(value) if isinstance(value, int) and value >= 0 else None


def metadata_identity(custom_data: Mapping[str, str] | None) -> tuple[str | None, str | None]:
    """Rule 3: ``(robot, joint)`` from a bag's ``custom_data`` (None where it says nothing)."""
    if not custom_data:
        return None, None
    robot = custom_data.get(ROBOT_KEY) or None
    joint = custom_data.get(JOINT_KEY) or None
    return robot, joint
