"""A flight's identification report: one figure and ``report.md`` (``rocketroll identify
FLIGHT --report DIR``).

The tunnel's report (:mod:`identification.reports.report`) re-creates the paper's
figures; a flight has none in the paper, so its report shows what a reader of
a flight identification checks first, on one time axis (s after the first
sample):

1. the airspeed and the height: the operating points the model was carried to
   (eq. 4-8), and the reference airspeed ``V_ref`` it was identified at;
2. the fin: the command and the servo's path (or the measured fin angle);
3. the roll rate, measured and re-simulated from the first sample by each
   damping model driven by its own ``u_d`` (§3.5 in flight);
4. ``u_d``, the turbulence as an equivalent fin angle, per model (and the true
   one of a synthetic recording).

``report.md`` holds the table ``rocketroll identify`` prints and links the figure.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from identification.methods import ModelFit
from identification.methods.flightfit import (
    SUBSTEPS,
    flight_inputs,
    measured_rate,
    resimulated,
)
from identification.model import Rig
from identification.recordings.recording import Recording
from rocketroll_common.plotting import new_figure, png_bytes
from rocketroll_physics.scaling import FlightReference

__all__ = ["FIGURE_NAME", "REPORT_NAME", "render_flight_report"]

FIGURE_NAME = "flight_identification.png"
REPORT_NAME = "report.md"
_COLORS = {"constant": "tab:orange", "theta": "tab:green"}


def _headroom(ax: Axes, fraction: float = 0.3) -> None:
    """Raise the top of the y axis so that the legend does not hide data."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + fraction * (hi - lo))


def render_flight_report(
    recording: Recording, fits: Mapping[str, ModelFit], table: str
) -> dict[str, str | bytes]:
    """The report's files as ``{file name: content}``, nothing written.

    Parameters
    ----------
    recording : Recording
        The flight identified.
    fits : mapping
        ``{model: ModelFit}`` of one flight method on it.
    table : str
        The identification's table, as printed (goes into ``report.md``).
    """
    if not fits:
        raise ValueError("no flight fits to report")
    first = next(iter(fits.values()))
    fitted = _fitted_part(recording, first.metrics.get("fitted_s"))
    inputs = flight_inputs(
        fitted,
        v_ref_mps=float(first.trace_settings["v_ref_mps"]),
        servo_rate_dps=float(first.trace_settings["servo_rate_dps"]),
        rig=Rig(**first.trace_settings.get("rig", {})),
    )
    start = float(recording.time_s[0])
    t_all = np.asarray(recording.time_s) - start
    t = np.asarray(fitted.time_s) - start
    fig = new_figure(figsize=(8.0, 9.0), layout="constrained")
    ax_air, ax_fin, ax_rate, ax_ud = fig.subplots(4, 1, sharex=True)
    if fitted.n_samples < recording.n_samples:  # the model's limits left some out
        for ax in (ax_air, ax_fin, ax_rate, ax_ud):
            ax.axvspan(t[0], t[-1], color="tab:green", alpha=0.07, lw=0)
        ax_air.text(
            0.5 * (t[0] + t[-1]), 0.02, "fitted", transform=ax_air.get_xaxis_transform(),
            ha="center", va="bottom", fontsize=8, color="tab:green",
        )  # fmt: skip

    assert recording.airspeed_mps is not None
    ax_air.plot(t_all, recording.airspeed_mps, color="tab:blue", lw=1.2, label="airspeed")
    ax_air.axhline(inputs.v_ref_mps, color="0.4", ls=":", lw=1.0, label="V_ref")
    ax_air.set_ylabel("airspeed (m/s)")
    if recording.altitude_m is not None:
        height = ax_air.twinx()
        height.plot(t_all, recording.altitude_m, color="tab:brown", lw=1.0, ls="--")
        height.set_ylabel("altitude (m, dashed)", color="tab:brown")
    ax_air.legend(loc="upper left", fontsize=8)

    if recording.fin_cmd_deg is not None:
        ax_fin.step(
            t_all, recording.fin_cmd_deg, where="post", color="0.6", lw=0.8, label="command"
        )
    theta = inputs.theta[::SUBSTEPS]
    label = "servo (eq. 23)" if inputs.rate_limit_dps is not None else "measured"
    ax_fin.plot(t, theta, color="black", lw=0.9, label=f"fin angle θ, {label}")
    ax_fin.set_ylabel("fin (°)")
    ax_fin.legend(loc="upper right", fontsize=8, ncols=2)

    measured = measured_rate(inputs)
    source = "gyro" if inputs.rate is not None else "angle, differenced"
    ax_rate.plot(t, measured, color="0.5", lw=1.6, label=f"measured ({source})")
    for model, f in fits.items():
        rate0 = float(f.trace_settings["rate0_dps"])
        reference = FlightReference.from_metrics(f.metrics)
        assert reference is not None  # a flight method's fit records it
        sim = resimulated(inputs, f.params, f.disturbance.u_d_deg, rate0, reference.scaling)
        mae = f.metrics["resim_rate_mae_pct"]
        ax_rate.plot(
            t,
            sim.rate_dps,
            color=_COLORS.get(model),
            lw=0.8,
            label=f"re-simulated, {model} model (MAE {mae:.2f} % of mean |rate|)",
        )
    _headroom(ax_rate)
    ax_rate.set_ylabel("roll rate (°/s)")
    ax_rate.legend(loc="upper right", fontsize=8)

    edges = t[:-1] + 0.5 * np.diff(t)
    if recording.ud_true_deg is not None:
        ax_ud.plot(t_all, recording.ud_true_deg, color="0.5", lw=1.6, label="true u_d (synthetic)")
    for model, f in fits.items():
        ax_ud.plot(edges, f.disturbance.u_d_deg, color=_COLORS.get(model), lw=0.8, label=model)
    _headroom(ax_ud)
    ax_ud.set_ylabel("u_d (° of fin)")
    ax_ud.set_xlabel("time since the first sample (s)")
    ax_ud.legend(loc="upper right", fontsize=8, ncols=3)

    kind = "synthetic: a virtual flight" if recording.source == "synthetic" else recording.source
    fig.suptitle(
        f"Flight identification at V_ref {inputs.v_ref_mps:.2f} m/s: {recording.name} ({kind})",
        fontsize=10,
    )
    png = png_bytes(fig, dpi=110)
    markdown = (
        f"# Flight identification: {recording.name}\n\n"
        f"Source: {kind}. Method `{first.method}`, at the reference airspeed "
        f"{inputs.v_ref_mps:.2f} m/s and density ρ_ref {inputs.rho_ref_kgm3:.4f} kg/m³ "
        f"(in flight: {inputs.density}).\n\n"
        f"```\n{table}\n```\n\n"
        f"![airspeed, fin, roll rate measured and re-simulated, u_d]({FIGURE_NAME})\n"
    )
    return {FIGURE_NAME: png, REPORT_NAME: markdown}


def _fitted_part(recording: Recording, fitted_s: Any) -> Recording:
    """The part of ``recording`` a flight fit saw (its ``fitted_s``: first and last sample
    times); the whole where it saw all of it or does not say."""
    if not fitted_s:
        return recording
    first, last = (float(x) for x in fitted_s)
    time = np.asarray(recording.time_s)
    if first <= time[0] and last >= time[-1]:
        return recording
    stop = int(np.searchsorted(time, last, side="right"))
    end = float(time[stop]) if stop < time.size else float(time[-1]) + 1.0
    return recording.part(first, end)
