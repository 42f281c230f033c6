"""What an online identifier reports after each sample: :class:`Estimate` and its state.

Both online identifiers (:class:`~genbacklash_core.online.windowed.WindowedIdentifier` and
:class:`~genbacklash_core.online.recursive.RecursiveIdentifier`) follow one interface,
:class:`OnlineIdentifier`: ``update(u, y) -> Estimate`` for one sample,
``update_many(u, y) -> Estimate`` for a batch of samples (the same result, vectorised), and
``seed(estimate)`` to continue from a saved estimate after a restart. An
:class:`Estimate` is frozen: the natural parameters in
:class:`~genbacklash_core.structure.Structure` order, their covariance, the recent residual, an
excitation measure, a state out of five and a confidence in ``[0, 1]`` that a compensator uses
to fade to pass-through.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from functools import cached_property
from statistics import NormalDist
from typing import Any, Protocol

import numpy as np

from ._typing import ArrayLike, FloatArray
from .backlash import GeneralBacklash
from .cascade import Cascade, model_to_dict
from .data import as_float_array
from .errors import GenBacklashError
from .structure import Structure

__all__ = ["Estimate", "EstimatorState", "OnlineIdentifier", "track"]


class EstimatorState(str, Enum):
    """State of an online identifier.

    ``WARMING_UP``
        No estimate yet: too few samples, or not enough excitation for a first batch fit.
    ``CONVERGING``
        An estimate exists but is not settled or its uncertainty is still large.
    ``CONVERGED``
        The estimate is settled and every parameter's standard deviation is small.
    ``NO_EXCITATION``
        The recent data carry no information (the input does not move or no branch is
        engaged): the estimate is frozen at its last value.
    ``DIVERGED``
        The estimate blew up or left the valid set; the identifier re-initialises from a batch
        fit over its buffered recent window as soon as that succeeds. The parameters are the
        last valid ones.
    """

    WARMING_UP = "warming_up"
    CONVERGING = "converging"
    CONVERGED = "converged"
    NO_EXCITATION = "no_excitation"
    DIVERGED = "diverged"


def _number(name: str, value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as err:
        raise GenBacklashError(f"{name} must be a number, got {value!r}") from err


def _frozen(values: ArrayLike, shape: tuple[int, ...], name: str) -> FloatArray:
    """``values`` as a read-only float array of ``shape`` (no copy when it already is one)."""
    array = as_float_array(name, values)
    if array.shape != shape:
        raise GenBacklashError(f"{name} must have shape {shape}, got {array.shape}")
    if array.flags.writeable:
        array = array.copy()
        array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Estimate:
    """One online estimate: parameters, uncertainty, residual, excitation and state.

    Attributes
    ----------
    structure : Structure
        Degree, linear orders and branch sense (the sense is +1 while it is still unknown).
    parameters : ndarray, shape (P,)
        Natural parameters in ``structure.names()`` order; NaN while warming up.
    covariance : ndarray, shape (P, P)
        Covariance of ``parameters`` (least-squares ``sigma^2 (Phi^T Phi)^-1`` of the paper's
        regression, eqs. 23/33, carried to the natural parameters by the delta method); in a
        published online estimate also the lag and model-error terms of
        :mod:`genbacklash_core.online.tracking` (a band, not what the identifier's state and
        confidence read); NaN when unknown.
    residual : float
        RMS one-step prediction error (the equation error of eqs. 29/37) on the recent
        informative samples; NaN when unknown.
    excitation : float
        Share in ``[0, 1]`` of the recent samples that carried information about the
        parameters: a branch was engaged while the input moved.
    state : EstimatorState
    confidence : float
        In ``[0, 1]``: 0 while warming up or diverged; otherwise it falls with the relative
        standard deviation of the parameters (at most 0.5 while converging).
    samples : int
        Samples seen by the identifier so far.
    reason : str
        A sentence on the state: why it is frozen, diverged or not converged yet.

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> from genbacklash_core.structure import Structure
    >>> truth = paper_example(1).model
    >>> est = Estimate(
    ...     Structure(3), truth.parameters(), np.eye(8) * 1e-4, residual=0.02,
    ...     excitation=0.6, state=EstimatorState.CONVERGED, confidence=0.9, samples=500,
    ... )
    >>> est.names[:4], est.state == "converged"
    (('m_left_1', 'm_left_2', 'm_left_3', 'c_left'), True)
    >>> est.model == truth, round(float(est.std()[3]), 3)
    (True, 0.01)
    >>> low, high = est.confidence_interval(0.95)
    >>> round(float(high[3] - low[3]), 4)
    0.0392
    """

    structure: Structure
    parameters: FloatArray
    covariance: FloatArray
    residual: float
    excitation: float
    state: EstimatorState
    confidence: float
    samples: int
    reason: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.structure, Structure):
            raise GenBacklashError(f"structure must be a Structure, got {self.structure!r}")
        size = self.structure.n_parameters
        object.__setattr__(self, "parameters", _frozen(self.parameters, (size,), "parameters"))
        object.__setattr__(self, "covariance", _frozen(self.covariance, (size, size), "covariance"))
        try:
            state = EstimatorState(self.state)
        except ValueError as err:
            allowed = ", ".join(s.value for s in EstimatorState)
            raise GenBacklashError(f"state must be one of {allowed}, got {self.state!r}") from err
        object.__setattr__(self, "state", state)
        confidence = _number("confidence", self.confidence)
        if not 0.0 <= confidence <= 1.0:
            raise GenBacklashError(f"confidence must lie in [0, 1], got {confidence}")
        object.__setattr__(self, "confidence", confidence)
        excitation = _number("excitation", self.excitation)
        if not 0.0 <= excitation <= 1.0:
            raise GenBacklashError(f"excitation must lie in [0, 1], got {excitation}")
        object.__setattr__(self, "excitation", excitation)
        object.__setattr__(self, "residual", _number("residual", self.residual))
        try:
            whole = not isinstance(self.samples, bool) and int(self.samples) == self.samples
        except (TypeError, ValueError, OverflowError):
            whole = False
        if not whole or self.samples < 0:
            raise GenBacklashError(f"samples must be a whole number >= 0, got {self.samples!r}")
        object.__setattr__(self, "samples", int(self.samples))
        object.__setattr__(self, "reason", str(self.reason))

    @staticmethod
    def trusted(
        structure: Structure,
        parameters: FloatArray,
        covariance: FloatArray | Callable[[], FloatArray],
        residual: float,
        excitation: float,
        state: EstimatorState,
        confidence: float,
        samples: int,
        reason: str,
    ) -> Estimate:
        """Construct without validation, for the identifiers' per-sample path.

        The caller guarantees what ``__post_init__`` would check and hands over arrays that
        nothing else will change (they are made read-only here). ``covariance`` may be a
        function that computes it: it then runs on first use only.
        """
        parameters.flags.writeable = False
        fields = {
            "structure": structure,
            "parameters": parameters,
            "residual": residual,
            "excitation": excitation,
            "state": state,
            "confidence": confidence,
            "samples": samples,
            "reason": reason,
        }
        if callable(covariance):
            est: Estimate = object.__new__(_LazyCovarianceEstimate)
            fields["_covariance_factory"] = covariance
        else:
            covariance.flags.writeable = False
            est = object.__new__(Estimate)
            fields["covariance"] = covariance
        est.__dict__.update(fields)
        return est

    def with_samples(self, samples: int) -> Estimate:
        """The same estimate at a later sample count (cheap: shares the frozen arrays)."""
        clone = object.__new__(type(self))
        clone.__dict__.update(self.__dict__)  # fields, and the cached model when computed
        clone.__dict__["samples"] = int(samples)
        return clone

    @classmethod
    def empty(
        cls,
        structure: Structure,
        samples: int = 0,
        excitation: float = 0.0,
        state: EstimatorState = EstimatorState.WARMING_UP,
        reason: str = "warming up",
    ) -> Estimate:
        """An estimate without parameters (NaN), e.g. while warming up.

        >>> Estimate.empty(Structure(1)).model is None
        True
        """
        size = structure.n_parameters
        nan = np.full(size, np.nan)
        cov = np.full((size, size), np.nan)
        return cls(structure, nan, cov, math.nan, excitation, state, 0.0, samples, reason)

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order (as published on ``~/estimate``)."""
        return self.structure.names()

    @cached_property
    def available(self) -> bool:
        """True when the estimate holds parameters (always, except while warming up).

        Worked out once: the parameters are read-only (the node asks at every feed, stretch
        and publication)."""
        return bool(np.isfinite(self.parameters).all())

    def std(self) -> FloatArray:
        """Standard deviation of each parameter (square root of the covariance diagonal)."""
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def play(self) -> tuple[float, float]:
        """The play ``c_L + c_R`` (rad, the whole dead band) and its standard deviation, the
        covariance propagated by the play's gradient; NaN while there is no estimate.

        >>> from genbacklash_core import Structure
        >>> est = Estimate(Structure(1), [1.0, 0.1, 1.0, 0.2], np.diag([0, 0.09, 0, 0.16]),
        ...                0.0, 1.0, EstimatorState.CONVERGED, 1.0, 100)
        >>> est.play()
        (0.30000000000000004, 0.5)
        """
        names = self.names
        i, j = names.index("c_left"), names.index("c_right")
        cov = self.covariance
        value = float(self.parameters[i] + self.parameters[j])
        variance = float(cov[i, i] + cov[j, j] + 2.0 * cov[i, j])
        std = math.nan if math.isnan(variance) else math.sqrt(max(variance, 0.0))
        return value, std

    def confidence_interval(self, level: float = 0.95) -> tuple[FloatArray, FloatArray]:
        """Two-sided normal confidence interval ``(lower, upper)`` per parameter."""
        if not 0.0 < _number("level", level) < 1.0:
            raise GenBacklashError(f"level must lie strictly between 0 and 1, got {level}")
        half = NormalDist().inv_cdf(0.5 + level / 2.0) * self.std()
        return self.parameters - half, self.parameters + half

    @cached_property
    def model(self) -> GeneralBacklash | Cascade | None:
        """The model object, or None while there is no valid estimate."""
        if not self.available or self.structure.problem(self.parameters) is not None:
            return None
        return self.structure.model(self.parameters)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (NaN becomes None).

        Keys: ``state``, ``confidence``, ``samples``, ``residual``, ``excitation``, ``reason``,
        ``parameters`` and ``std`` (name -> value mappings), ``play`` and ``play_std`` (the
        play ``c_L + c_R`` and its standard deviation, rad: :meth:`play`), and ``model``: the
        model in the form of the CLI's identify output (``{"model": "backlash"|"cascade",
        "backlash": {...}, "linear": {...}}``) or None while there is none.
        """

        def clean(value: float) -> float | None:
            return value if math.isfinite(value) else None

        std = self.std()
        play, play_std = self.play()
        return {
            "state": self.state.value,
            "confidence": self.confidence,
            "samples": self.samples,
            "residual": clean(self.residual),
            "excitation": self.excitation,
            "reason": self.reason,
            "parameters": {
                n: clean(float(v)) for n, v in zip(self.names, self.parameters, strict=True)
            },
            "std": {n: clean(float(v)) for n, v in zip(self.names, std, strict=True)},
            "play": clean(play),
            "play_std": clean(play_std),
            "model": _model_dict(self.model),
        }


def _model_dict(model: GeneralBacklash | Cascade | None) -> dict[str, Any] | None:
    """A model as the CLI's identify JSON describes it (GUIDE §4), or None."""
    return None if model is None else model_to_dict(model)


