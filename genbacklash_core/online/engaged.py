"""Whether the data engaged each branch at all: a check a cold start needs before it fits.

Under the backlash (eq. 20) the output changes between two consecutive samples only where a
branch is engaged (eqs. 18-19): while the play holds, ``x(t) = x(t-1)``. A branch's ``n + 1``
parameters (eq. 23) are determined only by samples that follow it at ``n + 1`` distinct
inputs at least (the condition :func:`~genbacklash_core.refine.branch_support` puts on a
model's free run). So when the output changed during moves of the input in one direction
(down: the left branch, eq. 18; up: the right branch, eq. 19) at fewer than ``n + 1``
distinct inputs, no fit -- the paper's iteration or its output-error refinement from any
start -- can determine that branch: the data lack it, not the estimate. A cold start on such
data fails whatever it tries; :func:`unengaged_branch` says so before it tries.

The test asks nothing of the noise: white output noise changes the output at every sample,
and then the test passes and the fit decides as before. It bites on the data it is for: a
quantised encoder on a load the play holds reads the same count, so moves inside the play
add no changed output.

Examples
--------
>>> from genbacklash_core.structure import Structure
>>> u = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.3, 0.2, 0.1, 0.0])
>>> y = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.4, 0.4, 0.4, 0.4])  # held all the way down
>>> print(unengaged_branch(Structure(3), u, y, None))
... # doctest: +NORMALIZE_WHITESPACE
not enough excitation: the output changed while the input moved down at 0 distinct inputs;
the left branch's 4 parameters need 4 (the data never engaged it)
>>> unengaged_branch(Structure(1), u, np.where(u > 0.2, u, u + 1.0), None) is None
True
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.structure import Structure

__all__ = ["engaged_inputs", "unengaged_branch"]


def engaged_inputs(u: FloatArray, y: FloatArray, breaks: BoolArray | None) -> tuple[int, int]:
    """Distinct inputs ``u(t)`` at which the output changed from the sample before while the
    input moved down, and up (pairs across a break, ``breaks[t]``, do not count)."""
    follows = np.ones(u.size, dtype=bool)
    follows[:1] = False
    if breaks is not None:
        follows &= ~breaks
    step_u = np.diff(u)
    changed = follows[1:] & (np.diff(y) != 0.0)
    after = u[1:]
    down = np.unique(after[changed & (step_u < 0.0)]).size
    up = np.unique(after[changed & (step_u > 0.0)]).size
    return int(down), int(up)


def unengaged_branch(
    structure: Structure, u: FloatArray, y: FloatArray, breaks: BoolArray | None
) -> str | None:
    """Why the data cannot determine a branch of a backlash alone (see the module notes), or
    None when the output changed in both directions of the input's moves at ``n + 1``
    distinct inputs at least. None for a cascade, whose linear block moves the output while
    the play holds."""
    if structure.cascade:
        return None
    needed = structure.degree + 1
    down, up = engaged_inputs(u, y, breaks)
    said = [
        f"the output changed while the input moved {way} at {count} distinct inputs; the "
        f"{name} branch's {needed} parameters need {needed} (the data never engaged it)"
        for way, name, count in (("down", "left", down), ("up", "right", up))
        if count < needed
    ]
    return "not enough excitation: " + "; ".join(said) if said else None
