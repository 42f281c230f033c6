"""A general backlash followed by linear dynamics (paper §4, Fig. 7)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ._typing import ArrayLike, FloatArray
from .backlash import GeneralBacklash
from .data import as_float_array, as_order
from .errors import GenBacklashError
from .linear import LinearBlock

__all__ = ["Cascade", "backlash_of", "model_from_dict", "model_to_dict"]


@dataclass(frozen=True)
class Cascade:
    """General input backlash followed by the linear block of eq. (30).

    Examples
    --------
    >>> bl = GeneralBacklash((0.5, -0.3, 0.3), 0.45, (0.6, 0.4, 0.2), 0.55)
    >>> model = Cascade(bl, LinearBlock(a=(1.0, 0.15), b=(-0.2, 0.35)))
    >>> model.parameter_names[-4:]
    ('c_right', 'a_2', 'b_1', 'b_2')
    """

    backlash: GeneralBacklash
    linear: LinearBlock

    def __post_init__(self) -> None:
        if not isinstance(self.backlash, GeneralBacklash):
            raise GenBacklashError(f"backlash must be a GeneralBacklash, got {self.backlash!r}")
        if not isinstance(self.linear, LinearBlock):
            raise GenBacklashError(f"linear must be a LinearBlock, got {self.linear!r}")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Backlash names followed by ``a_2..a_r, b_1..b_p``."""
        return (*self.backlash.parameter_names, *self.linear.parameter_names)

    def parameters(self) -> FloatArray:
        """Natural parameters: the backlash's, then ``a_2..a_r, b_1..b_p``."""
        return np.concatenate([self.backlash.parameters(), self.linear.parameters()])

    @classmethod
    def from_parameters(cls, values: ArrayLike, degree: int, na: int, nb: int) -> Cascade:
        """Inverse of :meth:`parameters`."""
        p = as_float_array("values", values)
        degree, na, nb = as_order("degree", degree), as_order("na", na), as_order("nb", nb)
        if degree < 1 or na < 1 or nb < 0:
            raise GenBacklashError(
                f"need degree >= 1, na >= 1 and nb >= 0, got degree={degree}, na={na}, nb={nb}"
            )
        nbl = 2 * degree + 2
        if p.shape != (nbl + na - 1 + nb,):
            raise GenBacklashError(
                f"expected {nbl + na - 1 + nb} parameters for degree={degree}, na={na}, "
                f"nb={nb}, got shape {p.shape}"
            )
        backlash = GeneralBacklash.from_parameters(p[:nbl], degree)
        linear = LinearBlock(a=(1.0, *p[nbl : nbl + na - 1]), b=tuple(p[nbl + na - 1 :]))
        return cls(backlash, linear)

    def simulate(self, u: ArrayLike, x0: float = 0.0) -> FloatArray:
        """Output ``y`` of the cascade; see :func:`simulate_cascade`."""
        from .simulate import simulate_cascade

        return simulate_cascade(self, u, x0).y


def backlash_of(model: object) -> GeneralBacklash:
    """The backlash of ``model``: a :class:`GeneralBacklash` itself, a cascade's first stage
    (its linear block is what follows the play).

    >>> b = GeneralBacklash.ideal(1.0, 0.1, 0.1)
    >>> backlash_of(b) is b
    True
    """
    if isinstance(model, Cascade):
        return model.backlash
    if isinstance(model, GeneralBacklash):
        return model
    raise GenBacklashError(f"model must be a GeneralBacklash or a Cascade, got {model!r}")


def model_to_dict(model: GeneralBacklash | Cascade) -> dict[str, Any]:
    """A model as the CLI's identify JSON describes it (GUIDE §4): ``model``, ``backlash``
    (``m_left``, ``c_left``, ``m_right``, ``c_right``) and, for a cascade, ``linear``.

    >>> model_to_dict(GeneralBacklash((1.0,), 0.1, (1.0,), 0.2))["backlash"]["c_right"]
    0.2
    """
    backlash = model.backlash if isinstance(model, Cascade) else model
    out: dict[str, Any] = {
        "model": "cascade" if isinstance(model, Cascade) else "backlash",
        "backlash": {
            "m_left": list(backlash.m_left),
            "c_left": backlash.c_left,
            "m_right": list(backlash.m_right),
            "c_right": backlash.c_right,
        },
    }
    if isinstance(model, Cascade):
        out["linear"] = {"a": list(model.linear.a), "b": list(model.linear.b)}
    return out


def model_from_dict(data: object) -> GeneralBacklash | Cascade:
    """The model of a :func:`model_to_dict` object (raises ``ValueError``, ``KeyError`` or
    ``TypeError`` on anything else).

    >>> m = GeneralBacklash((1.0,), 0.1, (1.0,), 0.2)
    >>> model_from_dict(model_to_dict(m)) == m
    True
    """
    if not isinstance(data, dict):
        raise ValueError(f"a model must be an object, got {data!r}")
    bl = data["backlash"]
    backlash = GeneralBacklash(
        tuple(bl["m_left"]), float(bl["c_left"]), tuple(bl["m_right"]), float(bl["c_right"])
    )
    if data.get("model") == "cascade":
        lin = data["linear"]
        return Cascade(backlash, LinearBlock(tuple(lin["a"]), tuple(lin["b"])))
    return backlash
