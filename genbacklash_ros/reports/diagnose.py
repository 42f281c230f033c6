"""The ``genbacklash diagnose --report DIR`` report: plots and a readable summary.

Plot functions return figures (compute and plotting split, as in python-control);
:func:`write_report` saves them with ``index.html`` (the page, the layout every report
shares: :mod:`genbacklash_ros.reports.page`) and ``summary.md`` (the same sections as
Markdown) into a directory.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_core.diagnose import Diagnosis, ResidualAnalysis
from genbacklash_core.diagnose.context import StepErrorShape, build_context
from genbacklash_core.diagnose.settings import DiagnoseSettings
from genbacklash_ros.reports.page import Figure as PageFigure
from genbacklash_ros.reports.page import Section, Table, render, write_page

__all__ = [
    "gap_map",
    "plot_correlations",
    "plot_fit_steps",
    "plot_gap_breakdown",
    "plot_gap_map",
    "plot_gap_steps",
    "plot_step_error",
    "report_sections",
    "summary_markdown",
    "write_report",
]

_WINDOW = 600  # validation samples shown in the measured-vs-simulated panels
_BINS = 8  # travel bins and time slices of the gap map


def _labels(result: Diagnosis) -> list[str]:
    return ["start"] + [f"+ {step.effect}" for step in result.steps]


def _axis(t: np.ndarray | None, n: int) -> tuple[np.ndarray | None, str]:
    """Seconds from the record's start when ``t`` has one time per sample, else None."""
    if t is None:
        return None, ""
    tt = np.asarray(t, dtype=np.float64)
    if tt.shape != (n,) or not np.all(np.isfinite(tt)):
        return None, ""
    return tt - tt[0], "time [s]"


def plot_fit_steps(
    result: Diagnosis, y: np.ndarray, t: np.ndarray | None = None, unit: str = "rad"
) -> Figure:
    """Measured vs simulated output on the validation segment, before and after each step.

    ``t``: the time of each sample in seconds (the x axis is then time, else the sample
    number); ``unit``: the unit of ``y``.
    """
    val = result.split.validation
    start = val.start
    stop = min(val.stop, start + _WINDOW)
    seconds, xlabel = _axis(t, np.asarray(y).size)
    x = np.arange(start, stop) if seconds is None else seconds[start:stop]
    labels = _labels(result)
    rows = len(result.reports)
    fig, axes = plt.subplots(
        rows,
        1,
        figsize=(9, 2.3 * rows + 0.9),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    for ax, report, label in zip(axes[:, 0], result.reports, labels, strict=True):
        ax.plot(x, y[start:stop], color="0.6", lw=1.0, label="measured")
        ax.plot(x, report.y_sim[start:stop], color="C0", lw=1.2, label="simulated (free run)")
        ax.plot(x, y[start:stop] - report.y_sim[start:stop], color="C3", lw=0.8, label="error")
        ax.set_title(f"{label}: validation misfit {report.gap:.4f} (NRMSE)", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.set_ylabel(f"position [{unit}]")
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncol=3, fontsize="small")
    axes[-1, 0].set_xlabel(xlabel or "sample (validation segment)")
    fig.suptitle("Measured and simulated position on the held-out validation data", fontsize=11)
    return fig


def plot_gap_steps(result: Diagnosis) -> Figure:
    """The validation gap per step as a bar chart."""
    labels = _labels(result)
    gaps = [report.gap for report in result.reports]
    fig, ax = plt.subplots(figsize=(max(6.0, 1.8 * len(gaps) + 2.5), 4.0), layout="constrained")
    x = np.arange(len(gaps))
    bars = ax.bar(x, gaps, color=["C7"] + ["C0"] * (len(gaps) - 1), width=0.6)
    ax.set_xticks(x, labels)
    ax.bar_label(bars, [f"{gap:.4f}" for gap in gaps], padding=2, fontsize=9)
    if result.floor is not None:
        floor = result.floor
        name = f"floor {floor.gap:.4f}" + ("" if floor.known else " (quantisation only)")
        ax.axhline(floor.gap, color="C3", ls="--", lw=1.0, label=name)
        ax.legend(loc="upper right", fontsize="small", framealpha=0.9)
    ax.set_ylim(0.0, 1.15 * max(max(gaps), result.floor.gap if result.floor else 0.0))
    ax.set_ylabel("validation misfit (NRMSE, unitless)")
    ax.set_title("Misfit per step\n(dashed: the floor quantisation and noise allow)", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    return fig


def plot_gap_breakdown(result: Diagnosis) -> Figure:
    """Where the gap sits: each group's share of the squared error against its share of the
    samples, for the starting and the final model."""
    first, last = result.reports[0], result.reports[-1]
    names = [f"{g.aspect}: {g.label}" for g in first.groups]
    y_pos = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(names) + 2.2), layout="constrained")
    ax.barh(
        y_pos - 0.27,
        [g.sample_share for g in first.groups],
        0.27,
        color="0.75",
        label="share of samples",
    )
    ax.barh(
        y_pos,
        [g.error_share for g in first.groups],
        0.27,
        color="C3",
        label=f"share of squared error, start (misfit {first.gap:.3f})",
    )
    ax.barh(
        y_pos + 0.27,
        [g.error_share for g in last.groups],
        0.27,
        color="C0",
        label=f"share of squared error, final (misfit {last.gap:.3f})",
    )
    ax.set_yticks(y_pos, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0.0, 1.0)
    ax.set_xlabel("share of the validation segment (fraction, 0..1)")
    ax.set_title("Where the validation misfit concentrates")
    fig.legend(loc="outside lower center", ncol=3, fontsize="small")
    ax.grid(True, axis="x", alpha=0.3)
    return fig


