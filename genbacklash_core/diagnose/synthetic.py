"""Synthetic records with hidden effects, for tests, benchmarks and examples.

The input is a filtered random walk: a velocity that is an AR(1) process, integrated and
reflected at ``+/- amplitude``, so the joint moves with varying speed and reverses at random
points (not the i.i.d. uniform input of the paper's examples, which a real drivetrain cannot
follow). The system is an ideal backlash (eq. 1) with random slope and gaps, to which each
named effect is added at a random strength; white output noise sets the SNR
(``std(output) / std(noise)``, as in the paper).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.linear import LinearBlock

from .model import AugmentedModel, Drift, Saturation

__all__ = ["EFFECT_NAMES", "SyntheticCase", "random_walk_input", "synthetic_case"]

EFFECT_NAMES = (
    "curved_branches",
    "linear_dynamics",
    "time_delay",
    "output_offset",
    "gap_drift",
    "saturation",
)


def random_walk_input(
    n_samples: int,
    rng: np.random.Generator,
    *,
    amplitude: float = 2.0,
    correlation: float = 0.95,
    speed: float = 0.04,
) -> FloatArray:
    """A filtered random walk reflected into ``[-amplitude, amplitude]``.

    Parameters
    ----------
    n_samples : int
        Length.
    rng : numpy.random.Generator
        Source of randomness (seed it).
    amplitude : float
        Bound of the travel.
    correlation : float
        Pole of the AR(1) velocity, in ``[0, 1)``: closer to 1 is smoother.
    speed : float
        Standard deviation of the velocity as a fraction of ``amplitude`` per sample.

    Examples
    --------
    >>> u = random_walk_input(2000, np.random.default_rng(1))
    >>> bool(np.all(np.abs(u) <= 2.0)), bool(np.sum(np.diff(np.sign(np.diff(u))) != 0) > 50)
    (True, True)
    """
    if n_samples < 2 or not amplitude > 0 or not 0.0 <= correlation < 1.0 or not speed > 0:
        raise GenBacklashError(
            "need n_samples >= 2, amplitude > 0, 0 <= correlation < 1 and speed > 0, got "
            f"{n_samples}, {amplitude}, {correlation}, {speed}"
        )
    sigma = speed * amplitude * np.sqrt(1.0 - correlation**2)
    shocks = rng.normal(0.0, sigma, n_samples)
    out = np.empty(n_samples)
    position = rng.uniform(-0.5, 0.5) * amplitude
    velocity = rng.normal(0.0, speed * amplitude)
    for t, shock in enumerate(shocks.tolist()):
        velocity = correlation * velocity + shock
        position += velocity
        if position > amplitude:  # reflect at the ends of travel
            position = 2.0 * amplitude - position
            velocity = -velocity
        elif position < -amplitude:
            position = -2.0 * amplitude - position
            velocity = -velocity
        out[t] = position
    return out


@dataclass(frozen=True, eq=False)
class SyntheticCase:
    """A generated record and what is hidden in it.

    Attributes
    ----------
    u, y : ndarray
        Input and noisy output.
    y_clean : ndarray
        Output without noise.
    truth : AugmentedModel
        The system that produced it.
    effects : tuple of str
        The catalog effects hidden in it (empty for a clean record).
    noise_std : float
        Standard deviation of the added white noise.
    description : str
        One line naming the effects and their strengths.
    """

    u: FloatArray
    y: FloatArray
    y_clean: FloatArray
    truth: AugmentedModel
    effects: tuple[str, ...]
    noise_std: float
    description: str


def _curved(
    rng: np.random.Generator, bl: GeneralBacklash, amplitude: float
) -> tuple[GeneralBacklash, str]:
    """Cubic branches with random curvature that stay monotonic and apart (eqs. 11-12)."""
    for _ in range(100):
        strength = rng.uniform(0.4, 1.0)
        m2 = rng.uniform(-0.12, 0.12, 2) * strength
        m3 = rng.uniform(0.04, 0.12, 2) * strength
        left = (bl.m_left[0], float(m2[0]), float(m3[0]))
        right = (bl.m_right[0], float(m2[1]), float(m3[1]))
        curved = GeneralBacklash(left, bl.c_left, right, bl.c_right)
        grid = np.linspace(-amplitude, amplitude, 201)
        slopes_ok = all(
            np.all(np.gradient(branch(grid), grid) > 0.2 * bl.m_left[0])
            for branch in (curved.left, curved.right)
        )
        if slopes_ok and curved.branches_separated(-amplitude, amplitude):
            return curved, f"cubic branches (m_3 {m3[0]:.3f}/{m3[1]:.3f})"
    raise GenBacklashError("could not draw curved branches")  # pragma: no cover


def _linear(rng: np.random.Generator) -> tuple[LinearBlock, str]:
    """A stable first- or second-order block in the paper's form (eq. 30)."""
    if rng.uniform() < 0.5:
        pole = rng.uniform(0.5, 0.85)
        return LinearBlock(a=(1.0,), b=(-pole,)), f"first-order lag (pole {pole:.2f})"
    radius = rng.uniform(0.5, 0.8)
    angle = rng.uniform(0.1, 0.6)
    b = (-2.0 * radius * np.cos(angle), radius**2)
    a2 = rng.uniform(0.0, 0.3)
    return (
        LinearBlock(a=(1.0, a2), b=(float(b[0]), float(b[1]))),
        f"second-order dynamics (poles {radius:.2f} at +/-{angle:.2f} rad)",
    )


