"""What the inverse-backlash compensator remembers between samples."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.structure import as_order

from .branches import MAX, hold_interval
from .options import DEFAULT_OPTIONS, CompensatorOptions, as_options, real_number


@dataclass(frozen=True)
class CompensatorState:
    """What the compensator remembers between samples.

    Parameters
    ----------
    x : float
        Modelled backlash output after the last command sent (``x(t-1)`` of eq. 8); tells the
        compensator on which side of the gap the load sits.
    u : float
        Last command sent (after smoothing, gating, rate limit and output limits).
    u_inverse : float
        Last exact inverse command, before smoothing and gating; the command held in the gap.
    direction : int
        Last push of the inverse: ``+1`` up, ``-1`` down, ``0`` none yet.
    offset : float
        Part of the last gap-crossing jump still to be delivered (smoothing).
    ramp : int
        Samples left in the smoothing ramp; ``0`` when no ramp runs (then ``offset`` is 0).

    Use :meth:`initial` for a state at rest.
    """

    x: float
    u: float
    u_inverse: float
    direction: int = 0
    offset: float = 0.0
    ramp: int = 0

    def __post_init__(self) -> None:
        # fast path: finite Python floats and ints, as every step makes them
        if not plain_memory(
            (self.x, self.u, self.u_inverse, self.direction, self.offset, self.ramp)
        ):
            self._validate()

    def _validate(self) -> None:
        for name in ("x", "u", "u_inverse", "offset"):
            raw = getattr(self, name)
            if isinstance(raw, (bool, np.bool_)) or not isinstance(raw, numbers.Real):
                raise GenBacklashError(f"state {name} must be a real number, got {raw!r}")
            value = float(raw)
            if not math.isfinite(value):
                raise GenBacklashError(f"state {name} must be finite, got {value}")
            object.__setattr__(self, name, value)
        direction = as_order("direction", self.direction)
        if direction not in (-1, 0, 1):
            raise GenBacklashError(f"direction must be -1, 0 or +1, got {direction}")
        ramp = as_order("ramp", self.ramp)
        if ramp < 0:
            raise GenBacklashError(f"ramp must be >= 0, got {ramp}")
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "ramp", ramp)

    @classmethod
    def initial(
        cls,
        model: GeneralBacklash | Cascade,
        x0: float = 0.0,
        u0: float | None = None,
        options: CompensatorOptions | None = None,
    ) -> CompensatorState:
        """A state at rest: load at ``x0``, command ``u0``.

        ``u0`` defaults to the middle of the hold interval ``[z_L, z_R]`` of ``x0``
        (eqs. 9-10) within the output limits, i.e. the motor anywhere inside the gap.

        >>> bl = GeneralBacklash.ideal(1.0, 0.5, 0.5)
        >>> CompensatorState.initial(bl, x0=1.0)
        CompensatorState(x=1.0, u=1.0, u_inverse=1.0, direction=0, offset=0.0, ramp=0)
        """
        opts = DEFAULT_OPTIONS if options is None else as_options(options)
        x = real_number("x0", x0)
        if not math.isfinite(x):
            raise GenBacklashError(f"x0 must be finite, got {x}")
        if u0 is None:
            z_left, z_right = hold_interval(model, x, opts)
            u = min(max(0.5 * z_left + 0.5 * z_right, opts.u_min), opts.u_max)
        else:
            u = real_number("u0", u0)
            if not (math.isfinite(u) and opts.u_min <= u <= opts.u_max):
                raise GenBacklashError(
                    f"u0 must be finite and within [{opts.u_min}, {opts.u_max}], got {u}"
                )
        return cls(x=x, u=u, u_inverse=u)


def plain_memory(memory: tuple[object, ...]) -> bool:
    """A state's fields in :class:`CompensatorState` order are finite Python floats and ints
    within range: a valid state as it stands (else :meth:`CompensatorState._validate`
    converts them or says why not)."""
    x, u, v, direction, offset, ramp = memory
    return (
        type(x) is float
        and type(u) is float
        and type(v) is float
        and type(offset) is float
        and type(direction) is int
        and type(ramp) is int
        and -MAX <= x <= MAX
        and -MAX <= u <= MAX
        and -MAX <= v <= MAX
        and -MAX <= offset <= MAX
        and -1 <= direction <= 1
        and ramp >= 0
    )
