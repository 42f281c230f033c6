"""Shared helpers for the genbacklash_core tests (imported by the test modules)."""

from __future__ import annotations

import numpy as np

from genbacklash_core import Cascade, GeneralBacklash, paper_example
from genbacklash_core.backlash import evaluate_branch
from genbacklash_core.play import play_operator
from genbacklash_core.simulate import play_bounds

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


def drifting_gap_data(
    seed: int,
    n: int,
    ramp: tuple[int, int],
    growth: float = 0.5,
    snr: float = 25.0,
    model: GeneralBacklash | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Example 1's backlash whose gaps grow by ``growth`` linearly over ``ramp`` (wear).

    Simulated with per-sample branches through the play operator. Returns ``u, y, c_left,
    c_right`` (the last two per sample).
    """
    bl = paper_example(1).model if model is None else model
    rng = np.random.default_rng(seed)
    u = rng.uniform(-2.0, 2.0, n)
    t = np.arange(n)
    share = np.clip((t - ramp[0]) / (ramp[1] - ramp[0]), 0.0, 1.0)
    c_left = bl.c_left * (1.0 + growth * share)
    c_right = bl.c_right * (1.0 + growth * share)
    left = evaluate_branch(np.asarray(bl.m_left), u + c_left)
    right = evaluate_branch(np.asarray(bl.m_right), u - c_right)
    x = play_operator(*play_bounds(left, right), 0.0)
    y = x + rng.normal(0.0, float(np.std(x)) / snr, n)
    return u, y, c_left, c_right


def tracking_lag(
    samples: np.ndarray, estimate: np.ndarray, truth: np.ndarray, window: tuple[int, int]
) -> float:
    """Mean ``(truth - estimate) / slope`` over ``window``: the lag behind a linear ramp."""
    a, b = window
    slope = (truth[b - 1] - truth[a]) / (b - 1 - a)
    inside = (samples >= a) & (samples <= b)
    return float(np.mean((truth[samples[inside] - 1] - estimate[inside]) / slope))
