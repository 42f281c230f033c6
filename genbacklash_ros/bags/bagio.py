"""Reading and writing rosbag2 MCAP bags with rosbags (Jazzy typestore).

:class:`BagReader` opens a rosbag2 directory (``metadata.yaml`` + ``.mcap``) or a bare
``.mcap`` file with :class:`rosbags.highlevel.AnyReader` and yields :class:`BagMessage` s
(topic, log time in integer nanoseconds, our message of :mod:`genbacklash_ros.node.messages`,
the raw CDR bytes) for chosen topics in log-time order. Every problem -- a missing path, a
file that is not a bag, a corrupt or truncated file, an unknown topic, a message type we do
not read -- is a :class:`BagError` with a one-line reason.

A truncated MCAP file (a recording cut short: no summary, no footer) cannot be opened by
rosbags. The reader then *salvages* it: it scans the records from the start and yields the
messages of every complete chunk, then raises :class:`BagError` saying where the file ends,
so that a replay can keep (and properly close) what it wrote so far.

:class:`BagWriter` writes a rosbag2 directory with one MCAP file
(``rosbags.rosbag2.Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)``, its MCAP
records written by foxglove-sdk's compiled writer where installed:
:mod:`~genbacklash_ros.bags.fast_mcap`) from our
messages (:func:`~genbacklash_ros.bags.rosbags_types.to_rosbags` + ``serialize_cdr``) or from raw
CDR bytes. :func:`align` is the batch form of the pipeline's alignment (one sample per
encoder message, the command held), used by ``genbacklash identify`` on bags.

Examples
--------
>>> import tempfile, pathlib
>>> from genbacklash_ros.node.messages import Float64
>>> out = pathlib.Path(tempfile.mkdtemp()) / "bag"
>>> with BagWriter(out) as writer:
...     writer.write("/x", 1_000, Float64(0.5))
>>> with BagReader(out) as reader:
...     [(m.topic, m.log_time_ns, m.message) for m in reader.messages(["/x"])]
[('/x', 1000, Float64(data=0.5))]
"""

from __future__ import annotations

import dataclasses
import difflib
import itertools
import struct
from collections import Counter
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, NamedTuple

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_core.measured import OfflineBaseline
from genbacklash_core.servo import ServoFit, ServoModel
from genbacklash_ros.bags.output_marker import mark_output
from genbacklash_ros.bags.raw_values import RawValueReader
from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore, to_rosbags
from genbacklash_ros.node.messages import (
    CommandType,
    DiagnosticArray,
    EncoderType,
    Float64,
    Float64MultiArray,
    JointState,
    Message,
)
from genbacklash_ros.node.sample_rule import ServoChoice, select_rows

__all__ = [
    "COMMAND_MSGTYPES",
    "ENCODER_MSGTYPES",
    "SUPPORTED_MSGTYPES",
    "AlignedSeries",
    "BagError",
    "BagMessage",
    "BagReader",
    "BagWriter",
    "RawMessage",
    "TopicInfo",
    "align",
    "check_selection",
    "read_aligned",
    "read_custom_data",
]

COMMAND_MSGTYPES: dict[str, CommandType] = {
    Float64.ros_type: "float64",
    Float64MultiArray.ros_type: "float64_multi_array",
    JointState.ros_type: "joint_state",
}
"""Command topic types and the pipeline's ``command_type`` for each."""

ENCODER_MSGTYPES: dict[str, EncoderType] = {
    JointState.ros_type: "joint_state",
    Float64.ros_type: "float64",
}
"""Encoder topic types and the pipeline's ``encoder_type`` for each."""

SUPPORTED_MSGTYPES = frozenset(
    {Float64.ros_type, Float64MultiArray.ros_type, JointState.ros_type, DiagnosticArray.ros_type}
)
"""Message types :class:`BagReader` converts into our messages."""

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_FOOTER = 0x03, 0x04, 0x05, 0x06, 0x02


class BagError(GenBacklashError):
    """A bag cannot be read or written (the message says why, in one line)."""


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """One topic of a bag: its name, ROS message type and message count."""

    name: str
    msgtype: str
    count: int


@dataclass(frozen=True, slots=True)
class BagMessage:
    """One message of a bag.

    Attributes
    ----------
    topic : str
    log_time_ns : int
        When the recorder received it (integer nanoseconds since the epoch).
    message : Message
        The message as our dataclass (:mod:`genbacklash_ros.node.messages`).
    msgtype : str
        Its ROS type, e.g. ``sensor_msgs/msg/JointState``.
    raw : bytes
        The CDR bytes as stored (to copy the message to another bag unchanged).
    """

    topic: str
    log_time_ns: int
    message: Message
    msgtype: str
    raw: bytes


class RawMessage(NamedTuple):
    """One message of a bag as stored: topic, log time (ns), ROS type, CDR bytes."""

    topic: str
    log_time_ns: int
    msgtype: str
    raw: bytes


RawRecord = tuple[str, int, str, bytes]
"""A :class:`RawMessage`'s fields as a plain tuple (what a block read elsewhere gives back:
:mod:`genbacklash_ros.bags.prefetch`); a :class:`RawMessage` is one too."""

_new = tuple.__new__


def _one_line(err: BaseException) -> str:
    text = " ".join(str(a) for a in err.args) if err.args else type(err).__name__
    return " ".join(text.split()) or type(err).__name__


# --------------------------------------------------------------------------- in order


class _ChunksInOrder:
    """Iterate the messages of ``channels`` chunk after chunk (see :func:`_chunks_in_order`);
    :attr:`count` is how many were yielded before the chunk being read (exact when rosbags
    raises: a chunk is decoded whole before its first message comes)."""

    def __init__(self, chunks: list[Any], channels: dict[int, Any], bio: Any, msgsrc: Any) -> None:
        self._chunks, self._channels, self._bio, self._msgsrc = chunks, channels, bio, msgsrc
        self.count = 0

    def __iter__(self) -> Iterator[RawMessage]:
        channels = self._channels
        topics = {cid: c.topic for cid, c in channels.items()}
        types = {cid: c.msgtype for cid, c in channels.items()}
        for chunk in self._chunks:
            if not any(chunk.channel_count.get(cid, 0) for cid in channels):
                continue
            start, stop = chunk.message_start_time, chunk.message_end_time + 1
            source = self._msgsrc(chunk, channels, start, stop, self._bio)
            next(source)  # its first item marks the chunk's start time (for a merge)
            batch = [  # tuple.__new__: a RawMessage without its Python-level __new__
                _new(RawMessage, (topics[conn.id], log_time, types[conn.id], raw))
                for log_time, _offset, conn, raw in source
            ]
            yield from batch
            self.count += len(batch)


