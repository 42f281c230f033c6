"""The replay report's figures of the record itself: the motion, the play over time, each
parameter's convergence, the free-run residuals and the characteristic.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from genbacklash_core import Cascade
from genbacklash_ros.bags.replay import ReplayResult
from genbacklash_ros.bags.simbags import BagTruth
from genbacklash_ros.reports.plots import parameter_unit

from .axes import band, finish_zoom, headroom, mark_phases, no_data
from .data import (
    BINS,
    COLORS,
    DENSE_BINS,
    ReportData,
    backlash_of,
    report_data,
    reversals,
    seconds_from,
)

# --------------------------------------------------------------------------- motion


def plot_motion(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """Load position (encoder) against the command: whole record (min/max band per pixel
    column) and the zoomed window (every command and reading)."""
    d = report_data(result) if data is None else data
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 7.2))
    span = (0.0, max(d.end, 1e-3))
    # commands that reverse in most pixel columns (random input) read best as a solid band
    bins = DENSE_BINS if reversals(d.cmd_raw).size > BINS else BINS
    if d.cmd_t.size:
        band(
            top,
            d.cmd_t,
            d.cmd_raw,
            span,
            hold=True,
            color=COLORS["command"],
            label="command (desired load position)",
            alpha=0.2,
            bins=bins,
        )
    if d.enc_t.size:
        band(
            top,
            d.enc_t,
            d.enc_y,
            span,
            hold=False,
            color=COLORS["load"],
            label="load position (encoder)",
            bins=bins,
        )
    if not (d.cmd_t.size or d.enc_t.size):
        no_data(top, "no command nor encoder reading")
    lo, hi = d.window
    top.axvspan(lo, hi, color="C1", alpha=0.15, lw=0, label="zoomed below")
    mark_phases(top, d.truth)
    top.set_xlim(*span)
    headroom(top)
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
            color=COLORS["command"],
            lw=1.2,
            label="command (held)",
        )
    if np.any(e_in):
        bottom.plot(
            d.enc_t[e_in],
            d.enc_y[e_in],
            ".-",
            color=COLORS["load"],
            lw=0.6,
            markersize=1.5,
            label="load position (encoder)",
        )
    if not (np.any(c_in) or np.any(e_in)):
        no_data(bottom, "nothing in the window")
    finish_zoom(fig, top, bottom, (lo, hi), "position [rad]")
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
        "t": seconds_from(hist.estimate_t, t0),
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
                    ("c_left", "sd_left", COLORS["left"], "c_L"),
                    ("c_right", "sd_right", COLORS["right"], "c_R"),
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
        no_data(top, "no estimate of c_left and c_right was published")
    if truth is not None:
        top.plot(
            truth.t_s,
            truth.c_left + truth.c_right,
            "--",
            color=COLORS["truth"],
            lw=1.2,
            label="c_L + c_R true",
        )
        bottom.plot(truth.t_s, truth.c_left, "--", color=COLORS["left"], lw=1.2, label="c_L true")
        bottom.plot(truth.t_s, truth.c_right, ":", color=COLORS["right"], lw=1.6, label="c_R true")
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
            end = backlash_of(truth.model_end)
            assert end is not None
            title += f", true at the end {end.c_left + end.c_right:.4f} rad"
    top.set_title(title, fontsize="medium")
    bottom.set_title("Dead zones c_L (left branch) and c_R (right branch)", fontsize="medium")
    top.set_ylabel("c_L + c_R [rad]")
    bottom.set_ylabel("dead zone [rad]")
    bottom.set_xlabel("data time [s]")
    bottom.set_xlim(0.0, max(d.end, 1e-3))
    mark_phases(top, truth)
    mark_phases(bottom, truth, label=False)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="lower right", fontsize="small", ncol=2)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- classic plots


def truth_values(truth: BagTruth, names: tuple[str, ...], t_s: np.ndarray) -> np.ndarray:
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
    t = seconds_from(hist.estimate_t, d.t0_ns) if hist.estimate_t else np.zeros(0)
    truth = None
    if d.truth is not None and t.size:
        truth = truth_values(d.truth, names, t)
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


def plot_characteristic_report(result: ReplayResult, data: ReportData | None = None) -> Figure:
    """The final estimate's branches with the aligned samples: position against command,
    and the same around the 1:1 line (branch - u), where a small play is visible."""
    d = report_data(result) if data is None else data
    model = result.estimate.model
    backlash = backlash_of(model)
    truth = d.truth_end
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.2), layout="constrained")
    if d.u.size:
        step = max(1, d.u.size // 20000)
        su, sy = d.u[::step], d.y[::step]
        ax.plot(su, sy, ".", color="0.7", markersize=1.5, label="samples", rasterized=True)
        bx.plot(su, sy - su, ".", color="0.7", markersize=1.5, label="samples", rasterized=True)
        grid = np.linspace(float(np.min(d.u)), float(np.max(d.u)), 400)
        if backlash is not None:
            for which, color in (("left", COLORS["left"]), ("right", COLORS["right"])):
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
        no_data(ax, "no samples")
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