def gap_map(
    result: Diagnosis, y: np.ndarray, bins: int = _BINS
) -> dict[str, list[tuple[str, list[float]]]]:
    """Where the gap sits in the travel and in time, for the start and after each step.

    The validation samples are cut into ``bins`` equal ranges of the measured position
    (``"travel"``) and ``bins`` equal slices of time (``"time"``); for each, the contribution
    to the gap: ``sqrt(sum of squared errors there / spread)``, the same units as the gap
    (the contributions add up in squares to it). Returns ``{"travel": [(range label,
    [per model]), ...], "time": [...]}``, models in the order start, step 1, ...
    """
    val = result.split.validation
    yy = np.asarray(y, dtype=np.float64)
    y_val = yy[val]
    spread = float(np.sum((y_val - np.mean(y_val)) ** 2))
    errors = [(y_val - report.y_sim[val]) ** 2 for report in result.reports]
    edges = np.linspace(float(np.min(y_val)), float(np.max(y_val)), bins + 1)
    where = np.clip(np.searchsorted(edges, y_val, side="right") - 1, 0, bins - 1)
    slices = np.minimum(np.arange(y_val.size) * bins // y_val.size, bins - 1)
    start = val.start

    def contributions(mask: np.ndarray) -> list[float]:
        return [float(np.sqrt(np.sum(e[mask]) / spread)) if spread > 0 else 0.0 for e in errors]

    travel = [
        (f"{edges[b]:+.3f} .. {edges[b + 1]:+.3f}", contributions(where == b)) for b in range(bins)
    ]
    n_val = y_val.size
    time = [
        (
            f"{start + b * n_val // bins}..{start + (b + 1) * n_val // bins - 1}",
            contributions(slices == b),
        )
        for b in range(bins)
    ]
    return {"travel": travel, "time": time}


def plot_gap_map(result: Diagnosis, y: np.ndarray, unit: str = "rad") -> Figure:
    """The gap's contributions per range of travel and per slice of time, start and after each
    step (see :func:`gap_map`), with the floor spread evenly over the bins for comparison."""
    mapped = gap_map(result, y)
    labels = _labels(result)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), layout="constrained")
    for ax, aspect, xlabel in zip(
        axes,
        ("travel", "time"),
        (f"measured position range [{unit}]", "validation samples (sample numbers)"),
        strict=True,
    ):
        groups = mapped[aspect]
        x = np.arange(len(groups))
        width = 0.8 / len(labels)
        for i, label in enumerate(labels):
            ax.bar(
                x + (i - (len(labels) - 1) / 2) * width,
                [values[i] for _, values in groups],
                width,
                label=label,
                color="C7" if i == 0 else f"C{i - 1}",
            )
        if result.floor is not None:
            ax.axhline(
                result.floor.gap / np.sqrt(len(groups)),
                color="C3",
                ls="--",
                lw=1.0,
                label="floor, spread evenly",
            )
        ax.set_xticks(x, [name for name, _ in groups], rotation=35, ha="right", fontsize=7)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("contribution to the misfit (NRMSE)")
        ax.set_yscale("log")
        ax.set_title(f"Where the misfit sits: {aspect}", fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncol=len(names), fontsize="small")
    return fig


