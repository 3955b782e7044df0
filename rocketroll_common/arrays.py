"""Array types and helpers shared by every layer."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FloatArray", "IntArray", "readonly_array"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def readonly_array(values: ArrayLike) -> FloatArray:
    """A private, read-only float copy of ``values`` (for frozen results)."""
    arr = np.array(values, dtype=float)
    arr.setflags(write=False)
    return arr
