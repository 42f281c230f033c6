"""The truth a synthetic bag carries in its metadata (:class:`BagTruth`, :data:`TRUTH_KEY`):
written with the bag, read back by a report (:func:`read_truth`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from genbacklash_core import (
    Cascade,
    GeneralBacklash,
)
from genbacklash_core.cascade import backlash_of, model_from_dict, model_to_dict
from genbacklash_core.scenarios import (
    OperationSettings,
)

TRUTH_KEY = "genbacklash.truth"
"""``custom_data`` key of the truth JSON (:class:`BagTruth`)."""
TRUTH_FORMAT = 1
TRUTH_STEP_S = 0.25  # resolution of the stored dead zones over time


@dataclass(frozen=True, eq=False)
class BagTruth:
    """The truth a synthetic bag carries in its metadata (``custom_data[TRUTH_KEY]``).

    Attributes
    ----------
    scenario : str
        ``"drivetrain"``, ``"example N"``, an operation phase kind, or the phases'
        ``kind:seconds,...`` list.
    description : str
        One line on what the bag holds.
    seed : int
    start_ns : int
        Bag time (ns since the epoch) of the record's time 0; times below count from it.
    model, model_end : GeneralBacklash or Cascade
        The drivetrain at the start and at the end of the record.
    t_s, c_left, c_right : ndarray
        The true dead zones at times ``t_s`` (seconds from ``start_ns``, every
        :data:`TRUTH_STEP_S`): they change when the gap wears.
    phases : tuple of (str, float)
        Each phase's kind and start time (s); empty for the random-input bags.
    settings : dict
        The scenario's settings as given (JSON values).
    """

    scenario: str
    description: str
    seed: int
    start_ns: int
    model: GeneralBacklash | Cascade
    model_end: GeneralBacklash | Cascade
    t_s: np.ndarray
    c_left: np.ndarray
    c_right: np.ndarray
    phases: tuple[tuple[str, float], ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)

    def dead_zones(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The true ``(c_left, c_right)`` at times ``t_s`` (s from :attr:`start_ns`),
        interpolated linearly and held beyond the ends."""
        t = np.asarray(t_s, dtype=np.float64)
        return np.interp(t, self.t_s, self.c_left), np.interp(t, self.t_s, self.c_right)

    def to_json(self) -> str:
        """The JSON stored under :data:`TRUTH_KEY` (compact, rounded to 1e-9)."""

        def r(values: np.ndarray) -> list[float]:
            return [round(float(v), 9) for v in values]

        return json.dumps(
            {
                "format": TRUTH_FORMAT,
                "scenario": self.scenario,
                "description": self.description,
                "seed": self.seed,
                "start_ns": self.start_ns,
                "model": model_to_dict(self.model),
                "model_end": model_to_dict(self.model_end),
                "dead_zones": {
                    "t": r(self.t_s),
                    "c_left": r(self.c_left),
                    "c_right": r(self.c_right),
                },
                "phases": [[kind, start] for kind, start in self.phases],
                "settings": self.settings,
            },
            separators=(",", ":"),
        )

    @classmethod
    def from_json(cls, text: str) -> BagTruth:
        """Parse :meth:`to_json`'s output; ``ValueError`` (or ``KeyError``/``TypeError``)
        when it is not one."""
        data = json.loads(text)
        if not isinstance(data, dict) or data.get("format") != TRUTH_FORMAT:
            raise ValueError("not a genbacklash truth record")
        zones = data["dead_zones"]
        t_s = np.asarray(zones["t"], dtype=np.float64)
        c_left = np.asarray(zones["c_left"], dtype=np.float64)
        c_right = np.asarray(zones["c_right"], dtype=np.float64)
        if not (t_s.ndim == 1 and t_s.size and t_s.shape == c_left.shape == c_right.shape):
            raise ValueError("dead_zones must hold equally long non-empty lists")
        if not (np.all(np.isfinite(t_s)) and np.all(np.diff(t_s) > 0)):
            raise ValueError("dead_zones.t must increase")
        settings = data.get("settings", {})
        return cls(
            scenario=str(data["scenario"]),
            description=str(data.get("description", "")),
            seed=int(data["seed"]),
            start_ns=int(data["start_ns"]),
            model=model_from_dict(data["model"]),
            model_end=model_from_dict(data["model_end"]),
            t_s=t_s,
            c_left=c_left,
            c_right=c_right,
            phases=tuple((str(k), float(t)) for k, t in data.get("phases", [])),
            settings=settings if isinstance(settings, dict) else {},
        )


def read_truth(custom_data: Mapping[str, str] | None) -> BagTruth | None:
    """The :class:`BagTruth` in a bag's ``custom_data`` (e.g.
    :attr:`~genbacklash_ros.bags.bagio.BagReader.custom_data`); None when there is none or it
    does not parse (tolerant: a report just goes without the truth)."""
    if not custom_data or TRUTH_KEY not in custom_data:
        return None
    try:
        return BagTruth.from_json(custom_data[TRUTH_KEY])
    except (ValueError, KeyError, TypeError, IndexError, AttributeError):
        return None


def constant_zones(
    model: GeneralBacklash | Cascade, duration_s: float, wear: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dead zones every :data:`TRUTH_STEP_S` for a gap growing linearly by ``wear``."""
    t = np.arange(0.0, duration_s, TRUTH_STEP_S)
    t = np.append(t, duration_s) if duration_s > t[-1] else t
    factor = 1.0 + wear * t / max(duration_s, 1e-12)
    bl = backlash_of(model)
    return t, bl.c_left * factor, bl.c_right * factor


def settings_dict(settings: OperationSettings) -> dict[str, Any]:
    """``settings`` as the truth JSON records them (the model as its parameters, the phases as
    their schedule)."""
    out: dict[str, Any] = {}
    for item in fields(settings):
        value = getattr(settings, item.name)
        if item.name == "model":
            out["model"] = model_to_dict(value)
        elif item.name == "phases":
            out["phases"] = [[kind, seconds] for kind, seconds in settings.schedule]
        else:
            out[item.name] = value
    return out
