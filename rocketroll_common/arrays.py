"""Array types and helpers shared by every layer."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FloatArray", "IntArray", "nan_to_none", "readonly_array"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def readonly_array(values: ArrayLike) -> FloatArray:
    """A private, read-only float copy of ``values`` (for frozen results)."""
    arr = np.array(values, dtype=float)
    arr.setflags(write=False)
    return arr


def nan_to_none(value: Any) -> Any:
    """``value`` (floats, dicts, lists, tuples) with every NaN as ``None``: JSON has no NaN.

    >>> nan_to_none({"a": [1.0, float("nan")], "b": (float("nan"),)})
    {'a': [1.0, None], 'b': [None]}
    """
    if isinstance(value, float):
        return None if np.isnan(value) else value
    if isinstance(value, dict):
        return {k: nan_to_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [nan_to_none(v) for v in value]
    return value
