""":class:`BagWriter`: a rosbag2 directory with one MCAP file (foxglove-sdk's compiled MCAP
writer where installed), from our messages or from raw CDR bytes.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from operator import itemgetter
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from genbacklash_ros.bags.output_marker import mark_output
from genbacklash_ros.bags.rosbags_types import jazzy_typestore, to_rosbags
from genbacklash_ros.node.messages import (
    Message,
)

from .messages import BagError, RawRecord, one_line

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
            raise BagError(f"cannot write {self.path}: {one_line(err)}") from err
        self._store = jazzy_typestore()
        try:
            # foxglove-sdk's compiled MCAP writer where it is installed, else rosbags' own
            self.compiled = compiled and fast_mcap.AVAILABLE
            kind = fast_mcap.FoxgloveWriter if self.compiled else Writer
            self._writer: Any = kind(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
            mark_output(self.path)  # --overwrite replaces only directories carrying it
        except Exception as err:
            raise BagError(f"cannot create {self.path}: {one_line(err)}") from err
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
            raise BagError(f"cannot add topic {topic!r} ({msgtype}): {one_line(err)}") from err
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
