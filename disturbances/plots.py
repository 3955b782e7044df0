"""Figures of stored traces (PNG bytes; the caller decides where they go)."""

from __future__ import annotations

import numpy as np
from scipy import signal, stats

from disturbances.rows import TraceRow
from rocketroll_common.plotting import new_figure, png_bytes

__all__ = ["plot_trace"]


def plot_trace(trace: TraceRow, source: TraceRow | None = None) -> bytes:
    """A trace over time, its histogram with the fitted normal, and its Welch PSD.

    For a surrogate, ``source`` (the trace it was made from) is drawn beside
    it in grey, so a reader sees at once whether the spectrum and the
    distribution were kept.
    """
    info = trace
    u = trace.samples()
    t = info.t0_s + info.dt_s * np.arange(u.size)
    fig = new_figure(figsize=(11, 6.5), constrained_layout=True)
    grid = fig.add_gridspec(2, 2, height_ratios=(1, 1.1))
    ax = fig.add_subplot(grid[0, :])
    if source is not None:
        ax.step(t, source.samples(), where="post", lw=0.5, color="0.6", label="source")
    ax.step(t, u, where="post", lw=0.6, color="C4", label=info.kind)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("u_d (° of fin angle)")
    ax.set_title(
        f"{info.uid}: {info.kind} trace of {info.recording} ({info.source}), "
        f"{info.method}/{info.model}, split {info.split}"
    )
    if source is not None:
        ax.legend(loc="upper right", fontsize=8)
        ax.set_xlim(t[0], t[0] + min(120.0, t[-1] - t[0]))

    ax = fig.add_subplot(grid[1, 0])
    bins = np.histogram_bin_edges(u, bins="fd").tolist()
    if source is not None:
        ax.hist(source.samples(), bins=bins, density=True, color="0.75", label="source")
    ax.hist(u, bins=bins, density=True, histtype="step", lw=1.5, color="C4", label=info.kind)
    x = np.linspace(bins[0], bins[-1], 200)
    ax.plot(x, stats.norm.pdf(x, info.mean_deg, info.sd_deg), "k--", lw=1, label="fitted normal")
    ax.axvline(info.q05_deg, color="C3", lw=0.8)
    ax.axvline(info.q95_deg, color="C3", lw=0.8, label="90 % interval")
    ax.set_xlabel("u_d (°)")
    ax.set_ylabel("density (1/°)")
    ax.legend(fontsize=8)

    ax = fig.add_subplot(grid[1, 1])
    nperseg = min(256, u.size)
    if source is not None:
        f, p = signal.welch(source.samples(), fs=1 / info.dt_s, nperseg=nperseg)
        ax.loglog(f[1:], p[1:], color="0.6", lw=1.5, label="source")
    f, p = signal.welch(u, fs=1 / info.dt_s, nperseg=nperseg)
    ax.loglog(f[1:], p[1:], color="C4", lw=1, label=info.kind)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("PSD (°²/Hz)")
    ax.set_title("Welch power spectral density", fontsize=9)
    ax.legend(fontsize=8)
    return png_bytes(fig, dpi=100)
