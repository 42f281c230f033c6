"""The replay report's compensation: the raw and compensated commands, and when the node's
``/diagnostics`` said compensation was on, faded or off, and why.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_ros.bags.replay import ReplayResult
from genbacklash_ros.reports.page import Section, Table

from .axes import no_data
from .data import ReportData, report_data, seconds_from


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
        no_data(ax, "no command")
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
    t = seconds_from(h.compensation_t, h.compensation_t[0])
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
        t = seconds_from(h.compensation_t, h.compensation_t[0])
        weight = np.array([c.weight for c in h.compensation])
        ax.step(t, weight, where="post", color="k", lw=1.2, label="share of the inverse applied")
        for a, b, state, _ in compensation_spans(result):
            ax.axvspan(a, max(b, a + 1e-3), color=_STATE_COLOURS.get(state, "0.5"), alpha=0.15)
        for state, colour in _STATE_COLOURS.items():
            ax.fill_between([], [], color=colour, alpha=0.15, label=f"compensation {state}")
        ax.set_ylim(-0.05, 1.05)
        ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.3), ncol=4, fontsize="small")
    else:
        no_data(ax, "no /diagnostics report")
    ax.set_xlabel("data time [s]")
    ax.set_ylabel("weight [0-1]")
    ax.set_title("Compensation over the record: on, faded or off", fontsize="medium")
    ax.grid(True, alpha=0.3)
    return fig


def compensation_summary(result: ReplayResult) -> str:
    """One line: how the compensation ended, and why."""
    h = result.history
    if not h.compensation:
        return "no /diagnostics report"
    last = h.compensation[-1]
    return f"{last.state} at the end (weight {last.weight:.2f}): {last.reason}"
