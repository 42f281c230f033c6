"""What the node's pipeline returns: the messages to publish, its counters, a batch's results.

:class:`~genbacklash_ros.node.pipeline.BacklashPipeline` returns :class:`Output` events (a
transport or the replay only converts and publishes them), :class:`PipelineStats` snapshots,
and for its batch form (:meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.on_batch`)
:class:`BatchOutputs`, filled in as the batch goes by a :class:`BatchCollector`. Plain data:
no stage, no transport.

Examples
--------
>>> from genbacklash_ros.node.messages import Float64
>>> Output("compensated_command", Float64(0.5), 1_000_000).joint
''
>>> collector = BatchCollector(3)
>>> collector.commands([0, 2], [10, 30], [0.5, 0.7])
>>> done = collector.done()
>>> done.accepted.tolist(), done.stamps.tolist()
([True, False, True], [10, 0, 30])
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, TypeAlias

import numpy as np

from genbacklash_core import Estimate
from genbacklash_ros.node.messages import CommandMessage, DiagnosticArray, Float64MultiArray

__all__ = ["BatchCollector", "BatchOutputs", "Output", "PipelineStats", "TopicKey"]

TopicKey: TypeAlias = Literal["compensated_command", "estimate", "diagnostics"]


@dataclass(frozen=True, slots=True)
class Output:
    """One message to publish.

    Attributes
    ----------
    topic : {"compensated_command", "estimate", "diagnostics"}
        Which publisher (GUIDE §4: ``compensated_command``, ``~/estimate``, ``/diagnostics``).
    message : Float64, Float64MultiArray, JointState or DiagnosticArray
    stamp_ns : int
        Data time of the message (a compensated command: its command's time), e.g. the log
        time when writing a bag.
    estimate : Estimate or None
        The estimate behind an ``estimate`` or ``diagnostics`` output (with its covariance,
        for reports); None for commands.
    joint : str
        With several joints in one node (:mod:`~genbacklash_ros.node.multijoint`): the joint
        an ``estimate`` or ``diagnostics`` output is about (an estimate goes to
        ``~/<joint>/estimate``); "" for a single joint's outputs and for the compensated
        command.
    """

    topic: TopicKey
    message: CommandMessage | Float64MultiArray | DiagnosticArray
    stamp_ns: int
    estimate: Estimate | None = None
    joint: str = ""


@dataclass(frozen=True)
class PipelineStats:
    """Counters since construction (a snapshot).

    ``dropped`` maps each reason key (``command_invalid``, ``command_duplicate``,
    ``command_out_of_order``, the same for ``encoder_``, ``identifier_error``,
    ``before_first_command``, ``encoder_spike``, ``encoder_stuck``, ``encoder_after_gap``,
    ``identifier_behind``) to a count; ``last_problem`` is the latest reason text.
    """

    commands: int
    encoder_messages: int
    samples: int
    compensated: int
    checkpoints: int
    checkpoint_errors: int
    dropped: MappingProxyType[str, int]
    last_problem: str


@dataclass(frozen=True, slots=True)
class BatchOutputs:
    """What :meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.on_batch` made of a batch of
    messages.

    Attributes
    ----------
    accepted : numpy.ndarray of bool
        Per message: a command the pipeline accepted (it has a compensated command).
    stamps : numpy.ndarray of int64
        Per message: an accepted command's time (0 for the others).
    sent : numpy.ndarray of float
        Per message: an accepted command's compensated value (NaN for the others).
    outputs : list of (int, Output)
        The periodic outputs (estimates, diagnostics), each with the index of the message
        that made it due, in order; compensated commands are in ``sent`` instead.
    """

    accepted: np.ndarray
    stamps: np.ndarray
    sent: np.ndarray
    outputs: list[tuple[int, Output]]


class BatchCollector:
    """What :meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.on_batch` fills in as it
    goes: the per-message arrays of :class:`BatchOutputs` and its periodic outputs.

    Parameters
    ----------
    n : int
        Messages in the batch.
    """

    __slots__ = ("_sent", "_stamps", "_where", "accepted", "outputs", "sent", "stamps")

    def __init__(self, n: int) -> None:
        self.accepted = np.zeros(n, dtype=bool)
        self.stamps = np.zeros(n, dtype=np.int64)
        self.sent = np.full(n, math.nan)
        self.outputs: list[tuple[int, Output]] = []
        # the stretches' accepted commands, put in the arrays once at the end
        self._where: list[int] = []
        self._stamps: list[int] = []
        self._sent: list[float] = []

    def commands(self, where: list[int], stamps: list[int], sent: list[float]) -> None:
        """Accepted commands at the messages ``where``: their times and compensated values."""
        self._where += where
        self._stamps += stamps
        self._sent += sent

    def done(self) -> BatchOutputs:
        """The batch's outputs."""
        if self._where:
            where = np.array(self._where, dtype=np.intp)
            self.accepted[where] = True
            self.stamps[where] = self._stamps
            self.sent[where] = self._sent
        return BatchOutputs(self.accepted, self.stamps, self.sent, self.outputs)
