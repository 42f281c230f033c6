"""A truncated MCAP file (a recording cut short: no summary, no footer) scanned from the start:
the messages of every complete chunk, then where the file ends.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

from .messages import MCAP_MAGIC, OP_CHANNEL, OP_CHUNK, OP_FOOTER, OP_MESSAGE, OP_SCHEMA, one_line

# --------------------------------------------------------------------------- salvage


class Truncated(Exception):
    """The MCAP records end before the file does (internal)."""


class _ChunkDamaged(Exception):
    """The records inside a chunk stop making sense (internal; args: what was kept)."""


def read_string(buf: bytes, pos: int) -> tuple[str, int]:
    (size,) = struct.unpack_from("<I", buf, pos)
    end = pos + 4 + size
    if end > len(buf):
        raise Truncated
    return buf[pos + 4 : end].decode("utf-8"), end


class Salvage:
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
                raise Truncated
            op = buf[pos]
            (size,) = struct.unpack_from("<Q", buf, pos + 1)
            end = pos + 9 + size
            if end > len(buf):
                raise Truncated
            yield op, buf[pos + 9 : end]
            pos = end

    def _record(self, op: int, body: bytes) -> Iterator[tuple[str, str, int, bytes]]:
        if op == OP_SCHEMA:
            (sid,) = struct.unpack_from("<H", body, 0)
            name, _ = read_string(body, 2)
            self.schemas[sid] = name
        elif op == OP_CHANNEL:
            cid, sid = struct.unpack_from("<HH", body, 0)
            topic, _ = read_string(body, 4)
            self.channels[cid] = (topic, self.schemas.get(sid, ""))
        elif op == OP_MESSAGE:
            cid, _seq, log_time, _pub = struct.unpack_from("<HIQQ", body, 0)
            if cid in self.channels:
                topic, msgtype = self.channels[cid]
                yield topic, msgtype, int(log_time), bytes(body[22:])
        elif op == OP_CHUNK:
            from rosbags.rosbag2.storage_mcap import decompress

            _start, _end, size, crc = struct.unpack_from("<QQQI", body, 0)
            compression, pos = read_string(body, 28)
            (length,) = struct.unpack_from("<Q", body, pos)
            data = body[pos + 8 : pos + 8 + length]
            inner = decompress(data, compression, size, crc)
            found: list[tuple[str, str, int, bytes]] = []
            damage: Exception | None = None
            try:
                for sub_op, sub_body in self._records(inner):
                    found.extend(self._record(sub_op, sub_body))
            except (Truncated, struct.error, UnicodeDecodeError) as err:
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
            compression, pos = read_string(body, 28)
        except (Truncated, struct.error, UnicodeDecodeError):
            return
        if compression:
            return
        found: list[tuple[str, str, int, bytes]] = []
        try:
            for sub_op, sub_body in self._records(body[pos + 8 :]):
                found.extend(self._record(sub_op, sub_body))
        except (Truncated, struct.error, UnicodeDecodeError):
            pass  # the record cut by the end of the file
        found.sort(key=lambda item: item[2])
        yield from found

    def messages(self) -> Iterator[tuple[str, str, int, bytes]]:
        count = 0
        offset = len(MCAP_MAGIC)
        try:
            with self.path.open("rb") as stream:
                if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                    self.problem = f"{self.path} is not an MCAP file (bad magic)"
                    return
                while True:
                    head = stream.read(9)
                    if not head:
                        raise Truncated
                    if len(head) < 9:
                        raise Truncated
                    op = head[0]
                    (size,) = struct.unpack_from("<Q", head, 1)
                    body = stream.read(size)
                    if len(body) != size:
                        if op == OP_CHUNK:  # cut inside a chunk: keep its complete records
                            for item in self._partial_chunk(body):
                                count += 1
                                yield item
                        raise Truncated
                    if op == OP_FOOTER:
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
        except Truncated:
            self.problem = (
                f"{self.path} is truncated (records end at byte {offset}); "
                f"read {count} messages before the cut"
            )
        except (struct.error, UnicodeDecodeError, ValueError, OSError) as err:
            self.problem = (
                f"{self.path} is corrupt at byte {offset} ({one_line(err)}); "
                f"read {count} messages before it"
            )
        except Exception as err:  # rosbags' ReaderError for a bad chunk, and the like
            self.problem = (
                f"{self.path} is corrupt at byte {offset} ({one_line(err)}); "
                f"read {count} messages before it"
            )


def mcap_files(path: Path) -> list[Path]:
    if path.is_dir():
        return sorted(path.glob("*.mcap"))
    return [path]
