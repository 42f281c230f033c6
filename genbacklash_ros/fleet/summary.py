"""The fleet summary: per drivetrain, the play c_L + c_R over time, its trend, and the
ranking by time to service (the JSON ``genbacklash fleet-report`` writes for other tools).

:func:`summarise` takes the results rows
(:meth:`~genbacklash_ros.fleet.database.ResultStore.results`), groups them by drivetrain
``(robot, joint)``, fits each drivetrain's trend
(:func:`~genbacklash_ros.fleet.trends.fit_trend`) on its ``ok`` rows that have a time, and
ranks the drivetrains by days to service: the crossing date minus ``as_of`` (default the
newest bag in the database). Overdue drivetrains (negative days) come first, those with no
predicted crossing (no wear, or too few bags) last.

A bag analysed more than once (different settings, or the same bytes under two paths) counts
once per drivetrain: its newest row.

JSON (:meth:`FleetSummary.to_json`, ``format`` 1)::

    {"format": 1, "play_limit": L, "level": 0.95, "as_of": ISO, "as_of_ns": int,
     "drivetrains": [{"rank": 1, "robot": ..., "joint": ..., "bags_used": n,
       "statuses": {"ok": n, "no_motion": n, ...},
       "first": ISO, "last": ISO, "last_play": x, "last_play_std": x,
       "wear_rate_per_day": b, "wear_rate_std": s, "play_at_first": a, "scatter_scale": k,
       "crossing": ISO|null, "crossing_low": ISO|null, "crossing_high": ISO|null,
       "days_to_service": d|null, "note": "...",
       "truncated_bags": [{"bag_path": ..., "recorded_at": ISO, "status": ..., "read_s": x,
         "recorded_s": x|null, "flag": "truncated: read X of Y s"}, ...],
       "points": {"t_ns": [...], "play": [...], "play_std": [...], "truncated": [...]}}, ...]}

Times are ISO 8601 UTC; the play in radians; the wear rate in radians per day. The same
numbers stay under their older keys (the play was called the gap): ``gap_limit``,
``last_gap``, ``last_gap_std``, ``gap_at_first``, ``points.gap``, ``points.gap_std``.
``truncated_bags`` lists the drivetrain's bags that were cut part-way and analysed on their
readable part (:mod:`genbacklash_ros.fleet.job`), whatever their status; a point of a
truncated bag is flagged in ``points.truncated``.
"""

from __future__ import annotations

import json
import math
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_ros.fleet.database import iso_utc
from genbacklash_ros.fleet.trends import Trend, fit_trend

__all__ = ["DAY_NS", "DrivetrainSummary", "FleetSummary", "TruncatedBag", "summarise"]

DAY_NS = 86_400 * 1_000_000_000
SUMMARY_FORMAT = 1


