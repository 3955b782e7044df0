"""Tunnel turbulence flown: ``u_d`` traces time- and amplitude-scaled to a flight's airspeed.

The database's traces were identified in the wind tunnel at one airspeed
``V_ref`` (about 50 km/h, paper §4).  ``u_d`` is an equivalent fin angle: a
flow-angle disturbance, roughly gust velocity / airspeed.  Flown at airspeed
``V(t)``, a trace becomes::

    u_flight(t) = (V_ref / max(V(t), V_ref)) · u_tunnel(s + τ(t)),   τ(t) = ∫₀ᵗ V/V_ref dt'

Two documented assumptions:

* **Taylor's frozen turbulence** (Taylor 1938): the eddies are carried past
  the rocket by the mean flow and do not change on the way, so a stretch of
  tunnel turbulence that took ``Δτ`` to pass at ``V_ref`` passes in
  ``Δτ·V_ref/V`` at ``V``: time is compressed by ``V/V_ref``.
* **The tunnel's gust velocities**: the air moves as fast relative to the
  mean flow as it did in the tunnel, so the flow angle it makes shrinks like
  ``V_ref/V``.  The tunnel's turbulence is strong (the paper's §4: no
  screens, no honeycomb), so this is a pessimistic stand-in for the free
  atmosphere; below ``V_ref`` (leaving the rail, near apogee) the factor is
  held at 1 rather than grow without bound as ``V → 0``.

With the flown gain ``α·V/V_ref`` of eq. 4-8 the disturbance's torque term
``α·u_d`` is then the tunnel's: a gust pushes the roll rate as hard as in the
tunnel, while the damping that fights it grows like ``ρ·V``.

Each flown sample is the exact average of the (piecewise-constant) tunnel
trace over the stretch of tunnel time it covers, so the compressed trace is
not aliased when a 0.1-s tunnel sample passes in less than the env's 0.01-s
substep.

References
----------
G. I. Taylor, "The spectrum of turbulence", Proc. R. Soc. Lond. A 164 (1938) 476-490.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from disturbances.bank import TraceBank, interval_means
from disturbances.rows import TraceRow, derived_row
from rocketroll_common.arrays import FloatArray

__all__ = ["flight_bank", "fly_trace", "tunnel_time"]


def tunnel_time(edges_s: FloatArray, airspeed_mps: FloatArray, v_ref_mps: float) -> FloatArray:
    """τ at each of ``edges_s``: the tunnel time that has passed, ∫ V/V_ref dt (trapezoid).

    ``airspeed_mps`` is the airspeed at each edge (m/s, ≥ 0); τ starts at 0.
    """
    ratio = np.asarray(airspeed_mps, dtype=float) / v_ref_mps
    steps = 0.5 * (ratio[1:] + ratio[:-1]) * np.diff(edges_s)
    return np.concatenate([[0.0], np.cumsum(steps)])


def fly_trace(
    u_deg: FloatArray,
    dt_s: float,
    start_s: float,
    tau_s: FloatArray,
    amplitude: FloatArray,
) -> FloatArray:
    """One flown trace: the tunnel trace's average over ``[start + τ_j, start + τ_{j+1}]``,
    times ``amplitude[j]``, for each flown sample ``j``.

    Parameters
    ----------
    u_deg : ndarray, shape (n,)
        The tunnel trace, °, each sample held for ``dt_s``.
    dt_s : float
        Its Δt, s.
    start_s : float
        Tunnel time of the flight's start, s.
    tau_s : ndarray, shape (m + 1,)
        Tunnel time at the flown samples' edges (:func:`tunnel_time`), increasing.
    amplitude : ndarray, shape (m,)
        ``V_ref / max(V, V_ref)`` at each flown sample.

    Returns
    -------
    ndarray, shape (m,)
        The flown ``u_d``, °.
    """
    return np.asarray(interval_means(u_deg, dt_s, start_s + np.asarray(tau_s)) * amplitude)


def flight_bank(
    bank: TraceBank,
    edges_s: FloatArray,
    airspeed_mps: FloatArray,
    *,
    v_ref_mps: float,
    stride_s: float = 2.0,
    max_traces: int = 1024,
    marks: Mapping[str, Any] | None = None,
) -> TraceBank:
    """A bank of flown traces: every trace of ``bank`` flown from starts ``stride_s`` apart.

    Parameters
    ----------
    bank : TraceBank
        Tunnel traces (one split), with their rockets.
    edges_s : ndarray, shape (m + 1,)
        Edges of the flown samples, s from the episode's start, evenly spaced
        (their spacing is the flown traces' Δt: the env's substep).
    airspeed_mps : ndarray, shape (m + 1,)
        The airspeed at each edge, m/s.
    v_ref_mps : float
        The tunnel's airspeed, m/s.
    stride_s : float
        Tunnel time between the starts of two flights in one trace, s.
    max_traces : int
        At most this many flown traces, taken evenly over all (trace, start)
        pairs (a bank of posterior draws holds many traces).
    marks : mapping, optional
        Added to each flown trace's ``settings`` (JSON-safe).

    Returns
    -------
    TraceBank
        One trace per flight, exactly one episode long, with its source's
        rocket; its uid is the source's with ``@<start>s`` appended and its
        ``settings`` say how it was flown.
    """
    edges = np.asarray(edges_s, dtype=float)
    speed = np.asarray(airspeed_mps, dtype=float)
    if edges.ndim != 1 or edges.size < 3 or speed.shape != edges.shape:
        raise ValueError("edges_s and airspeed_mps must be 1-D arrays of one length (>= 3)")
    h = float(edges[1] - edges[0])
    if not (h > 0 and np.allclose(np.diff(edges), h, rtol=1e-9, atol=1e-12)):
        raise ValueError("edges_s must be evenly spaced and increasing")
    if not (np.all(np.isfinite(speed)) and np.all(speed >= 0)):
        raise ValueError("airspeed_mps must be finite and >= 0")
    if not (v_ref_mps > 0 and stride_s > 0 and max_traces >= 1):
        raise ValueError("v_ref_mps and stride_s must be positive, max_traces at least 1")
    tau = tunnel_time(edges, speed, v_ref_mps)
    middle = 0.5 * (speed[1:] + speed[:-1])
    amplitude = v_ref_mps / np.maximum(middle, v_ref_mps)
    need = float(tau[-1])
    pairs = [
        (k, float(s))
        for k, row in enumerate(bank.traces)
        for s in np.arange(0.0, row.duration_s - need + 1e-9, stride_s)
    ]
    if not pairs:
        raise ValueError(
            f"a flight takes {need:.1f} s of tunnel turbulence; no trace in {bank.description} "
            f"is that long (the longest is {bank.longest_s:g} s)"
        )
    if len(pairs) > max_traces:
        pick = np.linspace(0, len(pairs) - 1, max_traces).round().astype(int)
        pairs = [pairs[i] for i in pick]
    rows: list[TraceRow] = []
    for k, start in pairs:
        source = bank.traces[k]
        u = fly_trace(source.samples(), source.dt_s, start, tau, amplitude)
        settings = {
            "flown_from": source.uid,
            "tunnel_start_s": start,
            "tunnel_duration_s": need,
            "v_ref_mps": v_ref_mps,
            **(marks or {}),
        }
        rows.append(derived_row(source, u, h, f"{start:g}s", settings))
    return TraceBank(rows, f"{bank.description}, flown")
