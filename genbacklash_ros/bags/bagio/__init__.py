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

from .alignment import AlignedSeries, align, node_outputs, read_aligned
from .custom_data import read_custom_data
from .messages import (
    COMMAND_MSGTYPES,
    ENCODER_MSGTYPES,
    SUPPORTED_MSGTYPES,
    BagError,
    BagMessage,
    RawMessage,
    RawRecord,
    TopicInfo,
)
from .reader import BagReader
from .selection import check_motor, check_selection
from .writer import BagWriter

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
    "RawRecord",
    "TopicInfo",
    "align",
    "check_motor",
    "check_selection",
    "node_outputs",
    "read_aligned",
    "read_custom_data",
]
