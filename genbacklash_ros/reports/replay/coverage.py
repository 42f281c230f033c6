"""The replay report's branch coverage: which part of the command range each branch was
engaged over, as a figure and a sentence.
"""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_core import GenBacklashError, GeneralBacklash, simulate_backlash
from genbacklash_ros.bags.replay import ReplayResult

from .axes import no_data
from .data import COLORS, ReportData, report_data

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
            no_data(ax, "not enough samples")
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
    hx.bar(centres, right, width, color=COLORS["right"], label="right branch R (u increasing)")
    hx.bar(centres, -left, width, color=COLORS["left"], label="left branch L (u decreasing)")
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
            ("R", model.right(grid) - grid, seen_r, COLORS["right"]),
            ("L", model.left(grid) - grid, seen_l, COLORS["left"]),
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
        no_data(cx, "no model to draw")
    cx.axhline(0.0, color="k", lw=0.6)
    cx.set_xlabel("command u [rad]")
    cx.set_ylabel("branch position - u [rad]")
    cx.legend(loc="best", fontsize="small")
    for ax in (hx, cx):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


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
