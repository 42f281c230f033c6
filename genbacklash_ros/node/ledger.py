"""What the pipeline counts and what went wrong: the numbers and texts of ``/diagnostics``.

:class:`Ledger` holds the counters since construction (commands, encoder messages, samples
identified, compensated commands, checkpoints), the messages and samples dropped by reason,
those dropped since the last report with the latest reason of each, and the problems since
the last report. Every stage's drops end here (the pipeline routes them); a report takes the
per-report part and starts it afresh (:meth:`Ledger.take_period`).

Examples
--------
>>> ledger = Ledger()
>>> ledger.drop("encoder_invalid", "encoder: value nan is not finite")
>>> ledger.dropped["encoder_invalid"], ledger.last_problem
(1, 'encoder: value nan is not finite')
>>> ledger.take_period().drops
{'encoder_invalid': 1}
>>> ledger.take_period().drops
{}
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = [
    "DROP_KEYS",
    "ENCODER_REJECTS",
    "LIVE_ONLY_DROPS",
    "MOTOR_DROPS",
    "QUIET_DROPS",
    "SHOWN_WHEN_ANY",
    "Ledger",
    "Period",
]

DROP_KEYS = (
    "command_invalid",
    "command_duplicate",
    "command_out_of_order",
    "encoder_invalid",
    "encoder_duplicate",
    "encoder_out_of_order",
    "identifier_error",
    "before_first_command",
    "encoder_spike",
    "encoder_stuck",
    "encoder_after_gap",
    "identifier_behind",
    "motor_invalid",
    "motor_out_of_order",
    "motor_missing",
)
# expected at start, or reported as a fault of their own: counted, no WARN of their own
QUIET_DROPS = frozenset(
    {"before_first_command", "encoder_stuck", "encoder_after_gap", "motor_missing"}
)
ENCODER_REJECTS = frozenset({"encoder_invalid", "encoder_duplicate", "encoder_out_of_order"})
# only a live worker that fell behind drops these: listed in a report only when there were any
LIVE_ONLY_DROPS = frozenset({"identifier_behind"})
# only a node whose gear input is a motor encoder (gear_input) drops these: listed likewise
MOTOR_DROPS = frozenset({"motor_invalid", "motor_out_of_order", "motor_missing"})
SHOWN_WHEN_ANY = LIVE_ONLY_DROPS | MOTOR_DROPS


@dataclass
class Period:
    """What happened since the last report: drops by reason (with the latest reason of
    each) and the problems, in the order they first came."""

    drops: dict[str, int] = field(default_factory=dict)
    reasons: dict[str, str] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


class Ledger:
    """The pipeline's counters and problems (see the module notes)."""

    def __init__(self) -> None:
        self.dropped = dict.fromkeys(DROP_KEYS, 0)
        self.last_problem = ""
        self.commands = 0
        self.encoders = 0
        self.samples = 0
        self.compensated = 0
        self.checkpoints = 0
        self.checkpoint_errors = 0
        self.last_checkpoint_ns: int | None = None
        self._period = Period()

    def drop(self, key: str, reason: str, count: int = 1) -> None:
        """Count ``count`` dropped for ``key``; a loud key's ``reason`` is the latest problem."""
        self.dropped[key] += count
        period = self._period
        period.drops[key] = period.drops.get(key, 0) + count
        period.reasons[key] = reason
        if key not in QUIET_DROPS:
            self.last_problem = reason

    def note(self, text: str) -> None:
        """``text`` (a fault's reason) is the latest problem."""
        self.last_problem = text

    def problem(self, text: str) -> None:
        """A problem to report once (and the latest problem)."""
        problems = self._period.problems
        if text not in problems:
            problems.append(text)
        self.last_problem = text

    def take_period(self) -> Period:
        """What happened since the last report; starts the next period."""
        period, self._period = self._period, Period()
        return period