def _chunks_in_order(reader: Any, wanted: set[str]) -> _ChunksInOrder | None:
    """The messages of ``wanted`` topics chunk after chunk, with rosbags' own chunk reader
    (``storage_mcap.msgsrc``: decompress, check, sort by log time), when the bag is one
    MCAP file whose chunks follow each other in time, as a recorder writes them; None
    otherwise (then rosbags' reader merges the chunks' streams, which gives the same order
    at about 1.3 times the cost: BENCHMARKS.md "Replay throughput").

    Also None when rosbags' internals are not those of the versions this was written for
    (0.11): the caller then takes rosbags' public reader.
    """
    try:
        from rosbags.rosbag2.storage_mcap import McapReader, msgsrc

        sources = reader.readers
        if len(sources) != 1:
            return None
        storage = sources[0].storage
        if not isinstance(storage, McapReader):  # a rosbag2 directory
            files = storage.storages
            if len(files) != 1 or storage.metadata.compression_mode == "message":
                return None
            storage = files[0]
        if not isinstance(storage, McapReader):
            return None
        chunks, bio = list(storage.chunks), storage.bio
        channels = {c.id: c for c in storage.connections if c.topic in wanted}
        if not chunks or bio is None:
            return None
        in_order = all(
            a.message_end_time <= b.message_start_time for a, b in itertools.pairwise(chunks)
        )
    except (ImportError, AttributeError, TypeError):
        return None
    return _ChunksInOrder(chunks, channels, bio, msgsrc) if in_order else None


# --------------------------------------------------------------------------- salvage


class _Truncated(Exception):
    """The MCAP records end before the file does (internal)."""


class _ChunkDamaged(Exception):
    """The records inside a chunk stop making sense (internal; args: what was kept)."""


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    (size,) = struct.unpack_from("<I", buf, pos)
    end = pos + 4 + size
    if end > len(buf):
        raise _Truncated
    return buf[pos + 4 : end].decode("utf-8"), end


