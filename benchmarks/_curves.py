"""Learning curves as a PNG: headline against training progress, every run of every recipe,
with reference controllers as horizontal lines (``train_curve.py``, ``run_curve.py``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

__all__ = ["write_curves"]


def write_curves(
    path: Path,
    runs: Sequence[tuple[str, Sequence[float], Sequence[float]]],
    references: Mapping[str, float],
    *,
    unit: str,
    xlabel: str,
    title: str,
) -> None:
    """``runs``: ``(label, x, headline)`` per run, one colour and one legend entry (with the
    count of its runs) per label; the headline on a log scale; ``references`` dashed, then
    dotted."""
    from rocketroll_common.plotting import new_figure, png_bytes

    fig = new_figure(figsize=(7.5, 4.5))
    ax = fig.subplots()
    labels = list(dict.fromkeys(label for label, _, _ in runs))
    counts = {label: sum(r[0] == label for r in runs) for label in labels}
    shown: set[str] = set()
    for label, x, y in runs:
        ax.plot(
            np.asarray(x, dtype=float),
            np.asarray(y, dtype=float),
            marker="o",
            ms=3,
            lw=1,
            color=f"C{labels.index(label)}",
            alpha=0.8,
            label=None if label in shown else f"{label} ({counts[label]} run(s))",
        )
        shown.add(label)
    for (name, value), style in zip(references.items(), ("--", ":"), strict=False):
        ax.axhline(value, color="black", ls=style, lw=1, label=f"{name} {value:.2f} {unit}")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"headline: regulation RMS ({unit})")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(frameon=False, fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png_bytes(fig, dpi=110))
