"""What the transports' answer-first tests share: a pipeline whose building of diagnostics
reports is recorded beside what the node publishes, and the order both transports keep."""

from __future__ import annotations

from collections.abc import Callable

from genbacklash_ros.node.multijoint import MultiJointPipeline
from genbacklash_ros.node.pipeline import BacklashPipeline, Output

# two commands, the second 1.2 s of data time after the first: a report comes due at it
ANSWER_FIRST = [
    ("published", "compensated_command"),
    ("published", "compensated_command"),
    ("built", "diagnostics"),
    ("published", "diagnostics"),
]


def recorded(
    pipe: BacklashPipeline | MultiJointPipeline,
) -> tuple[list[tuple[str, str]], Callable[[list[Output]], None]]:
    """``(events, publish)``: ``pipe`` records in ``events`` each report it builds, and
    ``publish``, put in place of a node's own, each output the node publishes."""
    assert isinstance(pipe, BacklashPipeline)
    events: list[tuple[str, str]] = []
    build = pipe.diagnostics

    def diagnostics(stamp_ns: int, *, stale: bool = False) -> Output:
        events.append(("built", "diagnostics"))
        return build(stamp_ns, stale=stale)

    def publish(outputs: list[Output]) -> None:
        events.extend(("published", o.topic) for o in outputs)

    pipe.diagnostics = diagnostics  # type: ignore[method-assign]
    return events, publish