def _correlation_row(axes: np.ndarray, analysis: ResidualAnalysis, label: str) -> None:
    tests = (analysis.autocorrelation, analysis.cross_correlation, *analysis.higher_order)
    for ax, test in zip(axes, tests, strict=False):
        ax.vlines(test.lags, 0.0, test.values, color="C0", lw=1.5)
        ax.plot(test.lags, test.values, "o", color="C0", ms=2.5)
        ax.axhline(test.bound, color="C3", ls="--", lw=0.8)
        ax.axhline(-test.bound, color="C3", ls="--", lw=0.8)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"{label}: {test.name}\np = {test.test.p_value:.2g}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("lag [samples]", fontsize=7)
        ax.set_ylabel("correlation (normalised)", fontsize=7)


def plot_correlations(result: Diagnosis) -> Figure:
    """Residual correlation functions with their 95% bounds, start and final model."""
    first = result.rounds[0].analysis
    last = result.rounds[-1].analysis
    columns = 2 + len(first.higher_order)
    fig, axes = plt.subplots(
        2, columns, figsize=(3.2 * columns, 6.0), squeeze=False, layout="constrained"
    )
    _correlation_row(axes[0], first, "start")
    _correlation_row(axes[1], last, "final")
    fig.suptitle("Residual correlations on the estimation data (dashed: 95% bounds)", fontsize=10)
    return fig


def plot_step_error(
    shape: StepErrorShape, title: str = "starting model", unit: str = "rad"
) -> Figure:
    """The error step response with its box (dead time) and decay (lag) fits."""
    k = np.arange(shape.taps.size)
    fig, ax = plt.subplots(figsize=(7.4, 4.6), layout="constrained")
    se = shape.fir.std_errors[shape.fir.lags >= 0][: shape.taps.size]
    ax.fill_between(k, -1.96 * se, 1.96 * se, color="0.85", label="95% band of zero", zorder=1)
    ax.vlines(k, 0.0, shape.taps, color="C0", lw=2.0, label="taps g_k", zorder=3)
    box = np.where(k < shape.box_delay, shape.box_height, 0.0)
    ax.step(
        k,
        box,
        where="mid",
        color="C3",
        label=f"box, d = {shape.box_delay} ({100 * shape.box_fit:.0f}%)",
        zorder=2,
    )
    decay_scale = float(shape.taps @ shape.decay_pole**k) / float(
        (shape.decay_pole**k) @ (shape.decay_pole**k)
    )
    ax.plot(
        k,
        decay_scale * shape.decay_pole**k,
        color="C2",
        label=f"decay, a = {shape.decay_pole:.2f} ({100 * shape.decay_fit:.0f}%)",
        zorder=2,
    )
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("lag k [samples]")
    ax.set_ylabel(f"g_k: error per unit input step [{unit}/{unit}]")
    ax.set_title(
        f"Error step response of the {title}:\ndead time (box) or lag (decay)?", fontsize=10
    )
    fig.legend(loc="outside lower center", ncol=4, fontsize="small")
    ax.grid(True, alpha=0.3)
    return fig


