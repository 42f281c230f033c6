"""Thresholds of the diagnosis loop, in one validated place."""

from __future__ import annotations

from dataclasses import dataclass, fields

from genbacklash_core.errors import GenBacklashError

__all__ = ["DiagnoseSettings"]


@dataclass(frozen=True)
class DiagnoseSettings:
    """Options of :func:`~genbacklash_core.diagnose.diagnose`.

    Parameters
    ----------
    validation : float
        Fraction of the record held out at its end for the validation gap.
    alpha : float
        Level of the whiteness and input-independence tests that end the loop.
    screen_alpha : float
        p-value a detector's signature test must beat to nominate its effect.
    min_share : float
        Share of the residual's variance a detector's signature must explain.
    bic_margin : float
        An augmentation must lower the BIC on the estimation data by more than this.
    min_gap_drop : float
        ...and lower the validation gap by at least this fraction,
    min_excess_drop : float
        ...or, when the record's dwells measured the floor quantisation and noise allow, close
        at least this share of the gap's excess over that floor,
    gap_alpha : float
        ...significantly: a one-sided test on the squared validation errors (Newey-West).
    max_steps : int
        Most effects added.
    max_delay : int
        Longest dead time searched, in samples.
    max_degree : int
        Highest branch degree tried.
    floor_margin : float
        Stop when the validation gap is within this factor of what quantisation and noise
        allow (:mod:`~genbacklash_core.diagnose.floor`; only when the record's dwells measured
        the noise). An effect must also lower the gap by at least ``floor_margin - 1`` times
        that floor: a smaller drop is within what the floor allows.
    folds : int
        Held-out blocks the acceptance verdict pools (:mod:`~genbacklash_core.diagnose.folds`):
        1, the validation segment at the record's end alone; 2, also a block as long at its
        start, with the models refitted on the rest (about twice the fits per verdict).

    Examples
    --------
    >>> DiagnoseSettings(validation=0.25).validation
    0.25
    >>> DiagnoseSettings(alpha=2.0)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: alpha must be in (0, 1), got 2.0
    """

    validation: float = 0.3
    alpha: float = 0.01
    screen_alpha: float = 1e-3
    min_share: float = 0.02
    bic_margin: float = 10.0
    min_gap_drop: float = 0.05
    gap_alpha: float = 0.01
    max_steps: int = 6
    max_delay: int = 20
    max_degree: int = 5
    floor_margin: float = 1.3
    min_excess_drop: float = 0.1
    folds: int = 2

    def __post_init__(self) -> None:
        for name in ("validation", "alpha", "screen_alpha", "min_share", "gap_alpha"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise GenBacklashError(f"{name} must be a number, got {value!r}")
            if not 0.0 < value < 1.0:
                raise GenBacklashError(f"{name} must be in (0, 1), got {value}")
        for name in ("bic_margin", "min_gap_drop", "min_excess_drop"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                raise GenBacklashError(f"{name} must be a number >= 0, got {value!r}")
        margin = self.floor_margin
        if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not margin >= 1.0:
            raise GenBacklashError(f"floor_margin must be a number >= 1, got {margin!r}")
        if not self.min_excess_drop < 1.0:
            raise GenBacklashError(f"min_excess_drop must be < 1, got {self.min_excess_drop}")
        if not self.min_gap_drop < 1.0:
            raise GenBacklashError(f"min_gap_drop must be < 1, got {self.min_gap_drop}")
        for name in ("max_steps", "max_delay", "max_degree"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise GenBacklashError(f"{name} must be a whole number >= 1, got {value!r}")
        if (
            not isinstance(self.folds, int)
            or isinstance(self.folds, bool)
            or self.folds not in (1, 2)
        ):
            raise GenBacklashError(f"folds must be 1 or 2, got {self.folds!r}")

    def as_dict(self) -> dict[str, float]:
        """The settings as a plain mapping (for reports)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