class _Salvage:
    """Sequential scan of an MCAP file that has no valid footer (a cut-off recording).

    Yields ``(topic, msgtype, log_time_ns, raw)`` for the messages outside chunks and in
    every complete chunk, in file order (sorted by log time within a chunk), and records
    where and why the scan stopped in :attr:`problem`.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.problem = ""
        self.schemas: dict[int, str] = {}
        self.channels: dict[int, tuple[str, str]] = {}

    def _records(self, buf: bytes) -> Iterator[tuple[int, bytes]]:
        pos = 0
        while pos < len(buf):
            if pos + 9 > len(buf):
                raise _Truncated
            op = buf[pos]
            (size,) = struct.unpack_from("<Q", buf, pos + 1)
            end = pos + 9 + size
            if end > len(buf):
                raise _Truncated
            yield op, buf[pos + 9 : end]
            pos = end

    def _record(self, op: int, body: bytes) -> Iterator[tuple[str, str, int, bytes]]:
        if op == _OP_SCHEMA:
            (sid,) = struct.unpack_from("<H", body, 0)
            name, _ = _string(body, 2)
            self.schemas[sid] = name
        elif op == _OP_CHANNEL:
            cid, sid = struct.unpack_from("<HH", body, 0)
            topic, _ = _string(body, 4)
            self.channels[cid] = (topic, self.schemas.get(sid, ""))
        elif op == _OP_MESSAGE:
            cid, _seq, log_time, _pub = struct.unpack_from("<HIQQ", body, 0)
            if cid in self.channels:
                topic, msgtype = self.channels[cid]
                yield topic, msgtype, int(log_time), bytes(body[22:])
        elif op == _OP_CHUNK:
            from rosbags.rosbag2.storage_mcap import decompress

            _start, _end, size, crc = struct.unpack_from("<QQQI", body, 0)
            compression, pos = _string(body, 28)
            (length,) = struct.unpack_from("<Q", body, pos)
            data = body[pos + 8 : pos + 8 + length]
            inner = decompress(data, compression, size, crc)
            found: list[tuple[str, str, int, bytes]] = []
            damage: Exception | None = None
            try:
                for sub_op, sub_body in self._records(inner):
                    found.extend(self._record(sub_op, sub_body))
            except (_Truncated, struct.error, UnicodeDecodeError) as err:
                # a chunk without a CRC (rosbags writes none) damaged inside: its records
                # up to the damage are intact, the rest is lost
                damage = _ChunkDamaged(f"{len(found)} messages of the chunk read before it")
                damage.__cause__ = err
            found.sort(key=lambda item: item[2])
            yield from found
            if damage is not None:
                raise damage

    def _partial_chunk(self, body: bytes) -> Iterator[tuple[str, str, int, bytes]]:
        """The complete message records of an uncompressed chunk cut short (a compressed
        one cannot be read in part: nothing)."""
        try:
            compression, pos = _string(body, 28)
        except (_Truncated, struct.error, UnicodeDecodeError):
            return
        if compression:
            return
        found: list[tuple[str, str, int, bytes]] = []
        try:
            for sub_op, sub_body in self._records(body[pos + 8 :]):
                found.extend(self._record(sub_op, sub_body))
        except (_Truncated, struct.error, UnicodeDecodeError):
            pass  # the record cut by the end of the file
        found.sort(key=lambda item: item[2])
        yield from found

    def messages(self) -> Iterator[tuple[str, str, int, bytes]]:
        count = 0
        offset = len(_MCAP_MAGIC)
        try:
            with self.path.open("rb") as stream:
                if stream.read(len(_MCAP_MAGIC)) != _MCAP_MAGIC:
                    self.problem = f"{self.path} is not an MCAP file (bad magic)"
                    return
                while True:
                    head = stream.read(9)
                    if not head:
                        raise _Truncated
                    if len(head) < 9:
                        raise _Truncated
                    op = head[0]
                    (size,) = struct.unpack_from("<Q", head, 1)
                    body = stream.read(size)
                    if len(body) != size:
                        if op == _OP_CHUNK:  # cut inside a chunk: keep its complete records
                            for item in self._partial_chunk(body):
                                count += 1
                                yield item
                        raise _Truncated
                    if op == _OP_FOOTER:
                        return
                    for item in self._record(op, body):
                        count += 1
                        yield item
                    offset += 9 + size
        except _ChunkDamaged as err:
            self.problem = (
                f"{self.path} is corrupt inside the chunk at byte {offset} ({err}); "
                f"read {count} messages before the damage"
            )
        except _Truncated:
            self.problem = (
                f"{self.path} is truncated (records end at byte {offset}); "
                f"read {count} messages before the cut"
            )
        except (struct.error, UnicodeDecodeError, ValueError, OSError) as err:
            self.problem = (
                f"{self.path} is corrupt at byte {offset} ({_one_line(err)}); "
                f"read {count} messages before it"
            )
        except Exception as err:  # rosbags' ReaderError for a bad chunk, and the like
            self.problem = (
                f"{self.path} is corrupt at byte {offset} ({_one_line(err)}); "
                f"read {count} messages before it"
            )


def _mcap_files(path: Path) -> list[Path]:
    if path.is_dir():
        return sorted(path.glob("*.mcap"))
    return [path]


# --------------------------------------------------------------------------- reading


class BagReader:
    """Read the messages of a rosbag2 directory or a bare ``.mcap`` file.

    Parameters
    ----------
    path : str or Path
        A rosbag2 directory (with ``metadata.yaml``) or an ``.mcap`` file.

    Notes
    -----
    Use as a context manager. :attr:`salvaged` is True when the file could not be opened
    normally and is scanned record by record (a truncated recording): :meth:`messages` then
    yields what it can and raises :class:`BagError` at the damage.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f"no bag at {self.path}: the path does not exist")
        self._reader: Any = None
        self._salvage: list[Path] = []
        self._salvage_reason = ""
        self._topics: dict[str, TopicInfo] = {}
        self._custom_data: object = _UNREAD

    # context management

    def __enter__(self) -> BagReader:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]:
        self.close()
        return False

    def open(self) -> None:
        """Open the bag (or prepare its salvage); raises :class:`BagError`."""
        from rosbags.highlevel import AnyReader

        try:
            reader = AnyReader([self.path], default_typestore=jazzy_typestore())
            reader.open()
        except Exception as err:  # AnyReaderError, FileNotFoundError, yaml and type errors
            reason = _one_line(err)
            files = [f for f in _mcap_files(self.path) if f.is_file()]
            with_magic = [f for f in files if _starts_with_magic(f)]
            if not with_magic:
                kind = "directory" if self.path.is_dir() else "file"
                raise BagError(
                    f"{self.path} is not a readable rosbag2 MCAP bag ({kind}): {reason}"
                ) from err
            self._salvage = with_magic
            self._salvage_reason = reason
            self._topics = self._scan_topics()
            if not any(t.count for t in self._topics.values()):
                raise BagError(
                    f"{self.path} cannot be opened ({reason}) and holds no complete message"
                ) from err
            return
        self._reader = reader
        topics: dict[str, TopicInfo] = {}
        for conn in reader.connections:
            old = topics.get(conn.topic)
            count = conn.msgcount + (old.count if old else 0)
            topics[conn.topic] = TopicInfo(conn.topic, conn.msgtype, count)
        self._topics = topics

    def _scan_topics(self) -> dict[str, TopicInfo]:
        counts: dict[tuple[str, str], int] = {}
        for file in self._salvage:
            scan = _Salvage(file)
            for topic, msgtype, _t, _raw in scan.messages():
                counts[topic, msgtype] = counts.get((topic, msgtype), 0) + 1
            for topic, msgtype in scan.channels.values():
                counts.setdefault((topic, msgtype), 0)
        return {t: TopicInfo(t, m, n) for (t, m), n in sorted(counts.items())}

    def close(self) -> None:
        """Close the bag (idempotent)."""
        reader, self._reader = self._reader, None
        if reader is not None:
            try:
                reader.close()
            except Exception:  # closing a reader that failed mid-way: nothing to keep
                pass

    # topics

    @property
    def salvaged(self) -> bool:
        """True when the bag is read record by record because it could not be opened."""
        return bool(self._salvage)

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> :class:`TopicInfo` (for a salvaged bag: what the scan found)."""
        return dict(self._topics)

    def topic_list(self) -> str:
        """The topics as ``name (type, count)``, one comma-separated line."""
        if not self._topics:
            return "none"
        return ", ".join(f"{t.name} ({t.msgtype}, {t.count})" for t in self._topics.values())

    def topic(self, name: str, allowed: Iterable[str] | None = None) -> TopicInfo:
        """The topic ``name``, checked to exist (and to have one of the ``allowed`` types).

        Raises :class:`BagError` listing the topics that exist, or the supported types.
        """
        info = self._topics.get(name)
        if info is None:
            raise BagError(
                f"topic {name!r} is not in {self.path}{_did_you_mean(name, self._topics)}; "
                f"the bag has: {self.topic_list()}"
            )
        kinds = SUPPORTED_MSGTYPES if allowed is None else frozenset(allowed)
        if info.msgtype not in kinds:
            raise BagError(
                f"topic {name!r} has type {info.msgtype}, which is not supported here; "
                f"use one of: {', '.join(sorted(kinds))}"
            )
        return info

    def count(self, topics: Iterable[str]) -> int:
        """Number of messages on ``topics`` (for progress bars)."""
        return sum(self._topics[t].count for t in topics if t in self._topics)

    @property
    def custom_data(self) -> dict[str, str] | None:
        """The bag's ``custom_data`` (rosbag2 metadata: a string -> string map), or None.

        Read from ``metadata.yaml`` of a bag directory, else from the rosbag2 metadata
        record embedded in the MCAP file (a bare ``.mcap`` keeps it too). Tolerant: a bag
        without it, or with one that is not a string -> string map, gives None.
        """
        if self._custom_data is _UNREAD:
            self._custom_data = read_custom_data(self.path)
        value = self._custom_data
        return dict(value) if isinstance(value, dict) else None

    # messages

    def messages(self, topics: Sequence[str]) -> Iterator[BagMessage]:
        """The messages of ``topics`` in log-time order, decoded into our dataclasses.

        Raises :class:`BagError` for an unknown topic or unsupported type (before yielding
        anything), and for a corrupt message or a truncated file (after yielding the
        messages before the damage).
        """
        store = jazzy_typestore()
        for item in self.raw_messages(topics):
            try:
                message = from_rosbags(store.deserialize_cdr(item.raw, item.msgtype))
            except Exception as err:  # rosbags' deserializer errors, MessageError
                raise BagError(
                    f"{self.path} is corrupt: a {item.msgtype} message on {item.topic} "
                    f"(log time {item.log_time_ns} ns) cannot be decoded: {_one_line(err)}"
                ) from err
            yield BagMessage(item.topic, item.log_time_ns, message, item.msgtype, item.raw)

    def raw_messages(self, topics: Sequence[str]) -> Iterator[RawMessage]:
        """The messages of ``topics`` in log-time order as stored (CDR bytes, not decoded).

        The same checks and the same handling of damage as :meth:`messages`.
        """
        for name in topics:
            self.topic(name)
        wanted = set(topics)
        if self._salvage:
            yield from self._salvaged_messages(wanted)
            return
        reader = self._reader
        if reader is None:
            raise BagError(f"{self.path} is not open")
        chunks = _chunks_in_order(reader, wanted)
        if chunks is not None:
            try:
                yield from chunks
            except GeneratorExit:
                raise
            except Exception as err:  # rosbags' reader errors
                yield from self._after_damage(err, wanted, chunks.count)
            return
        connections = [c for c in reader.connections if c.topic in wanted]
        # one bag: its own reader's stream (already in log-time order), without the merge
        # AnyReader puts over several bags
        sources = reader.readers
        stream = (sources[0] if len(sources) == 1 else reader).messages(connections=connections)
        count = 0
        try:
            for conn, log_time, raw in stream:
                count += 1
                yield RawMessage(
                    conn.topic,
                    int(log_time),
                    conn.msgtype,
                    raw if type(raw) is bytes else bytes(raw),
                )
        except GeneratorExit:
            raise
        except Exception as err:  # rosbags' reader errors
            yield from self._after_damage(err, wanted, count)

    def _after_damage(self, err: Exception, wanted: set[str], count: int) -> Iterator[RawMessage]:
        """rosbags stopped with ``err`` after ``count`` messages: :class:`BagError`, or the
        messages after those that a record-by-record scan recovers (then the error)."""
        reason = f"{self.path} is corrupt after {count} messages: {_one_line(err)}"
        files = [f for f in _mcap_files(self.path) if f.is_file() and _starts_with_magic(f)]
        if not files:
            raise BagError(reason) from err
        # rosbags reads through the summary's indexes, so damage anywhere (a chunk, an
        # index) can stop it early: scan the records from the start instead and keep every
        # intact chunk before the damage (the CRCs tell).
        self._salvage, self._salvage_reason = files, reason
        yield from self._salvaged_messages(wanted, skip=count)

    def _salvaged_messages(self, wanted: set[str], skip: int = 0) -> Iterator[RawMessage]:
        """The messages a record-by-record scan finds, after the first ``skip`` of them
        (those yielded already), then :class:`BagError` saying where the damage is."""
        seen = 0
        for file in self._salvage:
            scan = _Salvage(file)
            for topic, msgtype, log_time, raw in scan.messages():
                if topic not in wanted:
                    continue
                seen += 1
                if seen <= skip:
                    continue
                yield RawMessage(topic, log_time, msgtype, raw)
            if scan.problem:
                raise BagError(scan.problem)
        raise BagError(
            f"{self.path} could not be read normally ({self._salvage_reason}); "
            f"a record-by-record scan recovered {seen} messages"
        )


# --------------------------------------------------------------------------- selection

_PEEK_MESSAGES = 2048  # messages looked at, at most, to learn what a selection can match
_PEEK_EACH = 64  # per topic: enough to see every joint name and array length a topic uses


def _did_you_mean(name: str, known: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the close matches of ``name`` among ``known`` ('')."""
    known = list(known)
    folded = [k for k in known if k.casefold() == name.casefold() and k != name]
    close = folded or difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    if not close:
        return ""
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)"