def _map_tables(result: Diagnosis, y: np.ndarray, unit: str) -> list[Table]:
    """The gap map as tables (one per aspect)."""
    mapped = gap_map(result, y)
    labels = _labels(result)
    tables = []
    for aspect, first, caption in (
        ("travel", f"position range [{unit}]", "Per range of the measured position"),
        ("time", "validation samples", "Per slice of the validation segment"),
    ):
        rows = [[name, *(f"{v:.4f}" for v in values)] for name, values in mapped[aspect]]
        tables.append(Table([first, *labels], rows, caption=caption))
    return tables


_CAPTIONS = {
    "misfit_steps.png": "The validation misfit (free-run NRMSE on held-out data) after each step, "
    "with the floor that quantisation and noise allow.",
    "fit_steps.png": "Measured and simulated (free-run) position on the validation segment, "
    "and their difference, for the starting model and after each step.",
    "misfit_breakdown.png": "Each group's share of the squared validation error against its "
    "share of the samples, for the starting and the final model: a group whose error share "
    "exceeds its sample share is where the model misses.",
    "misfit_map.png": "Contribution to the misfit per range of travel and per slice of time "
    "(log scale; the contributions add up in squares to the misfit).",
    "correlations.png": "Residual autocorrelation, input cross-correlation and higher-order "
    "correlations of the starting and the final model, with 95% bounds of white noise.",
    "step_error.png": "The error's response to an input step (FIR taps) for the starting "
    "model, with a box fit (a dead time) and a decay fit (a lag).",
}


def report_sections(
    result: Diagnosis, figures: list[str], y: np.ndarray | None = None, unit: str = "rad"
) -> tuple[str, list[tuple[str, str]], list[Section]]:
    """The page's subtitle, summary block and sections (shared by ``index.html`` and
    ``summary.md``)."""
    split = result.split
    subtitle = (
        f"Estimation samples 0..{split.n_estimation - 1}; validation (held out) "
        f"{split.n_estimation}..{split.n_samples - 1}. Misfit = free-run NRMSE on the validation "
        "segment (unitless: the RMS error over the spread of the measured position)."
    )
    floor = result.floor
    floor_text = (
        floor.describe() + f"; the final misfit is {result.gap_final / floor.gap:.1f} times it"
        if floor is not None and floor.gap > 0
        else "not measured (no dwells to measure the noise on)"
    )
    summary = [
        ("Misfit (NRMSE)", f"{result.gap_initial:.4f} \u2192 {result.gap_final:.4f}"),
        ("Effects added", ", ".join(result.effects) or "none named"),
        ("Floor", floor_text),
        ("Stopped", result.reason),
    ]
    if result.unexplained is not None:
        summary.append(("Unexplained", result.unexplained_text()))
    if result.steps:
        rows = [
            [
                str(i),
                step.effect,
                f"{step.gap_before:.4f}",
                f"{step.gap_after:.4f}",
                f"{step.bic_change:+.1f}",
            ]
            for i, step in enumerate(result.steps, 1)
        ]
        head = ["#", "effect", "misfit before", "misfit after", "BIC change"]
        steps = Section(
            "Steps",
            tables=[Table(head, rows, numeric_from=2)],
            items=[f"{step.effect}: {step.evidence}" for step in result.steps],
        )
    else:
        steps = Section("Steps", paragraphs=["No missing effect named."])
    where = Section(
        "Where the misfit sits",
        items=[
            f"start: {result.reports[0].describe()}",
            f"final: {result.reports[-1].describe()}",
        ],
        paragraphs=(
            [
                "Contribution to the misfit (they add up in squares to it) per range of the "
                "measured position and per slice of the validation segment, for the start and "
                "after each step."
            ]
            if y is not None
            else []
        ),
        tables=_map_tables(result, y, unit) if y is not None else [],
    )
    residual = Section(
        "Residual tests (estimation data)",
        items=[
            f"start: {result.rounds[0].analysis.summary()}",
            f"final: {result.rounds[-1].analysis.summary()}",
        ],
    )
    rounds = []
    for i, rnd in enumerate(result.rounds, 1):
        items = [] if rnd.detections else ["residual consistent with noise; no detector run"]
        for found in rnd.detections:
            mark = "fires" if found.fires else "quiet"
            items.append(f"{found.effect} ({mark}): {found.evidence}")
        for trial in rnd.trials:
            items.append(f"tried {trial.effect}: {trial.verdict}")
        rounds.append(Section(f"Round {i} (misfit {rnd.gap:.4f})", items=items))
    detectors = Section("Detectors per round", subsections=rounds)
    model = Section("Final model", code=json.dumps(result.model_dict(), indent=2))
    plots = Section(
        "Figures", figures=[PageFigure(name, _CAPTIONS.get(name, name)) for name in figures]
    )
    return subtitle, summary, [steps, where, plots, residual, detectors, model]


