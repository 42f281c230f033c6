"""Checks on measured series before identification: finiteness and excitation."""

from __future__ import annotations

from typing import Literal

import numpy as np

from ._typing import ArrayLike, FloatArray
from .errors import GenBacklashError, NonFiniteInputError, NotEnoughExcitationError

__all__ = ["NonFinitePolicy", "check_excitation", "count_reversals", "prepare_series"]

NonFinitePolicy = Literal["raise", "drop"]


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
    if nonfinite not in ("raise", "drop"):
        raise GenBacklashError(f"nonfinite must be 'raise' or 'drop', got {nonfinite!r}")
    uu = np.asarray(u, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
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


def count_reversals(u: FloatArray) -> int:
    """Number of changes of direction of ``u`` (flat steps ignored)."""
    steps = np.sign(np.diff(u))
    steps = steps[steps != 0.0]
    return int(np.count_nonzero(steps[1:] != steps[:-1]))


def check_excitation(u: FloatArray, y: FloatArray, n_parameters: int) -> None:
    """Raise :class:`NotEnoughExcitationError` saying what is missing, or return.

    The data must be long enough (at least 5 samples per parameter and 20 in all), the input
    must vary, and it must reverse direction at least twice so that both branches are seen.
    """
    needed = max(20, 5 * n_parameters)
    if u.size < needed:
        raise NotEnoughExcitationError(
            f"not enough excitation: {u.size} samples for {n_parameters} parameters; "
            f"need at least {needed}"
        )
    span = float(np.ptp(u))
    if span <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
        raise NotEnoughExcitationError(
            f"not enough excitation: the input is constant ({float(u[0])!r}); move the joint "
            "back and forth across the gap"
        )
    if float(np.ptp(y)) == 0.0:
        raise NotEnoughExcitationError(
            "not enough excitation: the output never changes; is the encoder connected?"
        )
    reversals = count_reversals(u)
    if reversals < 2:
        raise NotEnoughExcitationError(
            f"not enough excitation: the input reverses direction {reversals} time(s); at "
            "least 2 reversals are needed so that both branches and the gap are seen"
        )
