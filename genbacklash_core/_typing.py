"""Array type aliases shared by the core modules."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.intp]
ArrayLike = npt.ArrayLike

__all__ = ["ArrayLike", "BoolArray", "FloatArray", "IntArray"]
