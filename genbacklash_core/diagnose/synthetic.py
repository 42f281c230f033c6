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
from typing import Any

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.linear import LinearBlock
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    STRAIGHT_BACKLASH,
    HiddenEffects,
    OperationRecord,
    OperationSettings,
    operation_record,
)

from .model import AugmentedModel, Drift, Saturation

__all__ = [
    "EFFECT_NAMES",
    "OPERATION_EFFECTS",
    "OperationCase",
    "SyntheticCase",
    "operation_case",
    "random_walk_input",
    "synthetic_case",
]

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


# --------------------------------------------------------------------------- operation records

OPERATION_EFFECTS = (*EFFECT_NAMES, "input_lag", "periodic_error")


@dataclass(frozen=True, eq=False)
class OperationCase:
    """A drivetrain in normal operation with effects hidden in it (see :func:`operation_case`).

    Attributes
    ----------
    u, y : ndarray
        The node's samples: the held command and the reading, one per reading that arrived.
    breaks : ndarray of bool
        The sample rule (:func:`~genbacklash_core.samples.sample_breaks`).
    record : OperationRecord
        The simulated record with its truth.
    effects : tuple of str
        The catalog effects hidden in it, in the order given.
    description : str
        One line naming the drivetrain, the effects and their strengths.
    """

    u: FloatArray
    y: FloatArray
    breaks: BoolArray
    record: OperationRecord
    effects: tuple[str, ...]
    description: str

    def without(self, effect: str) -> FloatArray:
        """The noise-free output of the same record with ``effect`` taken out (every other
        effect, the motion and the stamps unchanged), at the readings that arrived."""
        if effect not in self.effects:
            raise GenBacklashError(f"{effect!r} is not hidden in this record")
        record = self.record
        settings = record.settings
        hidden = record.hidden if record.hidden is not None else HiddenEffects()
        if effect == "curved_branches":
            m = settings.model
            settings = replace(settings, model=GeneralBacklash.ideal(1.0, m.c_left, m.c_right))
        elif effect == "gap_drift":
            settings = replace(settings, wear=0.0)
        elif effect == "time_delay":
            hidden = replace(hidden, delay=0.0)
        elif effect == "input_lag":
            hidden = replace(hidden, input_lag=0.0)
        elif effect == "linear_dynamics":
            hidden = replace(hidden, load_lag=0.0)
        elif effect == "output_offset":
            hidden = replace(hidden, offset=0.0)
        elif effect == "saturation":
            hidden = replace(hidden, limit=(None, None))
        else:  # periodic_error
            hidden = replace(hidden, period=0.0, harmonics=())
        other = operation_record(settings, record.seed, hidden=hidden)
        return np.asarray(other.x_all[record.received], dtype=np.float64)

    def sizes(self) -> dict[str, float]:
        """How much each hidden effect moves the output: the RMS change of the noise-free
        output when it alone is taken out. "Named in the order of size" is this order."""
        clean = self.record.x_all[self.record.received]
        return {
            effect: float(np.sqrt(np.mean((clean - self.without(effect)) ** 2)))
            for effect in self.effects
        }


