"""The fleet page: drivetrains ranked by time to service (HTML + PNG, matplotlib Agg).

:func:`write_fleet_report` writes into a directory:

* ``index.html``: the ranking table (days to service with its interval, crossing date, wear
  rate, the last play, bags used and the other statuses) and the plots, in the layout every
  report shares (:mod:`genbacklash_ros.reports.page`);
* ``fleet.png``: days to service per drivetrain with the crossing interval, the limit's
  day marked;
* ``drivetrain-<robot>-<joint>.png``: the play against time with 2-sigma bars, the fitted trend
  with its 95 % band drawn through to the crossing, the limit, and the crossing date with
  its interval;
* ``summary.json``: :meth:`~genbacklash_ros.fleet.summary.FleetSummary.to_json`.

The play c_L + c_R is in rad everywhere, as ``--play-limit`` takes it; the wear
rate in rad per day. A wide crossing interval is clipped to the view (the page's table gives
its dates) so that it cannot squeeze the measured points into a few pixels.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.dates as mdates
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from genbacklash_ros.fleet.summary import DAY_NS, DrivetrainSummary, FleetSummary
from genbacklash_ros.reports.page import DASH, Section, Table, write_page
from genbacklash_ros.reports.page import Figure as PageFigure

__all__ = ["plot_drivetrain", "plot_fleet", "write_fleet_report"]


def _dates(ns: np.ndarray) -> np.ndarray:
    return np.array(
        [dt.datetime.fromtimestamp(x / 1e9, tz=dt.timezone.utc).replace(tzinfo=None) for x in ns]
    )


def _file_name(d: DrivetrainSummary) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", f"{d.robot}-{d.joint}").strip("_") or "drivetrain"
    return f"drivetrain-{safe}.png"


_FAR_DAYS = 10 * 365  # a crossing further than this from the bags is not drawn, but named


def _pad(lo: int, hi: int) -> tuple[int, int]:
    pad = max((hi - lo) // 12, DAY_NS // 4)
    return lo - pad, hi + pad


def _time_ranges(d: DrivetrainSummary) -> list[tuple[int, int]]:
    """The x range(s) of a drivetrain's plot: its bags and the crossing date (the interval
    is clipped to it). When the crossing lies far beyond the bags (more than twice their
    span away), two: the bags alone, then through to the crossing, so that the bags do not
    shrink to a few pixels."""
    t = np.array(d.t_ns, dtype=np.int64)
    first, last = int(t[0]), int(t[-1])
    if d.crossing_ns is None:
        return [_pad(first, last)]
    lo, hi = min(first, d.crossing_ns), max(last, d.crossing_ns)
    span = max(last - first, DAY_NS)
    if hi - lo > _FAR_DAYS * DAY_NS:  # a century away: said in words (see plot_drivetrain)
        return [_pad(first, last)]
    if (hi - lo) > 3 * span:
        return [_pad(first, last), _pad(lo, hi)]
    return [_pad(lo, hi)]


def _value_range(values: list[np.ndarray], spreads: list[np.ndarray]) -> tuple[float, float]:
    """A y range around ``values`` (the points, the limit, the trend) that takes in the
    ``spreads`` (error bars, the trend's band) only up to half the values' own span beyond
    them: a wide band is clipped, not allowed to squeeze the data."""
    core = np.concatenate([np.ravel(v) for v in values])
    core = core[np.isfinite(core)]
    lo, hi = float(np.min(core)), float(np.max(core))
    span = max(hi - lo, 1e-3 * max(abs(hi), 1e-6))
    wide = np.concatenate([np.ravel(v) for v in spreads]) if spreads else np.zeros(0)
    wide = wide[np.isfinite(wide)]
    if wide.size:
        lo = max(min(lo, float(np.min(wide))), lo - 0.5 * span)
        hi = min(max(hi, float(np.max(wide))), hi + 0.5 * span)
    margin = 0.06 * (hi - lo) if hi - lo >= span else 0.5 * span  # one value: a band around it
    return lo - margin, hi + margin


def _draw(ax: Axes, d: DrivetrainSummary, gap_limit: float, view: tuple[int, int]) -> None:
    """One panel of :func:`plot_drivetrain` over ``view`` (ns)."""
    lo_ns, hi_ns = view
    values: list[np.ndarray] = [np.array([gap_limit])]
    spreads: list[np.ndarray] = []
    t = np.array(d.t_ns, dtype=np.int64)
    gap = np.array(d.gap)
    bars = 2 * np.nan_to_num(np.array(d.gap_std))
    ax.errorbar(
        _dates(t), gap, yerr=bars, fmt="o", ms=4, color="C0", label="play per bag (2 sigma)"
    )
    cut = np.array(d.point_truncated, dtype=bool)
    if cut.size == t.size and cut.any():  # a cut recording: its readable part, flagged
        ax.plot(
            _dates(t[cut]),
            gap[cut],
            "o",
            ms=9,
            mfc="none",
            mec="C3",
            label="truncated bag (readable part only)",
        )
    values.append(gap)
    spreads += [gap - bars, gap + bars]
    # the trend over the whole view: from the bags through to the crossing
    grid = np.linspace(float(lo_ns), float(hi_ns), 300)
    line, sd = d.trend_line(grid)
    if np.all(np.isfinite(line)):
        ax.plot(_dates(grid), line, color="C1", label="trend (least squares)")
        ax.fill_between(
            _dates(grid),
            line - 2 * sd,
            line + 2 * sd,
            color="C1",
            alpha=0.2,
            lw=0,
            label="trend, 2 sigma",
        )
        values.append(line)
        spreads += [line - 2 * sd, line + 2 * sd]
    ax.set_xlim(*_dates(np.array([lo_ns, hi_ns])))
    if d.crossing_ns is not None and lo_ns <= d.crossing_ns <= hi_ns:
        ax.axvline(_dates(np.array([d.crossing_ns]))[0], color="C3", lw=1, label="crossing")
    if d.crossing_low_ns is not None and d.crossing_high_ns is not None:
        lo = max(d.crossing_low_ns, lo_ns)
        hi = min(d.crossing_high_ns, hi_ns)
        if lo < hi:
            clipped = d.crossing_high_ns > hi_ns or d.crossing_low_ns < lo_ns
            label = "crossing interval" + (" (clipped to the view)" if clipped else "")
            a, b = _dates(np.array([lo, hi]))
            ax.axvspan(a, b, color="C3", alpha=0.1, label=label)
    ax.axhline(gap_limit, color="C3", ls="--", label=f"limit {gap_limit:.4g} rad (--play-limit)")
    ax.set_ylim(*_value_range(values, spreads))
    # concise dates: the default labels overlapped ("2024-02-29" over "2024-03-01")
    locator = mdates.AutoDateLocator(minticks=3, maxticks=9)  # type: ignore[no-untyped-call]
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))  # type: ignore[no-untyped-call]
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("date (UTC)")


def plot_drivetrain(d: DrivetrainSummary, gap_limit: float) -> Figure:
    """The play of one drivetrain against time, with its trend and crossing (two panels
    when the crossing is far: the bags, then through to the crossing)."""
    title = f"{d.robot} / {d.joint}: play c_L + c_R over time"
    if not d.t_ns:
        fig, ax = plt.subplots(figsize=(8, 4.8), layout="constrained")
        ax.text(0.5, 0.5, "no bag with an estimate", transform=ax.transAxes, ha="center")
        ax.axhline(gap_limit, color="C3", ls="--", label=f"limit {gap_limit:.4g} rad")
        ax.set_ylim(0.0, 1.5 * gap_limit)
        ax.set_title(title, fontsize=11)
        ax.set_ylabel("play c_L + c_R [rad]")
        ax.set_xlabel("date (UTC)")
        return fig
    views = _time_ranges(d)
    if len(views) == 1:
        fig, ax = plt.subplots(figsize=(8, 4.8), layout="constrained")
        _draw(ax, d, gap_limit, views[0])
        if d.crossing_ns is not None and not views[0][0] <= d.crossing_ns <= views[0][1]:
            ax.text(
                0.02,
                0.97,
                f"crossing predicted on {_date(d.crossing_ns)}, beyond this plot",
                transform=ax.transAxes,
                va="top",
                fontsize=9,
                bbox={"facecolor": "white", "alpha": 0.9, "edgecolor": "0.7"},
            )
        ax.set_title(title, fontsize=11)
        ax.set_ylabel("play c_L + c_R [rad]")
        fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncol=3, fontsize=8)
        return fig
    fig, (near, far) = plt.subplots(
        1, 2, figsize=(11, 4.8), layout="constrained", width_ratios=(1, 1.6)
    )
    _draw(near, d, gap_limit, views[0])
    _draw(far, d, gap_limit, views[1])
    near.set_title("the bags", fontsize=10)
    far.set_title("through to the crossing", fontsize=10)
    near.set_ylabel("play c_L + c_R [rad]")
    fig.suptitle(title, fontsize=11)
    fig.legend(*far.get_legend_handles_labels(), loc="outside lower center", ncol=3, fontsize=8)
    return fig


def plot_fleet(summary: FleetSummary) -> Figure:
    """Days to service per drivetrain (ranked), with the crossing intervals."""
    ranked = list(summary.drivetrains)
    fig, ax = plt.subplots(figsize=(8, 1.6 + 0.4 * max(len(ranked), 1)), layout="constrained")
    labels = [f"{d.rank}. {d.robot}/{d.joint}" for d in ranked]
    y = np.arange(len(ranked))[::-1]
    as_of = summary.as_of_ns or 0
    days = [d.days_to_service for d in ranked if d.days_to_service is not None]
    # the view: the estimates whose interval is bounded (one drivetrain that barely wears,
    # predicted to cross in a century, would squeeze all the others into a pixel); bars
    # and intervals beyond it are clipped and labelled with their value
    bounded = [
        d.days_to_service
        for d in ranked
        if d.days_to_service is not None and d.crossing_low_ns is not None
    ]
    reach = max([abs(x) for x in (bounded or days)] + [1.0])
    view = (min([0.0, *days]) - 0.1 * reach, 1.6 * reach)
    for yi, d in zip(y, ranked, strict=True):
        if d.days_to_service is None:
            ax.text(0, yi, "  no crossing predicted", va="center", fontsize=8, color="0.4")
            continue
        color = "C3" if d.days_to_service < 0 else "C0"
        ax.barh(yi, min(d.days_to_service, view[1]), color=color, alpha=0.7)
        if d.days_to_service > view[1]:
            ax.annotate(
                f"{d.days_to_service:.3g} d \u2192",
                (view[1], yi),
                xytext=(-2, 0),
                textcoords="offset points",
                ha="right",
                va="center",
                fontsize=7,
            )
        if d.crossing_low_ns is not None and d.crossing_high_ns is not None:
            lo = (d.crossing_low_ns - as_of) / DAY_NS
            hi = (d.crossing_high_ns - as_of) / DAY_NS
            ax.plot([max(lo, view[0]), min(hi, view[1])], [yi, yi], color="k", lw=1.5)
            if hi > view[1]:
                ax.annotate(
                    f"to {hi:.0f} d",
                    (view[1], yi),
                    xytext=(-2, 4),
                    textcoords="offset points",
                    ha="right",
                    fontsize=7,
                )
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlim(*view)
    ax.set_ylim(-0.7, len(ranked) - 0.3)
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlabel(f"days to service [days] (the play reaches {summary.gap_limit:.4g} rad)")
    ax.set_title(
        "Fleet: drivetrains ranked by time to service\n(bars: estimate; lines: interval)",
        fontsize=11,
    )
    ax.grid(True, axis="x", alpha=0.3)
    return fig


def _num(value: float | None, digits: int = 3) -> str:
    return DASH if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


def _rate(rate: float | None, std: float | None) -> str:
    """The wear rate and its standard deviation in rad/day, to the std's second digit."""
    if rate is None or not math.isfinite(rate):
        return DASH
    if std is None or not math.isfinite(std) or std <= 0:
        return f"{rate:.3g}"
    decimals = min(9, max(0, 1 - math.floor(math.log10(std))))
    return f"{rate:.{decimals}f} \u00b1 {std:.{decimals}f}"


def _date(ns: int | None) -> str:
    if ns is None:
        return DASH
    return dt.datetime.fromtimestamp(ns / 1e9, tz=dt.timezone.utc).strftime("%Y-%m-%d")


def _first(d: DrivetrainSummary | None) -> str:
    if d is None or d.days_to_service is None:
        return "none predicted"
    days = d.days_to_service
    when = f"overdue by {-days:.1f} days" if days < 0 else f"in {days:.1f} days"
    return f"{d.robot}/{d.joint}, {when} ({_date(d.crossing_ns)})"


def write_fleet_report(summary: FleetSummary, out: str | Path) -> Path:
    """Write the fleet page into ``out`` (created); returns the path of ``index.html``."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "summary.json").write_text(summary.to_json() + "\n", encoding="utf-8")
    fig = plot_fleet(summary)
    fig.savefig(folder / "fleet.png", dpi=100)
    plt.close(fig)
    rows = []
    cut_rows: list[list[str]] = []
    figures = [PageFigure("fleet.png", "Days to service per drivetrain, with the intervals.")]
    for d in summary.drivetrains:
        name = _file_name(d)
        fig = plot_drivetrain(d, summary.gap_limit)
        fig.savefig(folder / name, dpi=90)
        plt.close(fig)
        other = ", ".join(f"{n} {s}" for s, n in d.statuses.items() if s != "ok") or DASH
        interval = (
            f"{_date(d.crossing_low_ns)} {DASH} {_date(d.crossing_high_ns)}"
            if d.crossing_low_ns is not None
            else "unbounded"
            if d.crossing_ns is not None
            else DASH
        )
        last_gap = d.gap[-1] if d.gap else None
        cut_rows.extend(
            [
                f"{d.robot}/{d.joint}",
                _date(bag.recorded_ns),
                bag.bag_path,
                bag.status,
                bag.flag,
            ]
            for bag in d.truncated
        )
        rows.append(
            [
                str(d.rank),
                d.robot,
                d.joint,
                _num(d.days_to_service),
                _date(d.crossing_ns),
                interval,
                _rate(d.wear_rate_per_day, d.wear_rate_std),
                _num(last_gap, 4),
                str(d.bags_used),
                other,
                str(len(d.truncated)) if d.truncated else DASH,
                d.note or DASH,
            ]
        )
        figures.append(
            PageFigure(
                name,
                f"Play of {d.robot}/{d.joint} over time with its trend, the limit and the "
                "crossing date.",
            )
        )
    level = f"{summary.level:.0%}"
    head = ["rank", "robot", "joint", "days to service", "crossing", f"interval ({level})"]
    head += ["wear rate [rad/day]", "last play [rad]", "bags used", "other bags"]
    head += ["truncated bags", "note"]
    first = next((d for d in summary.drivetrains if d.days_to_service is not None), None)
    summary_block = [
        ("Play limit", f"{summary.gap_limit:.4g} rad (c_L + c_R, as --play-limit takes it)"),
        ("As of", f"{_date(summary.as_of_ns)} (the newest bag)"),
        ("Drivetrains", str(len(summary.drivetrains))),
        ("First to service", _first(first)),
    ]
    if cut_rows:
        summary_block.append(
            (
                "Truncated bags",
                f"{len(cut_rows)}: cut part-way, their readable part analysed (listed below)",
            )
        )
    sections = [
        Section(
            "Ranking: time to service",
            paragraphs=[
                f"Days to service counted from {_date(summary.as_of_ns)}; crossing intervals "
                f"at {level} (Fieller, from the fitted line's band). Play in rad; wear rate in "
                "rad per day \u00b1 one standard deviation."
            ],
            tables=[Table(head, rows, align="rllrrrrrrlrl")],
        ),
    ]
    if cut_rows:
        sections.append(
            Section(
                "Truncated bags",
                paragraphs=[
                    "Recordings cut part-way (a recorder killed mid-write, a damaged file). "
                    "Their readable part was analysed, as genbacklash replay keeps it; the "
                    "play of an 'ok' one is in the trend, drawn with a red ring."
                ],
                tables=[
                    Table(
                        ["drivetrain", "date", "bag", "status", "what was read"],
                        cut_rows,
                        align="lllll",
                    )
                ],
            )
        )
    sections += [
        Section("Plots", figures=figures),
        Section("Machine-readable", paragraphs=["summary.json beside this page."]),
    ]
    return write_page(
        folder / "index.html",
        title="Fleet wear: time to service",
        summary=summary_block,
        sections=sections,
    )
