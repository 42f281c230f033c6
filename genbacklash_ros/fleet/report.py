"""The fleet page: drivetrains ranked by time to service (HTML + PNG, matplotlib Agg).

:func:`write_fleet_report` writes into a directory:

* ``index.html``: the ranking table (days to service with its interval, crossing date, wear
  rate, the last gap, bags used and the other statuses) and the plots;
* ``fleet.png``: days to service per drivetrain with the crossing interval, the limit's
  day marked;
* ``drivetrain-<robot>-<joint>.png``: the gap against time with 2-sigma bars, the fitted trend
  with its 95 % band carried to the crossing, the limit, and the crossing date with its
  interval;
* ``summary.json``: :meth:`~genbacklash_ros.fleet.summary.FleetSummary.to_json`.
"""

from __future__ import annotations

import datetime as dt
import html
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from genbacklash_ros.fleet.summary import DAY_NS, DrivetrainSummary, FleetSummary

__all__ = ["plot_drivetrain", "plot_fleet", "write_fleet_report"]


def _dates(ns: np.ndarray) -> np.ndarray:
    return np.array(
        [dt.datetime.fromtimestamp(x / 1e9, tz=dt.timezone.utc).replace(tzinfo=None) for x in ns]
    )


def _file_name(d: DrivetrainSummary) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{d.robot}-{d.joint}").strip("_") or "drivetrain"
    return f"drivetrain-{safe}.png"


def plot_drivetrain(d: DrivetrainSummary, gap_limit: float) -> Figure:
    """The gap of one drivetrain against time, with its trend and crossing."""
    fig, ax = plt.subplots(figsize=(8, 4.2), layout="constrained")
    if d.t_ns:
        t = np.array(d.t_ns, dtype=np.int64)
        ax.errorbar(
            _dates(t),
            np.array(d.gap) * 1e3,
            yerr=2 * np.nan_to_num(np.array(d.gap_std)) * 1e3,
            fmt="o",
            ms=4,
            color="C0",
            label="gap per bag (2 sigma)",
        )
        end = max(t[-1], d.crossing_high_ns or d.crossing_ns or t[-1])
        end = min(end, t[-1] + 4 * max(t[-1] - t[0], DAY_NS))
        grid = np.linspace(t[0], end, 200)
        line, sd = d.trend_line(grid)
        if np.all(np.isfinite(line)):
            ax.plot(_dates(grid), line * 1e3, color="C1", label="trend")
            ax.fill_between(
                _dates(grid),
                (line - 2 * sd) * 1e3,
                (line + 2 * sd) * 1e3,
                color="C1",
                alpha=0.2,
                label="trend, 2 sigma",
            )
    ax.axhline(gap_limit * 1e3, color="C3", ls="--", label=f"limit {gap_limit * 1e3:.1f} mrad")
    if d.crossing_ns is not None:
        ax.axvline(_dates(np.array([d.crossing_ns]))[0], color="C3", lw=1)
        if d.crossing_low_ns is not None and d.crossing_high_ns is not None:
            lo, hi = _dates(np.array([d.crossing_low_ns, d.crossing_high_ns]))
            ax.axvspan(lo, hi, color="C3", alpha=0.1, label="crossing interval")
    ax.set_title(f"{d.robot} / {d.joint}: gap c_L + c_R over time")
    ax.set_ylabel("gap [mrad]")
    ax.legend(fontsize=8, loc="upper left")
    fig.autofmt_xdate()
    return fig


