""":class:`BagReader`: a rosbag2 directory or a bare ``.mcap`` read with rosbags (salvaged
when truncated), its topics, custom data and messages.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore

from .custom_data import UNREAD, read_custom_data, starts_with_magic
from .in_order import chunks_in_order
from .messages import (
    SUPPORTED_MSGTYPES,
    BagError,
    BagMessage,
    RawMessage,
    TopicInfo,
    did_you_mean,
    one_line,
)
from .salvage import Salvage, mcap_files

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
        self._custom_data: object = UNREAD

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
            reason = one_line(err)
            files = [f for f in mcap_files(self.path) if f.is_file()]
            with_magic = [f for f in files if starts_with_magic(f)]
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
            scan = Salvage(file)
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
                f"topic {name!r} is not in {self.path}{did_you_mean(name, self._topics)}; "
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
        if self._custom_data is UNREAD:
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
                    f"(log time {item.log_time_ns} ns) cannot be decoded: {one_line(err)}"
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
        chunks = chunks_in_order(reader, wanted)
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
        reason = f"{self.path} is corrupt after {count} messages: {one_line(err)}"
        files = [f for f in mcap_files(self.path) if f.is_file() and starts_with_magic(f)]
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
            scan = Salvage(file)
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