def _peek(reader: BagReader, topics: Sequence[str]) -> dict[str, list[Message]]:
    """The first messages of ``topics`` that decode (up to ``_PEEK_EACH`` each); damage
    stops the look (the full read reports it)."""
    store = jazzy_typestore()
    seen: dict[str, list[Message]] = {t: [] for t in topics}
    stream = reader.raw_messages(topics)
    try:
        for k, item in enumerate(stream):
            if k >= _PEEK_MESSAGES or all(len(v) >= _PEEK_EACH for v in seen.values()):
                break
            if len(seen[item.topic]) >= _PEEK_EACH:
                continue
            try:
                seen[item.topic].append(from_rosbags(store.deserialize_cdr(item.raw, item.msgtype)))
            except Exception:  # an undecodable message: the full read counts it
                continue
    except BagError:
        pass
    finally:
        if isinstance(stream, Generator):  # stop the reader where the look stopped
            stream.close()
    return seen


def _joint_names(messages: Iterable[Message]) -> list[str]:
    names: dict[str, None] = {}
    for message in messages:
        if isinstance(message, JointState):
            names.update(dict.fromkeys(message.name))
    return list(names)


def _check_joint(topic: str, role: str, joint: str, names: list[str], path: Path) -> None:
    if not names:
        return  # no names seen (no message decoded, or nameless JointStates): the adapters
    listed = ", ".join(names)
    if joint and joint not in names:
        raise BagError(
            f"joint {joint!r} is not in the {role} JointState on {topic} in {path}"
            f"{_did_you_mean(joint, names)}; it holds: {listed}"
        )
    if not joint and len(names) > 1:
        raise BagError(
            f"the {role} JointState on {topic} in {path} holds {len(names)} joints ({listed}): "
            "say which with --joint NAME (or the parameter joint)"
        )


