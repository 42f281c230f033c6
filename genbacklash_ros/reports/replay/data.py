"""What the replay report's plots and tables share: the replay's history sorted, in seconds
from one origin, with the bag's truth parsed and the zoomed window chosen.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from genbacklash_core import Cascade, GeneralBacklash
from genbacklash_core.cascade import backlash_of as core_backlash_of
from genbacklash_core.guard import GuardSettings
from genbacklash_ros.bags.bagio import align
from genbacklash_ros.bags.replay import ReplayResult
from genbacklash_ros.bags.simbags import BagTruth, read_truth

if TYPE_CHECKING:
    from .coverage import Coverage
    from .tracking import TrackingErrors


DPI = 110
BINS = 900  # pixel columns of a full-record plot (envelopes)
DENSE_BINS = 150  # columns when the command reverses in most of them: a clean band
_MAX_REVERSALS = 30  # at most this many command reversals in the zoomed window
_WINDOWS = (4.0, 2.0, 1.0, 0.5, 0.25, 0.1)  # zoom lengths tried, seconds
COLORS = {
    "command": "0.35",
    "load": "C0",
    "none": "C3",
    "node": "C0",
    "final": "C2",
    "measured": "0.55",
    "left": "C0",
    "right": "C1",
    "truth": "k",
}


_DEFAULT_GUARD = GuardSettings()  # a ReportData built by hand: the node's defaults


def backlash_of(model: GeneralBacklash | Cascade | None) -> GeneralBacklash | None:
    """:func:`genbacklash_core.cascade.backlash_of`, None for no model."""
    return None if model is None else core_backlash_of(model)


# --------------------------------------------------------------------------- data


@dataclass(frozen=True, eq=False)
class ReportData:
    """What the plots share: times in seconds from one origin (the record's start).

    Attributes
    ----------
    t0_ns : int
        The origin: the truth's start for a synthetic bag, else the first message.
    truth : BagTruth or None
    cmd_t, cmd_raw, cmd_sent : ndarray
        Accepted commands in time order: time (s), recorded value, compensated value.
    enc_t, enc_y : ndarray
        Encoder readings in time order.
    t, u, y : ndarray
        Aligned samples (one per reading, the command held).
    model : GeneralBacklash or None
        The final estimate's backlash.
    window : (float, float)
        The zoomed window, seconds.
    end : float
        The end of the record, seconds.
    guard : GuardSettings
        The replay's guard settings: their thresholds judge whether the plant the
        predictions simulate describes the readings (:mod:`~.plant_check`).
    """

    t0_ns: int
    truth: BagTruth | None
    cmd_t: np.ndarray
    cmd_raw: np.ndarray
    cmd_sent: np.ndarray
    enc_t: np.ndarray
    enc_y: np.ndarray
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    model: GeneralBacklash | None
    window: tuple[float, float]
    end: float
    guard: GuardSettings = _DEFAULT_GUARD

    @property
    def truth_end(self) -> GeneralBacklash | None:
        """The true backlash at the end of the record (None without truth)."""
        return backlash_of(self.truth.model_end) if self.truth is not None else None

    @functools.cached_property
    def tracking(self) -> TrackingErrors | None:
        """The predicted tracking errors (:func:`tracking_errors`), computed once."""
        from .tracking import compute_tracking_errors  # it reads this class

        return compute_tracking_errors(self)

    @functools.cached_property
    def coverage(self) -> Coverage | None:
        """The branch coverage (:func:`branch_coverage`), computed once."""
        from .coverage import branch_coverage  # it reads this class

        return branch_coverage(self, self.truth_end)


def reversals(values: np.ndarray) -> np.ndarray:
    """Indices where the direction of a sequence flips (constant stretches skipped)."""
    steps = np.diff(values)
    moving = np.flatnonzero(steps != 0)
    if moving.size < 2:
        return np.zeros(0, dtype=np.int64)
    signs = np.sign(steps[moving])
    flips: np.ndarray = moving[1:][signs[1:] != signs[:-1]]
    return flips


def _zoom_window(cmd_t: np.ndarray, cmd_u: np.ndarray, end: float) -> tuple[float, float]:
    """A window to look at closely: the longest of :data:`_WINDOWS` with at most
    :data:`_MAX_REVERSALS` command reversals, where the commands reverse most (reversals
    show the play), preferably in the second half of the record (the estimate has had
    time)."""
    if cmd_t.size < 2 or end <= 0:
        return 0.0, max(end, 1e-3)
    flips = cmd_t[reversals(cmd_u) + 1] if cmd_u.size > 2 else np.zeros(0)
    for length in _WINDOWS:
        if length >= end:
            continue
        starts = np.arange(0.0, end - length + 1e-9, length / 4)
        counts = np.searchsorted(flips, starts + length) - np.searchsorted(flips, starts)
        ok = counts <= _MAX_REVERSALS
        if not np.any(ok):
            continue
        late = ok & (starts >= 0.5 * end - length)
        pool = late if np.any(late) and counts[late].max() > 0 else ok
        best = np.flatnonzero(pool & (counts == counts[pool].max()))[-1]
        return float(starts[best]), float(starts[best] + length)
    length = min(_WINDOWS[-1], end)
    return end - length, end


def report_data(result: ReplayResult) -> ReportData:
    """Gather what the plots need from a replay (sorted, in seconds, the truth parsed)."""
    hist = result.history
    truth = read_truth(result.custom_data)
    cmd_t_ns = np.asarray(hist.command_t, dtype=np.int64)
    order = np.argsort(cmd_t_ns, kind="stable")
    cmd_t_ns = cmd_t_ns[order]
    cmd_raw = np.asarray(hist.command_raw, dtype=np.float64)[order]
    cmd_sent = np.asarray(hist.command_sent, dtype=np.float64)[order]
    enc_t_ns = np.asarray(hist.encoder_t, dtype=np.int64)
    enc_order = np.argsort(enc_t_ns, kind="stable")
    enc_t_ns = enc_t_ns[enc_order]
    enc_y = np.asarray(hist.encoder_y, dtype=np.float64)[enc_order]
    firsts = [int(a[0]) for a in (cmd_t_ns, enc_t_ns) if a.size]
    if truth is not None:
        t0 = truth.start_ns
    elif firsts:
        t0 = min(firsts)
    elif hist.estimate_t:
        t0 = int(hist.estimate_t[0])
    else:
        t0 = 0
    if cmd_t_ns.size and enc_t_ns.size:
        series = align(cmd_t_ns, cmd_raw, enc_t_ns, enc_y)
        t_ns, u, y = series.t, series.u, series.y
    else:
        t_ns, u, y = np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    lasts = [int(a[-1]) for a in (cmd_t_ns, enc_t_ns) if a.size]
    end = (max(lasts) - t0) / 1e9 if lasts else 0.0
    cmd_t = (cmd_t_ns - t0) / 1e9
    return ReportData(
        t0_ns=t0,
        truth=truth,
        cmd_t=cmd_t,
        cmd_raw=cmd_raw,
        cmd_sent=cmd_sent,
        enc_t=(enc_t_ns - t0) / 1e9,
        enc_y=enc_y,
        t=(t_ns - t0) / 1e9,
        u=u,
        y=y,
        model=backlash_of(result.estimate.model),
        window=_zoom_window(cmd_t, cmd_raw, end),
        end=end,
        guard=result.params.guard_settings(),
    )


def seconds_from(t: list[int] | np.ndarray, origin: int) -> np.ndarray:
    return (np.asarray(t, dtype=np.int64) - origin) / 1e9
