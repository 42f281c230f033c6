"""The catalog of effects a diagnosis can name and add (names per GUIDE §4).

Each module holds one effect: a detector (signature statistic, threshold, evidence) and an
augmentation (how the model is extended and refitted). To add an effect, write a module with an
object satisfying :class:`~genbacklash_core.diagnose.effects._base.Effect` and append it to
:data:`CATALOG`.
"""

from __future__ import annotations

from . import (
    coasting_load,
    compliant_coupling,
    curved_branches,
    gap_drift,
    input_lag,
    linear_dynamics,
    load_torque,
    output_offset,
    periodic_error,
    saturation,
    time_delay,
)
from ._base import Detection, Effect

__all__ = ["CATALOG", "Detection", "Effect", "effect_names"]

CATALOG: tuple[Effect, ...] = (
    curved_branches.EFFECT,
    linear_dynamics.EFFECT,
    time_delay.EFFECT,
    output_offset.EFFECT,
    gap_drift.EFFECT,
    saturation.EFFECT,
    input_lag.EFFECT,
    periodic_error.EFFECT,
    coasting_load.EFFECT,
    compliant_coupling.EFFECT,
    load_torque.EFFECT,
)


def effect_names() -> tuple[str, ...]:
    """Names of the registered effects, in catalog order.

    >>> effect_names()  # doctest: +NORMALIZE_WHITESPACE
    ('curved_branches', 'linear_dynamics', 'time_delay', 'output_offset', 'gap_drift',
     'saturation', 'input_lag', 'periodic_error', 'coasting_load', 'compliant_coupling',
     'load_torque')
    """
    return tuple(effect.name for effect in CATALOG)
