"""Shared helpers for the genbacklash_core tests (imported by the test modules)."""

from __future__ import annotations

import numpy as np

from genbacklash_core import Cascade, GeneralBacklash

TOL_PAPER = 0.03  # parameter tolerance of the known-answer tests


def eq1_ideal(
    m_left: float, c_left: float, m_right: float, c_right: float, u: np.ndarray, x0: float
) -> np.ndarray:
    """The ideal backlash of eqs. (1)-(3), written literally with ``z_L`` and ``z_R``.

    The same three cases hold for increasing and decreasing lines (the paper allows both).
    """
    out = np.empty(len(u))
    x = float(x0)
    for t, ut in enumerate(u):
        z_left = x / m_left - c_left  # eq. (2): x(t-1) = m_L (z_L + c_L)
        z_right = x / m_right + c_right  # eq. (3): x(t-1) = m_R (z_R - c_R)
        if ut <= z_left:
            x = m_left * (ut + c_left)
        elif ut >= z_right:
            x = m_right * (ut - c_right)
        out[t] = x
    return out


def backlash_of(model: GeneralBacklash | Cascade) -> GeneralBacklash:
    """The backlash part of a model."""
    return model.backlash if isinstance(model, Cascade) else model
