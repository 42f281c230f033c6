"""One stream arrives, the other does not: the timing half of "what is wrong with the wiring".

When encoder messages arrive but no command has come for :data:`SILENT_STREAM_NS` (2 s), or
commands arrive but no encoder reading has, the node is most likely wired wrong: a topic
name that differs, a publisher of another type than the one the node subscribes, a driver
that is not running. :class:`SilentStreams` notices it and ``/diagnostics`` says which
stream is silent, for how long, how many messages of the other stream came meanwhile, and
which parameter selects the silent stream's type.

Which clock measures the 2 s? A silent stream has no stamps of its own, and the other
stream's header stamps may come from another clock (a drive's own time base) or be missing
(a Float64 command). Both streams share the *receive* clock: the transport's wall clock on a
live node (the DDS source timestamp, or when rclpy took the message), the bag's log time in
a replay. So the silence of one stream is measured at each message of the other, as that
message's receive time less the silent stream's last receive time (or, when it never came,
the receive time of the first message of the other stream). It is data time in a replay
(deterministic) and wall time live. When both streams are silent nothing is measured here:
the transports' wall-clock watchdog reports "no data" (STALE) then.

Only messages whose value could be read count as arrived: a stream of unreadable messages
is silent here, and its drops say why.

Examples
--------
>>> silence = SilentStreams()
>>> for k in range(2001):
...     silence.encoder(k * 1_000_000)
>>> report = silence.report("float64", "joint_state")
>>> report.level, report.values
(1, [('command_silent_s', '2.000')])
>>> print(report.parts[0][:72])
no command for 2.000 s while 2001 encoder messages arrived (command_type
>>> silence.command(2_001_000_000)
>>> silence.report("float64", "joint_state").parts
[]
"""

from __future__ import annotations

from typing import NamedTuple

from genbacklash_ros.node.messages import DiagnosticStatus

__all__ = ["SILENT_STREAM_NS", "SilenceReport", "SilentStreams"]

SILENT_STREAM_NS = 2_000_000_000  # a stream silent this long while the other arrives


class SilenceReport(NamedTuple):
    """What a report says about silent streams (empty when both arrive).

    Attributes
    ----------
    level : int
        WARN for silent commands (nothing to compensate), ERROR for a silent encoder (the
        commands are compensated blind); OK when neither is silent.
    parts : list of str
        The sentences for the report's message.
    values : list of (str, str)
        ``command_silent_s`` or ``encoder_silent_s``: how long, in seconds of the receive
        clock (only while silent).
    """

    level: int
    parts: list[str]
    values: list[tuple[str, str]]


class _Stream:
    """The receive times of one stream and the count of the other's messages since."""

    __slots__ = ("last", "others", "since")

    def __init__(self) -> None:
        self.last: int | None = None  # receive time of the last message
        self.since: int | None = None  # the other stream's first receive time since then
        self.others = 0  # the other stream's messages since

    def arrived(self, receive_ns: int) -> None:
        self.last = receive_ns
        self.since = None
        self.others = 0

    def other_arrived(self, receive_ns: int) -> None:
        if self.since is None:
            self.since = receive_ns if self.last is None else self.last
        self.others += 1

    def silent_ns(self, other_last: int | None) -> int:
        if self.since is None or other_last is None:
            return 0
        return other_last - self.since


class SilentStreams:
    """Watches whether one stream is silent while the other arrives (see the module notes)."""

    __slots__ = ("_command", "_encoder")

    def __init__(self) -> None:
        self._command = _Stream()
        self._encoder = _Stream()

    def command(self, receive_ns: int) -> None:
        """A command whose value was read, received at ``receive_ns``."""
        self._command.arrived(receive_ns)
        self._encoder.other_arrived(receive_ns)

    def encoder(self, receive_ns: int) -> None:
        """An encoder reading whose value was read, received at ``receive_ns``."""
        self._encoder.arrived(receive_ns)
        self._command.other_arrived(receive_ns)

    def arrived_many(
        self, command: tuple[int, int, int] | None, encoder: tuple[int, int, int] | None
    ) -> None:
        """Messages of both streams whose values were read, in one step: the same as
        :meth:`command` and :meth:`encoder` for each in turn. Per stream, ``(receive time of
        its last message, messages of the other stream after it, receive time of the first
        of those)``; for a stream without messages, ``(-1, messages of the other stream,
        receive time of the first)`` -- None when the stream had none and neither had the
        other after it."""
        for own, seen in ((self._command, command), (self._encoder, encoder)):
            if seen is None:
                continue
            last, others, first_other = seen
            if last >= 0:
                own.arrived(last)
            if others:
                if own.since is None:
                    own.since = first_other if own.last is None else own.last
                own.others += others

    def report(self, command_type: str, encoder_type: str) -> SilenceReport:
        """The silent streams now (``command_type``, ``encoder_type``: the parameters'
        values, named in the advice)."""
        level = DiagnosticStatus.OK
        parts: list[str] = []
        values: list[tuple[str, str]] = []
        for name, stream, other, kind, other_name, silent_level in (
            (
                "command",
                self._command,
                self._encoder,
                command_type,
                "encoder",
                DiagnosticStatus.WARN,
            ),
            (
                "encoder",
                self._encoder,
                self._command,
                encoder_type,
                "command",
                DiagnosticStatus.ERROR,
            ),
        ):
            silent = stream.silent_ns(other.last)
            if silent < SILENT_STREAM_NS:
                continue
            level = max(level, silent_level)
            seconds = f"{silent / 1e9:.3f}"
            parts.append(
                f"no {name} for {seconds} s while {stream.others} {other_name} messages "
                f"arrived ({name}_type = {kind}: is there a publisher of that type on the "
                f"{name} topic?)"
            )
            values.append((f"{name}_silent_s", seconds))
        return SilenceReport(level, parts, values)
