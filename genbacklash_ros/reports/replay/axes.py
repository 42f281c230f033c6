"""Drawing helpers the replay report's figures share: per-pixel-column envelopes, legend
room, the phases of a chained scenario, the zoomed lower panel, an empty panel's note.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from genbacklash_ros.bags.simbags import BagTruth

from .data import BINS


def _envelope(
    t: np.ndarray, v: np.ndarray, span: tuple[float, float], *, hold: bool, bins: int = BINS
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


def band(
    ax: Axes,
    t: np.ndarray,
    v: np.ndarray,
    span: tuple[float, float],
    *,
    hold: bool,
    color: str,
    label: str,
    alpha: float = 0.3,
    bins: int = BINS,
) -> None:
    c, lo, hi = _envelope(t, v, span, hold=hold, bins=bins)
    ax.fill_between(c, lo, hi, step="mid", color=color, alpha=alpha, lw=0)
    ax.plot(c, lo, color=color, lw=0.8, drawstyle="steps-mid", label=label)
    ax.plot(c, hi, color=color, lw=0.8, drawstyle="steps-mid")


def headroom(ax: Axes, share: float = 0.2) -> None:
    """Room above the data for a legend."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + share * (hi - lo))


def mark_phases(ax: Axes, truth: BagTruth | None, *, label: bool = True) -> None:
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


def finish_zoom(
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


def no_data(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")
