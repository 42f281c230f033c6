"""Raw messages in log-time order from rosbags' own chunk reader, where the bag's chunks
allow it (the fast path of :meth:`~.reader.BagReader.raw_messages`).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from typing import Any

from .messages import RawMessage, tuple_new

# --------------------------------------------------------------------------- in order


class _ChunksInOrder:
    """Iterate the messages of ``channels`` chunk after chunk (see :func:`chunks_in_order`);
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
                tuple_new(RawMessage, (topics[conn.id], log_time, types[conn.id], raw))
                for log_time, _offset, conn, raw in source
            ]
            yield from batch
            self.count += len(batch)


def chunks_in_order(reader: Any, wanted: set[str]) -> _ChunksInOrder | None:
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
