"""The replay report's page: the summary, the alerts, the sections and the figures written
into a directory with its ``index.html``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from genbacklash_ros.bags.replay import ReplayResult
from genbacklash_ros.bags.simbags import BagTruth
from genbacklash_ros.reports.page import DASH, Section, Table, write_page
from genbacklash_ros.reports.page import Figure as PageFigure
from genbacklash_ros.reports.plots import parameter_unit

from .compensation import (
    compensation_section,
    compensation_summary,
    plot_compensation,
    plot_compensation_state,
)
from .coverage import coverage_text, plot_coverage
from .data import DPI, ReportData, report_data
from .figures import (
    plot_characteristic_report,
    plot_convergence,
    plot_gap,
    plot_motion,
    plot_residuals,
    truth_values,
)
from .tracking import (
    TrackingErrors,
    plant_caption,
    plot_tracking_error,
    tracking_errors,
    tracking_headline,
    tracking_section,
)

# --------------------------------------------------------------------------- page


def _parameter_table(result: ReplayResult, truth: BagTruth | None) -> Table:
    est = result.estimate
    true_end = (
        truth_values(truth, est.names, truth.t_s[-1:])[0]
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
        ("Compensation", compensation_summary(result)),
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
        fig.savefig(directory / name, dpi=DPI)
        plt.close(fig)
        images.append((name, caption))
    return write_page(directory / "index.html", **_page_content(result, data, errors, images))