def check_selection(
    reader: BagReader,
    command_topic: str,
    encoder_topic: str,
    *,
    joint: str = "",
    command_index: int = 0,
) -> tuple[TopicInfo, TopicInfo]:
    """Check, before any work, that a selection matches something in an open bag.

    The one place ``replay``, ``identify``, ``diagnose`` and the fleet check what they read:
    both topics exist (else the bag's topics with their types are named), have a supported
    type and hold messages; the first messages of each (up to 64) show the joint names of a
    JointState and the length of a Float64MultiArray command: ``joint`` must be one of those
    names (the close matches are named), a JointState of several joints needs a ``joint``
    (the adapters would take the first), and ``command_index`` must lie inside the array.

    Returns the command's and the encoder's :class:`TopicInfo`; raises :class:`BagError`
    with a one-line reason that says what the bag holds.
    """
    if command_topic == encoder_topic:
        raise BagError(f"the command and encoder topics must differ, both are {command_topic!r}")
    cmd = reader.topic(command_topic, COMMAND_MSGTYPES)
    enc = reader.topic(encoder_topic, ENCODER_MSGTYPES)
    for info, role in ((cmd, "command"), (enc, "encoder")):
        if not info.count:
            raise BagError(
                f"the {role} topic {info.name} ({info.msgtype}) in {reader.path} holds no "
                f"messages; the bag has: {reader.topic_list()}"
            )
    if command_index < 0:
        raise BagError(f"the command index must be >= 0, got {command_index}")
    seen = _peek(reader, [command_topic, encoder_topic])
    if enc.msgtype == JointState.ros_type:
        _check_joint(
            encoder_topic, "encoder", joint, _joint_names(seen[encoder_topic]), reader.path
        )
    if cmd.msgtype == JointState.ros_type:
        _check_joint(
            command_topic, "command", joint, _joint_names(seen[command_topic]), reader.path
        )
    if cmd.msgtype == Float64MultiArray.ros_type:
        lengths = sorted(
            {len(m.data) for m in seen[command_topic] if isinstance(m, Float64MultiArray)}
        )
        if lengths and command_index >= lengths[-1]:
            held = " to ".join(str(n) for n in dict.fromkeys((lengths[0], lengths[-1])))
            last = lengths[-1] - 1
            indices = f"indices 0 to {last}" if last > 0 else "index 0" if last == 0 else "none"
            raise BagError(
                f"command index {command_index} is beyond the Float64MultiArray on "
                f"{command_topic} in {reader.path}: it holds {held} value"
                f"{'' if lengths[-1] == 1 else 's'} ({indices}); choose with --command-index I "
                "(or the parameter command_index)"
            )
    return cmd, enc


def check_motor(
    reader: BagReader, motor_topic: str, others: Sequence[str], *, joint: str = ""
) -> TopicInfo:
    """Check a motor encoder topic (the gear's input, dual encoders) as
    :func:`check_selection` checks the others: it exists (else the bag's topics are named),
    differs from ``others`` (the command and encoder topics), has an encoder's type, holds
    messages, and a JointState's ``joint`` is one it holds (a JointState of several joints
    needs one). Raises :class:`BagError` with a one-line reason."""
    if motor_topic in others:
        raise BagError(
            f"the motor encoder topic must differ from the command and encoder topics, "
            f"got {motor_topic!r} for both"
        )
    try:
        info = reader.topic(motor_topic, ENCODER_MSGTYPES)
    except BagError as err:
        raise BagError(f"motor encoder: {err}") from err
    if not info.count:
        raise BagError(
            f"the motor encoder topic {info.name} ({info.msgtype}) in {reader.path} holds no "
            f"messages; the bag has: {reader.topic_list()}"
        )
    if info.msgtype == JointState.ros_type:
        names = _joint_names(_peek(reader, [motor_topic])[motor_topic])
        listed = ", ".join(names)
        if names and joint and joint not in names:
            raise BagError(
                f"joint {joint!r} is not in the motor encoder JointState on {motor_topic} in "
                f"{reader.path}{_did_you_mean(joint, names)}; it holds: {listed} (choose with "
                "--motor-joint NAME)"
            )
        if names and not joint and len(names) > 1:
            raise BagError(
                f"the motor encoder JointState on {motor_topic} in {reader.path} holds "
                f"{len(names)} joints ({listed}): say which with --motor-joint NAME"
            )
    return info


# --------------------------------------------------------------------------- custom data

_UNREAD = object()
_OP_METADATA, _OP_METADATA_INDEX = 0x0C, 0x0D
_FOOTER_SIZE = 1 + 8 + 20  # opcode, length, summary start, summary offset start, CRC
_MAX_SUMMARY = 64 << 20  # a summary section larger than this is not searched


def _string_map(value: object) -> dict[str, str] | None:
    if not isinstance(value, dict) or not value:
        return None
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
        return None
    return dict(value)


def _custom_data_of(info: object) -> dict[str, str] | None:
    """``custom_data`` of a ``rosbag2_bagfile_information`` mapping (None if absent/bad)."""
    return _string_map(info.get("custom_data")) if isinstance(info, dict) else None


