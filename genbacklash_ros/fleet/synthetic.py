"""A synthetic fleet archive with known wear, for tests and benchmarks.

:func:`write_synthetic_fleet` writes ``drivetrains`` x ``days`` short bags of drivetrains in
normal operation (:func:`genbacklash_core.scenarios.operation_record` through
:func:`genbacklash_ros.bags.simbags.write_operation_bag`, each bag carrying its truth), laid
out by the archive rule of :mod:`genbacklash_ros.fleet.archive`::

    ROOT/robot-01/drive_joint/2024-03-01T08-00-00/        a rosbag2 directory
    ROOT/robot-01/drive_joint/2024-03-02T08-00-00.mcap    every third bag a bare .mcap file
    ...
    ROOT/fleet_truth.json                                 the truth (:class:`SyntheticFleet`)

Drivetrain ``i`` starts with :data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`'s dead zones
scaled by a factor drawn from ``base_scale`` and wears linearly: on day ``d`` both dead zones
are ``(1 + r_i d)`` times the first day's (:func:`~genbacklash_core.scenarios.worn`), ``r_i``
drawn from ``wear_per_day``. The gap ``c_L + c_R`` therefore grows by
``gap_0 r_i`` radians a day: :attr:`DrivetrainTruth.wear_rate`. Within a bag the gap is
constant (a day's wear over seconds is negligible).

``corrupt`` bags (chosen at random after each drivetrain's first two days) are cut to 45 % of
their size, as a recorder killed mid-write leaves them; ``no_motion`` bags are recorded while
the joint only creeps within its dead zone (commands over 1 mrad), so the encoder never moves.

Examples
--------
>>> import tempfile
>>> with tempfile.TemporaryDirectory() as tmp:
...     spec = SyntheticFleetSpec(drivetrains=1, days=3, seconds=2, corrupt=0, no_motion=1)
...     fleet = write_synthetic_fleet(tmp, spec)
...     [(b.relpath, b.kind) for b in fleet.bags], SyntheticFleet.read(tmp) == fleet
... # doctest: +NORMALIZE_WHITESPACE
([('robot-01/drive_joint/2024-03-01T08-00-00', 'normal'),
  ('robot-01/drive_joint/2024-03-02T08-00-00', 'normal'),
  ('robot-01/drive_joint/2024-03-03T08-00-00.mcap', 'no_motion')], True)
"""

from __future__ import annotations

import calendar
import json
import math
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_core.scenarios import OPERATION_BACKLASH, OperationSettings, worn
from genbacklash_ros.bags.simbags import JOINT, write_operation_bag

__all__ = [
    "TRUTH_FILE",
    "DrivetrainTruth",
    "SyntheticBag",
    "SyntheticFleet",
    "SyntheticFleetSpec",
    "write_synthetic_fleet",
]

TRUTH_FILE = "fleet_truth.json"
_DAY_NS = 86_400 * 1_000_000_000
_CORRUPT_FRACTION = 0.45


