"""A gap that wears: both dead zones scaled (:func:`worn`) or changing sample by sample
(:func:`simulate_worn`).
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.simulate import simulate_backlash


def worn(model: GeneralBacklash, factor: float) -> GeneralBacklash:
    """``model`` with both dead zones scaled by ``factor``."""
    return GeneralBacklash(
        model.m_left, model.c_left * factor, model.m_right, model.c_right * factor
    )


def simulate_worn(
    model: GeneralBacklash,
    u: FloatArray,
    x0: float,
    c_left: FloatArray,
    c_right: FloatArray,
) -> FloatArray:
    """``model`` with the dead zones ``c_left[k]``, ``c_right[k]`` at sample ``k`` (a gap that
    wears), driven by ``u`` from the state ``x0``: the play operator of eqs. (20)-(21) over each
    run of equal dead zones, the state carried from one run to the next.

    >>> m = GeneralBacklash((1.0,), 0.1, (1.0,), 0.1)
    >>> simulate_worn(m, np.array([0.5, 0.0, 0.5]), 0.0, np.array([0.1, 0.1, 0.2]),
    ...               np.array([0.1, 0.1, 0.2])).tolist()
    [0.4, 0.1, 0.3]
    """
    out = np.empty(u.size)
    change = np.flatnonzero((np.diff(c_left) != 0.0) | (np.diff(c_right) != 0.0)) + 1
    starts = np.concatenate([[0], change]).astype(int)
    stops = np.append(change, u.size).astype(int)
    x = float(x0)
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        piece = GeneralBacklash(model.m_left, float(c_left[a]), model.m_right, float(c_right[a]))
        out[a:b] = simulate_backlash(piece, u[a:b], x)
        x = float(out[b - 1])
    return out
