"""Inverse-backlash compensation: the feedforward command that cancels a general backlash.

Given a desired load position ``x_d(t)`` and a model, the compensator sends the command
``u(t)`` for which the modelled backlash output equals ``x_d(t)``. The output of the model
(eqs. 8-10, 13-15) is

    x(t) = L(u(t))  if u(t) <= z_L,   x(t-1)  if z_L <= u(t) <= z_R,   R(u(t))  if u(t) >= z_R,

with ``L(z_L) = R(z_R) = x(t-1)`` (eqs. 9-10, 14-15); for the paper's polynomial branches
(eqs. 11-12) this is the clamp ``x(t) = min(max(x(t-1), lo(u)), hi(u))`` with
``lo, hi = min/max(L(u), R(u))`` (the switching of eq. 20). Inverting it gives three cases:

* ``x_d > x(t-1)``: the lower branch must push the output up: solve ``lo(u) = x_d``
  (``R`` for increasing branches, ``L`` for decreasing ones);
* ``x_d < x(t-1)``: the upper branch must push it down: solve ``hi(u) = x_d``;
* ``x_d = x(t-1)``: any ``u`` in the hold interval ``[z_L, z_R]`` keeps the output; the
  compensator keeps its previous command (moved to the nearest edge if it left the interval).

A reversal of ``x_d`` therefore makes the command jump across the dead zone, by about
``c_L + c_R`` for an ideal unit-slope backlash. Each branch is inverted on its monotone part
inside the valid input range (a safeguarded Newton iteration on a bisection bracket); where
``x_d`` lies beyond what the branch reaches there, the range end is used.

On top of the exact inverse the compensator offers gap-crossing smoothing (the jump is spread
over a number of samples, like printer firmware's backlash smoothing), confidence gating (the
correction fades to the pass-through command ``u = x_d`` when the model is not trusted), and a
rate limit and output limits that always hold. The modelled output ``x`` in the state is
advanced with the command actually sent, so the compensator's picture of the gap stays right
whatever the limits, smoothing and gating did.

For a :class:`~genbacklash_core.Cascade` only the backlash is inverted: the linear block
belongs to the user's controller.

Two forms, which the tests hold equal: the pure :func:`compensate_step` (and its loop
:func:`compensate`) on a frozen :class:`CompensatorState`, and the stateful
:class:`InverseBacklash` with ``step(x_d, confidence)``.
"""

from __future__ import annotations

from .branches import branch_inverse, hold_interval, invertible_range
from .compensator import InverseBacklash, compensate, compensate_step
from .options import CompensatorOptions
from .state import CompensatorState

__all__ = [
    "CompensatorOptions",
    "CompensatorState",
    "InverseBacklash",
    "branch_inverse",
    "compensate",
    "compensate_step",
    "hold_interval",
    "invertible_range",
]
