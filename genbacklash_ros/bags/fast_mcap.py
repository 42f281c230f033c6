"""A compiled MCAP storage for rosbags' rosbag2 writer (foxglove-sdk's Rust MCAP writer).

rosbags' :class:`rosbags.rosbag2.Writer` writes ``metadata.yaml`` and hands the messages to a
*storage plugin*; its own MCAP plugin assembles every record in Python. :class:`FoxgloveMcap`
implements the same storage protocol (``add_msgtype``, ``add_connection``, ``write``,
``close``, ``abort``) on foxglove-sdk's MCAP writer (``foxglove.open_mcap``: compiled, about
five times faster here, see BENCHMARKS.md "Replay throughput"), so that the bag directory,
its ``metadata.yaml`` and the MCAP file's contents are what rosbags writes:

* the header profile ``ros2``; one schema per message type (``ros2msg``, the definition
  rosbags generates from its Jazzy typestore), one channel per topic (message encoding
  ``cdr``, channel metadata ``offered_qos_profiles``);
* messages with log time = publish time; chunks of 1 MiB, uncompressed, without CRCs
  (like rosbags' default);
* the rosbag2 metadata record (``rosbag2`` / ``serialized_metadata``) that ``ros2 bag`` and
  :attr:`~genbacklash_ros.bags.bagio.BagReader.custom_data` read from a bare ``.mcap``;
* the summary section (statistics, chunk and message indexes) that rosbags,
  mcap-ros2-support and Foxglove use to seek.

:data:`AVAILABLE` is False when foxglove-sdk is not installed (it ships wheels for the usual
platforms only); :class:`~genbacklash_ros.bags.bagio.BagWriter` then falls back to rosbags'
own pure-Python MCAP writer.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2 import StoragePlugin, Writer

try:
    import foxglove
    from foxglove.mcap import MCAPWriteOptions
except ImportError:  # pragma: no cover - foxglove-sdk has wheels for the CI platforms
    AVAILABLE = False
else:
    AVAILABLE = True

__all__ = ["AVAILABLE", "FoxgloveMcap", "FoxgloveWriter"]

_CHUNK_BYTES = 1 << 20  # rosbags closes its chunks at 1 MiB too


class FoxgloveMcap:
    """rosbags' storage-writer protocol on foxglove-sdk's MCAP writer (see the module notes).

    Parameters
    ----------
    path : Path
        The bag directory (rosbags creates it); the file is ``<path>/<name>.mcap``.
    compression : object
        rosbags' compression mode; only none is supported (rosbags' MCAP default).
    """

    def __init__(self, path: Path, compression: object) -> None:
        _ = compression
        self.path = path / f"{path.name}.mcap"
        self._context = foxglove.Context()  # our own channels only, not the global ones
        # no chunk CRCs, as rosbags writes them (0): a reader then salvages a damaged chunk
        # message by message up to the damage instead of losing it whole
        options = MCAPWriteOptions(
            compression=None,
            profile="ros2",
            chunk_size=_CHUNK_BYTES,
            calculate_chunk_crcs=False,
        )
        self._writer = foxglove.open_mcap(self.path, context=self._context, writer_options=options)
        self._schemas: dict[str, Any] = {}
        self._channels: dict[int, Any] = {}  # rosbags connection id -> channel (compiled)

    def add_msgtype(self, connection: Any) -> None:
        """Register the schema of ``connection.msgtype`` (its ROS 2 message definition)."""
        msgdef = connection.msgdef
        encoding = "ros2msg" if msgdef.format == MessageDefinitionFormat.MSG else "ros2idl"
        self._schemas[connection.msgtype] = foxglove.Schema(
            name=connection.msgtype, encoding=encoding, data=msgdef.data.encode()
        )

    def add_connection(self, connection: Any, offered_qos_profiles: str) -> None:
        """Register the channel of ``connection`` (one per topic)."""
        channel = foxglove.Channel(
            connection.topic,
            schema=self._schemas[connection.msgtype],
            message_encoding=connection.ext.serialization_format,
            context=self._context,
            metadata={"offered_qos_profiles": offered_qos_profiles},
        )
        self._channels[connection.id] = channel.base

    def channel_log(self, connection: Any) -> Any:
        """The compiled channel's own ``log(data: bytes, log_time: int, sink_id: None)`` for
        ``connection`` (what :meth:`write` calls), for writers of many messages."""
        return self._channels[connection.id].log

    def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
        """Write one message's bytes at log time ``timestamp`` (ns)."""
        self._channels[connection.id].log(bytes(data), timestamp, None)

    def close(self, version: int, metadata: str) -> None:
        """Write the rosbag2 metadata record and finish the file (summary, footer)."""
        _ = version
        self._writer.write_metadata("rosbag2", {"serialized_metadata": metadata})
        self._writer.close()

    def abort(self) -> None:
        """Finish the file after an error."""
        self._writer.close()


class FoxgloveWriter(Writer):
    """rosbags' rosbag2 :class:`~rosbags.rosbag2.Writer` with :class:`FoxgloveMcap` as its
    MCAP storage (use ``storage_plugin=StoragePlugin.MCAP``)."""

    STORAGE_PLUGINS = {StoragePlugin.MCAP: FoxgloveMcap}  # noqa: RUF012