_TITLE = "Backlash model diagnosis"


def summary_markdown(
    result: Diagnosis, figures: list[str], y: np.ndarray | None = None, unit: str = "rad"
) -> str:
    """The readable summary as Markdown: the same sections as the page ``index.html``."""
    return _markdown(*report_sections(result, figures, y, unit))


def _markdown(subtitle: str, summary: list[tuple[str, str]], sections: list[Section]) -> str:
    """summary.md from the page's parts."""
    return render(
        "summary.md",
        title=_TITLE,
        subtitle=subtitle,
        summary=summary,
        alerts=[],
        sections=sections,
    )


def write_report(
    result: Diagnosis,
    u: np.ndarray,
    y: np.ndarray,
    out_dir: str | Path,
    breaks: np.ndarray | None = None,
    *,
    t: np.ndarray | None = None,
    unit: str = "rad",
    progress: Callable[[str], None] | None = None,
) -> list[Path]:
    """Write the plots, ``index.html`` and ``summary.md`` into ``out_dir``; return the paths
    (``breaks``: the sample rule the diagnosis ran with; ``t``: each sample's time in
    seconds, for the time axes; ``unit``: the unit of the positions; ``progress``: called
    with each stage, for a progress line)."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    uu = np.asarray(u, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    est = result.split.estimation
    b_est = None if breaks is None else np.asarray(breaks, dtype=bool)[est]
    context = build_context(uu[est], yy[est], result.initial_fit, DiagnoseSettings(), b_est)
    makers: dict[str, Callable[[], Figure]] = {
        "misfit_steps.png": lambda: plot_gap_steps(result),
        "fit_steps.png": lambda: plot_fit_steps(result, yy, t, unit),
        "misfit_breakdown.png": lambda: plot_gap_breakdown(result),
        "misfit_map.png": lambda: plot_gap_map(result, yy, unit),
        "correlations.png": lambda: plot_correlations(result),
        "step_error.png": lambda: plot_step_error(context.step_error, unit=unit),
    }
    written = []
    for k, (name, make) in enumerate(makers.items(), 1):
        if progress is not None:
            progress(f"report: figure {k} of {len(makers)}")
        fig = make()
        path = directory / name
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    subtitle, summary, sections = report_sections(result, list(makers), yy, unit)
    markdown = _markdown(subtitle, summary, sections)
    (directory / "summary.md").write_text(markdown, encoding="utf-8")
    index = write_page(
        directory / "index.html",
        title=_TITLE,
        subtitle=subtitle,
        summary=summary,
        sections=sections,
    )
    written += [directory / "summary.md", index]
    return written
