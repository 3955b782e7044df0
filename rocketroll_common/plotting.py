"""Headless figures: matplotlib's object API on the Agg canvas, never pyplot.

Every figure rocketroll draws (reports, database plots, evaluation plots,
rendered frames) is made here, so no module changes the process-wide
matplotlib backend or pyplot state: a user's own plotting in the same
process keeps whatever backend they chose.
"""

from __future__ import annotations

import io
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["new_figure", "png_bytes"]


def new_figure(**kwargs: Any) -> Figure:
    """A :class:`~matplotlib.figure.Figure` on its own Agg canvas (``kwargs`` as for Figure)."""
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig: Figure, dpi: float | None = None) -> bytes:
    """The figure as PNG file contents."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi if dpi is not None else "figure")
    return buffer.getvalue()
