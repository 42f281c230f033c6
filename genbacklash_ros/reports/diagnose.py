"""The ``genbacklash diagnose --report DIR`` report: plots and a readable summary.

Plot functions return figures (compute and plotting split, as in python-control);
:func:`write_report` saves them with ``summary.md`` and ``report.html`` into a directory.
"""

from __future__ import annotations

import html
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_core.diagnose import Diagnosis, ResidualAnalysis
from genbacklash_core.diagnose.context import StepErrorShape, build_context
from genbacklash_core.diagnose.settings import DiagnoseSettings

__all__ = [
    "gap_map",
    "plot_correlations",
    "plot_fit_steps",
    "plot_gap_breakdown",
    "plot_gap_map",
    "plot_gap_steps",
    "plot_step_error",
    "summary_markdown",
    "write_report",
]

_WINDOW = 600  # validation samples shown in the measured-vs-simulated panels
_BINS = 8  # travel bins and time slices of the gap map


def _labels(result: Diagnosis) -> list[str]:
    return ["start"] + [f"+ {step.effect}" for step in result.steps]


def plot_fit_steps(result: Diagnosis, y: np.ndarray) -> Figure:
    """Measured vs simulated output on the validation segment, before and after each step."""
    val = result.split.validation
    start = val.start
    stop = min(val.stop, start + _WINDOW)
    t = np.arange(start, stop)
    labels = _labels(result)
    fig, axes = plt.subplots(
        len(result.reports), 1, figsize=(9, 2.4 * len(result.reports)), sharex=True, squeeze=False
    )
    for ax, report, label in zip(axes[:, 0], result.reports, labels, strict=True):
        ax.plot(t, y[start:stop], color="0.6", lw=1.0, label="measured")
        ax.plot(t, report.y_sim[start:stop], color="C0", lw=1.2, label="simulated (free run)")
        ax.plot(t, y[start:stop] - report.y_sim[start:stop], color="C3", lw=0.8, label="error")
        ax.set_title(f"{label}: validation gap {report.gap:.4f}", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.set_ylabel("y")
    axes[0, 0].legend(loc="upper right", fontsize="small", ncol=3)
    axes[-1, 0].set_xlabel("sample (validation segment)")
    fig.tight_layout()
    return fig


def plot_gap_steps(result: Diagnosis) -> Figure:
    """The validation gap per step as a bar chart."""
    labels = _labels(result)
    gaps = [report.gap for report in result.reports]
    fig, ax = plt.subplots(figsize=(max(4.0, 1.6 * len(gaps)), 3.6))
    bars = ax.bar(labels, gaps, color=["C7"] + ["C0"] * (len(gaps) - 1))
    for bar, gap in zip(bars, gaps, strict=True):
        ax.annotate(
            f"{gap:.4f}",
            (bar.get_x() + bar.get_width() / 2, bar.get_height()),
            ha="center",
            va="bottom",
            fontsize=9,
        )
    if result.floor is not None:
        floor = result.floor
        ax.axhline(floor.gap, color="C3", ls="--", lw=1.0)
        ax.annotate(
            f"floor {floor.gap:.4f}" + ("" if floor.known else " (quantisation only)"),
            (len(gaps) - 0.5, floor.gap),
            ha="right",
            va="bottom",
            fontsize=8,
            color="C3",
        )
    ax.set_ylabel("validation gap (NRMSE)")
    ax.set_title("Gap per step (dashed: what quantisation and noise allow)")
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    return fig


def plot_gap_breakdown(result: Diagnosis) -> Figure:
    """Where the gap sits: each group's share of the squared error against its share of the
    samples, for the starting and the final model."""
    first, last = result.reports[0], result.reports[-1]
    names = [f"{g.aspect}: {g.label}" for g in first.groups]
    y_pos = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(names) + 1.5))
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
        label=f"share of error, start (gap {first.gap:.3f})",
    )
    ax.barh(
        y_pos + 0.27,
        [g.error_share for g in last.groups],
        0.27,
        color="C0",
        label=f"share of error, final (gap {last.gap:.3f})",
    )
    ax.set_yticks(y_pos, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("share")
    ax.set_title("Where the validation gap concentrates")
    ax.legend(fontsize="small", loc="lower right")
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
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


def plot_gap_map(result: Diagnosis, y: np.ndarray) -> Figure:
    """The gap's contributions per range of travel and per slice of time, start and after each
    step (see :func:`gap_map`), with the floor spread evenly over the bins for comparison."""
    mapped = gap_map(result, y)
    labels = _labels(result)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.0))
    for ax, aspect, title in zip(
        axes, ("travel", "time"), ("position (measured)", "validation samples"), strict=True
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
        ax.set_xlabel(title)
        ax.set_ylabel("contribution to the gap")
        ax.set_yscale("log")
        ax.set_title(f"Where the gap sits: {aspect}", fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].legend(fontsize="small")
    fig.tight_layout()
    return fig


def _map_lines(result: Diagnosis, y: np.ndarray) -> list[str]:
    """The gap map as Markdown tables."""
    mapped = gap_map(result, y)
    labels = _labels(result)
    lines: list[str] = []
    for aspect, first in (("travel", "position range"), ("time", "validation samples")):
        lines += [
            f"| {first} | " + " | ".join(labels) + " |",
            "|---|" + "---|" * len(labels),
        ]
        for name, values in mapped[aspect]:
            lines.append(f"| {name} | " + " | ".join(f"{v:.4f}" for v in values) + " |")
        lines.append("")
    return lines


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
        ax.set_xlabel("lag", fontsize=7)


def plot_correlations(result: Diagnosis) -> Figure:
    """Residual correlation functions with their 95% bounds, start and final model."""
    first = result.rounds[0].analysis
    last = result.rounds[-1].analysis
    columns = 2 + len(first.higher_order)
    fig, axes = plt.subplots(2, columns, figsize=(3.0 * columns, 5.6), squeeze=False)
    _correlation_row(axes[0], first, "start")
    _correlation_row(axes[1], last, "final")
    fig.suptitle("Residual correlations on the estimation data (dashed: 95% bounds)", fontsize=10)
    fig.tight_layout()
    return fig


def plot_step_error(shape: StepErrorShape, title: str = "starting model") -> Figure:
    """The error step response with its box (dead time) and decay (lag) fits."""
    k = np.arange(shape.taps.size)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    ax.vlines(k, 0.0, shape.taps, color="C0", lw=2.0, label="taps g_k")
    se = shape.fir.std_errors[shape.fir.lags >= 0][: shape.taps.size]
    ax.fill_between(k, -1.96 * se, 1.96 * se, color="0.85", label="95% band of zero")
    box = np.where(k < shape.box_delay, shape.box_height, 0.0)
    ax.step(
        k,
        box,
        where="mid",
        color="C3",
        label=f"box, d = {shape.box_delay} ({100 * shape.box_fit:.0f}%)",
    )
    decay_scale = float(shape.taps @ shape.decay_pole**k) / float(
        (shape.decay_pole**k) @ (shape.decay_pole**k)
    )
    ax.plot(
        k,
        decay_scale * shape.decay_pole**k,
        color="C2",
        label=f"decay, a = {shape.decay_pole:.2f} ({100 * shape.decay_fit:.0f}%)",
    )
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("lag k")
    ax.set_ylabel("g_k")
    ax.set_title(f"Error step response of the {title}: dead time (box) or lag (decay)?", fontsize=9)
    ax.legend(fontsize="small")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def summary_markdown(result: Diagnosis, figures: list[str], y: np.ndarray | None = None) -> str:
    """The readable summary: steps with evidence, the gaps against the floor, where the gap
    sits (in the travel and in time, when ``y`` is given), the model."""
    split = result.split
    lines = [
        "# Backlash model diagnosis",
        "",
        f"Estimation samples 0..{split.n_estimation - 1}; validation (held out) "
        f"{split.n_estimation}..{split.n_samples - 1}. Gap = free-run NRMSE on the validation "
        "segment.",
        "",
        f"**Gap: {result.gap_initial:.4f} -> {result.gap_final:.4f}** "
        f"({', '.join(result.effects) or 'no effect named'}).",
        "",
        (
            "The floor: " + result.floor.describe() + ". "
            f"The final gap is {result.gap_final / result.floor.gap:.1f} times it."
            if result.floor is not None and result.floor.gap > 0
            else "The floor (what quantisation and noise allow) was not measured."
        ),
        "",
        "## Steps",
        "",
    ]
    if result.steps:
        lines += ["| # | effect | gap before | gap after | BIC change |", "|---|---|---|---|---|"]
        for i, step in enumerate(result.steps, 1):
            lines.append(
                f"| {i} | `{step.effect}` | {step.gap_before:.4f} | {step.gap_after:.4f} | "
                f"{step.bic_change:+.1f} |"
            )
        lines.append("")
        for i, step in enumerate(result.steps, 1):
            lines += [f"{i}. **{step.effect}**: {step.evidence}", ""]
    else:
        lines += ["No missing effect named.", ""]
    lines += [f"Stopped: {result.reason}.", "", "## Where the gap sits", ""]
    lines += [f"* start: {result.reports[0].describe()}"]
    lines += [f"* final: {result.reports[-1].describe()}", ""]
    if y is not None:
        lines += [
            "Contribution to the gap (they add up in squares to it) per range of the measured "
            "position and per slice of the validation segment, for the start and after each "
            "step:",
            "",
        ]
        lines += _map_lines(result, y)
    lines += ["## Residual tests (estimation data)", ""]
    lines += [f"* start: {result.rounds[0].analysis.summary()}"]
    lines += [f"* final: {result.rounds[-1].analysis.summary()}", ""]
    lines += ["## Detectors per round", ""]
    for i, rnd in enumerate(result.rounds, 1):
        lines.append(f"Round {i} (gap {rnd.gap:.4f}):")
        lines.append("")
        if not rnd.detections:
            lines.append("* residual consistent with noise; no detector run")
        for found in rnd.detections:
            mark = "fires" if found.fires else "quiet"
            lines.append(f"* `{found.effect}` ({mark}): {found.evidence}")
        for trial in rnd.trials:
            lines.append(f"  * tried `{trial.effect}`: {trial.verdict}")
        lines.append("")
    lines += ["## Final model", "", "```json"]
    import json

    lines += [json.dumps(result.model_dict(), indent=2), "```", "", "## Figures", ""]
    lines += [f"![{name}]({name})" for name in figures]
    return "\n".join(lines) + "\n"


def _html(markdown: str) -> str:
    """A minimal HTML rendering of the summary (headings, images, paragraphs)."""
    body = []
    in_code = False
    for line in markdown.splitlines():
        if line.startswith("```"):
            body.append("</pre>" if in_code else "<pre>")
            in_code = not in_code
        elif in_code:
            body.append(html.escape(line))
        elif line.startswith("# "):
            body.append(f"<h1>{html.escape(line[2:])}</h1>")
        elif line.startswith("## "):
            body.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line.startswith("!["):
            name = line[line.index("(") + 1 : -1]
            body.append(f'<p><img src="{html.escape(name)}" style="max-width:100%"></p>')
        elif line.strip():
            body.append(f"<p>{html.escape(line)}</p>")
    return (
        "<!DOCTYPE html>\n<html><head><meta charset='utf-8'><title>Backlash diagnosis</title>"
        "</head><body style='font-family:sans-serif;max-width:60em;margin:auto'>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )


def write_report(
    result: Diagnosis,
    u: np.ndarray,
    y: np.ndarray,
    out_dir: str | Path,
    breaks: np.ndarray | None = None,
) -> list[Path]:
    """Write the plots, ``summary.md`` and ``report.html`` into ``out_dir``; return the paths
    (``breaks``: the sample rule the diagnosis ran with)."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    uu = np.asarray(u, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    est = result.split.estimation
    b_est = None if breaks is None else np.asarray(breaks, dtype=bool)[est]
    context = build_context(uu[est], yy[est], result.initial_fit, DiagnoseSettings(), b_est)
    figures = {
        "fit_steps.png": plot_fit_steps(result, yy),
        "gap_steps.png": plot_gap_steps(result),
        "gap_breakdown.png": plot_gap_breakdown(result),
        "gap_map.png": plot_gap_map(result, yy),
        "correlations.png": plot_correlations(result),
        "step_error.png": plot_step_error(context.step_error),
    }
    written = []
    for name, fig in figures.items():
        path = directory / name
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    markdown = summary_markdown(result, list(figures), yy)
    (directory / "summary.md").write_text(markdown, encoding="utf-8")
    (directory / "report.html").write_text(_html(markdown), encoding="utf-8")
    written += [directory / "summary.md", directory / "report.html"]
    return written