class _LazyCovarianceEstimate(Estimate):
    """An :class:`Estimate` whose covariance is computed on first use (see ``trusted``)."""

    @cached_property
    def covariance(self) -> FloatArray:
        """Covariance of ``parameters``, computed on first use."""
        factory: Callable[[], FloatArray] = self.__dict__["_covariance_factory"]
        covariance = np.array(factory(), dtype=np.float64)
        covariance.flags.writeable = False
        return covariance


class OnlineIdentifier(Protocol):
    """The interface both online identifiers implement."""

    @property
    def estimate(self) -> Estimate:
        """The latest estimate."""
        ...

    def update(self, u: float, y: float) -> Estimate:
        """Take one sample of input ``u`` and measured output ``y``."""
        ...

    def update_many(self, u: ArrayLike, y: ArrayLike, breaks: ArrayLike | None = None) -> Estimate:
        """Take a series of samples; the same as :meth:`update` on each, vectorised.

        ``breaks[k]`` True: sample ``k`` does not follow the sample before it on the
        encoder's clock (a lost reading, a gap; :mod:`genbacklash_core.samples`), so no
        regression row pairs it with that sample. ``breaks[0]`` refers to the last sample
        of the previous call. Default: every sample follows its predecessor.
        """
        ...

    def reset(self) -> None:
        """Forget everything, as if newly constructed."""
        ...

    def seed(self, estimate: Estimate) -> Estimate:
        """Forget everything and continue from a saved ``estimate`` (e.g. a checkpoint's)."""
        ...

    @property
    def from_seed(self) -> bool:
        """True while the estimate still rests mainly on the seed of :meth:`seed`."""
        ...


