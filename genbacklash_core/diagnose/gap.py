"""The validation gap and where it concentrates.

The record is split into an estimation segment (fit there) and a held-out validation segment
that follows it. The model is simulated free-run over the whole record from its first sample,
so the validation part continues from the state the estimation part left; the gap is the
NRMSE on the validation part, ``||y - y_sim|| / ||y - mean(y)||``.

The gap is broken down by which branch the model has engaged (eqs. 18-19), by the direction of
motion, near input reversals, at the extremes of travel and over the thirds of the validation
segment. For each group: its share of the samples, its share of the squared error, and its
contribution to the gap (the contributions of one aspect add up in squares to the gap).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import nrmse

from .model import AugmentedModel
from .spec import ModelSpec

__all__ = ["GapGroup", "GapReport", "Split", "measure_gap", "split_record", "turning_points"]

_REVERSAL_WINDOW = 10  # samples after an input reversal counted as "near a reversal"
_HYSTERESIS = 0.02  # a reversal is a turn back by this share of the input span (not jitter)
_EXTREME_SHARE = 0.1  # outer share of the input range on each side counted as "extreme"


def turning_points(u: FloatArray, hysteresis: float) -> IntArray:
    """Indices where the input turns back by more than ``hysteresis`` (its reversals).

    >>> turning_points(np.array([0.0, 1.0, 0.95, 1.1, 0.0, 0.5]), 0.2).tolist()
    [3, 4]
    """
    turns: list[int] = []
    direction = 0
    extreme = 0
    values = u.tolist()
    for t, value in enumerate(values):
        if direction == 0:
            if abs(value - values[0]) > hysteresis:
                direction = 1 if value > values[0] else -1
                extreme = t
        elif direction * (value - values[extreme]) > 0:
            extreme = t
        elif direction * (values[extreme] - value) > hysteresis:
            turns.append(extreme)
            direction = -direction
            extreme = t
    return np.asarray(turns, dtype=np.intp)


@dataclass(frozen=True)
class Split:
    """Estimation samples ``[0, n_estimation)``, validation ``[n_estimation, n_samples)``.

    Examples
    --------
    >>> split_record(1000, 0.3)
    Split(n_samples=1000, n_estimation=700)
    """

    n_samples: int
    n_estimation: int

    def __post_init__(self) -> None:
        if not 0 < self.n_estimation < self.n_samples:
            raise GenBacklashError(
                f"need 0 < n_estimation < n_samples, got {self.n_estimation} of {self.n_samples}"
            )

    @property
    def estimation(self) -> slice:
        """The estimation segment."""
        return slice(0, self.n_estimation)

    @property
    def validation(self) -> slice:
        """The validation segment."""
        return slice(self.n_estimation, self.n_samples)


def split_record(n_samples: int, validation: float, min_validation: int = 50) -> Split:
    """Hold out the last ``validation`` fraction of the record (at least ``min_validation``)."""
    if not 0.0 < validation < 1.0:
        raise GenBacklashError(f"the validation fraction must be in (0, 1), got {validation}")
    n_val = round(validation * n_samples)
    if n_val < min_validation or n_samples - n_val < min_validation:
        raise GenBacklashError(
            f"a {validation:g} validation split of {n_samples} samples leaves {n_val} for "
            f"validation and {n_samples - n_val} for estimation; each needs {min_validation}"
        )
    return Split(n_samples, n_samples - n_val)


@dataclass(frozen=True)
class GapGroup:
    """One group of validation samples in the gap breakdown."""

    aspect: str
    label: str
    samples: int
    sample_share: float
    error_share: float
    contribution: float
    rms: float

    @property
    def concentration(self) -> float:
        """Share of the squared error over share of the samples (1 = spread evenly)."""
        return self.error_share / self.sample_share if self.sample_share > 0 else 0.0


@dataclass(frozen=True, eq=False)
class GapReport:
    """The validation gap of one model and its breakdown.

    Attributes
    ----------
    gap : float
        Free-run NRMSE on the validation segment.
    y_sim : ndarray
        The simulation over the whole record.
    split : Split
        The segments.
    groups : tuple of GapGroup
        The breakdown, grouped by aspect (branch, direction, reversal, travel, time).
    model : AugmentedModel or None
        The model simulated (None: not recorded).
    """

    gap: float
    y_sim: FloatArray
    split: Split
    groups: tuple[GapGroup, ...]
    model: AugmentedModel | None = None

    def aspect(self, name: str) -> tuple[GapGroup, ...]:
        """The groups of one aspect."""
        return tuple(g for g in self.groups if g.aspect == name)

    def hotspots(self, limit: int = 3, threshold: float = 1.5) -> tuple[GapGroup, ...]:
        """Groups holding at least ``threshold`` times their share of the error, worst first."""
        hot = [g for g in self.groups if g.concentration >= threshold and g.samples >= 10]
        return tuple(sorted(hot, key=lambda g: -g.concentration)[:limit])

    def describe(self) -> str:
        """Where the misfit (the validation NRMSE) concentrates, in one sentence."""
        hot = self.hotspots()
        if not hot:
            return (
                f"misfit {self.gap:.4f}, spread evenly over branches, directions, travel and time"
            )
        parts = [
            f"{g.aspect} {g.label} ({100 * g.error_share:.0f}% of the error on "
            f"{100 * g.sample_share:.0f}% of the samples)"
            for g in hot
        ]
        return f"misfit {self.gap:.4f}, concentrated at " + ", ".join(parts)


def _groups(
    aspect: str, masks: dict[str, BoolArray], error2: FloatArray, spread: float
) -> list[GapGroup]:
    total = float(np.sum(error2))
    n = error2.size
    out = []
    for label, mask in masks.items():
        count = int(np.sum(mask))
        part = float(np.sum(error2[mask]))
        out.append(
            GapGroup(
                aspect,
                label,
                count,
                count / n,
                part / total if total > 0 else 0.0,
                float(np.sqrt(part / spread)) if spread > 0 else 0.0,
                float(np.sqrt(part / count)) if count else 0.0,
            )
        )
    return out


def measure_gap(model: AugmentedModel, u: FloatArray, y: FloatArray, split: Split) -> GapReport:
    """Simulate ``model`` over the record and measure its gap on the validation segment.

    Examples
    --------
    >>> from genbacklash_core import GeneralBacklash
    >>> from genbacklash_core.diagnose.synthetic import random_walk_input
    >>> u = random_walk_input(1000, np.random.default_rng(0))
    >>> truth = AugmentedModel(GeneralBacklash.ideal(1.0, 0.3, 0.3))
    >>> y = truth.simulate(u) + np.random.default_rng(1).normal(0, 0.05, 1000)
    >>> report = measure_gap(truth, u, y, split_record(1000, 0.3))
    >>> round(report.gap, 3), [g.label for g in report.aspect("branch")]
    (0.049, ['left', 'right', 'inside'])
    """
    spec = ModelSpec.of(model)
    theta = spec.vector(model)
    y_start = float(y[0])
    out = spec.simulate(theta, u, y_start)
    val = split.validation
    y_val, sim_val = y[val], out.y[val]
    gap = nrmse(y_val, sim_val)
    error2 = (y_val - sim_val) ** 2
    spread = float(np.sum((y_val - np.mean(y_val)) ** 2))
    left, right = spec.engaged(theta, u, out, y_start)
    left, right = left[val], right[val]
    du = np.diff(u, prepend=u[0])
    still = np.abs(du) <= 1e-9 * max(1.0, float(np.ptp(u)))
    rising = (du > 0) & ~still
    falling = (du < 0) & ~still
    reversal = np.zeros(u.size, dtype=bool)
    turns = turning_points(u, _HYSTERESIS * float(np.ptp(u)))
    for lag in range(_REVERSAL_WINDOW):
        reversal[np.minimum(turns + lag, u.size - 1)] = True
    lo, hi = float(np.min(u)), float(np.max(u))
    edge = _EXTREME_SHARE * (hi - lo)
    extreme = (u <= lo + edge) | (u >= hi - edge)
    n_val = y_val.size
    thirds = np.minimum(np.arange(n_val) * 3 // n_val, 2)
    groups = _groups(
        "branch", {"left": left, "right": right, "inside": ~(left | right)}, error2, spread
    )
    groups += _groups(
        "direction",
        {"rising": rising[val], "falling": falling[val], "still": still[val]},
        error2,
        spread,
    )
    groups += _groups(
        "reversal",
        {"near a reversal": reversal[val], "away from reversals": ~reversal[val]},
        error2,
        spread,
    )
    groups += _groups(
        "travel", {"extremes": extreme[val], "interior": ~extreme[val]}, error2, spread
    )
    groups += _groups(
        "time",
        {"first third": thirds == 0, "middle third": thirds == 1, "last third": thirds == 2},
        error2,
        spread,
    )
    return GapReport(gap, out.y, split, tuple(groups), model)
