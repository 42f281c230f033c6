"""The fleet page: escaped text, rad throughout, trends drawn to the crossing, and a wide
interval that does not squeeze the bags."""

from __future__ import annotations

import html
import re
import zlib
from pathlib import Path
from types import SimpleNamespace

import matplotlib.dates as mdates
import matplotlib.pyplot as plt
import numpy as np

from genbacklash_ros.fleet.report import plot_drivetrain, write_fleet_report
from genbacklash_ros.fleet.summary import DAY_NS, FleetSummary, summarise

T0 = 1_709_251_200 * 10**9  # 2024-03-01


def _rows(robot: str, gap0: float, rate: float, days: int = 6, noise: float = 1e-4) -> list:
    rng = np.random.default_rng(zlib.crc32(robot.encode()))
    return [
        SimpleNamespace(
            id=hash((robot, d)),
            robot=robot,
            joint="elbow",
            bag_hash=f"{robot}{d}",
            bag_path=f"{robot}/{d}",
            status="ok",
            recorded_ns=T0 + d * DAY_NS,
            gap=gap0 + rate * d + noise * float(rng.standard_normal()),
            gap_std=noise,
            processed_at="2024-04-01T00:00:00Z",
        )
        for d in range(days)
    ]


def fleet_summary() -> FleetSummary:
    """A fleet with a fast, an overdue, a far (wide interval) and a noisy drivetrain, and a
    robot whose name needs escaping (also used by the browser test)."""
    rows = (
        _rows("fast", 0.10, 0.004)
        + _rows("over", 0.16, 0.001)
        + _rows("slow & far", 0.05, 0.0002, noise=2e-4)
        + _rows("<noisy>", 0.10, 0.002, days=4, noise=0.004)
    )
    return summarise(rows, gap_limit=0.15)


def _text(page: str) -> str:
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", page)).split())


def test_page_is_escaped_text_in_rad(tmp_path: Path) -> None:
    index = write_fleet_report(fleet_summary(), tmp_path / "rep")
    page = index.read_text(encoding="utf-8")
    text = _text(page)
    assert "&ndash;" not in text and "&plusmn;" not in text  # no entity shown as text
    assert "&lt;noisy&gt;" in page and "<noisy>" in text  # a name is escaped, shown as is
    assert "mrad" not in text  # the play in rad, as --play-limit takes it
    assert "Play limit 0.15 rad" in text and "wear rate [rad/day]" in text
    for src in re.findall(r'<img src="([^"]+)"', page):
        assert (tmp_path / "rep" / src).read_bytes()[:4] == b"\x89PNG"


def test_trend_reaches_the_crossing_and_a_wide_interval_does_not_squeeze() -> None:
    summary = fleet_summary()
    far = next(d for d in summary.drivetrains if d.robot == "slow & far")
    assert far.crossing_ns is not None and far.crossing_high_ns is not None
    assert far.crossing_high_ns - far.crossing_ns > 300 * DAY_NS  # a wide interval
    fig = plot_drivetrain(far, summary.gap_limit)
    try:
        near, whole = fig.axes[:2]  # the bags alone, then through to the crossing
        trend = next(line for line in whole.get_lines() if line.get_label().startswith("trend"))
        x_end = mdates.num2date(max(trend.get_xdata(orig=False)))  # type: ignore[no-untyped-call]
        assert x_end.timestamp() * 1e9 >= far.crossing_ns  # drawn through to the crossing
        gaps = np.array(far.gap)
        for ax in (near, whole):
            lo, hi = ax.get_ylim()
            shown = max(float(np.max(gaps)), summary.gap_limit) - float(np.min(gaps))
            assert hi - lo < 3 * shown  # the band is clipped: the data keep the height
        lo, hi = near.get_xlim()
        assert hi - lo < 10  # days: the bags fill the first panel
    finally:
        plt.close(fig)