def track(
    identifier: OnlineIdentifier, u: ArrayLike, y: ArrayLike, every: int = 100
) -> list[Estimate]:
    """Feed ``(u, y)`` to ``identifier`` in chunks of ``every`` samples; one estimate per chunk.

    The trajectory of the estimates, for plots, benchmarks and drift tracking. Each estimate
    is the one after its chunk's last sample.

    Examples
    --------
    >>> from genbacklash_core import WindowedIdentifier, paper_example
    >>> data = paper_example(1).generate(seed=0, n_samples=600)
    >>> trace = track(WindowedIdentifier(degree=3), data.u, data.y, every=200)
    >>> [e.samples for e in trace], trace[-1].state.value
    ([200, 400, 600], 'converged')
    """
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise GenBacklashError(f"every must be a whole number >= 1, got {every!r}")
    if not callable(getattr(identifier, "update_many", None)):
        raise GenBacklashError(f"identifier must be an OnlineIdentifier, got {identifier!r}")
    uu, yy = as_series(u, y)
    out: list[Estimate] = []
    for start in range(0, uu.size, every):
        out.append(identifier.update_many(uu[start : start + every], yy[start : start + every]))
    return out


def relative_std(parameters: FloatArray, covariance: FloatArray) -> float:
    """Largest standard deviation relative to ``max(1, max|p|)`` (the batch iteration's scale)."""
    return relative_std_of(parameters.tolist(), covariance.diagonal().tolist())


