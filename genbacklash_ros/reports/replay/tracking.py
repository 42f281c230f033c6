"""The replay report's tracking error: a plant driven by the commands with and without
compensation, the check that the plant describes the recording
(:mod:`~genbacklash_ros.reports.plant_check`), its figure, headline and section.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_core import (
    CompensatorState,
    GenBacklashError,
    GeneralBacklash,
    compensate,
    simulate_backlash,
)
from genbacklash_core.scenarios import simulate_worn
from genbacklash_ros.bags.replay import ReplayResult
from genbacklash_ros.bags.simbags import BagTruth
from genbacklash_ros.reports.page import DASH, Section, Table
from genbacklash_ros.reports.plant_check import PlantCheck, check_plant

from .axes import finish_zoom, headroom, mark_phases, no_data
from .data import COLORS, ReportData, backlash_of, report_data

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
    base = backlash_of(truth.model)
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


def compute_tracking_errors(d: ReportData) -> TrackingErrors | None:
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
        check = check_plant(
            lambda u, x0: _plant(d.truth, d.model, d.t, u, x0), d.u, d.y, d.guard, plant
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
            no_data(ax, plant_caption(None))
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
            color=COLORS["measured"],
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
            color=COLORS[key],
            lw=1.2,
            drawstyle="steps-mid",
            label=f"{label} (RMS {errors.rms(e):.3g} rad)",
        )
    top.set_xlim(*span)
    top.set_ylim(bottom=0)
    headroom(top, 0.45)
    who = "true drivetrain" if errors.plant == "truth" else "final estimate (no truth in bag)"
    top.set_title(
        f"Predicted load tracking error, RMS per {width:.3g} s (plant: {who})", fontsize="medium"
    )
    top.set_xlabel("time [s]")
    top.set_ylabel("RMS of load - command [rad]")
    top.legend(loc="upper left", fontsize="small", ncol=2, framealpha=0.9)
    lo, hi = d.window
    top.axvspan(lo, hi, color="C1", alpha=0.15, lw=0)
    mark_phases(top, d.truth)
    inside = (errors.t >= lo) & (errors.t <= hi)
    for key, label, e in errors.variants():
        if e is None or not np.any(inside):
            continue
        bottom.step(
            errors.t[inside], e[inside], where="post", color=COLORS[key], lw=1.1, label=label
        )
    m_in = (mt >= lo) & (mt <= hi)
    if np.any(m_in):
        bottom.plot(
            mt[m_in],
            errors.measured[m_in],
            ".",
            color=COLORS["measured"],
            markersize=1.5,
            label="measured: encoder - command",
        )
    bottom.axhline(0.0, color="k", lw=0.6)
    finish_zoom(fig, top, bottom, (lo, hi), "load - command [rad]")
    return fig


def fmt(value: float, digits: int = 4) -> str:
    return DASH if not math.isfinite(value) else f"{value:.{digits}g}"


def cut_text(before: float, after: float) -> str:
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
        f"RMS tracking error without compensation {fmt(base_all)} rad, with the final "
        f"estimate's inverse {fmt(final)} rad ({cut_text(base_all, final)} cut); with the "
        f"compensation the node sent {fmt(node)} rad ({cut_text(base_all, node)} cut)."
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
        cuts = [cut_text(base_all, all_), fmt(second), cut_text(base_half, second)]
        rows.append([label, fmt(all_), *cuts, fmt(peak)])
    me = errors.measured
    measured = float(np.sqrt(np.mean(me**2))) if me.size else math.nan
    head = ["command sequence", "RMS [rad]", "cut", f"RMS after {half:.1f} s [rad]", "cut"]
    return Section(
        title,
        paragraphs=[
            tracking_headline(errors),
            plant_caption(errors) + " RMS values are weighted by how long each command is held.",
            f"Measured while recording (encoder \u2212 command held, {me.size} readings, no "
            f"compensation applied): RMS {fmt(measured)} rad.",
        ],
        tables=[Table([*head, "max |error| [rad]"], rows)],
    )