def operation_case(
    effects: Sequence[str], seed: int, duration: float = 30.0, *, noise: float | None = None
) -> OperationCase:
    """A record of a drivetrain in normal operation with the named effects hidden in it.

    The drivetrain of :mod:`genbacklash_core.scenarios` (smooth moves, dwells and jogs, 100 Hz
    commands held, a 1 kHz encoder quantised to 4096 counts per revolution with 2% of the
    readings lost) with the play of :data:`~genbacklash_core.scenarios.STRAIGHT_BACKLASH`
    (2.6 and 2.9 degrees) scaled by 0.8-1.6, plus each named effect at a random strength:

    * ``curved_branches``: quadratic and cubic branch terms (0.6-1.6 times those of
      :data:`~genbacklash_core.scenarios.OPERATION_BACKLASH`);
    * ``linear_dynamics``: a first-order load lag of 3-10 ms after the backlash;
    * ``time_delay``: a dead time of 3-8 ms;
    * ``output_offset``: an encoder zero 0.15-0.6 rad away (larger than the dead zones);
    * ``gap_drift``: both dead zones growing 50-150% over the record;
    * ``saturation``: an output limit cutting 5-15% of the output range on one side (of the
      range the first 70% of the record reaches);
    * ``input_lag``: the servo's first-order lag of 5-20 ms before the backlash;
    * ``periodic_error``: a runout of 0.15-0.4 degrees with period 0.25-0.8 rad of load
      travel, with a second harmonic of up to half its size on half the records.

    Parameters
    ----------
    effects : sequence of str
        Names from :data:`OPERATION_EFFECTS` (empty: a clean record).
    seed : int
        Seeds every choice (strengths, motion, stamps, noise, losses).
    duration : float
        Seconds (1000 readings per second).
    noise : float, optional
        Encoder noise before quantisation, radians; default drawn from ``[0, 0.0005]``.

    Examples
    --------
    >>> case = operation_case(["input_lag"], seed=2, duration=3.0)
    >>> case.effects, case.u.size == case.y.size == case.breaks.size
    (('input_lag',), True)
    """
    unknown = [name for name in effects if name not in OPERATION_EFFECTS]
    if unknown:
        raise GenBacklashError(f"unknown effects {unknown}; known: {', '.join(OPERATION_EFFECTS)}")
    rng = np.random.default_rng([int(seed), 14])
    scale = float(rng.uniform(0.8, 1.6))
    model = GeneralBacklash(
        (1.0,), STRAIGHT_BACKLASH.c_left * scale, (1.0,), STRAIGHT_BACKLASH.c_right * scale
    )
    notes = [f"straight branches, c_L {model.c_left:.4f}, c_R {model.c_right:.4f} rad"]
    if "curved_branches" in effects:
        k = float(rng.uniform(0.6, 1.6))
        ref = OPERATION_BACKLASH
        model = GeneralBacklash(
            (1.0, ref.m_left[1] * k, ref.m_left[2] * k),
            model.c_left,
            (1.0, ref.m_right[1] * k, ref.m_right[2] * k),
            model.c_right,
        )
        notes.append(f"curved branches ({k:.2f} x the operation drivetrain's curvature)")
    wear = 0.0
    if "gap_drift" in effects:
        wear = float(rng.uniform(0.5, 1.5))
        notes.append(f"gaps growing {100 * wear:.0f}% over the record")
    level = float(rng.uniform(0.0, 5e-4)) if noise is None else float(noise)
    settings = OperationSettings(duration=duration, model=model, wear=wear, noise=level)
    hidden: dict[str, Any] = {}
    if "time_delay" in effects:
        hidden["delay"] = float(rng.uniform(0.003, 0.008))
        notes.append(f"dead time {1e3 * hidden['delay']:.1f} ms")
    if "input_lag" in effects:
        hidden["input_lag"] = float(rng.uniform(0.005, 0.02))
        notes.append(f"servo lag {1e3 * hidden['input_lag']:.1f} ms")
    if "linear_dynamics" in effects:
        hidden["load_lag"] = float(rng.uniform(0.003, 0.01))
        notes.append(f"load lag {1e3 * hidden['load_lag']:.1f} ms")
    if "output_offset" in effects:
        hidden["offset"] = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.15, 0.6))
        notes.append(f"output offset {hidden['offset']:+.3f} rad")
    if "periodic_error" in effects:
        period = float(rng.uniform(0.25, 0.8))
        amplitude = float(np.deg2rad(rng.uniform(0.15, 0.4)))
        harmonics = [(amplitude, float(rng.uniform(-np.pi, np.pi)))]
        if rng.uniform() < 0.5:
            harmonics.append((amplitude * float(rng.uniform(0.2, 0.5)), float(rng.uniform(-3, 3))))
        hidden["period"] = period
        hidden["harmonics"] = tuple(harmonics)
        notes.append(
            f"periodic error {np.rad2deg(amplitude):.2f} deg, period {period:.3f} rad"
            + (
                f", second harmonic {np.rad2deg(harmonics[1][0]):.2f} deg"
                if len(harmonics) > 1
                else ""
            )
        )
    draw_limit = "saturation" in effects
    side = float(rng.uniform()) < 0.5
    depth = float(rng.uniform(0.05, 0.15))
    if draw_limit:
        # the limit cuts into the range the first 70% of the record reaches: the part a
        # diagnosis fits on (a limit first reached in the held-out part cannot be seen there)
        free = operation_record(settings, seed, hidden=HiddenEffects(**hidden)).x_all
        free = free[: int(0.7 * free.size)]
        cut = depth * float(np.ptp(free))
        if side:
            hidden["limit"] = (None, float(np.max(free)) - cut)
            notes.append(f"upper output limit {hidden['limit'][1]:+.3f} rad")
        else:
            hidden["limit"] = (float(np.min(free)) + cut, None)
            notes.append(f"lower output limit {hidden['limit'][0]:+.3f} rad")
    record = operation_record(settings, seed, hidden=HiddenEffects(**hidden))
    notes.append(f"encoder noise {level:.2g} rad, 4096 counts/rev, 2% of readings lost")
    u, y, breaks = record.series()
    return OperationCase(u, y, breaks, record, tuple(effects), "; ".join(notes))
