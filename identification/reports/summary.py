"""A recording's summary: what ``rocketroll info`` prints, and its figure."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.signal import savgol_filter

from identification import paper
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray

__all__ = ["RecordingSummary", "plot_recording", "rate_from_angle", "summarize"]

#: Window of the Savitzky-Golay derivative used to estimate the roll rate
#: from an encoder angle.  One encoder count (1.41°) over 1 s is 1.4 °/s, so a
#: window of about a second keeps quantisation noise well below the signal.
RATE_WINDOW_S = 1.0


def rate_from_angle(
    angle_deg: FloatArray, dt_s: float, window_s: float = RATE_WINDOW_S
) -> FloatArray:
    """Roll rate from a sampled roll angle, °/s.

    A quadratic Savitzky-Golay derivative over ``window_s`` (odd number of
    samples, at least 3), which suppresses the encoder's quantisation steps.
    """
    window = max(3, round(window_s / dt_s) | 1)
    window = min(window, angle_deg.size - (1 - angle_deg.size % 2))
    return np.asarray(savgol_filter(angle_deg, window, 2, deriv=1, delta=dt_s), dtype=float)


@dataclass(frozen=True)
class RecordingSummary:
    """Headline numbers of a recording.

    Attributes
    ----------
    mean_abs_rate_dps : float
        Mean absolute roll rate, °/s (the paper's abstract: 16.4 °/s), from the
        gyro if present, else from the encoder (:func:`rate_from_angle`).
    rate_source : str
        Where ``mean_abs_rate_dps`` came from.
    fin_changes : int or None
        Number of changes of the commanded fin angle.
    truth : dict or None
        Ground-truth metadata of a synthetic recording (``truth.*`` keys).
    ud_true : dict or None
        Mean, SD and 5th/95th percentiles of the ground-truth ``u_d``, °.
    """

    name: str
    source: str
    n_samples: int
    dt_s: float
    duration_s: float
    columns: tuple[str, ...]
    fin_min_deg: float
    fin_max_deg: float
    fin_changes: int | None
    mean_abs_rate_dps: float
    rate_source: str
    roll_total_deg: float | None
    truth: dict[str, str] | None
    ud_true: dict[str, float] | None
    flight: dict[str, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        out = asdict(self)
        out["columns"] = list(self.columns)
        return out

    def format(self) -> str:
        """Human-readable multi-line text."""
        lines = [
            f"recording      {self.name}  ({self.source})",
            f"samples        {self.n_samples} every {self.dt_s:g} s, {self.duration_s:g} s",
            f"columns        {', '.join(self.columns)}",
            f"fin angle      {self.fin_min_deg:g} .. {self.fin_max_deg:g} °"
            + ("" if self.fin_changes is None else f", {self.fin_changes} command changes"),
            f"mean |rate|    {self.mean_abs_rate_dps:.2f} °/s  (from {self.rate_source}"
            + (
                f"; paper: {paper.MEAN_ABS_RATE_DPS:g} °/s)"
                if self.flight is None
                else "; a flight: the paper's figure is the tunnel's)"
            ),
        ]
        if self.flight is not None:
            f = self.flight
            lines.append(
                f"airspeed       {f['airspeed_min_mps']:.1f} .. {f['airspeed_max_mps']:.1f} m/s, "
                f"peak Mach {f['peak_mach']:.2f}"
                + (" (above 0.8: the roll model is subsonic)" if f["peak_mach"] > 0.8 else "")
            )
            if "altitude_min_m" in f:
                lines.append(
                    f"altitude       {f['altitude_min_m']:.0f} .. {f['altitude_max_m']:.0f} m "
                    "above sea level"
                    + (
                        f" (logged above the pad, site {f['site_elevation_m']:g} m)"
                        if f.get("site_elevation_m")
                        else ""
                    )
                )
        if self.roll_total_deg is not None:
            lines.append(f"roll travel    {self.roll_total_deg:.1f} °")
        if self.truth:
            lines.append(
                "ground truth   "
                + ", ".join(f"{k.removeprefix('truth.')}={v}" for k, v in self.truth.items())
            )
        if self.ud_true:
            u = self.ud_true
            lines.append(
                f"true u_d       mean {u['mean']:.2f}°, SD {u['sd']:.2f}°, "
                f"90 % interval [{u['q05']:.2f}, {u['q95']:.2f}]° (the identified u_d of "
                "`rocketroll identify` is smoother)"
            )
        return "\n".join(lines)


def _fin(recording: Recording) -> FloatArray:
    fin = recording.fin_deg if recording.fin_deg is not None else recording.fin_cmd_deg
    assert fin is not None  # validated: at least one fin column
    return fin


def _rate(recording: Recording) -> tuple[FloatArray, str]:
    if recording.roll_rate_dps is not None:
        return recording.roll_rate_dps, "rate gyro"
    assert recording.roll_deg is not None  # validated: at least one roll column
    return rate_from_angle(recording.roll_deg, recording.dt_s), (
        f"encoder, Savitzky-Golay derivative over {RATE_WINDOW_S:g} s"
    )


def summarize(recording: Recording) -> RecordingSummary:
    """Compute the :class:`RecordingSummary` of a recording."""
    fin = _fin(recording)
    rate, rate_source = _rate(recording)
    truth = {k: v for k, v in recording.metadata.items() if k.startswith("truth.")} or None
    ud = recording.ud_true_deg
    ud_stats = None
    if ud is not None:
        q05, q95 = np.percentile(ud, [5, 95])
        ud_stats = {
            "mean": float(ud.mean()),
            "sd": float(ud.std(ddof=1)),
            "q05": float(q05),
            "q95": float(q95),
        }
    cmd = recording.fin_cmd_deg
    return RecordingSummary(
        name=recording.name,
        source=recording.source,
        n_samples=recording.n_samples,
        dt_s=recording.dt_s,
        duration_s=recording.duration_s,
        columns=tuple(recording.columns()),
        fin_min_deg=float(fin.min()),
        fin_max_deg=float(fin.max()),
        fin_changes=None if cmd is None else int(np.count_nonzero(np.diff(cmd))),
        mean_abs_rate_dps=float(np.mean(np.abs(rate))),
        rate_source=rate_source,
        roll_total_deg=None
        if recording.roll_deg is None
        else float(recording.roll_deg[-1] - recording.roll_deg[0]),
        truth=truth,
        ud_true=ud_stats,
        flight=_flight(recording),
    )


def _flight(recording: Recording) -> dict[str, float] | None:
    """A flight's airspeed, Mach and altitude ranges (None for a tunnel run)."""
    if not recording.is_flight:
        return None
    from identification.recordings.flight import mach_numbers, site_elevation

    assert recording.airspeed_mps is not None
    out = {
        "airspeed_min_mps": float(recording.airspeed_mps.min()),
        "airspeed_max_mps": float(recording.airspeed_mps.max()),
        "peak_mach": float(mach_numbers(recording).max()),
    }
    if recording.altitude_m is not None:
        site = site_elevation(recording)
        out["altitude_min_m"] = float(recording.altitude_m.min()) + site
        out["altitude_max_m"] = float(recording.altitude_m.max()) + site
        out["site_elevation_m"] = site
    return out


def plot_recording(recording: Recording) -> bytes:
    """A PNG in the spirit of the paper's Fig. 2: fin input, roll response.

    Panels: fin angle (command and measured), roll angle, roll rate and, for
    synthetic recordings, the ground-truth disturbance ``u_d``.  Returns the
    PNG bytes, so the caller decides where (and whether) they are written.
    """
    from rocketroll_common.plotting import new_figure, png_bytes

    t = recording.time_s
    rate, rate_source = _rate(recording)
    panels = 3 + (recording.ud_true_deg is not None)
    fig = new_figure(figsize=(10, 2.3 * panels), constrained_layout=True)
    axes = fig.subplots(panels, 1, sharex=True)
    ax = axes[0]
    if recording.fin_cmd_deg is not None:
        ax.step(t, recording.fin_cmd_deg, where="post", lw=1.2, label="commanded")
    if recording.fin_deg is not None:
        ax.plot(t, recording.fin_deg, lw=0.9, label="measured")
    ax.set_ylabel("fin angle θ (°)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"{recording.name} ({recording.source})")
    ax = axes[1]
    if recording.roll_deg is not None:
        ax.plot(t, recording.roll_deg, lw=1.0, color="C2")
        ax.set_ylabel("roll angle φ (°)")
    else:
        ax.plot(
            t,
            np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))]),
            lw=1.0,
            color="C2",
        )
        ax.set_ylabel("∫ rate dt (°)")
    ax = axes[2]
    ax.plot(t, rate, lw=0.6, color="C3")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_ylabel("roll rate v (°/s)")
    ax.text(
        0.01,
        0.95,
        f"from {rate_source}; mean |v| = {np.mean(np.abs(rate)):.1f} °/s",
        transform=ax.transAxes,
        va="top",
        fontsize=8,
    )
    if recording.ud_true_deg is not None:
        ax = axes[3]
        ax.step(t, recording.ud_true_deg, where="post", lw=0.5, color="C4")
        ax.set_ylabel("true u_d (°)")
    axes[-1].set_xlabel("time (s)")
    return png_bytes(fig, dpi=110)