@dataclass(frozen=True)
class DrivetrainSummary:
    """One drivetrain's line of the summary (see the module notes for the fields; times in
    ns since the epoch, None where unknown)."""

    rank: int
    robot: str
    joint: str
    bags_used: int
    statuses: dict[str, int]
    t_ns: tuple[int, ...]
    gap: tuple[float, ...]
    gap_std: tuple[float, ...]
    wear_rate_per_day: float | None = None
    wear_rate_std: float | None = None
    gap_at_first: float | None = None
    intercept_slope_cov: tuple[float, float, float] | None = None
    scatter_scale: float | None = None
    crossing_ns: int | None = None
    crossing_low_ns: int | None = None
    crossing_high_ns: int | None = None
    days_to_service: float | None = None
    note: str = ""
    truncated: tuple[TruncatedBag, ...] = ()
    point_truncated: tuple[bool, ...] = ()

    def trend_line(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The fitted gap and its standard deviation at times ``t_ns`` (NaN without a trend)."""
        t = (np.asarray(t_ns, dtype=np.float64) - self.t_ns[0]) / DAY_NS if self.t_ns else None
        if t is None or self.wear_rate_per_day is None or self.intercept_slope_cov is None:
            nan = np.full(np.shape(t_ns), np.nan)
            return nan, nan
        assert self.gap_at_first is not None  # set with the slope
        vaa, vab, vbb = self.intercept_slope_cov
        var = vaa + 2 * t * vab + t * t * vbb
        return self.gap_at_first + self.wear_rate_per_day * t, np.sqrt(np.maximum(var, 0.0))


def _iso(ns: int | None) -> str | None:
    return iso_utc(ns)


@dataclass(frozen=True)
class TruncatedBag:
    """A bag cut part-way whose readable part was analysed: where, when, its row's status,
    the seconds read and the recording's length (None: unknown)."""

    bag_path: str
    recorded_ns: int | None
    status: str
    read_s: float | None
    recorded_s: float | None

    @property
    def flag(self) -> str:
        """``truncated: read X of Y s`` (:func:`~genbacklash_ros.fleet.job.truncation_note`)."""
        from genbacklash_ros.fleet.job import truncation_note

        return truncation_note(self.read_s, self.recorded_s)

    def to_dict(self) -> dict[str, Any]:
        """The JSON item of ``truncated_bags``."""
        return {
            "bag_path": self.bag_path,
            "recorded_at": _iso(self.recorded_ns),
            "recorded_ns": self.recorded_ns,
            "status": self.status,
            "read_s": self.read_s,
            "recorded_s": self.recorded_s,
            "flag": self.flag,
        }


@dataclass(frozen=True)
class FleetSummary:
    """Every drivetrain, ranked by days to service."""

    gap_limit: float
    level: float
    as_of_ns: int | None
    drivetrains: tuple[DrivetrainSummary, ...]

    def to_dict(self) -> dict[str, Any]:
        """The JSON object (module notes)."""
        items = []
        for d in self.drivetrains:
            item = {
                "rank": d.rank,
                "robot": d.robot,
                "joint": d.joint,
                "bags_used": d.bags_used,
                "statuses": d.statuses,
                "first": _iso(d.t_ns[0]) if d.t_ns else None,
                "last": _iso(d.t_ns[-1]) if d.t_ns else None,
                "last_gap": d.gap[-1] if d.gap else None,
                "last_gap_std": d.gap_std[-1] if d.gap_std else None,
                "last_play": d.gap[-1] if d.gap else None,
                "last_play_std": d.gap_std[-1] if d.gap_std else None,
                "wear_rate_per_day": d.wear_rate_per_day,
                "wear_rate_std": d.wear_rate_std,
                "gap_at_first": d.gap_at_first,
                "play_at_first": d.gap_at_first,
                "intercept_slope_cov": list(d.intercept_slope_cov)
                if d.intercept_slope_cov
                else None,
                "scatter_scale": d.scatter_scale,
                "crossing": _iso(d.crossing_ns),
                "crossing_low": _iso(d.crossing_low_ns),
                "crossing_high": _iso(d.crossing_high_ns),
                "crossing_ns": d.crossing_ns,
                "crossing_low_ns": d.crossing_low_ns,
                "crossing_high_ns": d.crossing_high_ns,
                "days_to_service": d.days_to_service,
                "note": d.note,
                "truncated_bags": [bag.to_dict() for bag in d.truncated],
                "points": {
                    "t_ns": list(d.t_ns),
                    "gap": list(d.gap),
                    "gap_std": list(d.gap_std),
                    "play": list(d.gap),
                    "play_std": list(d.gap_std),
                    "truncated": list(d.point_truncated),
                },
            }
            items.append(item)
        return {
            "format": SUMMARY_FORMAT,
            "gap_limit": self.gap_limit,
            "play_limit": self.gap_limit,
            "level": self.level,
            "as_of": _iso(self.as_of_ns),
            "as_of_ns": self.as_of_ns,
            "drivetrains": items,
        }

    def to_json(self) -> str:
        """:meth:`to_dict` as indented JSON."""
        return json.dumps(self.to_dict(), indent=1)

    @classmethod
    def from_json(cls, text: str) -> FleetSummary:
        """Read :meth:`to_json` back (a summary written by ``fleet-report``)."""
        try:
            data: Any = json.loads(text)
            if data.get("format") != SUMMARY_FORMAT:
                raise GenBacklashError(
                    f"unsupported fleet summary format {data.get('format')!r}; expected "
                    f"{SUMMARY_FORMAT}"
                )
            items = []
            for d in data["drivetrains"]:
                cov = d["intercept_slope_cov"]
                items.append(
                    DrivetrainSummary(
                        rank=d["rank"],
                        robot=d["robot"],
                        joint=d["joint"],
                        bags_used=d["bags_used"],
                        statuses=dict(d["statuses"]),
                        t_ns=tuple(d["points"]["t_ns"]),
                        gap=tuple(d["points"]["gap"]),
                        gap_std=tuple(d["points"]["gap_std"]),
                        wear_rate_per_day=d["wear_rate_per_day"],
                        wear_rate_std=d["wear_rate_std"],
                        gap_at_first=d["gap_at_first"],
                        intercept_slope_cov=None if cov is None else (cov[0], cov[1], cov[2]),
                        scatter_scale=d["scatter_scale"],
                        crossing_ns=d["crossing_ns"],
                        crossing_low_ns=d["crossing_low_ns"],
                        crossing_high_ns=d["crossing_high_ns"],
                        days_to_service=d["days_to_service"],
                        note=d["note"],
                        truncated=tuple(
                            TruncatedBag(
                                b["bag_path"],
                                b["recorded_ns"],
                                b["status"],
                                b["read_s"],
                                b["recorded_s"],
                            )
                            for b in d.get("truncated_bags", [])
                        ),
                        point_truncated=tuple(d["points"].get("truncated", [])),
                    )
                )
            return cls(data["gap_limit"], data["level"], data["as_of_ns"], tuple(items))
        except (ValueError, KeyError, TypeError, IndexError) as err:
            raise GenBacklashError(f"not a fleet summary JSON: {err!r}") from err


def _newest_per_bag(rows: Iterable[Any]) -> list[Any]:
    """One row per (robot, joint, bag_hash) and per (robot, joint, bag_path): the newest."""
    ordered = sorted(rows, key=lambda r: (r.processed_at or "", r.id))
    by_hash: dict[tuple[str, str, str], Any] = {}
    for row in ordered:
        by_hash[row.robot, row.joint, row.bag_hash] = row
    by_path: dict[tuple[str, str, str], Any] = {}
    for row in sorted(by_hash.values(), key=lambda r: (r.processed_at or "", r.id)):
        by_path[row.robot, row.joint, row.bag_path] = row
    return list(by_path.values())


def _days(ns: int | None, origin: int) -> float | None:
    return None if ns is None else (ns - origin) / DAY_NS


def _ns(day: float | None, origin: int) -> int | None:
    if day is None or not math.isfinite(day) or abs(day) > 1e6:
        return None
    return origin + round(day * DAY_NS)


def _one(
    robot: str, joint: str, rows: list[Any], limit: float, level: float, as_of: int | None
) -> DrivetrainSummary:
    statuses = dict(sorted(Counter(r.status for r in rows).items()))
    usable = sorted(
        (r for r in rows if r.status == "ok" and r.recorded_ns is not None and r.gap is not None),
        key=lambda r: r.recorded_ns,
    )
    t_ns = tuple(int(r.recorded_ns) for r in usable)
    gap = tuple(float(r.gap) for r in usable)
    std = tuple(float(r.gap_std) if r.gap_std is not None else math.nan for r in usable)
    cut = sorted(
        (r for r in rows if getattr(r, "truncated", None)),  # NULL in an older table: unknown
        key=lambda r: (r.recorded_ns is None, r.recorded_ns or 0, r.bag_path),
    )
    base: dict[str, Any] = {
        "rank": 0,
        "robot": robot,
        "joint": joint,
        "bags_used": len(usable),
        "statuses": statuses,
        "t_ns": t_ns,
        "gap": gap,
        "gap_std": std,
        "truncated": tuple(
            TruncatedBag(
                r.bag_path,
                r.recorded_ns,
                r.status,
                r.duration_s,
                getattr(r, "recorded_s", None),
            )
            for r in cut
        ),
        "point_truncated": tuple(bool(getattr(r, "truncated", None)) for r in usable),
    }
    if not usable:
        return DrivetrainSummary(**base, note="no bag with an estimate")
    origin = t_ns[0]
    t = np.array([(x - origin) / DAY_NS for x in t_ns])
    finite_std = np.nan_to_num(np.array(std), nan=0.0)
    try:
        trend: Trend = fit_trend(t, np.array(gap), finite_std, limit=limit, level=level)
    except GenBacklashError as err:
        return DrivetrainSummary(**base, note=f"no trend: {err}")
    lo, hi = trend.crossing_interval
    crossing_ns = _ns(trend.crossing, origin)
    note = ""
    if trend.crossing is None:
        note = "the play does not grow: no crossing predicted"
    elif lo is None:
        note = "the wear rate is not significant: the crossing date cannot be bounded"
    days = None
    if crossing_ns is not None and as_of is not None:
        days = (crossing_ns - as_of) / DAY_NS
    c = trend.covariance
    return DrivetrainSummary(
        **base,
        wear_rate_per_day=trend.slope,
        wear_rate_std=trend.slope_std,
        gap_at_first=trend.intercept,
        intercept_slope_cov=(float(c[0, 0]), float(c[0, 1]), float(c[1, 1])),
        scatter_scale=trend.scale,
        crossing_ns=crossing_ns,
        crossing_low_ns=_ns(lo, origin),
        crossing_high_ns=_ns(hi, origin),
        days_to_service=days,
        note=note,
    )


def summarise(
    rows: Iterable[Any],
    *,
    gap_limit: float,
    level: float = 0.95,
    as_of_ns: int | None = None,
) -> FleetSummary:
    """The fleet summary of the results ``rows`` (see the module notes).

    Parameters
    ----------
    rows : iterable of row
        Objects with the ``bag_results`` columns as attributes.
    gap_limit : float
        The gap ``c_L + c_R`` (radians) at which a drivetrain needs service.
    level : float
        Confidence level of the crossing intervals.
    as_of_ns : int, optional
        The date days to service count from (default: the newest bag's time).
    """
    if not (math.isfinite(gap_limit) and gap_limit > 0):
        raise GenBacklashError(
            f"--play-limit must be a positive number of radians, got {gap_limit}"
        )
    kept = _newest_per_bag(rows)
    if as_of_ns is None:
        times = [r.recorded_ns for r in kept if r.recorded_ns is not None]
        as_of_ns = max(times) if times else None
    groups: dict[tuple[str, str], list[Any]] = defaultdict(list)
    for row in kept:
        groups[row.robot, row.joint].append(row)
    items = [_one(r, j, g, gap_limit, level, as_of_ns) for (r, j), g in sorted(groups.items())]

    def order(d: DrivetrainSummary) -> tuple[int, float, str, str]:
        if d.days_to_service is None:
            return (1, -(d.wear_rate_per_day or 0.0), d.robot, d.joint)
        return (0, d.days_to_service, d.robot, d.joint)

    ranked = tuple(replace(d, rank=k + 1) for k, d in enumerate(sorted(items, key=order)))
    return FleetSummary(float(gap_limit), float(level), as_of_ns, ranked)
