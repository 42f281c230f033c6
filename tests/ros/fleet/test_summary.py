"""The fleet summary: grouping, one row per bag, ranking, JSON round trip."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.fleet.summary import DAY_NS, FleetSummary, summarise

T0 = 1_709_251_200 * 10**9  # 2024-03-01


def _rows(robot: str, gap0: float, rate: float, days: int = 6, status: str = "ok") -> list:
    return [
        SimpleNamespace(
            id=hash((robot, d)),
            robot=robot,
            joint="j",
            bag_hash=f"{robot}{d}",
            bag_path=f"{robot}/{d}",
            status=status,
            recorded_ns=T0 + d * DAY_NS,
            gap=gap0 + rate * d + (1e-4 if d % 2 else -1e-4),
            gap_std=1e-4,
            processed_at="2024-04-01T00:00:00Z",
        )
        for d in range(days)
    ]


def test_ranking_by_days_to_service() -> None:
    rows = (
        _rows("slow", 0.10, 0.001)
        + _rows("fast", 0.10, 0.004)
        + _rows("flat", 0.10, 0.0)
        + _rows("broken", 0.10, 0.004, status="unreadable")
        + _rows("over", 0.16, 0.001)
    )
    summary = summarise(rows, gap_limit=0.15)
    order = [d.robot for d in summary.drivetrains]
    assert order[:3] == ["over", "fast", "slow"]
    assert set(order[3:]) == {"flat", "broken"}
    over, fast = summary.drivetrains[0], summary.drivetrains[1]
    assert over.days_to_service is not None and over.days_to_service < 0  # overdue
    assert fast.days_to_service == pytest.approx((0.05 / 0.004) - 5, abs=0.3)
    assert fast.wear_rate_per_day == pytest.approx(0.004, rel=0.05)
    broken = next(d for d in summary.drivetrains if d.robot == "broken")
    assert broken.statuses == {"unreadable": 6} and broken.note == "no bag with an estimate"
    assert FleetSummary.from_json(summary.to_json()) == summary


def test_a_bag_counts_once_its_newest_row() -> None:
    rows = _rows("a", 0.10, 0.002)
    rerun = [SimpleNamespace(**{**vars(r), "id": r.id + 1, "gap": 0.5}) for r in rows[:1]]
    rerun[0].processed_at = "2024-05-01T00:00:00Z"
    summary = summarise(rows + rerun, gap_limit=0.15)
    (item,) = summary.drivetrains
    assert item.bags_used == 6 and item.gap[0] == 0.5


def test_bad_limit_and_bad_json() -> None:
    with pytest.raises(GenBacklashError, match="--play-limit must be a positive"):
        summarise([], gap_limit=0.0)
    with pytest.raises(GenBacklashError, match="not a fleet summary JSON"):
        FleetSummary.from_json("{}")