def plot_fleet(summary: FleetSummary) -> Figure:
    """Days to service per drivetrain (ranked), with the crossing intervals."""
    ranked = list(summary.drivetrains)
    fig, ax = plt.subplots(figsize=(8, 0.8 + 0.35 * max(len(ranked), 1)), layout="constrained")
    labels = [f"{d.rank}. {d.robot}/{d.joint}" for d in ranked]
    y = np.arange(len(ranked))[::-1]
    as_of = summary.as_of_ns or 0
    for yi, d in zip(y, ranked, strict=True):
        if d.days_to_service is None:
            ax.text(0, yi, "  no crossing predicted", va="center", fontsize=8, color="0.4")
            continue
        color = "C3" if d.days_to_service < 0 else "C0"
        ax.barh(yi, d.days_to_service, color=color, alpha=0.7)
        if d.crossing_low_ns is not None and d.crossing_high_ns is not None:
            lo = (d.crossing_low_ns - as_of) / DAY_NS
            hi = (d.crossing_high_ns - as_of) / DAY_NS
            ax.plot([lo, hi], [yi, yi], color="k", lw=1.5)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlabel(f"days to service (gap reaches {summary.gap_limit * 1e3:.1f} mrad)")
    ax.set_title("Fleet: drivetrains ranked by time to service (bars: estimate; lines: interval)")
    return fig


def _fmt(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    return "&ndash;" if value is None else f"{value * scale:.{digits}g}"


def _date(ns: int | None) -> str:
    if ns is None:
        return "&ndash;"
    return dt.datetime.fromtimestamp(ns / 1e9, tz=dt.timezone.utc).strftime("%Y-%m-%d")


def write_fleet_report(summary: FleetSummary, out: str | Path) -> Path:
    """Write the fleet page into ``out`` (created); returns the path of ``index.html``."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "summary.json").write_text(summary.to_json() + "\n", encoding="utf-8")
    fig = plot_fleet(summary)
    fig.savefig(folder / "fleet.png", dpi=100)
    plt.close(fig)
    rows = []
    figures = []
    for d in summary.drivetrains:
        name = _file_name(d)
        fig = plot_drivetrain(d, summary.gap_limit)
        fig.savefig(folder / name, dpi=90)
        plt.close(fig)
        other = ", ".join(f"{n} {s}" for s, n in d.statuses.items() if s != "ok") or "&ndash;"
        interval = (
            f"{_date(d.crossing_low_ns)} &ndash; {_date(d.crossing_high_ns)}"
            if d.crossing_low_ns is not None
            else "unbounded"
        )
        last_gap = d.gap[-1] if d.gap else None
        rows.append(
            f"<tr><td>{d.rank}</td><td>{html.escape(d.robot)}</td><td>{html.escape(d.joint)}</td>"
            f"<td>{_fmt(d.days_to_service, digits=3)}</td><td>{_date(d.crossing_ns)}</td>"
            f"<td>{interval}</td><td>{_fmt(d.wear_rate_per_day, 1e3)} &plusmn; "
            f"{_fmt(d.wear_rate_std, 1e3, 2)}</td><td>{_fmt(last_gap, 1e3, 4)}</td>"
            f"<td>{d.bags_used}</td><td>{html.escape(other)}</td>"
            f"<td>{html.escape(d.note)}</td></tr>"
        )
        figures.append(
            f'<figure><img src="{name}" alt="gap of {html.escape(d.robot)}/'
            f'{html.escape(d.joint)}"></figure>'
        )
    level = f"{summary.level:.0%}"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>genbacklash fleet report</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}
table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:2px 6px;font-size:90%}}
img{{max-width:100%}}</style></head><body>
<h1>Fleet wear: time to service</h1>
<p>Gap limit {summary.gap_limit * 1e3:.2f} mrad (c_L + c_R); days to service counted from
{_date(summary.as_of_ns)} (the newest bag); crossing intervals at {level} (Fieller, from the
fitted line's band). Wear rate in mrad per day &plusmn; one standard deviation.</p>
<table><tr><th>rank</th><th>robot</th><th>joint</th><th>days to service</th>
<th>crossing</th><th>interval ({level})</th><th>wear rate [mrad/day]</th>
<th>last gap [mrad]</th><th>bags used</th><th>other bags</th><th>note</th></tr>
{chr(10).join(rows)}
</table>
<figure><img src="fleet.png" alt="days to service per drivetrain"></figure>
{chr(10).join(figures)}
<p>Machine-readable: <a href="summary.json">summary.json</a>.</p>
</body></html>
"""
    index = folder / "index.html"
    index.write_text(page, encoding="utf-8")
    return index
