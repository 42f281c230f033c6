"""Checks on measured series before identification: finiteness and excitation."""

from __future__ import annotations

import math
import numbers
import operator
from typing import Literal

import numpy as np

from ._typing import ArrayLike, FloatArray
from .errors import GenBacklashError, NonFiniteInputError, NotEnoughExcitationError

__all__ = [
    "NonFinitePolicy",
    "as_float_array",
    "as_order",
    "as_real",
    "check_excitation",
    "check_scale",
    "count_reversals",
    "prepare_series",
    "scale_limits",
]

NonFinitePolicy = Literal["raise", "drop"]

_MAX_EXPONENT = 200.0  # decimal exponent the regressions' sums of squared powers may reach


def _shown(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def as_float_array(name: str, values: object) -> FloatArray:
    """``values`` as a float64 array, or a :class:`GenBacklashError` naming ``name``.

    >>> as_float_array("u", [1, 2]).tolist()
    [1.0, 2.0]
    >>> as_float_array("u", [1.0, "x"])
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: u must be an array of real numbers, got [1.0, 'x']
    """
    try:
        array = np.asarray(values)
        if array.dtype.kind == "c":
            raise GenBacklashError(f"{name} must hold real numbers, got complex values")
        return array.astype(np.float64, copy=False)
    except (TypeError, ValueError, OverflowError) as err:
        if isinstance(err, GenBacklashError):
            raise
        raise GenBacklashError(
            f"{name} must be an array of real numbers, got {_shown(values)}"
        ) from err


def as_order(name: str, value: object) -> int:
    """``value`` as a Python int (a degree or model order), or a clear error."""
    if isinstance(value, (bool, np.bool_)):
        raise GenBacklashError(f"{name} must be a whole number, got {value!r}")
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError as err:
        raise GenBacklashError(f"{name} must be a whole number, got {_shown(value)}") from err


def as_real(name: str, value: object, *, finite: bool = True) -> float:
    """``value`` as a float (not NaN; finite unless ``finite=False``), or a clear error.

    >>> as_real("x0", 2)
    2.0
    >>> as_real("x0", float("inf"))
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: x0 must be a finite number, got inf
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise GenBacklashError(f"{name} must be a real number, got {_shown(value)}")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond the float range
        number = math.copysign(math.inf, operator.index(value))  # type: ignore[arg-type]
    if math.isnan(number) or (finite and math.isinf(number)):
        kind = "a finite number" if finite else "a number (not NaN)"
        raise GenBacklashError(f"{name} must be {kind}, got {number}")
    return number


def _describe_positions(positions: np.ndarray, limit: int = 5) -> str:
    shown = ", ".join(str(int(p)) for p in positions[:limit])
    more = f" and {positions.size - limit} more" if positions.size > limit else ""
    return f"{shown}{more}"


def prepare_series(
    u: ArrayLike, y: ArrayLike, nonfinite: NonFinitePolicy = "raise"
) -> tuple[FloatArray, FloatArray]:
    """Validate an input/output pair and return them as float arrays.

    Parameters
    ----------
    u, y : array_like, shape (N,)
    nonfinite : {"raise", "drop"}
        What to do with NaN/inf samples: raise :class:`NonFiniteInputError` naming how many
        and where, or drop those samples (the rest are then treated as consecutive).

    Examples
    --------
    >>> prepare_series([0.0, float("nan")], [1.0, 2.0])
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.NonFiniteInputError: 1 of 2 samples are NaN or infinite ...
    """
    if not isinstance(nonfinite, str) or nonfinite not in ("raise", "drop"):
        raise GenBacklashError(f"nonfinite must be 'raise' or 'drop', got {nonfinite!r}")
    uu = as_float_array("u", u)
    yy = as_float_array("y", y)
    if uu.ndim != 1 or yy.ndim != 1:
        raise GenBacklashError(
            f"u and y must be one-dimensional, got shapes {uu.shape}, {yy.shape}"
        )
    if uu.size != yy.size:
        raise GenBacklashError(f"u and y must have the same length, got {uu.size} and {yy.size}")
    bad_u = ~np.isfinite(uu)
    bad_y = ~np.isfinite(yy)
    bad = bad_u | bad_y
    if bad.any():
        if nonfinite == "drop":
            return uu[~bad].copy(), yy[~bad].copy()
        positions = np.flatnonzero(bad)
        raise NonFiniteInputError(
            f"{positions.size} of {uu.size} samples are NaN or infinite "
            f"(u: {int(bad_u.sum())}, y: {int(bad_y.sum())}), at index "
            f"{_describe_positions(positions)}; clean the data or pass nonfinite='drop' "
            "(--drop-nonfinite on the command line) to skip them"
        )
    return uu, yy


def count_reversals(u: ArrayLike) -> int:
    """Number of changes of direction of ``u`` (flat steps ignored)."""
    uu = as_float_array("u", u)
    if uu.ndim != 1:
        raise GenBacklashError(f"u must be one-dimensional, got shape {uu.shape}")
    if not np.all(np.isfinite(uu)):
        raise NonFiniteInputError("u holds NaN or infinite samples; clean the data first")
    with np.errstate(over="ignore"):  # a step of +-inf between huge samples keeps its sign
        steps = np.sign(np.diff(uu))
    steps = steps[steps != 0.0]
    return int(np.count_nonzero(steps[1:] != steps[:-1]))


def check_excitation(u: ArrayLike, y: ArrayLike, n_parameters: int) -> None:
    """Raise :class:`NotEnoughExcitationError` saying what is missing, or return.

    The data must be long enough (at least 5 samples per parameter and 20 in all), the input
    must vary, and it must reverse direction at least twice so that both branches are seen.
    Data that :func:`prepare_series` rejects raise its errors.
    """
    u, y = prepare_series(u, y)
    n_parameters = as_order("n_parameters", n_parameters)
    needed = max(20, 5 * n_parameters)
    if u.size < needed:
        raise NotEnoughExcitationError(
            f"not enough excitation: {u.size} samples for {n_parameters} parameters; "
            f"need at least {needed}"
        )
    with np.errstate(over="ignore"):  # the span of +-1e308 is inf: wide enough
        span = float(np.ptp(u))
        y_span = float(np.ptp(y))
    if span <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
        raise NotEnoughExcitationError(
            f"not enough excitation: the input is constant ({float(u[0])!r}); move the joint "
            "back and forth across the gap"
        )
    if y_span == 0.0:
        raise NotEnoughExcitationError(
            "not enough excitation: the output never changes; is the encoder connected?"
        )
    reversals = count_reversals(u)
    if reversals < 2:
        raise NotEnoughExcitationError(
            f"not enough excitation: the input reverses direction {reversals} time(s); at "
            "least 2 reversals are needed so that both branches and the gap are seen"
        )


def scale_limits(degree: int, samples: int) -> tuple[float, float]:
    """Largest ``|u|`` and ``|y|`` a degree-``degree`` regression over ``samples`` samples takes.

    Beyond them its sums of squared powers (``u^(2n)``, ``y^2``) leave float64's range.

    >>> [f"{v:.0e}" for v in scale_limits(3, 1000)]
    ['7e+32', '3e+98']
    """
    budget = _MAX_EXPONENT - math.log10(max(samples, 1))
    return 10.0 ** (budget / (2 * degree)), 10.0 ** (budget / 2)


def check_scale(u: FloatArray, y: FloatArray, degree: int) -> None:
    """Raise when finite data are so large or vary so little that a degree-``degree``
    regression over them overflows or underflows float64 (see :func:`scale_limits`)."""
    limits = scale_limits(degree, u.size)
    for name, values, power, limit in (("u", u, degree, limits[0]), ("y", y, 1, limits[1])):
        if values.size == 0:
            continue
        largest = float(np.max(np.abs(values)))
        with np.errstate(over="ignore"):
            span = float(np.ptp(values))
        what = f"{name}^{2 * power}"
        if largest > limit:
            raise GenBacklashError(
                f"{name} is too large to identify a degree-{degree} model: |{name}| reaches "
                f"{largest:.3g} (at most {limit:.3g} for {u.size} samples), and the "
                f"regression's sums of {what} overflow float64; rescale the data (e.g. to "
                "radians or metres)"
            )
        if 0.0 < span and 2 * power * math.log10(span) < -_MAX_EXPONENT:
            raise GenBacklashError(
                f"{name} varies too little to identify a degree-{degree} model: its span "
                f"{span:.3g} makes the regression's {what} underflow float64; rescale the data"
            )
