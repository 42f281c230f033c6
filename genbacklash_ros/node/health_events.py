"""What the stream health checks return to the pipeline: drops and notes, in order.

:class:`~genbacklash_ros.node.health.StreamHealth` and its spike screen
(:class:`~genbacklash_ros.node.spike_screen.SpikeScreen`) never call back into the pipeline:
each check returns the :data:`HealthEvent` s it found -- messages or samples to count as
dropped (:class:`Drop`), faults that started with a text (:class:`Note`) -- and the pipeline
routes them (drops to the ledger, notes as its latest problem).

>>> Drop("encoder_spike", "far from the prediction", 2).count
2
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

__all__ = ["Drop", "HealthEvent", "Note"]


@dataclass(frozen=True, slots=True)
class Drop:
    """``count`` samples (or messages) dropped for ``key`` (e.g. ``encoder_spike``), the
    latest ``reason`` in words."""

    key: str
    reason: str
    count: int


@dataclass(frozen=True, slots=True)
class Note:
    """A fault started (or went on) with ``text``: the pipeline's latest problem."""

    text: str


HealthEvent: TypeAlias = Drop | Note
"""What a :class:`StreamHealth` check found, in the order it found it."""
