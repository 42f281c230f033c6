"""What the pipeline's batch form knows of a block of messages before it runs any of them.

:meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.on_batch` takes a block of messages
(commands and encoder readings, values already read) and looks for *stretches* of them that
make nothing happen but bookkeeping. Whether a message makes something happen depends on
the pipeline's state only through its predecessor in the same stream (is it later, is the
value the same, how long since the previous reading) and through a few numbers of state
(the data clock, the next feed, the silence limit). :class:`BlockView` works out once per
block, in numpy steps, everything that depends on the messages alone -- each message's
time, the positions of the non-finite values, of the readings that are not later than the
one before, that follow a long gap, that change value, of the commands that are saturated
or late after a reading -- as sorted Python lists, so that finding where a stretch ends is
a few bisections against the current state, whatever the stretch's length.

Within a stretch every message is accepted, so a relation between two messages of the same
stretch is what the per-message path would see; the first message of each stream in a
stretch is checked against the pipeline's state instead (its predecessor may have been
dropped).

Examples
--------
>>> import numpy as np
>>> kinds = np.array([True, False, False, True, False])
>>> times = np.array([10, 11, 12, 20, 12], dtype=np.int64)
>>> view = BlockView(kinds, times, np.array([0.5, 1.0, 1.0, 0.5, 2.0]), times, False)
>>> view.enc_pos, view.cmd_pos, view.enc_disorder, view.enc_changed
([1, 2, 4], [0, 3], [2], [2])
"""

from __future__ import annotations

import numpy as np

from genbacklash_ros.node.health import SILENCE_MIN_NS, STUCK_NS

__all__ = ["BlockView"]


class BlockView:
    """The per-message facts of a block of messages (see the module notes).

    Parameters
    ----------
    kinds : numpy.ndarray of bool
        Per message: a command (else an encoder reading).
    heads, values, receive : numpy.ndarray
        Header stamps (int64, 0: none), values (float) and receive times (int64).
    use_header : bool
        A message's time is its header stamp when it has one.

    Attributes
    ----------
    times : numpy.ndarray of int64
        Each message's time.
    nonfinite : list of int
        Indices of the messages whose value is not finite.
    enc_pos, cmd_pos : list of int
        Indices of the encoder readings and of the commands (their *ordinals* index these).
    enc_before, cmd_before : list of int
        ``enc_before[k]``: readings before message ``k`` (``n + 1`` entries); likewise.
    enc_t, enc_y, enc_rx : list
        Time, value and receive time of each reading (by ordinal).
    enc_step : list of int
        ``enc_step[o - 1] = enc_t[o] - enc_t[o - 1]``.
    enc_disorder, enc_long, enc_changed : list of int
        Ordinals ``o >= 1`` of the readings not later than the one before, after a gap
        longer than ``SILENCE_MIN_NS``, of another value than the one before.
    enc_still : list of int
        Ordinals of readings equal to the one before, ``STUCK_NS`` or more after the last
        change of value within the block (candidates for the stuck-encoder check).
    cmd_t, cmd_u, cmd_rx : list
        Time, value and receive time of each command (by ordinal).
    cmd_disorder : list of int
        Ordinals ``o >= 1`` of the commands not later than the one before.
    cmd_prev_enc : list of int
        Per command, the ordinal of the last reading before it in the block (-1: none).
    cmd_late : list of int
        Ordinals of the commands received more than ``SILENCE_MIN_NS`` after that reading.
    cmd_gap : list of int
        Per command, its receive time minus that reading's (-1 without one).
    """

    __slots__ = (
        "_saturated",
        "cmd_before",
        "cmd_disorder",
        "cmd_gap",
        "cmd_late",
        "cmd_pos",
        "cmd_prev_enc",
        "cmd_rx",
        "cmd_t",
        "cmd_u",
        "enc_before",
        "enc_changed",
        "enc_disorder",
        "enc_long",
        "enc_pos",
        "enc_rx",
        "enc_step",
        "enc_still",
        "enc_t",
        "enc_y",
        "n",
        "nonfinite",
        "times",
        "values",
    )

    def __init__(
        self,
        kinds: np.ndarray,
        heads: np.ndarray,
        values: np.ndarray,
        receive: np.ndarray,
        use_header: bool,
    ) -> None:
        n = int(values.size)
        self.n = n
        times = np.where(heads != 0, heads, receive) if use_header else receive
        self.times = times
        self.values = values
        self.nonfinite: list[int] = np.flatnonzero(~np.isfinite(values)).tolist()
        enc = np.flatnonzero(~kinds)
        cmd = np.flatnonzero(kinds)
        self.enc_pos: list[int] = enc.tolist()
        self.cmd_pos: list[int] = cmd.tolist()
        enc_count = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(~kinds, out=enc_count[1:])
        self.enc_before: list[int] = enc_count.tolist()
        self.cmd_before: list[int] = (np.arange(n + 1) - enc_count).tolist()
        # the encoder stream
        et, ey, erx = times[enc], values[enc], receive[enc]
        self.enc_t: list[int] = et.tolist()
        self.enc_y: list[float] = ey.tolist()
        self.enc_rx: list[int] = erx.tolist()
        step = et[1:] - et[:-1]
        self.enc_step: list[int] = step.tolist()
        self.enc_disorder: list[int] = (np.flatnonzero(step <= 0) + 1).tolist()
        self.enc_long: list[int] = (np.flatnonzero(step > SILENCE_MIN_NS) + 1).tolist()
        same = ey[1:] == ey[:-1]
        self.enc_changed: list[int] = (np.flatnonzero(~same) + 1).tolist()
        ordinals = np.arange(1, et.size)
        changed_at = np.maximum.accumulate(np.where(same, 0, ordinals)) if et.size > 1 else ordinals
        still = same & (changed_at >= 1) & (et[1:] - et[changed_at] >= STUCK_NS)
        self.enc_still: list[int] = ordinals[still].tolist()
        # the command stream
        ct, cu, crx = times[cmd], values[cmd], receive[cmd]
        self.cmd_t: list[int] = ct.tolist()
        self.cmd_u: list[float] = cu.tolist()
        self.cmd_rx: list[int] = crx.tolist()
        self.cmd_disorder: list[int] = (np.flatnonzero(ct[1:] <= ct[:-1]) + 1).tolist()
        prev_enc = enc_count[cmd] - 1
        gap = np.where(prev_enc >= 0, crx - erx[np.maximum(prev_enc, 0)] if enc.size else 0, -1)
        self.cmd_prev_enc: list[int] = prev_enc.tolist()
        self.cmd_gap: list[int] = gap.tolist()
        self.cmd_late: list[int] = np.flatnonzero(gap > SILENCE_MIN_NS).tolist()
        self._saturated: tuple[float, float, list[int]] | None = None

    def saturated(self, u_min: float, u_max: float) -> list[int]:
        """Ordinals of the commands at or beyond the limits ``u_min``, ``u_max``."""
        known = self._saturated
        if known is not None and known[:2] == (u_min, u_max):
            return known[2]
        found: list[int] = []
        if np.isfinite(u_min) or np.isfinite(u_max):
            cu = self.values[np.asarray(self.cmd_pos, dtype=np.int64)]
            found = np.flatnonzero((cu >= u_max) | (cu <= u_min)).tolist()
        self._saturated = (u_min, u_max, found)
        return found