def _scaled(bl: GeneralBacklash, factor: float) -> GeneralBacklash:
    """The backlash with its output scaled (the key-term normalisation puts gains here)."""
    return GeneralBacklash(
        tuple(factor * m for m in bl.m_left),
        bl.c_left,
        tuple(factor * m for m in bl.m_right),
        bl.c_right,
    )


def synthetic_case(
    effects: Sequence[str],
    seed: int,
    n_samples: int = 3000,
    *,
    snr: float | None = None,
    input_kind: str = "walk",
) -> SyntheticCase:
    """A record of an ideal backlash with the named effects hidden at random strengths.

    Parameters
    ----------
    effects : sequence of str
        Names from :data:`EFFECT_NAMES` (empty for a clean record).
    seed : int
        Seeds every random choice (strengths, input, noise).
    n_samples : int
        Record length.
    snr : float, optional
        ``std(output) / std(noise)``; default drawn from ``[20, 50]``.
    input_kind : {"walk", "uniform"}
        A filtered random walk (default) or the paper's i.i.d. uniform input.

    Examples
    --------
    >>> case = synthetic_case(["time_delay"], seed=3, n_samples=500)
    >>> case.effects, case.truth.delay > 1
    (('time_delay',), True)
    """
    unknown = [name for name in effects if name not in EFFECT_NAMES]
    if unknown:
        raise GenBacklashError(f"unknown effects {unknown}; known: {', '.join(EFFECT_NAMES)}")
    if input_kind not in ("walk", "uniform"):
        raise GenBacklashError(f"input_kind must be 'walk' or 'uniform', got {input_kind!r}")
    rng = np.random.default_rng(seed)
    amplitude = 2.0
    slope = rng.uniform(0.7, 1.3)
    bl = GeneralBacklash.ideal(slope, rng.uniform(0.15, 0.4), rng.uniform(0.15, 0.4))
    notes = [f"ideal backlash (slope {slope:.2f}, gaps {bl.c_left:.2f}/{bl.c_right:.2f})"]
    if input_kind == "walk":
        u = random_walk_input(
            n_samples,
            rng,
            amplitude=amplitude,
            correlation=rng.uniform(0.9, 0.97),
            speed=rng.uniform(0.03, 0.06),
        )
    else:
        u = rng.uniform(-amplitude, amplitude, n_samples)
    base: GeneralBacklash | Cascade = bl
    model = AugmentedModel(bl)
    if "curved_branches" in effects:
        bl, note = _curved(rng, bl, amplitude)
        base = bl
        notes.append(note)
    if "linear_dynamics" in effects:
        block, note = _linear(rng)
        base = Cascade(_scaled(bl, 1.0 / block.dc_gain), block)  # unit static gain
        notes.append(note)
    model = replace(model, base=base)
    if "time_delay" in effects:
        delay = int(rng.integers(2, 9))
        model = replace(model, delay=delay)
        notes.append(f"dead time {delay} samples")
    if "output_offset" in effects:
        # Larger than the dead zones (a smaller offset is absorbed by c_L, c_R: not an effect)
        half_range = 0.5 * float(np.ptp(model.simulate(u)))
        size = max(rng.uniform(0.3, 1.0) * half_range, 2.5 * slope * max(bl.c_left, bl.c_right))
        offset = float(rng.choice([-1.0, 1.0]) * size)
        model = replace(model, offset=offset)
        notes.append(f"output offset {offset:+.2f}")
    if "gap_drift" in effects:
        growth = rng.uniform(0.5, 1.5)  # each gap grows by this fraction over the record
        rate = growth * 0.5 * (bl.c_left + bl.c_right) / n_samples
        model = replace(model, drift=Drift(rate, "time"))
        notes.append(f"gap growing {100 * growth:.0f}% over the record")
    if "saturation" in effects:
        free = model.simulate(u)
        depth = rng.uniform(0.05, 0.15) * float(np.ptp(free))  # how far the limit cuts in
        if rng.uniform() < 0.5:
            level = float(np.max(free)) - depth
            limit = Saturation(None, level)
            clipped = float(np.mean(free > level))
            notes.append(f"upper output limit {level:.2f} ({100 * clipped:.0f}% clipped)")
        else:
            level = float(np.min(free)) + depth
            limit = Saturation(level, None)
            clipped = float(np.mean(free < level))
            notes.append(f"lower output limit {level:.2f} ({100 * clipped:.0f}% clipped)")
        model = replace(model, saturation=limit)
    clean = model.simulate(u)
    ratio = rng.uniform(20.0, 50.0) if snr is None else float(snr)
    if not ratio > 0:
        raise GenBacklashError(f"snr must be > 0, got {snr}")
    noise_std = float(np.std(clean)) / ratio
    y = clean + rng.normal(0.0, noise_std, n_samples)
    notes.append(f"SNR {ratio:.0f}")
    return SyntheticCase(u, y, clean, model, tuple(effects), noise_std, "; ".join(notes))
