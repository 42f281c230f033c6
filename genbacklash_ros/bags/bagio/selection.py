"""Whether a command/encoder selection (topics, joint, command index, motor encoder) matches
what the bag holds, checked on its first messages before anything is written.
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Sequence
from pathlib import Path

from genbacklash_ros.bags.rosbags_types import from_rosbags, jazzy_typestore
from genbacklash_ros.node.messages import (
    Float64MultiArray,
    JointState,
    Message,
)

from .messages import COMMAND_MSGTYPES, ENCODER_MSGTYPES, BagError, TopicInfo, did_you_mean
from .reader import BagReader

# --------------------------------------------------------------------------- selection

_PEEK_MESSAGES = 2048  # messages looked at, at most, to learn what a selection can match
_PEEK_EACH = 64  # per topic: enough to see every joint name and array length a topic uses


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
            f"{did_you_mean(joint, names)}; it holds: {listed}"
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
                f"{reader.path}{did_you_mean(joint, names)}; it holds: {listed} (choose with "
                "--motor-joint NAME)"
            )
        if names and not joint and len(names) > 1:
            raise BagError(
                f"the motor encoder JointState on {motor_topic} in {reader.path} holds "
                f"{len(names)} joints ({listed}): say which with --motor-joint NAME"
            )
    return info
