"""What quantisation and noise allow: the floor under the validation gap.

No model can simulate a reading closer than the reading's own error. Two parts of that error
can be read off the record itself, without any model:

* the encoder's step ``q`` (quantisation): readings sit on a grid, and rounding to it leaves an
  error uniform over one step, RMS ``q / sqrt(12)``;
* the white noise on the readings: where the command has not changed for a while (a dwell)
  the load stands still, so the difference of two consecutive readings there is noise alone,
  ``var(y(t) - y(t-1)) = 2 sigma^2``.

The floor is ``sqrt(q^2 / 12 + sigma^2)`` (the two add up when the noise dithers the
quantiser; when the noise is far below one step the dwell differences are all zero and the
floor is the quantisation's), and as a gap (an NRMSE) that RMS over the spread of the
validation output. Records without dwells (the paper's input, a new value every sample) give
no noise estimate: then the floor is that of the quantisation alone, and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError

__all__ = ["NoiseFloor", "encoder_step", "noise_floor"]

_SETTLE = 50  # samples the command must have stood still before a pair counts as a dwell
_MIN_PAIRS = 50  # dwell pairs needed for a noise estimate


def encoder_step(y: FloatArray) -> float:
    """The encoder's step: the smallest difference of distinct readings, when every reading
    sits on that grid (within 5% of a step); 0 for unquantised data.

    >>> encoder_step(np.round(np.sin(np.arange(200.0) / 7) / 0.01) * 0.01)
    0.01
    >>> encoder_step(np.sin(np.arange(200.0) / 7))
    0.0
    """
    yy = np.asarray(y, dtype=np.float64)
    levels = np.unique(yy)
    if levels.size < 3 or levels.size > yy.size // 4:
        return 0.0
    steps = np.diff(levels)
    q = float(np.min(steps))
    if not q > 0.0:
        return 0.0
    ratio = (levels - levels[0]) / q
    if float(np.max(np.abs(ratio - np.round(ratio)))) >= 0.05:
        return 0.0
    return float(np.round(q, 12))


@dataclass(frozen=True)
class NoiseFloor:
    """The error a perfect model would still leave (see the module notes).

    Attributes
    ----------
    step : float
        The encoder's step (0: not quantised).
    noise : float or None
        Standard deviation of the white noise on the readings, from the dwells (None: the
        record has too few dwell samples to tell).
    pairs : int
        Dwell pairs the noise was estimated from.
    rms : float
        ``sqrt(step^2 / 12 + noise^2)`` (the noise taken as 0 when unknown).
    gap : float
        ``rms`` as a gap: over the standard deviation of the validation output.
    """

    step: float
    noise: float | None
    pairs: int
    rms: float
    gap: float

    def __post_init__(self) -> None:
        for name in ("step", "rms", "gap"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise GenBacklashError(f"{name} must be finite and >= 0, got {value!r}")

    @property
    def known(self) -> bool:
        """True when the noise was measured (dwells), so the floor is complete."""
        return self.noise is not None

    def describe(self) -> str:
        """One sentence with the numbers.

        >>> NoiseFloor(0.0015, 0.0002, 900, 0.0005, 0.0008).describe()[:60]
        'quantisation and noise allow a misfit of 0.0008 (RMS 0.0005:'
        """
        step = f"encoder step {self.step:.3g}" if self.step > 0 else "no quantisation seen"
        if self.noise is None:
            return (
                f"quantisation alone allows a misfit of {self.gap:.4f} "
                f"(RMS {self.rms:.3g}: {step}; "
                "the record has too few dwells to measure the noise, so the floor is a lower "
                "bound)"
            )
        return (
            f"quantisation and noise allow a misfit of {self.gap:.4f} (RMS {self.rms:.3g}: {step}, "
            f"noise {self.noise:.3g} from {self.pairs} dwell samples)"
        )


def noise_floor(
    u: FloatArray, y: FloatArray, validation: slice, breaks: BoolArray | None = None
) -> NoiseFloor:
    """Measure the floor of a record (see the module notes).

    Parameters
    ----------
    u, y : ndarray
        Command and reading.
    validation : slice
        The validation segment (the gap's denominator is its output's spread).
    breaks : ndarray of bool, optional
        The sample rule: a pair across a break is not a pair.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> u = np.repeat(rng.uniform(-1, 1, 40), 200)  # 40 dwells of 200 samples
    >>> y = u + rng.normal(0.0, 0.01, u.size)
    >>> floor = noise_floor(u, y, slice(5600, 8000))
    >>> round(floor.noise, 3), floor.step
    (0.01, 0.0)
    """
    uu = np.asarray(u, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    n = uu.size
    step = encoder_step(yy)
    # samples whose command has stood still for _SETTLE samples (a run length per sample)
    change = np.ones(n, dtype=bool)
    change[1:] = uu[1:] != uu[:-1]
    if breaks is not None:
        change |= np.asarray(breaks, dtype=bool)
    index = np.arange(n)
    last_change = np.maximum.accumulate(np.where(change, index, 0))
    still = (index - last_change) >= _SETTLE
    pairs = still.copy()
    pairs[0] = False
    count = int(np.sum(pairs))
    noise: float | None = None
    if count >= _MIN_PAIRS:
        d = yy[1:][pairs[1:]] - yy[:-1][pairs[1:]]
        noise = math.sqrt(float(np.mean(d**2)) / 2.0)  # var(y(t) - y(t-1)) = 2 sigma^2
    variance = step**2 / 12.0 + (0.0 if noise is None else noise**2)
    # the dithered quantiser's differences already carry part of q^2/12: count it once
    if noise is not None and step > 0.0:
        variance = max(step**2 / 12.0, noise**2)
    rms = math.sqrt(variance)
    spread = float(np.std(yy[validation]))
    gap = rms / spread if spread > 0.0 else 0.0
    return NoiseFloor(step, noise, count, rms, gap)