def relative_std_of(parameters: list[float], variances: list[float]) -> float:
    """:func:`relative_std` from the parameters and the variances (Python floats)."""
    scale = max(1.0, max(map(abs, parameters)))
    return math.sqrt(max(max(variances), 0.0)) / scale


def confidence_of(state: EstimatorState, rel_std: float, converged_std: float) -> float:
    """Confidence in ``[0, 1]`` from the state and the relative standard deviation.

    ``1 / (1 + (rel_std / converged_std)^2)``: 0.5 at the convergence threshold, near 1 well
    below it; capped at 0.5 while converging and 0 while warming up or diverged.
    """
    if state in (EstimatorState.WARMING_UP, EstimatorState.DIVERGED) or not math.isfinite(rel_std):
        return 0.0
    ratio = rel_std / converged_std
    value = 1.0 / (1.0 + ratio * ratio)  # (not **: no OverflowError for a huge ratio)
    if state is EstimatorState.CONVERGING:
        value = min(value, 0.5)
    return value


def aged_confidence(confidence: float, age: float, half_life: float) -> float:
    """A confidence that fades with the age of the information behind it.

    ``confidence * 0.5 ** (age / half_life)``: an estimate that no new data confirm (a joint
    at rest, or moving one way only) is trusted less and less, smoothly, never dropped at
    once. ``age`` and ``half_life`` in one unit (samples).

    >>> aged_confidence(0.8, 0.0, 1000.0), aged_confidence(0.8, 1000.0, 1000.0)
    (0.8, 0.4)
    """
    if not age > 0.0:
        return confidence
    if not half_life > 0.0:
        return 0.0
    return float(confidence * 0.5 ** (age / half_life))


def check_setting(name: str, value: object, low: float, high: float, *, whole: bool) -> None:
    """Raise a clear :class:`GenBacklashError` when a setting is not in ``[low, high]``."""
    kind = "a whole number" if whole else "a number"
    allowed = numbers.Integral if whole else numbers.Real
    if isinstance(value, bool) or not isinstance(value, allowed):
        raise GenBacklashError(f"{name} must be {kind}, got {value!r}")
    number = float(value)
    if math.isnan(number) or not low <= number <= high:
        raise GenBacklashError(f"{name} must lie in [{low:g}, {high:g}], got {value!r}")


def as_sample(u: object, y: object) -> tuple[float, float]:
    """One ``(u, y)`` sample as floats, or a clear error."""
    try:
        return float(u), float(y)  # type: ignore[arg-type]
    except (TypeError, ValueError) as err:
        raise GenBacklashError(f"u and y must be numbers, got {u!r} and {y!r}") from err


def as_series(u: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Two equal-length 1-D float arrays, or a clear error (finiteness is checked apart)."""
    try:
        uu = np.asarray(u, dtype=np.float64)
        yy = np.asarray(y, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise GenBacklashError("u and y must be sequences of numbers") from err
    if uu.ndim != 1 or yy.ndim != 1 or uu.size != yy.size:
        raise GenBacklashError(
            f"u and y must be one-dimensional of one length, got shapes {uu.shape}, {yy.shape}"
        )
    return uu, yy
