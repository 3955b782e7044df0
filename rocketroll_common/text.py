"""Numbers in the text files users bring: one strict reading for every loader."""

from __future__ import annotations

import re

__all__ = ["parse_number"]

_NUMBER = re.compile(
    r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:nan|inf|infinity)", re.ASCII | re.I
)


def parse_number(cell: str) -> float:
    """A CSV number: ASCII decimal or scientific notation (or nan/inf, to be reported).

    Stricter than ``float()``, which also takes ``5_0`` and non-ASCII digits.

    Raises
    ------
    ValueError
        If ``cell`` is not such a number.
    """
    text = cell.strip()
    if not _NUMBER.fullmatch(text):
        raise ValueError(f"not a number: {cell!r}")
    return float(text)
