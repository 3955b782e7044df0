"""Tables as text: the one renderer of every command, report and benchmark.

Two forms, as the outputs need them:

* :func:`markdown_table` -- a Markdown table (``report.md``, ``table.md``, the
  benchmarks' results): a header, the ``|---|`` rule, one line per row, a ``|``
  inside a cell escaped;
* :func:`text_table` -- the fixed-width columns a command prints: each
  :class:`Column` a title, a width, an alignment and the text before it; the cells
  are the callers' formatted strings, aligned as Python's ``format`` aligns them
  (a cell wider than its column is not cut), or by the columns a terminal shows
  (``display``: a combining mark, the bar of ``θ̄``, takes none).

>>> print("\\n".join(markdown_table(["a", "b|c"], [["1", "2"]])))
| a | b\\|c |
|---|---|
| 1 | 2 |
>>> print("\\n".join(text_table([Column("name", 6, "<"), Column("x", 5)], [["ab", "1.5"]])))
name      x
ab      1.5
"""

from __future__ import annotations

import unicodedata
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

__all__ = ["Column", "markdown_table", "text_table"]


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """The lines of a Markdown table of ``header`` and ``rows`` (strings, one per column)."""
    lines = ["| " + " | ".join(_cell(h) for h in header) + " |"]
    lines.append("|" + "---|" * len(header))
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


@dataclass(frozen=True)
class Column:
    """A fixed-width column of :func:`text_table`.

    Attributes
    ----------
    title : str
        The header's text.
    width : int
        The width cells are padded to (0: not padded).
    align : str
        ``">"`` (right) or ``"<"`` (left).
    gap : str
        The text before the column (the separator from the one before).
    display : bool
        Pad to the width a terminal shows (combining marks take no column), not to the
        number of characters.
    """

    title: str
    width: int = 0
    align: str = ">"
    gap: str = ""
    display: bool = False

    def aligned(self, cell: str) -> str:
        """``cell`` padded to the column's width on the side its alignment says."""
        if not self.display:
            return format(cell, f"{self.align}{self.width}" if self.width else "")
        fill = " " * max(0, self.width - sum(not unicodedata.combining(ch) for ch in cell))
        return cell + fill if self.align == "<" else fill + cell


def text_table(columns: Sequence[Column], rows: Iterable[Sequence[str]]) -> list[str]:
    """The lines of a fixed-width table: the titles, then each row of formatted cells."""

    def line(cells: Sequence[str]) -> str:
        return "".join(c.gap + c.aligned(cell) for c, cell in zip(columns, cells, strict=True))

    return [line([c.title for c in columns])] + [line(row) for row in rows]
