"""The HTML report of a replay: PNG plots (matplotlib, Agg) and an ``index.html``.

What a drivetrain engineer looks at, from the :class:`~genbacklash_ros.bags.replay.ReplayResult`
(its history of estimates, commands and encoder readings) and, for a synthetic bag, the truth
its metadata carries (:func:`genbacklash_ros.bags.simbags.read_truth`). :func:`write_report`
writes into a directory

* ``motion.png``: the load position (encoder) against the command over the whole record --
  per pixel column the band between the smallest and largest value, so that commands that
  change every sample stay readable -- and a zoomed window (a few seconds with reversals,
  late in the record) where every command and reading is drawn;
* ``tracking_error.png``: the predicted load tracking error (load minus the command, taken as
  the desired load position) without compensation, with the compensation the node sent
  (running estimate, gated by confidence) and with the final estimate's inverse, as an RMS
  over time and in the zoomed window. The plant is the true drivetrain when the bag holds
  it, else the final estimate (then the numbers are the model's own prediction); the
  measured error (encoder minus command) is drawn as a check;
* ``play.png``: the play ``c_L + c_R`` and each dead zone over data time with +/-2 sigma
  from the published estimates' covariance, and the truth when the bag has it;
* ``coverage.png``: which part of the command range each branch was engaged over (time spent
  on each branch per command bin, classified with the final estimate), and the branches
  around the 1:1 line with the engaged parts drawn bold: what the data taught;
* ``characteristic.png``: the final estimate's branches with the aligned samples, as
  position and as the play around the 1:1 line (truth dashed);
* ``convergence.png``: every parameter over data time with a +/-2 sigma band (truth dashed);
* ``residuals.png``: encoder minus the final model's free-run simulation, and its histogram;
* ``compensation.png``: raw and compensated command in the zoomed window;
* ``index.html``: the tracking-error numbers, the final parameters (with the truth), the
  branch coverage, the replay's counters and the plots with captions.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from genbacklash_core import (
    Cascade,
    CompensatorState,
    GenBacklashError,
    GeneralBacklash,
    compensate,
    simulate_backlash,
)
from genbacklash_core.guard import GuardSettings
from genbacklash_core.scenarios import simulate_worn
from genbacklash_ros.bags.bagio import align
from genbacklash_ros.bags.replay import ReplayResult
from genbacklash_ros.bags.simbags import BagTruth, read_truth
from genbacklash_ros.reports.page import DASH, Section, Table, write_page
from genbacklash_ros.reports.page import Figure as PageFigure
from genbacklash_ros.reports.plant_check import PlantCheck, check_plant
from genbacklash_ros.reports.plots import parameter_unit

__all__ = [
    "ReportData",
    "TrackingErrors",
    "plot_characteristic_report",
    "plot_compensation",
    "plot_convergence",
    "plot_coverage",
    "plot_gap",
    "plot_motion",
    "plot_residuals",
    "plot_tracking_error",
    "report_data",
    "tracking_errors",
    "write_report",
]

_DPI = 110
_BINS = 900  # pixel columns of a full-record plot (envelopes)
_DENSE_BINS = 150  # columns when the command reverses in most of them: a clean band
_MAX_REVERSALS = 30  # at most this many command reversals in the zoomed window
_WINDOWS = (4.0, 2.0, 1.0, 0.5, 0.25, 0.1)  # zoom lengths tried, seconds
_COLORS = {
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


def _backlash(model: GeneralBacklash | Cascade | None) -> GeneralBacklash | None:
    return model.backlash if isinstance(model, Cascade) else model


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
        return _backlash(self.truth.model_end) if self.truth is not None else None

    @functools.cached_property
    def tracking(self) -> TrackingErrors | None:
        """The predicted tracking errors (:func:`tracking_errors`), computed once."""
        return _tracking_errors(self)

    @functools.cached_property
    def coverage(self) -> Coverage | None:
        """The branch coverage (:func:`branch_coverage`), computed once."""
        return branch_coverage(self, self.truth_end)


def _reversals(values: np.ndarray) -> np.ndarray:
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
    flips = cmd_t[_reversals(cmd_u) + 1] if cmd_u.size > 2 else np.zeros(0)
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
        model=_backlash(result.estimate.model),
        window=_zoom_window(cmd_t, cmd_raw, end),
        end=end,
        guard=result.params.guard_settings(),
    )


def _seconds(t: list[int] | np.ndarray, origin: int) -> np.ndarray:
    return (np.asarray(t, dtype=np.int64) - origin) / 1e9


def _envelope(
    t: np.ndarray, v: np.ndarray, span: tuple[float, float], *, hold: bool, bins: int = _BINS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per time bin the smallest and largest value: ``(centres, low, high)``. ``hold``: the
    values are held between samples (commands), so a bin also holds the value entering it;
    otherwise empty bins are NaN (a gap)."""
    edges = np.linspace(span[0], span[1], bins + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    low = np.full(bins, np.inf)
    high = np.full(bins, -np.inf)
    if t.size:
        idx = np.searchsorted(edges, t, side="right") - 1
        inside = (idx >= 0) & (idx < bins)
        np.minimum.at(low, idx[inside], v[inside])
        np.maximum.at(high, idx[inside], v[inside])
        if hold:
            k = np.searchsorted(t, edges[:-1], side="right") - 1
            held = np.where(k >= 0, v[np.maximum(k, 0)], np.nan)
            has = k >= 0
            low[has] = np.minimum(low[has], held[has])
            high[has] = np.maximum(high[has], held[has])
    empty = ~np.isfinite(low)
    low[empty] = np.nan
    high[empty] = np.nan
    return centres, low, high


def _band(
    ax: Axes,
    t: np.ndarray,
    v: np.ndarray,
    span: tuple[float, float],
    *,
    hold: bool,
    color: str,
    label: str,
    alpha: float = 0.3,
    bins: int = _BINS,
) -> None:
    c, lo, hi = _envelope(t, v, span, hold=hold, bins=bins)
    ax.fill_between(c, lo, hi, step="mid", color=color, alpha=alpha, lw=0)
    ax.plot(c, lo, color=color, lw=0.8, drawstyle="steps-mid", label=label)
    ax.plot(c, hi, color=color, lw=0.8, drawstyle="steps-mid")


def _headroom(ax: Axes, share: float = 0.2) -> None:
    """Room above the data for a legend."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + share * (hi - lo))


def _mark_phases(ax: Axes, truth: BagTruth | None, *, label: bool = True) -> None:
    """Vertical lines at the starts of a chained scenario's phases, named at the top."""
    if truth is None or len(truth.phases) < 2:
        return
    for kind, start in truth.phases:
        ax.axvline(start, color="0.3", lw=0.8, ls="-.")
        if label:
            ax.text(
                start,
                1.0,
                f" {kind}",
                transform=ax.get_xaxis_transform(),
                va="top",
                ha="left",
                fontsize="small",
                color="0.3",
            )


def _finish_zoom(
    fig: Figure, top: Axes, bottom: Axes, window: tuple[float, float], ylabel: str
) -> None:
    """Label the zoomed lower panel of a two-panel time plot, grid both, lay out."""
    lo, hi = window
    bottom.set_xlim(lo, hi)
    bottom.set_title(f"Zoom: {lo:.2f} - {hi:.2f} s", fontsize="medium")
    bottom.set_xlabel("time [s]")
    bottom.set_ylabel(ylabel)
    bottom.legend(loc="best", fontsize="small")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()


def _no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


# --------------------------------------------------------------------------- motion


def plot_motion(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Load position (encoder) against the command: whole record (min/max band per pixel
    column) and the zoomed window (every command and reading)."""
    d = report_data(result) if data is None else data
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 7.2))
    span = (0.0, max(d.end, 1e-3))
    # commands that reverse in most pixel columns (random input) read best as a solid band
    bins = _DENSE_BINS if _reversals(d.cmd_raw).size > _BINS else _BINS
    if d.cmd_t.size:
        _band(
            top,
            d.cmd_t,
            d.cmd_raw,
            span,
            hold=True,
            color=_COLORS["command"],
            label="command (desired load position)",
            alpha=0.2,
            bins=bins,
        )
    if d.enc_t.size:
        _band(
            top,
            d.enc_t,
            d.enc_y,
            span,
            hold=False,
            color=_COLORS["load"],
            label="load position (encoder)",
            bins=bins,
        )
    if not (d.cmd_t.size or d.enc_t.size):
        _no_data(top, "no command nor encoder reading")
    lo, hi = d.window
    top.axvspan(lo, hi, color="C1", alpha=0.15, lw=0, label="zoomed below")
    _mark_phases(top, d.truth)
    top.set_xlim(*span)
    _headroom(top)
    top.set_title(
        "Load position against command, whole record (band: smallest to largest value in "
        "each pixel column)",
        fontsize="medium",
    )
    top.set_xlabel("time [s]")
    top.set_ylabel("position [rad]")
    top.legend(loc="upper right", fontsize="small", ncol=3)
    # zoom
    c_in = (d.cmd_t >= lo) & (d.cmd_t <= hi)
    e_in = (d.enc_t >= lo) & (d.enc_t <= hi)
    if np.any(c_in):
        k = np.flatnonzero(c_in)
        k = np.concatenate(([k[0] - 1], k)) if k[0] > 0 else k  # the command held into it
        tc = np.clip(d.cmd_t[k], lo, hi)
        bottom.step(
            np.append(tc, hi),
            np.append(d.cmd_raw[k], d.cmd_raw[k[-1]]),
            where="post",
            color=_COLORS["command"],
            lw=1.2,
            label="command (held)",
        )
    if np.any(e_in):
        bottom.plot(
            d.enc_t[e_in],
            d.enc_y[e_in],
            ".-",
            color=_COLORS["load"],
            lw=0.6,
            markersize=1.5,
            label="load position (encoder)",
        )
    if not (np.any(c_in) or np.any(e_in)):
        _no_data(bottom, "nothing in the window")
    _finish_zoom(fig, top, bottom, (lo, hi), "position [rad]")
    return fig


# --------------------------------------------------------------------------- tracking error


@dataclass(frozen=True, eq=False)
class TrackingErrors:
    """Predicted load tracking error (load minus command) at every command.

    Attributes
    ----------
    plant : str
        ``"truth"`` (the bag's true drivetrain, with its wear) or ``"estimate"`` (the final
        estimate: the model's own prediction).
    t, weight : ndarray
        Command times (s) and how long each command is held (s): the RMS weights.
    none, node, final : ndarray or None
        Error without compensation, with the compensated commands the node sent, with the
        final estimate's inverse (None without a final estimate).
    measured_t, measured : ndarray
        The recorded error: encoder minus the command held (no compensation was applied
        while recording), one per reading.
    check : PlantCheck or None
        Whether the plant, run free on the recorded commands, reproduces the readings
        (None without aligned samples): where it does not, the predictions are the plant's,
        not the drivetrain's, and the page says so instead of leading with them.
    """

    plant: str
    t: np.ndarray
    weight: np.ndarray
    none: np.ndarray
    node: np.ndarray
    final: np.ndarray | None
    measured_t: np.ndarray
    measured: np.ndarray
    check: PlantCheck | None = None

    @property
    def trusted(self) -> bool:
        """True unless the plant check found that the plant does not describe the
        readings."""
        return self.check is None or self.check.describes

    def rms(self, error: np.ndarray | None, since: float = -math.inf) -> float:
        """Time-weighted RMS of ``error`` over the commands from ``since`` (s) on."""
        if error is None:
            return math.nan
        keep = self.t >= since
        w = self.weight[keep]
        if not np.any(w > 0):
            return math.nan
        return float(np.sqrt(np.sum(w * error[keep] ** 2) / np.sum(w)))

    def variants(self) -> list[tuple[str, str, np.ndarray | None]]:
        """``(key, label, error)`` of the three predictions."""
        return [
            ("none", "no compensation", self.none),
            ("node", "compensation the node sent (running estimate)", self.node),
            ("final", "final estimate's inverse", self.final),
        ]


def _plant(
    truth: BagTruth | None,
    model: GeneralBacklash | None,
    t: np.ndarray,
    u: np.ndarray,
    x0: float | None = None,
) -> np.ndarray:
    """The load the plant makes of the commands ``u`` at times ``t`` (s), starting at rest
    at ``x0`` (default the first desired position). The true plant is simulated in pieces
    between the truth's dead-zone times (the gap as it wears; each piece at its midpoint's
    gap)."""
    x0 = float(u[0]) if x0 is None else x0
    if truth is None:
        assert model is not None
        return simulate_backlash(model, u, x0)
    base = _backlash(truth.model)
    assert base is not None
    edges = truth.t_s
    i = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 1)
    j = np.minimum(i + 1, edges.size - 1)
    c_left = 0.5 * (truth.c_left[i] + truth.c_left[j])
    c_right = 0.5 * (truth.c_right[i] + truth.c_right[j])
    return simulate_worn(base, u, x0, c_left, c_right)


def tracking_errors(result: ReplayResult, data: ReportData | None = None) -> TrackingErrors | None:
    """The predicted tracking errors (see :class:`TrackingErrors`); None when there is no
    plant (no truth and no final estimate) or no command."""
    return (report_data(result) if data is None else data).tracking


def _tracking_errors(d: ReportData) -> TrackingErrors | None:
    """:func:`tracking_errors` of the report's data (see :attr:`ReportData.tracking`)."""
    plant = "truth" if d.truth is not None else "estimate"
    if d.cmd_t.size == 0 or (d.truth is None and d.model is None):
        return None
    t = d.cmd_t
    period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    weight = np.diff(t, append=t[-1] + period)
    desired = d.cmd_raw
    try:
        none = _plant(d.truth, d.model, t, desired) - desired
        node = _plant(d.truth, d.model, t, d.cmd_sent) - desired
        final = None
        if d.model is not None:
            state = CompensatorState.initial(d.model, x0=float(desired[0]))
            sent = compensate(d.model, desired, state=state)
            final = _plant(d.truth, d.model, t, sent) - desired
    except GenBacklashError:
        return None
    check = None
    if d.u.size:
        checked = _backlash(d.truth.model) if d.truth is not None else d.model
        assert checked is not None
        check = check_plant(
            checked,
            d.u,
            d.y,
            d.guard,
            plant,
            lambda u, x0: _plant(d.truth, d.model, d.t, u, x0),
        )
    return TrackingErrors(plant, t, weight, none, node, final, d.t, d.y - d.u, check)


def _rolling_rms(
    t: np.ndarray, w: np.ndarray, e: np.ndarray, span: tuple[float, float], width: float
) -> tuple[np.ndarray, np.ndarray]:
    bins = max(1, round((span[1] - span[0]) / width))
    edges = np.linspace(span[0], span[1], bins + 1)
    idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, bins - 1)
    num = np.bincount(idx, weights=w * e**2, minlength=bins)
    den = np.bincount(idx, weights=w, minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(num / den)
    return 0.5 * (edges[:-1] + edges[1:]), rms


def plant_caption(errors: TrackingErrors | None) -> str:
    """What the tracking-error prediction simulated, and whether that plant describes
    the recording (:mod:`~genbacklash_ros.reports.plant_check`)."""
    if errors is None:
        return "No plant to simulate: the bag holds no truth and there is no final estimate."
    if errors.plant == "truth":
        text = (
            "Plant: the true drivetrain stored in the bag (its dead zones as they wear), "
            "driven by each command sequence; the error is the load position minus the "
            "command (the desired load position)."
        )
    else:
        text = (
            "Plant: the final estimate (the bag holds no truth), so these numbers are the "
            "model's own prediction and flatter the compensation; the error is the load "
            "position minus the command (the desired load position)."
        )
    if errors.check is None:
        return text
    if errors.check.describes:
        return f"{text} {errors.check.sentence()}"
    stored = (
        " The truth a bag stores is a play (for a physics bag its quasi-static "
        "characteristic): it leaves out the servo, the load's inertia, a spring or gravity."
        if errors.plant == "truth"
        else ""
    )
    return (
        f"{text} {errors.check.sentence()} This plant does not describe the recording: "
        "the predicted errors and cuts are not what this drivetrain would see; the "
        "measured error and the compensation table say what happened." + stored
    )


def plot_tracking_error(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Predicted load tracking error with and without compensation: RMS per time bin over
    the record, and every command in the zoomed window."""
    d = report_data(result) if data is None else data
    errors = tracking_errors(result, d)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 7.2))
    if errors is None:
        for ax in (top, bottom):
            _no_data(ax, plant_caption(None))
        fig.tight_layout()
        return fig
    span = (0.0, max(d.end, 1e-3))
    width = max(0.25, span[1] / 200)
    mt = errors.measured_t
    if mt.size > 1:
        mw = np.diff(mt, append=mt[-1] + float(np.median(np.diff(mt))))
        c, r = _rolling_rms(mt, mw, errors.measured, span, width)
        measured = float(np.sqrt(np.sum(mw * errors.measured**2) / np.sum(mw)))
        top.plot(
            c,
            r,
            color=_COLORS["measured"],
            lw=2.5,
            alpha=0.6,
            label=f"measured: encoder - command (RMS {measured:.3g} rad)",
        )
    for key, label, e in errors.variants():
        if e is None:
            continue
        c, r = _rolling_rms(errors.t, errors.weight, e, span, width)
        top.plot(
            c,
            r,
            color=_COLORS[key],
            lw=1.2,
            drawstyle="steps-mid",
            label=f"{label} (RMS {errors.rms(e):.3g} rad)",
        )
    top.set_xlim(*span)
    top.set_ylim(bottom=0)
    _headroom(top, 0.45)
    who = "true drivetrain" if errors.plant == "truth" else "final estimate (no truth in bag)"
    top.set_title(
        f"Predicted load tracking error, RMS per {width:.3g} s (plant: {who})", fontsize="medium"
    )
    top.set_xlabel("time [s]")
    top.set_ylabel("RMS of load - command [rad]")
    top.legend(loc="upper left", fontsize="small", ncol=2, framealpha=0.9)
    lo, hi = d.window
    top.axvspan(lo, hi, color="C1", alpha=0.15, lw=0)
    _mark_phases(top, d.truth)
    inside = (errors.t >= lo) & (errors.t <= hi)
    for key, label, e in errors.variants():
        if e is None or not np.any(inside):
            continue
        bottom.step(
            errors.t[inside], e[inside], where="post", color=_COLORS[key], lw=1.1, label=label
        )
    m_in = (mt >= lo) & (mt <= hi)
    if np.any(m_in):
        bottom.plot(
            mt[m_in],
            errors.measured[m_in],
            ".",
            color=_COLORS["measured"],
            markersize=1.5,
            label="measured: encoder - command",
        )
    bottom.axhline(0.0, color="k", lw=0.6)
    _finish_zoom(fig, top, bottom, (lo, hi), "load - command [rad]")
    return fig


# --------------------------------------------------------------------------- gap


def _gap_series(result: ReplayResult, t0: int) -> dict[str, np.ndarray] | None:
    """Estimates of c_L, c_R and c_L + c_R with their standard deviations over time."""
    hist = result.history
    names = list(hist.names)
    if "c_left" not in names or "c_right" not in names or not hist.estimates:
        return None
    i, j = names.index("c_left"), names.index("c_right")
    values = np.array([e.parameters for e in hist.estimates])
    cov = np.array(
        [[e.covariance[i, i], e.covariance[j, j], e.covariance[i, j]] for e in hist.estimates]
    )
    return {
        "t": _seconds(hist.estimate_t, t0),
        "c_left": values[:, i],
        "c_right": values[:, j],
        "gap": values[:, i] + values[:, j],
        "sd_left": np.sqrt(np.maximum(cov[:, 0], 0.0)),
        "sd_right": np.sqrt(np.maximum(cov[:, 1], 0.0)),
        "sd_gap": np.sqrt(np.maximum(cov[:, 0] + cov[:, 1] + 2 * cov[:, 2], 0.0)),
    }


def _robust_limits(ax: Axes, values: list[np.ndarray]) -> None:
    """y-limits that keep early wild estimates from flattening the plot."""
    finite = np.concatenate([v[np.isfinite(v)] for v in values]) if values else np.zeros(0)
    if finite.size == 0:
        return
    lo, hi = np.percentile(finite, [2, 100])
    pad = 0.15 * (hi - lo) + 0.05 * abs(hi) + 1e-6
    ax.set_ylim(max(lo - pad, 0.0) if lo >= 0 else lo - pad, hi + pad)


def plot_gap(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """The dead zones over data time: c_L + c_R, and c_L, c_R, each with +/-2 sigma."""
    d = report_data(result) if data is None else data
    series = _gap_series(result, d.t0_ns)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 7.2), sharex=True)
    truth = d.truth
    shown: list[np.ndarray] = []
    if series is not None:
        t = series["t"]
        for ax, keys in (
            (top, [("gap", "sd_gap", "C2", "c_L + c_R")]),
            (
                bottom,
                [
                    ("c_left", "sd_left", _COLORS["left"], "c_L"),
                    ("c_right", "sd_right", _COLORS["right"], "c_R"),
                ],
            ),
        ):
            for key, sd_key, color, label in keys:
                v, s = series[key], series[sd_key]
                ok = np.isfinite(v) & np.isfinite(s)
                ax.fill_between(
                    t[ok],
                    (v - 2 * s)[ok],
                    (v + 2 * s)[ok],
                    color=color,
                    alpha=0.2,
                    lw=0,
                    step="post",
                )
                ax.step(
                    t,
                    v,
                    where="post",
                    color=color,
                    lw=1.2,
                    label=f"{label} estimate, band +/-2 sigma",
                )
                shown.append(v[t >= 0.3 * d.end] if np.any(t >= 0.3 * d.end) else v)
    else:
        _no_data(top, "no estimate of c_left and c_right was published")
    if truth is not None:
        top.plot(
            truth.t_s,
            truth.c_left + truth.c_right,
            "--",
            color=_COLORS["truth"],
            lw=1.2,
            label="c_L + c_R true",
        )
        bottom.plot(truth.t_s, truth.c_left, "--", color=_COLORS["left"], lw=1.2, label="c_L true")
        bottom.plot(truth.t_s, truth.c_right, ":", color=_COLORS["right"], lw=1.6, label="c_R true")
        shown += [truth.c_left + truth.c_right]
    _robust_limits(top, [v for v in shown[:1]] + ([shown[-1]] if truth is not None else []))
    _robust_limits(bottom, shown[1:3] + ([truth.c_left, truth.c_right] if truth else []))
    est = result.estimate
    names = list(est.names)
    title = "Play c_L + c_R over data time"
    if "c_left" in names and "c_right" in names and est.model is not None:
        i, j = names.index("c_left"), names.index("c_right")
        cov = est.covariance
        sd = math.sqrt(max(float(cov[i, i] + cov[j, j] + 2 * cov[i, j]), 0.0))
        gap = float(est.parameters[i] + est.parameters[j])
        title += f": final {gap:.4f} +/- {2 * sd:.4f} rad (2 sigma)"
        if truth is not None:
            end = _backlash(truth.model_end)
            assert end is not None
            title += f", true at the end {end.c_left + end.c_right:.4f} rad"
    top.set_title(title, fontsize="medium")
    bottom.set_title("Dead zones c_L (left branch) and c_R (right branch)", fontsize="medium")
    top.set_ylabel("c_L + c_R [rad]")
    bottom.set_ylabel("dead zone [rad]")
    bottom.set_xlabel("data time [s]")
    bottom.set_xlim(0.0, max(d.end, 1e-3))
    _mark_phases(top, truth)
    _mark_phases(bottom, truth, label=False)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="lower right", fontsize="small", ncol=2)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- coverage


@dataclass(frozen=True, eq=False)
class Coverage:
    """Which branch each aligned sample sits on: ``branch`` is +1 (right), -1 (left) or 0
    (inside the dead zone, the load resting); ``by`` says what classified it."""

    u: np.ndarray
    dt: np.ndarray
    branch: np.ndarray
    by: str

    def engaged(self, side: int, minimum: float = 0.02) -> tuple[float, float] | None:
        """Command range (low, high) over which branch ``side`` held for at least
        ``minimum`` seconds in total; None if it never did."""
        on = self.branch == side
        if float(np.sum(self.dt[on])) < minimum:
            return None
        return float(np.min(self.u[on])), float(np.max(self.u[on]))


def branch_coverage(data: ReportData, truth_model: GeneralBacklash | None) -> Coverage | None:
    """Classify the aligned samples by branch: with the final estimate (free-run from the
    first reading), else the truth at the end, else the direction the command last moved."""
    u, y, t = data.u, data.y, data.t
    if u.size < 2:
        return None
    period = float(np.median(np.diff(t)))
    dt = np.minimum(np.diff(t, append=t[-1] + period), 5 * period)
    model = data.model if data.model is not None else truth_model
    if model is not None:
        by = "final estimate" if data.model is not None else "true drivetrain (end)"
        try:
            x = simulate_backlash(model, u, float(y[0]))
        except GenBacklashError:
            model = None
        else:
            scale = max(1.0, float(np.max(np.abs(x))))
            tol = 1e-9 * scale
            right = np.abs(x - model.right(u)) <= tol
            left = np.abs(x - model.left(u)) <= tol
            branch = np.where(right, 1, np.where(left, -1, 0))
            return Coverage(u, dt, branch, by)
    steps = np.diff(u, prepend=u[0])
    direction = np.sign(steps)
    moving = np.flatnonzero(direction)
    last = np.zeros(u.size)
    if moving.size:
        idx = np.maximum.accumulate(np.where(direction != 0, np.arange(u.size), 0))
        last = direction[idx]
    return Coverage(u, dt, last.astype(int), "direction the command last moved")


def plot_coverage(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Time spent on each branch per command bin, and the branches around the 1:1 line
    with the engaged parts bold."""
    d = report_data(result) if data is None else data
    cov = d.coverage
    truth_end = d.truth_end
    fig, (hx, cx) = plt.subplots(1, 2, figsize=(12, 4.8))
    if cov is None:
        for ax in (hx, cx):
            _no_data(ax, "not enough samples")
        fig.tight_layout()
        return fig
    lo, hi = float(np.min(cov.u)), float(np.max(cov.u))
    if hi <= lo:
        hi = lo + 1e-3
    edges = np.linspace(lo, hi, 61)
    width = edges[1] - edges[0]
    right = np.histogram(cov.u[cov.branch == 1], edges, weights=cov.dt[cov.branch == 1])[0]
    left = np.histogram(cov.u[cov.branch == -1], edges, weights=cov.dt[cov.branch == -1])[0]
    rest = np.histogram(cov.u[cov.branch == 0], edges, weights=cov.dt[cov.branch == 0])[0]
    centres = 0.5 * (edges[:-1] + edges[1:])
    hx.bar(centres, right, width, color=_COLORS["right"], label="right branch R (u increasing)")
    hx.bar(centres, -left, width, color=_COLORS["left"], label="left branch L (u decreasing)")
    hx.step(centres, rest, where="mid", color="0.5", lw=1, label="resting inside the dead zone")
    hx.axhline(0.0, color="k", lw=0.6)
    top = max(float(np.max(right)), float(np.max(left)), float(np.max(rest)), 1e-9)
    hx.set_ylim(-1.1 * top, 1.1 * top)
    ticks = hx.get_yticks()
    hx.set_yticks(ticks, [f"{abs(v):g}" for v in ticks])
    hx.set_ylim(-1.1 * top, 1.1 * top)
    hx.set_xlabel("command u [rad]")
    hx.set_ylabel("time on the branch [s]  (left branch downwards)")
    hx.set_title(f"Where each branch was engaged (classified by the {cov.by})", fontsize="medium")
    hx.legend(loc="upper left", fontsize="small")
    # branches around the 1:1 line
    model = d.model if d.model is not None else truth_end
    grid = np.linspace(lo, hi, 400)
    if model is not None:
        seen_r = np.interp(grid, centres, (right > 0.01).astype(float)) > 0.5
        seen_l = np.interp(grid, centres, (left > 0.01).astype(float)) > 0.5
        for side, values, seen, color in (
            ("R", model.right(grid) - grid, seen_r, _COLORS["right"]),
            ("L", model.left(grid) - grid, seen_l, _COLORS["left"]),
        ):
            cx.plot(grid, values, "--", color=color, lw=0.8, alpha=0.7)
            cx.plot(
                grid,
                np.where(seen, values, np.nan),
                color=color,
                lw=3,
                label=f"{side}(u) - u, engaged",
            )
        if d.model is not None and truth_end is not None:
            cx.plot(
                grid, truth_end.right(grid) - grid, ":", color="k", lw=1, label="truth at the end"
            )
            cx.plot(grid, truth_end.left(grid) - grid, ":", color="k", lw=1)
        what = "final estimate" if d.model is not None else "truth at the end"
        cx.set_title(
            f"Branches of the {what} around the 1:1 line\n(bold: engaged by the data; "
            "dashed: never engaged)",
            fontsize="medium",
        )
    else:
        _no_data(cx, "no model to draw")
    cx.axhline(0.0, color="k", lw=0.6)
    cx.set_xlabel("command u [rad]")
    cx.set_ylabel("branch position - u [rad]")
    cx.legend(loc="best", fontsize="small")
    for ax in (hx, cx):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- classic plots


def _truth_values(truth: BagTruth, names: tuple[str, ...], t_s: np.ndarray) -> np.ndarray:
    """The true parameters in the estimate's names at times ``t_s`` (shape (K, P)); NaN
    for names the truth lacks (coefficients beyond its degree are 0)."""
    known = dict(zip(truth.model.parameter_names, truth.model.parameters().tolist(), strict=True))
    c_left, c_right = truth.dead_zones(t_s)
    out = np.full((t_s.size, len(names)), np.nan)
    for k, name in enumerate(names):
        if name in ("c_left", "c_right"):
            out[:, k] = c_left if name == "c_left" else c_right
        elif name in known:
            out[:, k] = known[name]
        elif name.startswith(("m_left_", "m_right_")) or (
            isinstance(truth.model, Cascade) and name.startswith(("a_", "b_"))
        ):
            out[:, k] = 0.0  # a coefficient beyond the truth's degree or order
    return out


def plot_convergence(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Each parameter over data time with a +/-2 sigma band (estimate covariance) and, for
    a bag with its truth, the true value (dashed)."""
    d = report_data(result) if data is None else data
    hist = result.history
    names = hist.names
    _, values, std = hist.parameters()
    t = _seconds(hist.estimate_t, d.t0_ns) if hist.estimate_t else np.zeros(0)
    truth = None
    if d.truth is not None and t.size:
        truth = _truth_values(d.truth, names, t)
    cols = 4
    rows = max(1, -(-len(names) // cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(3.2 * cols, 2.4 * rows + 0.6), squeeze=False, layout="constrained"
    )
    for i, ax in enumerate(axes.flat):
        if i >= len(names):
            ax.set_visible(False)
            continue
        if t.size:
            v, s = values[:, i], std[:, i]
            band = np.isfinite(s)
            ax.fill_between(
                t[band], (v - 2 * s)[band], (v + 2 * s)[band], color="C0", alpha=0.25, lw=0
            )
            ax.plot(t, v, color="C0", lw=1)
            final = v[np.isfinite(v)]
            if truth is not None and np.all(np.isfinite(truth[:, i])):
                ax.plot(t, truth[:, i], "--", color="k", lw=1)
                final = np.concatenate([final, truth[:, i]])
            if final.size:  # keep early wild values from flattening the plot
                lo, hi = np.percentile(final, [5, 100])
                pad = 0.5 * (hi - lo) + 0.05 * max(abs(hi), 1e-3)
                ax.set_ylim(lo - pad, hi + pad)
        unit = parameter_unit(names[i])
        ax.set_title(f"{names[i]} [{unit}]" if unit else names[i], fontsize="small")
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize="x-small")
    fig.supxlabel("data time [s]", fontsize="small")
    extra = "; dashed: truth" if truth is not None else ""
    fig.suptitle(f"Parameter convergence (band: +/-2 sigma{extra})", fontsize="medium")
    return fig


def plot_residuals(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Encoder minus the final model's free-run simulation, over time and as a histogram."""
    d = report_data(result) if data is None else data
    model = result.estimate.model
    fig, (ax, hx) = plt.subplots(
        1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios": [3, 1]}, squeeze=True
    )
    if model is not None and d.t.size:
        sim = model.simulate(d.u, float(d.y[0]))
        res = d.y - sim
        ax.plot(d.t, res, ".", markersize=1.5, color="C3", rasterized=True)
        hx.hist(res, bins=60, color="C3", alpha=0.8)
        rms = float(np.sqrt(np.mean(res**2)))
        ax.set_title(f"Free-run residual of the final model (RMS {rms:.4g} rad)", fontsize="medium")
    else:
        ax.set_title("no model estimated: no residuals", fontsize="medium")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("encoder - model [rad]")
    hx.set_xlabel("residual [rad]")
    hx.set_ylabel("readings")
    for a in (ax, hx):
        a.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def plot_compensation(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Raw and compensated command in the zoomed window."""
    d = report_data(result) if data is None else data
    fig, ax = plt.subplots(figsize=(11, 3.6))
    lo, hi = d.window
    inside = (d.cmd_t >= lo) & (d.cmd_t <= hi)
    if np.any(inside):
        t = d.cmd_t[inside]
        ax.step(t, d.cmd_raw[inside], where="post", lw=1.0, color="0.5", label="raw command")
        ax.step(
            t,
            d.cmd_sent[inside],
            where="post",
            lw=1.0,
            color="C2",
            label="compensated command (as the node sent it)",
        )
        ax.set_xlim(lo, hi)
    else:
        _no_data(ax, "no command")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("command [rad]")
    ax.set_title(f"Inverse-backlash compensation, {lo:.2f} - {hi:.2f} s", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


_STATE_COLOURS = {"on": "C2", "faded": "C1", "off": "C3"}


def compensation_spans(result: ReplayResult) -> list[tuple[float, float, str, str]]:
    """``(from s, to s, state, reason)``: the stretches of data time over which the node's
    ``/diagnostics`` reported one compensation state (on, faded, off), with the reason it
    gave at the stretch's start; times from the first report."""
    h = result.history
    if not h.compensation:
        return []
    t = _seconds(h.compensation_t, h.compensation_t[0])
    spans: list[tuple[float, float, str, str]] = []
    for k, status in enumerate(h.compensation):
        # a state holds from its report to the next one
        if spans:
            spans[-1] = (spans[-1][0], float(t[k]), spans[-1][2], spans[-1][3])
        if not spans or spans[-1][2] != status.state:
            spans.append((float(t[k]), float(t[k]), status.state, status.reason))
    return spans


def compensation_section(result: ReplayResult) -> Section:
    """When compensation was on, faded or off over the replay, and why (issue 23)."""
    title = "Compensation: when it was on, faded or off, and why"
    spans = compensation_spans(result)
    if not spans:
        return Section(title, paragraphs=["No /diagnostics report was published."])
    total = max(spans[-1][1], 1e-9)
    share = {
        state: sum(b - a for a, b, s, _ in spans if s == state) / total
        for state in ("on", "faded", "off")
    }
    shown = spans[:30]
    rows = [[f"{a:.1f}", f"{b:.1f}", state, reason] for a, b, state, reason in shown]
    note = f" (the first 30 of {len(spans)} stretches)" if len(spans) > 30 else ""
    return Section(
        title,
        paragraphs=[
            f"Over the record the compensation was on {100 * share['on']:.0f} % of the time, "
            f"faded {100 * share['faded']:.0f} % and off {100 * share['off']:.0f} % (as each "
            "/diagnostics report said; the guard fades it out where the model's error on the "
            "commands is not well below the error with no compensation)."
        ],
        tables=[
            Table(
                ["from [s]", "to [s]", "state", "why (at the stretch's start)"],
                rows,
                caption=f"Stretches of one compensation state{note}.",
                align="rrll",
            )
        ],
    )


def plot_compensation_state(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """The share of the inverse applied over data time, shaded by state."""
    h = result.history
    fig, ax = plt.subplots(figsize=(11, 2.8), layout="constrained")
    if h.compensation:
        t = _seconds(h.compensation_t, h.compensation_t[0])
        weight = np.array([c.weight for c in h.compensation])
        ax.step(t, weight, where="post", color="k", lw=1.2, label="share of the inverse applied")
        for a, b, state, _ in compensation_spans(result):
            ax.axvspan(a, max(b, a + 1e-3), color=_STATE_COLOURS.get(state, "0.5"), alpha=0.15)
        for state, colour in _STATE_COLOURS.items():
            ax.fill_between([], [], color=colour, alpha=0.15, label=f"compensation {state}")
        ax.set_ylim(-0.05, 1.05)
        ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.3), ncol=4, fontsize="small")
    else:
        _no_data(ax, "no /diagnostics report")
    ax.set_xlabel("data time [s]")
    ax.set_ylabel("weight [0-1]")
    ax.set_title("Compensation over the record: on, faded or off", fontsize="medium")
    ax.grid(True, alpha=0.3)
    return fig


def plot_characteristic_report(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """The final estimate's branches with the aligned samples: position against command,
    and the same around the 1:1 line (branch - u), where a small play is visible."""
    d = report_data(result) if data is None else data
    model = result.estimate.model
    backlash = _backlash(model)
    truth = d.truth_end
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.2), layout="constrained")
    if d.u.size:
        step = max(1, d.u.size // 20000)
        su, sy = d.u[::step], d.y[::step]
        ax.plot(su, sy, ".", color="0.7", markersize=1.5, label="samples", rasterized=True)
        bx.plot(su, sy - su, ".", color="0.7", markersize=1.5, label="samples", rasterized=True)
        grid = np.linspace(float(np.min(d.u)), float(np.max(d.u)), 400)
        if backlash is not None:
            for which, color in (("left", _COLORS["left"]), ("right", _COLORS["right"])):
                branch = getattr(backlash, which)(grid)
                ax.plot(grid, branch, color=color, lw=1.5, label=f"estimate: {which} branch")
                bx.plot(grid, branch - grid, color=color, lw=1.5, label=f"estimate: {which}")
        if truth is not None:
            for k, which in enumerate(("left", "right")):
                branch = getattr(truth, which)(grid)
                label = "truth (end of record)" if k == 0 else None
                ax.plot(grid, branch, "--", color="k", lw=1, label=label)
                bx.plot(grid, branch - grid, "--", color="k", lw=1, label=label)
    else:
        _no_data(ax, "no samples")
    title = "General backlash characteristic" + ("" if backlash else " (no model estimated)")
    ax.set_title(title, fontsize="medium")
    ax.set_xlabel("command u [rad]")
    ax.set_ylabel("load position [rad]")
    bx.set_title("The same around the 1:1 line", fontsize="medium")
    bx.set_xlabel("command u [rad]")
    bx.set_ylabel("load position - u [rad]")
    for a in (ax, bx):
        a.grid(True, alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if handles:  # below both panels: over the axes it hid samples
        fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize="small")
    return fig


# --------------------------------------------------------------------------- page


def _parameter_table(result: ReplayResult, truth: BagTruth | None) -> Table:
    est = result.estimate
    true_end = (
        _truth_values(truth, est.names, truth.t_s[-1:])[0]
        if truth is not None
        else np.full(len(est.names), np.nan)
    )
    head = ["parameter", "unit", "estimate", "\u00b12\u03c3"]
    head += ["truth at the end"] if truth is not None else []
    rows = []
    for n, v, s, tv in zip(est.names, est.parameters, est.std(), true_end, strict=True):
        row = [n, parameter_unit(n), f"{v:.5f}", f"{2 * s:.5f}"]
        rows.append(row + ([f"{tv:.5f}"] if truth is not None else []))
    return Table(head, rows, numeric_from=2)


def _fmt(value: float, digits: int = 4) -> str:
    return DASH if not math.isfinite(value) else f"{value:.{digits}g}"


def _cut(before: float, after: float) -> str:
    if not (math.isfinite(before) and math.isfinite(after)) or before <= 0:
        return DASH
    return f"{100.0 * (1.0 - after / before):.0f}\u00a0%"


def tracking_headline(errors: TrackingErrors | None) -> str:
    """One sentence: the RMS tracking error without compensation, with the final estimate's
    inverse and with what the node sent."""
    if errors is None:
        return plant_caption(None)
    base_all = errors.rms(errors.none)
    final = errors.rms(errors.final)
    node = errors.rms(errors.node)
    numbers = (
        f"RMS tracking error without compensation {_fmt(base_all)} rad, with the final "
        f"estimate's inverse {_fmt(final)} rad ({_cut(base_all, final)} cut); with the "
        f"compensation the node sent {_fmt(node)} rad ({_cut(base_all, node)} cut)."
    )
    if errors.trusted:
        return numbers
    return (
        "Not a prediction for this drivetrain: the plant simulated does not describe the "
        f"recording, so the cuts below are the plant's own. Predicted by that plant: {numbers}"
    )


def tracking_section(errors: TrackingErrors | None, end: float) -> Section:
    """The tracking-error section of the page: RMS with and without compensation and the
    cut, over the whole record and over its second half."""
    title = "Tracking error: what compensation buys"
    if errors is None:
        return Section(title, paragraphs=[plant_caption(None)])
    half = 0.5 * end
    base_all, base_half = errors.rms(errors.none), errors.rms(errors.none, half)
    rows = []
    for _key, label, e in errors.variants():
        all_, second = errors.rms(e), errors.rms(e, half)
        peak = float(np.max(np.abs(e))) if e is not None and e.size else math.nan
        cuts = [_cut(base_all, all_), _fmt(second), _cut(base_half, second)]
        rows.append([label, _fmt(all_), *cuts, _fmt(peak)])
    me = errors.measured
    measured = float(np.sqrt(np.mean(me**2))) if me.size else math.nan
    head = ["command sequence", "RMS [rad]", "cut", f"RMS after {half:.1f} s [rad]", "cut"]
    return Section(
        title,
        paragraphs=[
            tracking_headline(errors),
            plant_caption(errors) + " RMS values are weighted by how long each command is held.",
            f"Measured while recording (encoder \u2212 command held, {me.size} readings, no "
            f"compensation applied): RMS {_fmt(measured)} rad.",
        ],
        tables=[Table([*head, "max |error| [rad]"], rows)],
    )


def coverage_text(data: ReportData) -> str:
    """One paragraph: the command range each branch was engaged over."""
    cov = data.coverage
    if cov is None:
        return "Not enough samples to say which branches were engaged."
    lo, hi = float(np.min(cov.u)), float(np.max(cov.u))
    span = max(hi - lo, 1e-12)
    parts = []
    for side, name in ((1, "right branch (u increasing)"), (-1, "left branch (u decreasing)")):
        seconds = float(np.sum(cov.dt[cov.branch == side]))
        got = cov.engaged(side)
        if got is None:
            parts.append(f"the {name} was never engaged")
        else:
            share = 100.0 * (got[1] - got[0]) / span
            parts.append(
                f"the {name} was engaged for {seconds:.1f} s over u in "
                f"[{got[0]:.3f}, {got[1]:.3f}] rad ({share:.0f}\u00a0% of the command range)"
            )
    rest = float(np.sum(cov.dt[cov.branch == 0]))
    return (
        f"Commands spanned [{lo:.3f}, {hi:.3f}] rad; {parts[0]}; {parts[1]}; the load "
        f"rested inside the dead zone for {rest:.1f} s (classified by the {cov.by})."
    )


def _play(result: ReplayResult) -> str:
    """The final play c_L + c_R with its 2-sigma band, from the estimate's covariance."""
    est = result.estimate
    names = list(est.names)
    if "c_left" not in names or "c_right" not in names:
        return DASH
    i, j = names.index("c_left"), names.index("c_right")
    gap = float(est.parameters[i] + est.parameters[j])
    cov = np.asarray(est.covariance, dtype=np.float64)
    var = float(cov[i, i] + cov[j, j] + 2 * cov[i, j]) if cov.shape[0] > max(i, j) else math.nan
    if not math.isfinite(gap):
        return DASH
    band = f" \u00b1 {2 * math.sqrt(var):.4f}" if math.isfinite(var) and var >= 0 else ""
    return f"{gap:.4f}{band} rad (2\u03c3)"


def _servo_summary(servo: dict[str, object]) -> str:
    """One line: the servo the identifier's input went through (``servo_model``)."""
    if "dead_time" not in servo:
        return f"{servo['state']} (no estimate: the data ended inside the window)"
    dead, lag = float(servo["dead_time"]), float(servo["time_constant"])  # type: ignore[arg-type]
    text = (
        f"{servo['state']}: dead time {1e3 * dead:.2f} ms, lag {1e3 * lag:.2f} ms; the play "
        "is on its output, and the compensated command aims it (the lag is not inverted)"
    )
    if "note" in servo:
        text += f"; {servo['note']}"
    return text


def _compensation_summary(result: ReplayResult) -> str:
    """One line: how the compensation ended, and why."""
    h = result.history
    if not h.compensation:
        return "no /diagnostics report"
    last = h.compensation[-1]
    return f"{last.state} at the end (weight {last.weight:.2f}): {last.reason}"


def _untrusted_alert(errors: TrackingErrors) -> str:
    """The alert of a page whose plant does not describe the recording."""
    assert errors.check is not None
    return (
        "The predicted tracking errors on this page come from a plant that does not "
        f"describe the recording (it misses the readings by {errors.check.ratio:.2f} of "
        "what the command misses them by): read the measured error and when compensation "
        "was on, not the predicted cuts."
    )


def _page_content(
    result: ReplayResult,
    data: ReportData,
    errors: TrackingErrors | None,
    images: list[tuple[str, str]],
) -> dict[str, Any]:
    """The page's title, summary block, alerts and sections (rendered by base.html)."""
    est = result.estimate
    stats = result.stats
    dropped = ", ".join(f"{k}: {n}" for k, n in stats.dropped.items() if n) or "none"
    truth = data.truth
    bag = (
        f"The bag holds its truth: {truth.description}."
        if truth is not None
        else "The bag holds no truth (no genbacklash.truth in its metadata): predictions use "
        "the final estimate as the plant."
    )
    params = result.params
    play = _play(result)
    if truth is not None and truth.c_left.size:
        play += f"; true at the end {float(truth.c_left[-1] + truth.c_right[-1]):.4f} rad"
    summary = [
        ("Output bag", str(result.output)),
        ("Model", f"{params.model}, degree {params.degree}, method {params.method}"),
        ("Data", f"{data.end:.1f} s"),
        ("Final state", f"{est.state.value}, confidence {est.confidence:.2f}"),
        ("Play c_L + c_R", play),
        *([("Servo model", _servo_summary(result.servo))] if result.servo is not None else []),
        ("Tracking error", tracking_headline(errors)),
        ("Compensation", _compensation_summary(result)),
    ]
    sections = [
        tracking_section(errors, data.end),
        compensation_section(result),
        Section(
            "Final estimate",
            paragraphs=[
                f"State {est.state.value}, confidence {est.confidence:.2f}, {est.samples} "
                f"samples. {est.reason}"
            ],
            tables=[_parameter_table(result, truth)],
        ),
        Section("What the data taught: branch coverage", paragraphs=[coverage_text(data)]),
        Section(
            "Replay counters",
            paragraphs=[
                f"{result.messages_in} messages replayed, {stats.compensated} compensated "
                f"commands, {result.messages_out} messages written; dropped: {dropped}."
            ],
        ),
        Section("Plots", figures=[PageFigure(name, caption) for name, caption in images]),
    ]
    return {
        "title": "Backlash replay report",
        "subtitle": bag,
        "summary": summary,
        "alerts": [
            *([f"Stopped early: {result.error}"] if result.error else []),
            *([_untrusted_alert(errors)] if errors is not None and not errors.trusted else []),
        ],
        "sections": sections,
    }


def write_report(
    result: ReplayResult,
    out_dir: str | Path,
    *,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Write the plots and ``index.html`` into ``out_dir``; return the page's path
    (``progress``: called with each stage, for a progress line)."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    if progress is not None:
        progress("simulating the tracking errors")
    data = report_data(result)
    errors = tracking_errors(result, data)
    truth_note = (
        " Dashed: the truth stored in the bag."
        if data.truth is not None
        else " The bag holds no truth to compare with."
    )
    plots = [
        (
            "motion.png",
            "Load position (encoder) against the command: the whole record as the band between "
            "the smallest and largest value in each pixel column, and a zoomed window late in "
            "the record with reversals, every command and reading drawn.",
            plot_motion,
        ),
        (
            "tracking_error.png",
            "Predicted load tracking error (load minus command) without compensation, with the "
            "compensated commands the node sent (running estimate, gated by its confidence) "
            "and with the final estimate's inverse. " + plant_caption(errors),
            plot_tracking_error,
        ),
        (
            "compensation_state.png",
            "The share of the inverse the node applied over data time, as its /diagnostics "
            "reported it, shaded where compensation was on, faded or off (the table above "
            "says why).",
            plot_compensation_state,
        ),
        (
            "play.png",
            "The play c_L + c_R and each dead zone over data time as published by the node, "
            f"with +/-2 sigma from the estimates' covariance.{truth_note}",
            plot_gap,
        ),
        (
            "coverage.png",
            "Branch coverage: time the load spent on each branch per command bin (right "
            "branch up, left branch down; grey: resting inside the dead zone), and the "
            "branches around the 1:1 line, bold where the data engaged them.",
            plot_coverage,
        ),
        (
            "characteristic.png",
            "Characteristic: the final estimate's branches with the aligned samples; right: "
            f"the same minus u, where the play is visible.{truth_note}",
            plot_characteristic_report,
        ),
        (
            "convergence.png",
            f"Parameter convergence with +/-2 sigma bands.{truth_note}",
            plot_convergence,
        ),
        ("residuals.png", "Free-run residuals of the final model.", plot_residuals),
        (
            "compensation.png",
            "Raw vs compensated command in the zoomed window.",
            plot_compensation,
        ),
    ]
    images = []
    for k, (name, caption, make) in enumerate(plots, 1):
        if progress is not None:
            progress(f"figure {k} of {len(plots)} ({name})")
        fig = make(result, data)
        fig.savefig(directory / name, dpi=_DPI)
        plt.close(fig)
        images.append((name, caption))
    return write_page(directory / "index.html", **_page_content(result, data, errors, images))
