"""What the bag reader and writer hand around: the message types read and their roles, a topic's
description, a message decoded or raw, and :class:`BagError` (a one-line reason).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.messages import (
    CommandType,
    DiagnosticArray,
    EncoderType,
    Float64,
    Float64MultiArray,
    JointState,
    Message,
)

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

MCAP_MAGIC = b"\x89MCAP0\r\n"
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_FOOTER = 0x03, 0x04, 0x05, 0x06, 0x02


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

tuple_new = tuple.__new__


def one_line(err: BaseException) -> str:
    text = " ".join(str(a) for a in err.args) if err.args else type(err).__name__
    return " ".join(text.split()) or type(err).__name__


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the close matches of ``name`` among ``known`` ('')."""
    known = list(known)
    folded = [k for k in known if k.casefold() == name.casefold() and k != name]
    close = folded or difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    if not close:
        return ""
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)"
