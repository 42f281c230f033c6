"""The paper's four simulation examples (§3c Examples 1-2, §4c Examples 3-4)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._typing import FloatArray
from .backlash import GeneralBacklash
from .cascade import Cascade
from .data import as_order, as_real
from .errors import GenBacklashError
from .linear import LinearBlock
from .simulate import simulate_backlash, simulate_cascade

__all__ = ["ExampleData", "PaperExample", "paper_example"]

_LINEAR = LinearBlock(
    a=(1.0, 0.15), b=(-0.2, 0.35)
)  # y = x(t-1) + 0.15x(t-2) + 0.2y(t-1) - 0.35y(t-2)


@dataclass(frozen=True, eq=False)
class ExampleData:
    """One noisy realisation of an example: input ``u``, noisy output ``y``, clean output."""

    u: FloatArray
    y: FloatArray
    y_clean: FloatArray
    noise_std: float


@dataclass(frozen=True)
class PaperExample:
    """A simulation setting from the paper: the true model and the data conditions.

    Examples
    --------
    >>> ex = paper_example(1)
    >>> ex.n_samples, ex.u_max, ex.snr
    (800, 2.0, 25.0)
    >>> data = ex.generate(seed=0)
    >>> data.u.shape, bool(np.all(np.abs(data.u) < 2.0))
    ((800,), True)
    """

    number: int
    model: GeneralBacklash | Cascade
    n_samples: int
    u_max: float
    snr: float

    @property
    def backlash(self) -> GeneralBacklash:
        """The backlash part of the model."""
        return self.model.backlash if isinstance(self.model, Cascade) else self.model

    def generate(
        self, seed: int, n_samples: int | None = None, snr: float | None = None
    ) -> ExampleData:
        """Uniform random input in ``(-u_max, u_max)``, simulated output plus white noise.

        SNR is the ratio of the output's and the noise's standard deviations (the paper's
        "square root of the ratio of output and noise variances").
        """
        n = self.n_samples if n_samples is None else as_order("n_samples", n_samples)
        ratio = self.snr if snr is None else as_real("snr", snr, finite=False)
        if n < 1 or not ratio > 0:
            raise GenBacklashError(f"need n_samples >= 1 and snr > 0, got {n} and {ratio}")
        if as_order("seed", seed) < 0:
            raise GenBacklashError(f"seed must be >= 0, got {seed}")
        rng = np.random.default_rng(seed)
        u = rng.uniform(-self.u_max, self.u_max, n)
        if isinstance(self.model, Cascade):
            clean = simulate_cascade(self.model, u).y
        else:
            clean = simulate_backlash(self.model, u)
        noise_std = float(np.std(clean)) / ratio
        if not math.isfinite(noise_std):
            raise GenBacklashError(f"snr {ratio:g} is too small: the noise overflows float64")
        y = clean + rng.normal(0.0, noise_std, n)
        return ExampleData(u=u, y=y, y_clean=clean, noise_std=noise_std)


def paper_example(number: int) -> PaperExample:
    """The paper's Example ``number`` (1-4) with its N, input range and SNR."""
    if number == 1:
        model: GeneralBacklash | Cascade = GeneralBacklash(
            (0.5, -0.3, 0.3), 0.7, (0.6, 0.4, 0.2), 0.8
        )
        return PaperExample(1, model, 800, 2.0, 25.0)
    if number == 2:
        model = GeneralBacklash((-0.5, 0.3, -0.3), 0.7, (-0.6, -0.4, -0.2), 0.8)
        return PaperExample(2, model, 800, 2.0, 25.0)
    if number == 3:
        bl = GeneralBacklash((0.5, -0.3, 0.3), 0.45, (0.6, 0.4, 0.2), 0.55)
        return PaperExample(3, Cascade(bl, _LINEAR), 1500, 1.0, 50.0)
    if number == 4:
        bl = GeneralBacklash((0.5, 0.0, 0.3), 0.4, (0.5, 0.0, 0.3), 0.4)
        return PaperExample(4, Cascade(bl, _LINEAR), 1500, 1.5, 50.0)
    raise GenBacklashError(f"the paper has Examples 1-4, got {number}")
