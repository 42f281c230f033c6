"""A simulated record fed to the node's pipeline as a node would receive it
(:func:`feed_record`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from genbacklash_core.scenarios import (
    OperationRecord,
)
from genbacklash_ros.node.pipeline import BacklashPipeline


class FedRecord(NamedTuple):
    """What :func:`feed_record` saw: the compensated value sent per command (the command
    itself where the pipeline dropped it), which commands were accepted, and the data time
    (s after the first command) of the first published estimate (None: none)."""

    sent: np.ndarray
    accepted: np.ndarray
    first_estimate_s: float | None


def feed_record(pipe: BacklashPipeline, rec: OperationRecord, delay_ns: int = 200_000) -> FedRecord:
    """Feed a simulated record to ``pipe`` message by message, in the order a node receives
    them: each command at its time, each reading ``delay_ns`` after its stamp (a reading and
    a command at the same time: the command first). The caller calls ``pipe.finish()``."""
    cmd_t, cmd_u = rec.command_t_ns, rec.command_u
    enc_t, enc_y = rec.encoder_t_ns, rec.encoder_y
    events = np.concatenate([cmd_t, enc_t + delay_ns])
    kinds = np.concatenate([np.zeros(cmd_t.size, dtype=int), np.ones(enc_t.size, dtype=int)])
    index = np.concatenate([np.arange(cmd_t.size), np.arange(enc_t.size)])
    sent = cmd_u.astype(np.float64, copy=True)
    accepted = np.zeros(cmd_t.size, dtype=bool)
    first: float | None = None
    for j in np.lexsort((kinds, events)).tolist():
        i = int(index[j])
        if kinds[j] == 0:
            result = pipe.on_command_value(None, float(cmd_u[i]), int(cmd_t[i]))
            if result is None:
                continue
            accepted[i] = True
            _, sent[i], outputs = result
        else:
            outputs = pipe.on_encoder_value(int(enc_t[i]), float(enc_y[i]), int(events[j]))
        if first is None and any(o.topic == "estimate" for o in outputs):
            first = (int(events[j]) - int(cmd_t[0])) / 1e9
    return FedRecord(sent, accepted, first)
