"""Plots of identification results (matplotlib, Agg backend; the core stays plot-free)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_core import (
    Cascade,
    GeneralBacklash,
    IdentificationResult,
    IterationHistory,
)

__all__ = ["plot_characteristic", "plot_history", "save_identification_plots"]


def _backlash_of(model: GeneralBacklash | Cascade) -> GeneralBacklash:
    return model.backlash if isinstance(model, Cascade) else model


def plot_characteristic(
    estimate: GeneralBacklash | Cascade,
    u_range: tuple[float, float],
    truth: GeneralBacklash | Cascade | None = None,
    data: tuple[np.ndarray, np.ndarray] | None = None,
) -> Figure:
    """The two branches of the estimate (and the truth) over ``u_range``, like Figs. 3, 5, 8, 11.

    ``data`` is an optional ``(u, x)`` scatter of measured backlash outputs.
    """
    u = np.linspace(u_range[0], u_range[1], 400)
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    if data is not None:
        ax.plot(data[0], data[1], ".", color="0.75", markersize=2, label="measured", zorder=1)
    est = _backlash_of(estimate)
    ax.plot(u, est.left(u), color="C0", label="estimate: left branch L(u)")
    ax.plot(u, est.right(u), color="C1", label="estimate: right branch R(u)")
    if truth is not None:
        tru = _backlash_of(truth)
        ax.plot(u, tru.left(u), "--", color="k", linewidth=1, label="truth")
        ax.plot(u, tru.right(u), "--", color="k", linewidth=1)
    ax.set_xlabel("input u")
    ax.set_ylabel("backlash output x")
    ax.set_title("General backlash characteristic")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


def plot_history(history: IterationHistory, truth: np.ndarray | None = None) -> Figure:
    """Parameter estimates per iteration (the paper's Figs. 4, 6, 9, 10, 12).

    ``truth``, in the order of ``history.names``, draws each true value as a dotted line.
    """
    names = history.names
    linear = [i for i, n in enumerate(names) if n.startswith(("a_", "b_"))]
    backlash = [i for i in range(len(names)) if i not in linear]
    panels = [backlash] + ([linear] if linear else [])
    fig, axes = plt.subplots(1, len(panels), figsize=(6.4 * len(panels), 4.8), squeeze=False)
    steps = np.arange(history.values.shape[0])
    titles = ["Backlash parameter estimates", "Linear block parameter estimates"]
    for ax, indices, title in zip(axes[0], panels, titles, strict=False):
        for k, i in enumerate(indices):
            color = f"C{k % 10}"
            ax.plot(steps, history.values[:, i], "o-", color=color, markersize=3, label=names[i])
            if truth is not None:
                ax.axhline(truth[i], color=color, linestyle=":", linewidth=1)
        ax.set_xlabel("iteration")
        ax.set_ylabel("estimate")
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="x-small", ncol=2)
    fig.tight_layout()
    return fig


def save_identification_plots(
    result: IdentificationResult,
    out_dir: str | Path,
    u: np.ndarray,
    y: np.ndarray,
    truth: GeneralBacklash | Cascade | None = None,
) -> list[Path]:
    """Write ``characteristic.png`` and ``history.png`` into ``out_dir``; return the paths."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    span = (float(np.min(u)), float(np.max(u)))
    data = None if isinstance(result.model, Cascade) else (u, y)
    written = []
    fig = plot_characteristic(result.model, span, truth, data)
    written.append(directory / "characteristic.png")
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)
    truth_values = truth.parameters() if truth is not None else None
    fig = plot_history(result.history, truth_values)
    written.append(directory / "history.png")
    fig.savefig(written[-1], dpi=120)
    plt.close(fig)
    return written