def _safe_yaml(text: str) -> object:
    """``yaml.safe_load(text)`` through libyaml's parser where PyYAML has it (the same
    safe constructor, so the same objects and the same ``yaml.YAMLError`` s; a bag's
    ``metadata.yaml`` parses in under a millisecond instead of ~18 ms)."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    return yaml.load(text, Loader=loader)  # a safe loader


def _embedded_metadata(path: Path) -> object:
    """The rosbag2 metadata an MCAP file holds (its ``rosbag2`` metadata record, found
    through the summary's metadata index), parsed from YAML; None when there is none."""

    size = path.stat().st_size
    with path.open("rb") as stream:
        if size < 2 * len(_MCAP_MAGIC) + _FOOTER_SIZE:
            return None
        stream.seek(size - len(_MCAP_MAGIC) - _FOOTER_SIZE)
        footer = stream.read(_FOOTER_SIZE)
        if footer[0] != _OP_FOOTER:
            return None
        (summary_start,) = struct.unpack_from("<Q", footer, 9)
        summary_end = size - len(_MCAP_MAGIC) - _FOOTER_SIZE
        if not 0 < summary_start < summary_end or summary_end - summary_start > _MAX_SUMMARY:
            return None
        stream.seek(summary_start)
        summary = stream.read(summary_end - summary_start)
        pos = 0
        while pos + 9 <= len(summary):
            op = summary[pos]
            (length,) = struct.unpack_from("<Q", summary, pos + 1)
            body = summary[pos + 9 : pos + 9 + length]
            pos += 9 + length
            if op != _OP_METADATA_INDEX:
                continue
            offset, record_length = struct.unpack_from("<QQ", body, 0)
            name, _ = _string(body, 16)
            if name != "rosbag2" or record_length > _MAX_SUMMARY:
                continue
            stream.seek(offset)
            record = stream.read(record_length)
            if len(record) < 9 or record[0] != _OP_METADATA:
                return None
            _, at = _string(record, 9)
            (map_size,) = struct.unpack_from("<I", record, at)
            at += 4
            end = at + map_size
            while at < end:
                key, at = _string(record, at)
                value, at = _string(record, at)
                if key == "serialized_metadata":
                    return _safe_yaml(value)
            return None
    return None


def read_custom_data(path: str | Path) -> dict[str, str] | None:
    """The ``custom_data`` map of a bag (directory or bare ``.mcap``), or None.

    Looks in ``metadata.yaml`` first, then in the rosbag2 metadata embedded in the MCAP
    file(s). Never raises for a bag without one or with a damaged one: None.
    """
    import yaml

    bag = Path(path)
    if bag.is_dir():
        try:
            document = _safe_yaml((bag / "metadata.yaml").read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            document = None
        if isinstance(document, dict) and "rosbag2_bagfile_information" in document:
            return _custom_data_of(document["rosbag2_bagfile_information"])
    for file in _mcap_files(bag):
        try:
            found = _custom_data_of(_embedded_metadata(file))
        except (OSError, struct.error, UnicodeDecodeError, _Truncated, yaml.YAMLError):
            continue
        if found is not None:
            return found
    return None


def _starts_with_magic(path: Path) -> bool:
    try:
        with path.open("rb") as stream:
            return stream.read(len(_MCAP_MAGIC)) == _MCAP_MAGIC
    except OSError:
        return False


# --------------------------------------------------------------------------- writing


class BagWriter:
    """Write a rosbag2 directory with one MCAP file (rosbag2 metadata version 9).

    Parameters
    ----------
    path : str or Path
        The bag directory to create; it must not exist.
    compiled : bool
        Write the MCAP file with foxglove-sdk's compiled writer
        (:mod:`~genbacklash_ros.bags.fast_mcap`) when it is installed; False: with rosbags'
        pure-Python writer. The files hold the same records either way.

    Attributes
    ----------
    compiled : bool
        Whether the compiled writer is in use.

    Notes
    -----
    Topics are registered on first use (or with :meth:`add_topic`). Use as a context
    manager: the writer is closed (metadata and MCAP summary written) even when an
    exception leaves the block, so that what was written stays a valid bag.
    """

    def __init__(self, path: str | Path, *, compiled: bool = True) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        from genbacklash_ros.bags import fast_mcap

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already; remove it or choose another output")
        try:  # like `ros2 bag record -o a/b`, create missing parent directories
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise BagError(f"cannot write {self.path}: {_one_line(err)}") from err
        self._store = jazzy_typestore()
        try:
            # foxglove-sdk's compiled MCAP writer where it is installed, else rosbags' own
            self.compiled = compiled and fast_mcap.AVAILABLE
            kind = fast_mcap.FoxgloveWriter if self.compiled else Writer
            self._writer: Any = kind(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
            mark_output(self.path)  # --overwrite replaces only directories carrying it
        except Exception as err:
            raise BagError(f"cannot create {self.path}: {_one_line(err)}") from err
        self._connections: dict[str, tuple[Any, str]] = {}
        self._logs: dict[str, Callable[[bytes, int, None], None]] = {}  # compiled channels
        self._open = True
        self.count = 0

    def set_custom_data(self, key: str, value: str) -> None:
        """Store ``value`` under ``key`` in the bag's ``custom_data`` (rosbag2 metadata:
        ``metadata.yaml`` and the MCAP file's embedded copy), written when the bag closes.
        Read back with :attr:`BagReader.custom_data`."""
        if not self._open:
            raise BagError(f"{self.path} is closed")
        if not isinstance(key, str) or not isinstance(value, str):
            raise BagError(f"custom_data needs string keys and values, got {key!r}: {value!r}")
        self._writer.set_custom_data(key, value)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]:
        self.close()
        return False

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Register ``topic`` with the ROS type ``msgtype`` (a Jazzy type)."""
        known = self._connections.get(topic)
        if known is not None:
            if known[1] != msgtype:
                raise BagError(f"topic {topic!r} has type {known[1]}, not {msgtype}")
            return
        try:
            conn = self._writer.add_connection(topic, msgtype, typestore=self._store)
        except Exception as err:
            raise BagError(f"cannot add topic {topic!r} ({msgtype}): {_one_line(err)}") from err
        self._connections[topic] = (conn, msgtype)
        if self.compiled:
            self._logs[topic] = self._writer.storage.channel_log(conn)

    def write(self, topic: str, log_time_ns: int, message: Message) -> None:
        """Write one of our messages on ``topic`` at ``log_time_ns``."""
        self.write_raw(topic, log_time_ns, self.encode(message), message.ros_type)

    def encode(self, message: Message) -> bytes:
        """The CDR bytes :meth:`write` writes for ``message`` (rosbags' serialiser)."""
        store = self._store
        return bytes(store.serialize_cdr(to_rosbags(message, store), message.ros_type))

    def write_raw(
        self, topic: str, log_time_ns: int, raw: bytes | memoryview, msgtype: str
    ) -> None:
        """Write CDR bytes of type ``msgtype`` on ``topic`` at ``log_time_ns``."""
        if not self._open:
            raise BagError(f"{self.path} is closed")
        entry = self._connections.get(topic)
        if entry is None:
            self.add_topic(topic, msgtype)
            entry = self._connections[topic]
        self._writer.write(entry[0], int(log_time_ns), raw)
        self.count += 1

    def write_raw_many(self, records: Sequence[tuple[str, int, bytes]]) -> None:
        """Write ``(topic, log time, CDR bytes)`` records in order on topics already added
        (:meth:`add_topic`): :meth:`write_raw` for each, in one call."""
        self._write_records(records, 2)

    def write_messages(self, messages: Sequence[RawRecord]) -> None:
        """Write messages as :meth:`BagReader.raw_messages` gives them (or their fields as
        :data:`RawRecord` tuples; the type is the topic's), in order, on topics already
        added: :meth:`write_raw` for each."""
        self._write_records(messages, 3)

    def _write_records(self, records: Sequence[Sequence[Any]], raw_at: int) -> None:
        """Records with the topic at 0, the log time at 1 and the bytes at ``raw_at``."""
        if not self._open:
            raise BagError(f"{self.path} is closed")
        if not records:
            return
        topics = Counter(map(itemgetter(0), records))
        missing = topics.keys() - self._connections.keys()
        if missing:
            raise BagError(f"topic {sorted(missing)[0]!r} was not added to {self.path}")
        writer = self._writer
        raws = list(map(itemgetter(raw_at), records))
        if self.compiled:
            # the compiled channels' own log (bytes only), then what rosbags' Writer.write
            # does per message (the counts and the time span for metadata.yaml) once
            raws = [r if type(r) is bytes else bytes(r) for r in raws]
            logs = self._logs
            for record, raw in zip(records, raws, strict=True):
                logs[record[0]](raw, record[1], None)
            counts = writer.counts
            for topic, n in topics.items():
                counts[self._connections[topic][0].id] += n
            times = list(map(itemgetter(1), records))
            writer.min_timestamp = min(writer.min_timestamp, min(times))
            writer.max_timestamp = max(writer.max_timestamp, max(times))
        else:
            connections = self._connections
            for record, raw in zip(records, raws, strict=True):
                writer.write(connections[record[0]][0], int(record[1]), raw)
        self.count += len(records)

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        if self._open:
            self._open = False
            self._writer.close()


# --------------------------------------------------------------------------- alignment


@dataclass(frozen=True, eq=False)
class AlignedSeries:
    """Identification samples: one per encoder message, the command held.

    ``t`` (int64 ns), ``u`` (the latest command at or before ``t``), ``y`` (the encoder);
    ``skipped`` counts encoder samples before the first command; ``breaks`` (bool) the
    sample rule: True where a sample does not follow the one before it on the encoder's
    clock (:mod:`genbacklash_ros.node.sample_rule`; pass it to the identifiers' ``breaks``).
    ``damage``: why the bag's reading stopped early ("" when it was read to its end; see
    :func:`read_aligned`'s ``keep_readable``). ``servo``, ``servo_fit``: the servo model
    whose output ``u`` is, and its estimate (:func:`~genbacklash_ros.node.sample_rule.select_rows`).
    ``baseline``: the record's tracking without compensation as the node's judge measures
    it (:func:`read_aligned`'s ``baseline``; None when not asked for, or when the bag may
    hold compensation: :func:`node_outputs`).
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    skipped: int
    breaks: np.ndarray
    damage: str = ""
    servo: ServoModel | None = None
    servo_fit: ServoFit | None = None
    baseline: OfflineBaseline | None = None


def node_outputs(topics: Iterable[str]) -> list[str]:
    """The topics of ``topics`` the node publishes (a compensated command, its estimate): a
    record that holds one may have had compensation in the loop, so its tracking is not
    counted as tracking without compensation (``/diagnostics`` is every node's, not counted).

    >>> node_outputs(["/command", "/encoder", "/compensated_command", "/diagnostics"])
    ['/compensated_command']
    """
    marks = ("compensated_command", "backlash_identifier/estimate")
    return [t for t in topics if t.endswith(marks)]


def align(
    cmd_t: np.ndarray,
    cmd_u: np.ndarray,
    enc_t: np.ndarray,
    enc_y: np.ndarray,
    *,
    marks: np.ndarray | None = None,
    bridge: bool = False,
    settle_ns: int = 0,
    servo: ServoChoice = None,
    motor: bool = False,
) -> AlignedSeries:
    """Zero-order-hold alignment of a command stream to encoder times (batch form); the rows
    and their breaks are :func:`~genbacklash_ros.node.sample_rule.select_rows`'s (shared with
    a CSV of the same readings).

    The pipeline's rule (:mod:`genbacklash_ros.node.pipeline`, ``sample_period = 0``): the input
    of the sample at encoder time ``t`` is the latest command with time ``<= t``; samples
    before the first command are skipped. Both streams must be sorted by time. With
    ``motor`` the "commands" are a motor encoder's readings (the gear's input): a reading
    whose motor reading is not its own is taken out
    (:func:`~genbacklash_ros.node.sample_rule.paired_keep`) and ``settle_ns`` is not applied.

    The breaks follow the pipeline's sample rule too: the encoder's nominal period is the
    median difference of ``enc_t`` (:func:`~genbacklash_core.samples.nominal_period`), a
    sample breaks where its stamp is not one period, rounded, after the one before, and
    where ``marks`` (one per encoder reading) says a reading was taken out before it (a
    message the adapters rejected); the first sample kept always breaks. With ``bridge`` (for
    a backlash alone: :func:`~genbacklash_core.samples.bridge_lost`), a break that only lost
    readings made -- at most :data:`~genbacklash_core.samples.MAX_BRIDGED` of them, none
    rejected -- is lifted where the commands in force over the gap were monotone.

    >>> s = align(np.array([10, 20]), np.array([1.0, 2.0]), np.array([5, 10, 15, 25]),
    ...           np.array([0.1, 0.2, 0.3, 0.4]))
    >>> s.u.tolist(), s.y.tolist(), s.skipped
    ([1.0, 1.0, 2.0], [0.2, 0.3, 0.4], 1)
    >>> s.breaks.tolist()  # 20 ns lost between 15 and 25
    [True, False, True]
    """
    ct = np.asarray(cmd_t, dtype=np.int64)
    et = np.asarray(enc_t, dtype=np.int64)
    k = np.searchsorted(ct, et, side="right") - 1
    rows = select_rows(
        et,
        k,
        cmd_u,
        enc_y,
        marks=marks,
        bridge=bridge,
        settle_ns=0 if motor else settle_ns,
        servo=None if motor else servo,
        input_stamps=ct if motor else None,
    )
    return AlignedSeries(
        rows.t,
        rows.u,
        rows.y,
        rows.skipped,
        rows.breaks,
        servo=rows.servo,
        servo_fit=rows.servo_fit,
    )


def _increasing(times: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop samples whose time is not after the previous accepted one (as the pipeline)."""
    t = np.asarray(times, dtype=np.int64)
    keep = _increasing_mask(t)
    return t[keep], np.asarray(values, dtype=np.float64)[keep]


def _increasing_mask(t: np.ndarray) -> np.ndarray:
    """Which of the times ``t`` are after every one before them."""
    if t.size < 2:
        return np.ones(t.size, dtype=bool)
    return t > np.maximum.accumulate(np.concatenate(([np.iinfo(np.int64).min], t[:-1])))


def read_aligned(
    path: str | Path,
    command_topic: str,
    encoder_topic: str,
    *,
    joint: str = "",
    command_index: int = 0,
    bridge: bool = False,
    settle_ns: int = 0,
    keep_readable: bool = False,
    servo: ServoChoice = None,
    motor_topic: str | None = None,
    motor_joint: str = "",
    baseline: bool = False,
) -> AlignedSeries:
    """Read a command and an encoder topic from a bag and align them (see :func:`align`;
    ``bridge`` for a backlash alone; ``settle_ns`` the servo's settling rule, as the node;
    ``servo`` the servo model, or ``"auto"``).

    With ``baseline`` the record's tracking without compensation is measured as the node's
    judge measures it (:func:`~genbacklash_ros.node.tracking_stage.record_baseline`, the
    encoder readings against the commands) into :attr:`AlignedSeries.baseline`, unless
    the bag holds a node's outputs (:func:`node_outputs`: compensation may have been in the
    loop).

    With ``motor_topic`` (a motor encoder, dual encoders: the node's ``gear_input =
    "motor_encoder"``) the input of each row is the motor reading of the encoder reading's
    stamp (``motor_joint``: its joint, default ``joint``), as the node pairs them; the
    command topic is still checked and read (the rows start at the first command).

    A bag that turns out truncated or corrupt part-way raises :class:`BagError`; with
    ``keep_readable`` the messages before the damage are aligned instead, as a replay keeps
    them, and :attr:`AlignedSeries.damage` says where the reading stopped.

    Times are header stamps when the message has a non-zero one, else the log time (the
    pipeline's default ``stamp_source = "header"``). Messages the adapters reject (joint
    missing, index out of range, non-finite values) are skipped; a rejected encoder message
    breaks the chain of consecutive samples at the next encoder reading in log order, as in
    the pipeline (``breaks``, see :func:`align`).
    """
    with BagReader(path) as reader:
        cmd_info, enc_info = check_selection(
            reader, command_topic, encoder_topic, joint=joint, command_index=command_index
        )
        plain = not node_outputs(reader.topics)
        cmd_type, enc_type = cmd_info.msgtype, enc_info.msgtype
        motor_joint = motor_joint or joint
        mot_type = ""
        if motor_topic is not None:
            mot_type = check_motor(
                reader, motor_topic, (command_topic, encoder_topic), joint=motor_joint
            ).msgtype
        # values straight from the CDR bytes, in numpy steps per block; a message the fast
        # path cannot vouch for is read (or rejected) by the adapters, one by one
        readers = {
            command_topic: RawValueReader(cmd_type, "command", index=command_index, joint=joint),
            encoder_topic: RawValueReader(enc_type, "encoder", joint=joint),
        }
        parts: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {
            command_topic: [],
            encoder_topic: [],
        }
        if motor_topic is not None:
            readers[motor_topic] = RawValueReader(mot_type, "encoder", joint=motor_joint)
            parts[motor_topic] = []

        def take(block: list[RawMessage]) -> None:
            for topic, read in readers.items():
                mine = [m for m in block if m.topic == topic]
                head, value, ok = read.read_all([m.raw for m in mine])
                log = np.fromiter((m.log_time_ns for m in mine), dtype=np.int64, count=len(mine))
                parts[topic].append((np.where(head != 0, head, log), value, ok))

        block: list[RawMessage] = []
        damage = ""
        try:
            for item in reader.raw_messages(list(parts)):
                block.append(item)
                if len(block) >= 8192:
                    take(block)
                    block = []
        except BagError as err:  # damaged part-way: the messages before it were yielded
            if not keep_readable:
                raise
            damage = str(err)
        take(block)

    c_t, c_u, c_ok = (np.concatenate(a) for a in zip(*parts[command_topic], strict=True))
    e_t, e_y, e_ok = (np.concatenate(a) for a in zip(*parts[encoder_topic], strict=True))
    # a reading taken out (rejected) breaks the chain at the next one kept (log order)
    e_m = np.diff(np.cumsum(~e_ok)[e_ok], prepend=0) > 0
    c_t, c_u, e_t, e_y = c_t[c_ok], c_u[c_ok], e_t[e_ok], e_y[e_ok]
    before = f" before the damage ({damage})" if damage else ""
    if not c_t.size:
        raise BagError(f"no readable command on {command_topic!r} in {path}{before}")
    if not e_t.size:
        raise BagError(f"no readable encoder reading on {encoder_topic!r} in {path}{before}")
    order_c = np.argsort(c_t, kind="stable")
    order_e = np.argsort(e_t, kind="stable")
    c_t, c_u = _increasing(c_t[order_c], c_u[order_c])
    e_t, e_y, e_m = e_t[order_e], e_y[order_e], e_m[order_e]
    unique = _increasing_mask(e_t)
    if not unique.all():  # a duplicate's mark passes to the next reading kept
        seen = np.cumsum(e_m)[unique]
        e_m = np.diff(seen, prepend=0) > 0
        e_t, e_y = e_t[unique], e_y[unique]
    if motor_topic is not None:  # the gear's input: the motor readings after the first command
        m_t, m_y, m_ok = (np.concatenate(a) for a in zip(*parts[motor_topic], strict=True))
        m_t, m_y = m_t[m_ok], m_y[m_ok]
        if not m_t.size:
            raise BagError(f"no readable motor reading on {motor_topic!r} in {path}{before}")
        order_m = np.argsort(m_t, kind="stable")
        m_t, m_y = _increasing(m_t[order_m], m_y[order_m])
        after = m_t >= c_t[0]
        m_t, m_y = m_t[after], m_y[after]
        if not m_t.size:
            raise BagError(f"no motor reading on {motor_topic!r} follows the first command")
        series = align(m_t, m_y, e_t, e_y, marks=e_m, bridge=bridge, motor=True)
    else:
        series = align(
            c_t, c_u, e_t, e_y, marks=e_m, bridge=bridge, settle_ns=settle_ns, servo=servo
        )
    if series.t.size == 0:
        raise BagError(f"no encoder reading on {encoder_topic!r} follows the first command{before}")
    if baseline and plain:
        from genbacklash_ros.node.tracking_stage import record_baseline

        series = dataclasses.replace(series, baseline=record_baseline(c_t, c_u, e_t, e_y))
    return dataclasses.replace(series, damage=damage) if damage else series
