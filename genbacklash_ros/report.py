"""The HTML report of a replay: PNG plots (matplotlib, Agg) and an ``index.html``.

:func:`write_report` writes into a directory

* ``characteristic.png``: the final estimate's branches over the command range, with the
  aligned samples (command held, encoder) as a scatter;
* ``convergence.png``: every parameter over data time with a +/-2 sigma band from the
  estimate's covariance;
* ``residuals.png``: encoder minus the final model's free-run simulation over the aligned
  samples, and its histogram;
* ``compensation.png``: raw and compensated command over time;
* ``index.html``: the four plots, the final parameter table (estimate, 2 sigma) and the
  replay's counters.
"""

from __future__ import annotations

import html
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from .bagio import align
from .plots import plot_characteristic
from .replay import ReplayResult

__all__ = [
    "plot_compensation",
    "plot_convergence",
    "plot_residuals",
    "write_report",
]

_DPI = 110


def _seconds(t: list[int] | np.ndarray, origin: int) -> np.ndarray:
    return (np.asarray(t, dtype=np.int64) - origin) / 1e9


def plot_convergence(result: ReplayResult) -> Figure:
    """Each parameter over data time with a +/-2 sigma band (estimate covariance)."""
    hist = result.history
    names = hist.names
    t, values, std = hist.parameters()
    cols = 4
    rows = max(1, -(-len(names) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.4 * rows), squeeze=False)
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
            if final.size:  # keep early wild values from flattening the plot
                lo, hi = np.percentile(final, [5, 100])
                pad = 0.5 * (hi - lo) + 0.05 * max(abs(hi), 1e-3)
                ax.set_ylim(lo - pad, hi + pad)
        ax.set_title(names[i], fontsize="small")
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize="x-small")
    fig.supxlabel("data time since the first estimate [s]", fontsize="small")
    fig.suptitle("Parameter convergence (band: +/-2 sigma)", fontsize="medium")
    fig.tight_layout()
    return fig


def _aligned(result: ReplayResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    hist = result.history
    if not hist.command_t or not hist.encoder_t:
        return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    order = np.argsort(np.asarray(hist.command_t, dtype=np.int64), kind="stable")
    series = align(
        np.asarray(hist.command_t, dtype=np.int64)[order],
        np.asarray(hist.command_raw)[order],
        np.asarray(hist.encoder_t, dtype=np.int64),
        np.asarray(hist.encoder_y),
    )
    return series.t, series.u, series.y


def plot_residuals(result: ReplayResult) -> Figure:
    """Encoder minus the final model's free-run simulation, over time and as a histogram."""
    t, u, y = _aligned(result)
    model = result.estimate.model
    fig, (ax, hx) = plt.subplots(
        1, 2, figsize=(10, 3.6), gridspec_kw={"width_ratios": [3, 1]}, squeeze=True
    )
    if model is not None and t.size:
        sim = model.simulate(u, float(y[0]))
        res = y - sim
        ts = _seconds(t, int(t[0]))
        ax.plot(ts, res, ".", markersize=1.5, color="C3")
        hx.hist(res, bins=60, color="C3", alpha=0.8)
        rms = float(np.sqrt(np.mean(res**2)))
        ax.set_title(f"Free-run residual of the final model (RMS {rms:.4g})", fontsize="small")
    else:
        ax.set_title("no model estimated: no residuals", fontsize="small")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("encoder - model")
    hx.set_xlabel("residual")
    for a in (ax, hx):
        a.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def plot_compensation(result: ReplayResult) -> Figure:
    """Raw and compensated command over time."""
    hist = result.history
    fig, ax = plt.subplots(figsize=(10, 3.6))
    if hist.command_t:
        t = _seconds(hist.command_t, hist.command_t[0])
        ax.step(t, hist.command_raw, where="post", lw=0.8, color="0.5", label="raw command")
        ax.step(t, hist.command_sent, where="post", lw=0.8, color="C2", label="compensated")
        if t.size > 400:  # show the last second or so in detail
            ax.set_xlim(max(float(t[-1]) - 1.0, 0.0), float(t[-1]))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("command")
    ax.set_title("Inverse-backlash compensation (last second)", fontsize="small")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


def _characteristic(result: ReplayResult) -> Figure:
    model = result.estimate.model
    _, u, y = _aligned(result)
    if model is None or u.size == 0:
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        ax.set_title("no model estimated")
        if u.size:
            ax.plot(u, y, ".", color="0.6", markersize=2)
        return fig
    span = (float(np.min(u)), float(np.max(u)))
    return plot_characteristic(model, span, None, (u, y))


def _table(result: ReplayResult) -> str:
    est = result.estimate
    rows = "\n".join(
        f"<tr><td>{html.escape(n)}</td><td>{v:.5f}</td><td>{2 * s:.5f}</td></tr>"
        for n, v, s in zip(est.names, est.parameters, est.std(), strict=True)
    )
    return (
        "<table><thead><tr><th>parameter</th><th>estimate</th><th>&plusmn;2&sigma;</th>"
        f"</tr></thead><tbody>\n{rows}\n</tbody></table>"
    )


def _page(result: ReplayResult, images: list[tuple[str, str]]) -> str:
    est = result.estimate
    stats = result.stats
    dropped = ", ".join(f"{k}: {n}" for k, n in stats.dropped.items() if n) or "none"
    error = f'<p class="err">Stopped early: {html.escape(result.error)}</p>' if result.error else ""
    figures = "\n".join(
        f'<figure><img src="{name}" alt="{html.escape(caption)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        for name, caption in images
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>genbacklash replay report</title>
<style>
body {{ font-family: sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }}
table {{ border-collapse: collapse; }} td, th {{ padding: 2px 12px; text-align: right; }}
th {{ border-bottom: 1px solid #999; }} td:first-child {{ text-align: left; }}
img {{ max-width: 100%; }} .err {{ color: #b00; }}
</style></head><body>
<h1>Backlash replay report</h1>
<p>Output bag <code>{html.escape(str(result.output))}</code>;
model <b>{html.escape(result.params.model)}</b>, degree {result.params.degree},
method {html.escape(result.params.method)}.</p>
{error}
<h2>Final estimate</h2>
<p>State <b>{html.escape(est.state.value)}</b>, confidence {est.confidence:.2f},
{est.samples} samples. {html.escape(est.reason)}</p>
{_table(result)}
<p>{result.messages_in} messages replayed, {stats.compensated} compensated commands,
{result.messages_out} messages written; dropped: {html.escape(dropped)}.</p>
<h2>Plots</h2>
{figures}
</body></html>
"""


def write_report(result: ReplayResult, out_dir: str | Path) -> Path:
    """Write the plots and ``index.html`` into ``out_dir``; return the page's path."""
    directory = Path(out_dir)
    directory.mkdir(parents=True, exist_ok=True)
    plots = [
        ("characteristic.png", "Characteristic: estimated branches and data", _characteristic),
        ("convergence.png", "Parameter convergence with +/-2 sigma bands", plot_convergence),
        ("residuals.png", "Residuals of the final model", plot_residuals),
        ("compensation.png", "Raw vs compensated command", plot_compensation),
    ]
    images = []
    for name, caption, make in plots:
        fig = make(result)
        fig.savefig(directory / name, dpi=_DPI)
        plt.close(fig)
        images.append((name, caption))
    index = directory / "index.html"
    index.write_text(_page(result, images), encoding="utf-8")
    return index