@dataclass(frozen=True)
class SyntheticFleetSpec:
    """What :func:`write_synthetic_fleet` makes.

    Attributes
    ----------
    drivetrains, days : int
        Robots (one drivetrain each) and days (one bag a day each).
    seconds : float
        Length of each bag.
    start_date : str
        The first day, ``YYYY-MM-DD``; bags are recorded at 08:00 UTC.
    corrupt, no_motion : int
        How many bags are cut short, and how many the joint does not move in.
    wear_per_day : (float, float)
        Range of the relative growth of the gap per day.
    base_scale : (float, float)
        Range of the first day's dead zones relative to ``OPERATION_BACKLASH``.
    bare_every : int
        Every ``bare_every``-th bag is a bare ``.mcap`` file (0: none).
    seed : int
    """

    drivetrains: int = 6
    days: int = 8
    seconds: float = 10.0
    start_date: str = "2024-03-01"
    corrupt: int = 1
    no_motion: int = 1
    wear_per_day: tuple[float, float] = (0.015, 0.05)
    base_scale: tuple[float, float] = (0.8, 1.2)
    bare_every: int = 3
    seed: int = 0

    def __post_init__(self) -> None:
        if self.drivetrains < 1 or self.days < 1:
            raise GenBacklashError("a synthetic fleet needs >= 1 drivetrain and >= 1 day")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise GenBacklashError(f"seconds must be > 0, got {self.seconds}")
        spare = self.drivetrains * max(self.days - 2, 0)
        if self.corrupt < 0 or self.no_motion < 0 or self.corrupt + self.no_motion > spare:
            raise GenBacklashError(
                f"corrupt + no_motion must lie in [0, {spare}] (bags after each drivetrain's "
                f"first two days), got {self.corrupt} + {self.no_motion}"
            )
        for name in ("wear_per_day", "base_scale"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi:
                raise GenBacklashError(f"{name} must be (low, high) with 0 <= low <= high")
        try:
            year, month, day = (int(x) for x in self.start_date.split("-"))
            calendar.timegm((year, month, day, 0, 0, 0, 0, 0, 0))
        except ValueError as err:
            raise GenBacklashError(
                f"start_date must be YYYY-MM-DD, got {self.start_date!r}"
            ) from err

    @property
    def start_ns(self) -> int:
        """08:00 UTC on :attr:`start_date`, ns since the epoch."""
        year, month, day = (int(x) for x in self.start_date.split("-"))
        return (calendar.timegm((year, month, day, 8, 0, 0, 0, 0, 0))) * 1_000_000_000


@dataclass(frozen=True)
class DrivetrainTruth:
    """One drivetrain's truth: ``gap(day) = gap_0 + wear_rate * day``.

    Attributes
    ----------
    robot, joint : str
    c_left_0, c_right_0 : float
        Dead zones on day 0, radians.
    relative_wear : float
        Growth of both dead zones per day, relative to day 0.
    """

    robot: str
    joint: str
    c_left_0: float
    c_right_0: float
    relative_wear: float

    @property
    def gap_0(self) -> float:
        """``c_L + c_R`` on day 0."""
        return self.c_left_0 + self.c_right_0

    @property
    def wear_rate(self) -> float:
        """Growth of the gap, radians per day."""
        return self.gap_0 * self.relative_wear

    def gap_at(self, day: float) -> float:
        """The true gap on ``day`` (days since the first bag)."""
        return self.gap_0 + self.wear_rate * day

    def crossing_day(self, limit: float) -> float:
        """The day the gap reaches ``limit`` (inf when it does not wear)."""
        if self.wear_rate <= 0:
            return math.inf
        return (limit - self.gap_0) / self.wear_rate


@dataclass(frozen=True)
class SyntheticBag:
    """A bag of the fleet: where, whose, which day, and ``kind`` (``normal``, ``corrupt``,
    ``no_motion``)."""

    relpath: str
    robot: str
    joint: str
    day: int
    kind: str
    seed: int


@dataclass(frozen=True)
class SyntheticFleet:
    """A written synthetic fleet and its truth (:data:`TRUTH_FILE` at its root)."""

    spec: SyntheticFleetSpec
    drivetrains: tuple[DrivetrainTruth, ...]
    bags: tuple[SyntheticBag, ...]

    def to_json(self) -> str:
        """The truth file's content."""
        return json.dumps(
            {
                "format": 1,
                "spec": asdict(self.spec),
                "drivetrains": [asdict(d) for d in self.drivetrains],
                "bags": [asdict(b) for b in self.bags],
            },
            indent=1,
        )

    @classmethod
    def from_json(cls, text: str) -> SyntheticFleet:
        """Inverse of :meth:`to_json`."""
        try:
            data: Any = json.loads(text)
            spec = dict(data["spec"])
            for name in ("wear_per_day", "base_scale"):
                spec[name] = tuple(spec[name])
            return cls(
                SyntheticFleetSpec(**spec),
                tuple(DrivetrainTruth(**d) for d in data["drivetrains"]),
                tuple(SyntheticBag(**b) for b in data["bags"]),
            )
        except (ValueError, KeyError, TypeError) as err:
            raise GenBacklashError(f"not a synthetic fleet truth file: {err}") from err

    @classmethod
    def read(cls, root: str | Path) -> SyntheticFleet:
        """The truth of the fleet written at ``root``."""
        path = Path(root) / TRUTH_FILE
        if not path.is_file():
            raise GenBacklashError(f"no {TRUTH_FILE} in {root}: not a synthetic fleet")
        return cls.from_json(path.read_text(encoding="utf-8"))

    def truth(self, robot: str, joint: str = JOINT) -> DrivetrainTruth:
        """The drivetrain ``(robot, joint)``."""
        for item in self.drivetrains:
            if (item.robot, item.joint) == (robot, joint):
                return item
        raise GenBacklashError(f"no drivetrain {robot}/{joint} in this fleet")


def _stamp(ns: int) -> str:
    import datetime as dt

    return dt.datetime.fromtimestamp(ns / 1e9, tz=dt.timezone.utc).strftime("%Y-%m-%dT%H-%M-%S")


def write_synthetic_fleet(
    root: str | Path, spec: SyntheticFleetSpec | None = None, *, progress: bool = False
) -> SyntheticFleet:
    """Write the fleet ``spec`` describes under ``root`` (created; must hold no bag of the
    same name) and return its truth (also written to ``root/fleet_truth.json``)."""
    cfg = SyntheticFleetSpec() if spec is None else spec
    out = Path(root)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([cfg.seed, 13])
    width = max(2, len(str(cfg.drivetrains)))
    drivetrains = []
    for i in range(cfg.drivetrains):
        scale = float(rng.uniform(*cfg.base_scale))
        base = worn(OPERATION_BACKLASH, scale)
        relative = float(rng.uniform(*cfg.wear_per_day))
        drivetrains.append(
            DrivetrainTruth(f"robot-{i + 1:0{width}d}", JOINT, base.c_left, base.c_right, relative)
        )
    eligible = [(i, d) for i in range(cfg.drivetrains) for d in range(2, cfg.days)]
    picks = rng.permutation(len(eligible))[: cfg.corrupt + cfg.no_motion]
    special = {
        eligible[k]: ("corrupt" if n < cfg.corrupt else "no_motion")
        for n, k in enumerate(picks.tolist())
    }
    bags = []
    jobs = [(i, d) for d in range(cfg.days) for i in range(cfg.drivetrains)]
    iterator: Any = jobs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(jobs, desc="synthetic bags", unit="bag", disable=None)
    for n, (i, day) in enumerate(iterator):
        truth = drivetrains[i]
        kind = special.get((i, day), "normal")
        seed = cfg.seed * 1_000_003 + i * 1009 + day
        model = GeneralBacklash(
            OPERATION_BACKLASH.m_left,
            truth.c_left_0 * (1.0 + truth.relative_wear * day),
            OPERATION_BACKLASH.m_right,
            truth.c_right_0 * (1.0 + truth.relative_wear * day),
        )
        if kind == "no_motion":  # creeping within the dead zone: the load never moves
            settings = OperationSettings(
                duration=cfg.seconds, model=model, travel=(0.3, 0.301), jog_size=(0.0, 5e-4)
            )
        else:
            settings = OperationSettings(duration=cfg.seconds, model=model)
        name = _stamp(cfg.start_ns + day * _DAY_NS)
        folder = out / truth.robot / truth.joint
        bare = cfg.bare_every > 0 and n % cfg.bare_every == cfg.bare_every - 1
        target = folder / (name + ".mcap" if bare else name)
        if target.exists():
            raise GenBacklashError(f"{target} exists: write a synthetic fleet into a new directory")
        bag_dir = folder / (name + ".tmp" if bare else name)
        write_operation_bag(bag_dir, settings, seed)
        if bare:  # the .mcap alone (it keeps the rosbag2 metadata, truth included)
            next(bag_dir.glob("*.mcap")).rename(target)
            shutil.rmtree(bag_dir)
        if kind == "corrupt":
            file = target if bare else next(target.glob("*.mcap"))
            data = file.read_bytes()
            file.write_bytes(data[: int(len(data) * _CORRUPT_FRACTION)])
        relpath = target.relative_to(out).as_posix()
        bags.append(SyntheticBag(relpath, truth.robot, truth.joint, day, kind, seed))
    fleet = SyntheticFleet(cfg, tuple(drivetrains), tuple(bags))
    (out / TRUTH_FILE).write_text(fleet.to_json() + "\n", encoding="utf-8")
    return fleet
