"""The augmented model: the paper's general backlash (or cascade) plus the effects a diagnosis adds.

The model output is

    y(t) = sat( z(t) + o + E(z(t)) ),    z = G(q) x,
    x = general backlash of v with gaps c(t) = c + k s(t),
    v(t) = a v(t-1) + (1 - a) ((1 - f) u(t - d) + f u(t - d - 1))

where the backlash is eqs. (11)-(13)/(20), ``G(q)`` the linear block of eq. (30) (absent for a
backlash alone, where ``z = x``), ``d`` a dead time in samples, ``a`` the pole of the servo's
first-order lag before the backlash (``input_lag``; 0: none), ``f`` a fraction of a sample of
dead time before that lag (linear interpolation between samples), ``o`` an output offset, ``k`` a
gap drift (wear) along ``s(t)`` = the sample index or the input travel so far, ``E`` an error
periodic in the load position ``z`` (``periodic_error``: harmonics of a period ``P``) and
``sat`` an output limit. The base model classes stay untouched; this wrapper composes them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from genbacklash_core._typing import ArrayLike, FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.linear import LinearBlock
from genbacklash_core.structure import as_order

from .physics import LoadPhysics

__all__ = [
    "AugmentedModel",
    "Drift",
    "DriftBasis",
    "PeriodicError",
    "Saturation",
    "drift_coordinate",
    "lag_pole",
    "without_effect",
]

MAX_LAG_POLE = 0.995  # an input lag's pole above this is a time constant of > 200 samples


def lag_pole(time_constant: float) -> float:
    """The pole ``a = exp(-1 / T)`` of a first-order lag with time constant ``T`` samples.

    >>> round(lag_pole(10.0), 4)
    0.9048
    """
    if not time_constant > 0.0:
        raise GenBacklashError(f"the time constant must be > 0 samples, got {time_constant}")
    return math.exp(-1.0 / time_constant)


DriftBasis = Literal["time", "travel"]
_BASES = ("time", "travel")


def drift_coordinate(u: ArrayLike, basis: DriftBasis) -> FloatArray:
    """The coordinate ``s(t)`` the gap drifts along: sample index, or input travel so far.

    >>> drift_coordinate([0.0, 1.0, 0.5], "time").tolist()
    [0.0, 1.0, 2.0]
    >>> drift_coordinate([0.0, 1.0, 0.5], "travel").tolist()
    [0.0, 1.0, 1.5]
    """
    uu = np.asarray(u, dtype=np.float64)
    if basis == "time":
        return np.arange(uu.size, dtype=np.float64)
    if basis == "travel":
        return np.concatenate([[0.0], np.cumsum(np.abs(np.diff(uu)))])
    raise GenBacklashError(f"drift basis must be 'time' or 'travel', got {basis!r}")


@dataclass(frozen=True)
class Drift:
    """Gap growth (wear): ``c_L(t) = c_L + rate s(t)`` and ``c_R(t) = c_R + rate s(t)``.

    Parameters
    ----------
    rate : float
        Growth of each dead-zone constant per sample (``basis="time"``) or per unit of input
        travel (``basis="travel"``); negative when the gap closes.
    basis : {"time", "travel"}
        What the gap drifts along, see :func:`drift_coordinate`.

    Examples
    --------
    >>> Drift(1e-4, "time").rate
    0.0001
    """

    rate: float
    basis: DriftBasis = "time"

    def __post_init__(self) -> None:
        if isinstance(self.rate, bool) or not isinstance(self.rate, (int, float, np.floating)):
            raise GenBacklashError(f"drift rate must be a number, got {self.rate!r}")
        if not math.isfinite(self.rate):
            raise GenBacklashError(f"drift rate must be finite, got {self.rate}")
        if self.basis not in _BASES:
            raise GenBacklashError(f"drift basis must be 'time' or 'travel', got {self.basis!r}")
        object.__setattr__(self, "rate", float(self.rate))


@dataclass(frozen=True)
class Saturation:
    """Output limits ``low <= y <= high``; either side may be absent (None).

    Examples
    --------
    >>> Saturation(None, 1.5).high
    1.5
    >>> Saturation(2.0, 1.0)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: saturation needs low < high, got low=2.0, high=1.0
    """

    low: float | None = None
    high: float | None = None

    def __post_init__(self) -> None:
        if self.low is None and self.high is None:
            raise GenBacklashError("saturation needs at least one limit (low or high)")
        for name in ("low", "high"):
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise GenBacklashError(f"saturation {name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise GenBacklashError(f"saturation {name} must be finite, got {value}")
            object.__setattr__(self, name, float(value))
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise GenBacklashError(
                f"saturation needs low < high, got low={self.low}, high={self.high}"
            )

    @property
    def sides(self) -> tuple[bool, bool]:
        """Which limits are present: ``(low, high)``."""
        return self.low is not None, self.high is not None


@dataclass(frozen=True)
class PeriodicError:
    """An output error periodic in the load position ``z`` (gear runout, encoder eccentricity):
    ``E(z) = sum_j cos_j cos(2 pi j z / P) + sin_j sin(2 pi j z / P)``, ``j = 1..K``.

    Parameters
    ----------
    period : float
        ``P``, in units of the output (radians of load travel, say).
    cos, sin : tuple of float
        The coefficients of harmonics ``1..K`` (one each per harmonic).

    Examples
    --------
    >>> e = PeriodicError(0.5, (0.0,), (0.01,))
    >>> round(float(e(np.array([0.125]))[0]), 6)
    0.01
    >>> e.amplitudes
    (0.01,)
    """

    period: float
    cos: tuple[float, ...]
    sin: tuple[float, ...]

    def __post_init__(self) -> None:
        period = self.period
        if isinstance(period, bool) or not isinstance(period, (int, float, np.floating)):
            raise GenBacklashError(f"the period must be a number, got {period!r}")
        if not (math.isfinite(period) and period > 0.0):
            raise GenBacklashError(f"the period must be finite and > 0, got {period}")
        object.__setattr__(self, "period", float(period))
        cos = tuple(float(c) for c in self.cos)
        sin = tuple(float(c) for c in self.sin)
        if not cos or len(cos) != len(sin):
            raise GenBacklashError(
                f"need one cos and one sin coefficient per harmonic, got {len(cos)} and {len(sin)}"
            )
        if not all(math.isfinite(c) for c in (*cos, *sin)):
            raise GenBacklashError("the coefficients of a periodic error must be finite")
        object.__setattr__(self, "cos", cos)
        object.__setattr__(self, "sin", sin)

    @property
    def harmonics(self) -> int:
        """``K``."""
        return len(self.cos)

    @property
    def amplitudes(self) -> tuple[float, ...]:
        """The amplitude of each harmonic, ``sqrt(cos_j^2 + sin_j^2)``."""
        return tuple(math.hypot(c, s) for c, s in zip(self.cos, self.sin, strict=True))

    def __call__(self, z: FloatArray) -> FloatArray:
        """``E(z)``."""
        out = np.zeros_like(z, dtype=np.float64)
        for j, (c, s) in enumerate(zip(self.cos, self.sin, strict=True), 1):
            phase = (2.0 * math.pi * j / self.period) * z
            out += c * np.cos(phase) + s * np.sin(phase)
        return out


@dataclass(frozen=True)
class AugmentedModel:
    """A general backlash or cascade with dead time, output offset, gap drift, saturation,
    an input lag and a periodic error.

    Parameters
    ----------
    base : GeneralBacklash or Cascade
        The paper's model (eqs. 13/21, or 21 + 30).
    delay : int
        Dead time ``d >= 0`` in samples: the base model sees ``u(t - d)``.
    offset : float
        Constant added to the output (an encoder zero that is not the backlash's).
    drift : Drift, optional
        Gap growth with time or travel (wear).
    saturation : Saturation, optional
        Output limits (a hard stop or a sensor range).
    input_lag : float
        Pole ``a`` in ``[0, 0.995]`` of the servo's first-order lag between the (delayed)
        command and the backlash input: ``v(t) = a v(t-1) + (1 - a) u(t - d)``; 0: none.
    periodic : PeriodicError, optional
        An output error periodic in the load position.
    physics : LoadPhysics, optional
        The load's own motion after the play (coasting, a compliant coupling, a load
        torque; :mod:`.physics`), in place of the play operator of eq. (20).
    input_lag_order : {1, 2}
        Stages of the input lag, each with the pole ``input_lag``: 2 is a critically damped
        servo (a position loop's two equal poles), the lag applied twice.
    input_lag_fraction : float
        ``f`` in ``[0, 1)``: a fraction of a sample of dead time before the input lag, its
        input ``(1 - f) u(t - d) + f u(t - d - 1)`` (linear interpolation between samples;
        0: none). A held command sampled by the servo between the encoder's readings lands a
        fraction of a sample late, and the zero-order-hold discretisation of a lag has this
        form (a numerator ``b_1 + b_2 q^-1``, ``f = b_2 / (b_1 + b_2)``). Only with an input
        lag: it belongs to the servo's model.

    Examples
    --------
    >>> bl = GeneralBacklash.ideal(1.0, 0.3, 0.3)
    >>> model = AugmentedModel(bl, delay=2, offset=0.5)
    >>> model.simulate([0.0, 1.0, 1.0, 1.0, 0.0]).tolist()
    [0.5, 0.5, 0.5, 1.2, 1.2]
    >>> model.effects
    ('time_delay', 'output_offset')
    """

    base: GeneralBacklash | Cascade
    delay: int = 0
    offset: float = 0.0
    drift: Drift | None = None
    saturation: Saturation | None = None
    input_lag: float = 0.0
    periodic: PeriodicError | None = None
    physics: LoadPhysics | None = None
    input_lag_order: int = 1
    input_lag_fraction: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.base, (GeneralBacklash, Cascade)):
            raise GenBacklashError(
                f"base must be a GeneralBacklash or a Cascade, got {type(self.base).__name__}"
            )
        delay = as_order("delay", self.delay)
        if delay < 0:
            raise GenBacklashError(f"delay must be >= 0 samples, got {delay}")
        object.__setattr__(self, "delay", delay)
        if isinstance(self.offset, bool) or not isinstance(self.offset, (int, float, np.floating)):
            raise GenBacklashError(f"offset must be a number, got {self.offset!r}")
        if not math.isfinite(self.offset):
            raise GenBacklashError(f"offset must be finite, got {self.offset}")
        object.__setattr__(self, "offset", float(self.offset))
        if self.drift is not None and not isinstance(self.drift, Drift):
            raise GenBacklashError(f"drift must be a Drift or None, got {self.drift!r}")
        if self.saturation is not None and not isinstance(self.saturation, Saturation):
            raise GenBacklashError(
                f"saturation must be a Saturation or None, got {self.saturation!r}"
            )
        lag = self.input_lag
        if isinstance(lag, bool) or not isinstance(lag, (int, float, np.floating)):
            raise GenBacklashError(f"input_lag must be a number, got {lag!r}")
        if not 0.0 <= lag <= MAX_LAG_POLE:
            raise GenBacklashError(f"input_lag (a pole) must be in [0, {MAX_LAG_POLE}], got {lag}")
        object.__setattr__(self, "input_lag", float(lag))
        order = self.input_lag_order
        if isinstance(order, bool) or order not in (1, 2):
            raise GenBacklashError(f"input_lag_order must be 1 or 2, got {order!r}")
        object.__setattr__(self, "input_lag_order", int(order))
        fraction = self.input_lag_fraction
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float, np.floating)):
            raise GenBacklashError(f"input_lag_fraction must be a number, got {fraction!r}")
        if not 0.0 <= fraction < 1.0:
            raise GenBacklashError(f"input_lag_fraction must be in [0, 1), got {fraction}")
        if fraction != 0.0 and self.input_lag == 0.0:
            raise GenBacklashError("input_lag_fraction needs an input lag (it is the servo's)")
        object.__setattr__(self, "input_lag_fraction", float(fraction))
        if self.periodic is not None and not isinstance(self.periodic, PeriodicError):
            raise GenBacklashError(
                f"periodic must be a PeriodicError or None, got {self.periodic!r}"
            )
        if self.physics is not None and not isinstance(self.physics, LoadPhysics):
            raise GenBacklashError(f"physics must be a LoadPhysics or None, got {self.physics!r}")

    @property
    def backlash(self) -> GeneralBacklash:
        """The backlash part of the base model."""
        return self.base.backlash if isinstance(self.base, Cascade) else self.base

    @property
    def cascade(self) -> bool:
        """True when a linear block follows the backlash."""
        return isinstance(self.base, Cascade)

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the catalog effects this model carries beyond an ideal backlash."""
        names = []
        if self.backlash.degree > 1:
            names.append("curved_branches")
        if self.cascade:
            names.append("linear_dynamics")
        if self.delay:
            names.append("time_delay")
        if self.offset != 0.0:
            names.append("output_offset")
        if self.drift is not None:
            names.append("gap_drift")
        if self.saturation is not None:
            names.append("saturation")
        if self.input_lag != 0.0:
            names.append("input_lag")
        if self.periodic is not None:
            names.append("periodic_error")
        if self.physics is not None:
            names.append(self.physics.kind)
        return tuple(names)

    def simulate(self, u: ArrayLike, y_start: float | None = None) -> FloatArray:
        """Free-run output for input ``u``.

        Parameters
        ----------
        u : array_like, shape (N,)
            Input; before the first sample it is held at ``u[0]`` (for the dead time).
        y_start : float, optional
            Measured output at the first sample: the backlash state (and a linear block's
            steady state) starts where it explains this value. Default: from rest (0).
        """
        from .spec import ModelSpec  # spec builds on this module

        uu = np.asarray(u, dtype=np.float64)
        if uu.ndim != 1 or uu.size == 0:
            raise GenBacklashError(f"u must be a non-empty 1-D array, got shape {uu.shape}")
        spec = ModelSpec.of(self)
        return spec.simulate(spec.vector(self), uu, y_start).y

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AugmentedModel:
        """A model from the identify or diagnose JSON (the inverse of :meth:`to_dict`).

        Accepts ``genbacklash identify --json`` output (``model``, ``backlash`` and, for a
        cascade, ``linear``), the ``model`` object of ``genbacklash diagnose --json`` (which
        adds ``delay``, ``offset``, ``drift``, ``saturation``, ``input_lag``,
        ``periodic_error``), or a whole diagnose result.

        >>> model = AugmentedModel(GeneralBacklash.ideal(1.0, 0.2, 0.3), delay=2)
        >>> AugmentedModel.from_dict(model.to_dict()) == model
        True
        """
        if "steps" in data and isinstance(data.get("model"), Mapping):
            data = data["model"]  # a whole diagnose result
        try:
            bl = data["backlash"]
            backlash = GeneralBacklash(
                tuple(bl["m_left"]), bl["c_left"], tuple(bl["m_right"]), bl["c_right"]
            )
            base: GeneralBacklash | Cascade = backlash
            kind = data.get("model", "cascade" if "linear" in data else "backlash")
            if kind == "cascade":
                linear = data["linear"]
                base = Cascade(backlash, LinearBlock(tuple(linear["a"]), tuple(linear["b"])))
            elif kind != "backlash":
                raise GenBacklashError(f"'model' must be 'backlash' or 'cascade', got {kind!r}")
            drift = data.get("drift")
            saturation = data.get("saturation")
            lag = data.get("input_lag")
            periodic = data.get("periodic_error")
            physics = data.get("physics")
            return cls(
                base,
                delay=data.get("delay", 0),
                offset=data.get("offset", 0.0),
                drift=None if drift is None else Drift(drift["rate"], drift.get("basis", "time")),
                saturation=(
                    None
                    if saturation is None
                    else Saturation(saturation.get("low"), saturation.get("high"))
                ),
                input_lag=0.0 if lag is None else lag["pole"],
                input_lag_order=1 if lag is None else lag.get("order", 1),
                input_lag_fraction=0.0 if lag is None else lag.get("fraction", 0.0),
                periodic=(
                    None
                    if periodic is None
                    else PeriodicError(
                        periodic["period"], tuple(periodic["cos"]), tuple(periodic["sin"])
                    )
                ),
                physics=None if physics is None else LoadPhysics.from_dict(physics),
            )
        except (KeyError, TypeError, AttributeError) as err:
            raise GenBacklashError(
                f"not a model description (identify/diagnose JSON): missing or malformed {err}"
            ) from err

    def to_dict(self) -> dict[str, Any]:
        """The model part of the JSON contract: the identify shape plus the added effects."""
        backlash = self.backlash
        out: dict[str, Any] = {
            "model": "cascade" if self.cascade else "backlash",
            "backlash": {
                "m_left": list(backlash.m_left),
                "c_left": backlash.c_left,
                "m_right": list(backlash.m_right),
                "c_right": backlash.c_right,
            },
        }
        if isinstance(self.base, Cascade):
            out["linear"] = {"a": list(self.base.linear.a), "b": list(self.base.linear.b)}
        out["delay"] = self.delay
        out["offset"] = self.offset
        out["drift"] = (
            None if self.drift is None else {"rate": self.drift.rate, "basis": self.drift.basis}
        )
        out["saturation"] = (
            None
            if self.saturation is None
            else {"low": self.saturation.low, "high": self.saturation.high}
        )
        out["input_lag"] = (
            None
            if self.input_lag == 0.0
            else {
                "pole": self.input_lag,
                "time_constant": -1.0 / math.log(self.input_lag),
                "order": self.input_lag_order,
                "fraction": self.input_lag_fraction,
            }
        )
        periodic = self.periodic
        out["periodic_error"] = (
            None
            if periodic is None
            else {
                "period": periodic.period,
                "cos": list(periodic.cos),
                "sin": list(periodic.sin),
                "amplitudes": list(periodic.amplitudes),
            }
        )
        out["physics"] = None if self.physics is None else self.physics.to_dict()
        return out


def without_effect(model: AugmentedModel, effect: str) -> AugmentedModel | None:
    """``model`` with one of its effects taken out (a start for a refit without it), or None
    when it does not carry ``effect``.

    Curved branches become straight (the first coefficients kept); a linear block goes with
    its static gain moved into the branch slopes; the other effects are simply removed.

    >>> model = AugmentedModel(GeneralBacklash.ideal(1.0, 0.2, 0.3), delay=2, offset=0.5)
    >>> without_effect(model, "time_delay").effects
    ('output_offset',)
    >>> without_effect(model, "saturation") is None
    True
    """
    if effect not in model.effects:
        return None
    bl = model.backlash
    if effect == "curved_branches":
        straight = GeneralBacklash((bl.m_left[0],), bl.c_left, (bl.m_right[0],), bl.c_right)
        base: GeneralBacklash | Cascade = (
            Cascade(straight, model.base.linear) if isinstance(model.base, Cascade) else straight
        )
        return replace(model, base=base)
    if effect == "linear_dynamics" and isinstance(model.base, Cascade):
        gain = model.base.linear.dc_gain
        if not (math.isfinite(gain) and gain != 0.0):
            return None
        scaled = GeneralBacklash(
            tuple(gain * m for m in bl.m_left),
            bl.c_left,
            tuple(gain * m for m in bl.m_right),
            bl.c_right,
        )
        return replace(model, base=scaled)
    neutral: dict[str, dict[str, Any]] = {
        "time_delay": {"delay": 0},
        "output_offset": {"offset": 0.0},
        "gap_drift": {"drift": None},
        "saturation": {"saturation": None},
        "input_lag": {"input_lag": 0.0, "input_lag_order": 1, "input_lag_fraction": 0.0},
        "periodic_error": {"periodic": None},
        "coasting_load": {"physics": None},
        "compliant_coupling": {"physics": None},
        "load_torque": {"physics": None},
    }
    return replace(model, **neutral[effect])
