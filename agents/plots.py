"""The evaluation's figures: a typical episode per controller, and the error distributions."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agents.base import Evaluation
from rocketroll_common.plotting import new_figure, png_bytes
from rollenv.config import RollConfig

__all__ = ["plot_episode", "plot_errors", "typical_episode"]

#: One colour per controller, in table order (colour-blind safe, Okabe-Ito).
COLOURS = ("#999999", "#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9")


def typical_episode(results: Sequence[Evaluation]) -> int:
    """The episode whose RMS error is the median one of the PID (else the first controller)."""
    ref = next((r for r in results if r.name == "PID"), results[0])
    rms = np.array([e["rms_error"] for e in ref.episodes])
    return int(np.argsort(rms)[(rms.size - 1) // 2])


def plot_episode(results: Sequence[Evaluation], config: RollConfig) -> tuple[bytes, int]:
    """Every controller overlaid on the typical episode: the PNG and the episode's index."""
    k = typical_episode(results)
    angle_task = config.task == "angle"
    fig = new_figure(figsize=(10, 7.5))
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2, 1.3]})
    first = results[0].rollouts[k]
    t = first.time_s
    top, mid, low = axes
    top.step(t, first.setpoint, where="post", color="black", lw=1.2, ls="--", label="setpoint")
    for r, colour in zip(results, COLOURS, strict=False):
        ro = r.rollouts[k]
        y = ro.setpoint - ro.error if angle_task else ro.rate_dps
        rms = r.episodes[k]["rms_error"]
        top.plot(t, y, color=colour, lw=1.3, label=f"{r.name} (RMS {rms:.2f})")
        mid.plot(t, ro.fin_deg, color=colour, lw=1.0)
    low.plot(t, first.u_d_deg, color="#444444", lw=1.0)
    unit = "°" if angle_task else "°/s"
    top.set_ylabel("roll angle (°), unwrapped to the setpoint" if angle_task else "roll rate (°/s)")
    top.legend(loc="upper left", fontsize=8, ncol=min(len(results) + 1, 5), frameon=False)
    top.set_title(
        f"Typical held-out episode ({'angle' if angle_task else 'rate'} task): "
        f"median-RMS episode {k}, error in {unit}"
    )
    mid.axhline(config.fin_range_deg, color="k", lw=0.6, ls=":")
    mid.axhline(-config.fin_range_deg, color="k", lw=0.6, ls=":")
    mid.set_ylabel("fin angle θ (°)")
    low.set_ylabel("u_d (°)")
    low.set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return png_bytes(fig, dpi=110), k


def plot_errors(
    results: Sequence[Evaluation], config: RollConfig, metric: str = "regulation_rms_error"
) -> bytes:
    """Per controller: the distribution of |error| over all steps, and ``metric`` (PNG)."""
    unit = "°" if config.task == "angle" else "°/s"
    fig = new_figure(figsize=(11, 4.5))
    left, right = fig.subplots(1, 2)
    floor = 1e-3
    for r, colour in zip(results, COLOURS, strict=False):
        err = np.abs(np.concatenate([ro.error[1:] for ro in r.rollouts]))
        err = np.sort(np.maximum(err, floor))
        share = 1.0 - np.arange(err.size) / err.size
        left.step(err, share, where="post", color=colour, lw=1.5, label=r.name)
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel(f"|tracking error| ({unit}), every step of every episode")
    left.set_ylabel("share of steps with a larger error")
    left.legend(frameon=False)
    left.grid(alpha=0.3, which="both")
    rms = [[e[metric] for e in r.episodes] for r in results]
    positions = np.arange(len(results))
    right.boxplot(rms, positions=positions, widths=0.5, showfliers=False)
    rng = np.random.default_rng(0)
    for i, (values, colour) in enumerate(zip(rms, COLOURS, strict=False)):
        jitter = rng.uniform(-0.15, 0.15, len(values))
        right.scatter(i + jitter, values, s=12, color=colour, alpha=0.8, zorder=3)
    right.set_xticks(positions, [r.name for r in results])
    right.set_yscale("log")
    right.set_ylabel(f"{metric} per episode ({unit})")
    right.grid(alpha=0.3, axis="y", which="both")
    n = len(results[0].episodes)
    fig.suptitle(f"Tracking error on {n} held-out episodes ({config.task} task)")
    fig.tight_layout()
    return png_bytes(fig, dpi=110)
