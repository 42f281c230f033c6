"""What both online identifiers take: their structure, their settings and the samples.

Each identifier is built from a degree, linear orders and a branch sense (:func:`template`)
and its own settings (:func:`settings_or_default`), and takes samples one at a time or as
series. A sample is checked once, here, for both:

* **Non-finite or overflowing input.** A sample whose ``u`` or ``y`` is not finite, or so
  large that the regression's sums over the identifier's longest memory would overflow
  (:func:`~genbacklash_core.data.scale_limits`, :class:`InputLimits`), raises
  :class:`~genbacklash_core.errors.NonFiniteInputError`, or with ``nonfinite='drop'`` is
  skipped. A skipped sample breaks the chain of the sample rule
  (:mod:`genbacklash_core.samples`): no row pairs the samples on either side of it.
* **The input deadband.** An input step below ``input_deadband`` of the input span counts as
  rest: such a row carries no information (:func:`deadband`).

Examples
--------
>>> limits = InputLimits.of(degree=3, rows=1000)
>>> accept_sample(0.5, float("nan"), limits, "drop", 0)  # dropped
False
>>> u, y, breaks, dropped_last = checked_series([0.1, 0.2, 0.3], [0.0, 1e300, 0.2], None,
...                                             limits, "drop")
>>> u.tolist(), breaks.tolist(), dropped_last  # the sample after the dropped one breaks
([0.1, 0.3], [False, True], False)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar, overload

import numpy as np

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.data import NonFinitePolicy, scale_limits
from genbacklash_core.errors import GenBacklashError, NonFiniteInputError
from genbacklash_core.estimate import as_series
from genbacklash_core.samples import as_breaks
from genbacklash_core.structure import Structure

__all__ = [
    "InputLimits",
    "accept_sample",
    "checked_series",
    "deadband",
    "settings_or_default",
    "template",
]

_Settings = TypeVar("_Settings")


def template(degree: int, na: int, nb: int, sign: float | None) -> tuple[Structure, bool]:
    """The structure an identifier starts from and whether its branch sense is known
    (``sign`` None: detected at the first fit; the template then says +1)."""
    if sign is not None and sign not in (1, -1):
        raise GenBacklashError(f"sign must be +1, -1 or None (detect), got {sign!r}")
    return Structure(degree, na, nb, 1.0 if sign is None else float(sign)), sign is not None


def settings_or_default(settings: object, kind: type[_Settings]) -> _Settings:
    """``settings``, or ``kind()`` when None; a clear error for anything else."""
    if settings is None:
        return kind()
    if not isinstance(settings, kind):
        raise GenBacklashError(f"settings must be {kind.__name__}, got {settings!r}")
    return settings


@dataclass(frozen=True)
class InputLimits:
    """The largest ``|u|`` and ``|y|`` the regression takes without overflow."""

    u: float
    y: float

    @classmethod
    def of(cls, degree: int, rows: int) -> InputLimits:
        """The limits for branch polynomials of ``degree`` summed over ``rows`` rows (the
        longest regression the identifier forms)."""
        u, y = scale_limits(degree, rows)
        return cls(u, y)


def accept_sample(
    uf: float, yf: float, limits: InputLimits, policy: NonFinitePolicy, index: int
) -> bool:
    """Whether one sample (floats: :func:`~genbacklash_core.estimate.as_sample`) is taken;
    False when it is to be dropped (``policy`` 'drop'). Raises
    :class:`NonFiniteInputError` (``policy`` 'raise') naming the sample's ``index``."""
    if abs(uf) <= limits.u and abs(yf) <= limits.y:  # NaN fails too
        return True
    if policy == "drop":
        return False
    raise NonFiniteInputError(
        f"sample {index} is not finite (u={uf!r}, y={yf!r}) or beyond "
        f"|u| <= {limits.u:.3g}, |y| <= {limits.y:.3g}; pass "
        "nonfinite='drop' in the settings to skip such samples"
    )


def checked_series(
    u: ArrayLike,
    y: ArrayLike,
    breaks: ArrayLike | None,
    limits: InputLimits,
    policy: NonFinitePolicy,
) -> tuple[FloatArray, FloatArray, BoolArray, bool]:
    """A series as float arrays with its sample rule's ``breaks`` (default: none), the
    samples to drop left out. Returns ``(u, y, breaks, dropped_last)``: ``dropped_last``
    True when the last sample was dropped (the next call's first sample then breaks).
    Raises :class:`NonFiniteInputError` (``policy`` 'raise') on the first bad sample."""
    uu, yy = as_series(u, y)
    bb = np.zeros(uu.size, dtype=bool) if breaks is None else as_breaks(breaks, uu.size)
    bad = ~((np.abs(uu) <= limits.u) & (np.abs(yy) <= limits.y))  # NaN too
    if not bad.any():
        return uu, yy, bb, False
    if policy != "drop":
        where = int(np.argmax(bad))
        raise NonFiniteInputError(
            f"{int(bad.sum())} of {uu.size} samples are not finite or beyond |u| <= "
            f"{limits.u:.3g}, |y| <= {limits.y:.3g} (first at index "
            f"{where}); pass nonfinite='drop' in the settings to skip such samples"
        )
    after = np.concatenate([[False], bad[:-1]])  # a dropped sample breaks the chain
    return uu[~bad], yy[~bad], (bb | after)[~bad], bool(bad[-1])


@overload
def deadband(fraction: float, span: float) -> float: ...


@overload
def deadband(fraction: float, span: FloatArray) -> FloatArray: ...


def deadband(fraction: float, span: float | FloatArray) -> float | FloatArray:
    """The input step below which the input counts as resting: ``fraction``
    (``input_deadband``) of the input ``span`` (a number, or one per sample). Each
    identifier passes the span it knows (the windowed one the widest span of an accepted
    fit, the recursive one the span seen so far at each sample, or the window's at a batch
    fit).

    >>> deadband(1e-4, 2.0)
    0.0002
    """
    if isinstance(span, np.ndarray):
        return np.asarray(fraction * span, dtype=np.float64)
    return fraction * span
