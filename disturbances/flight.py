"""Tunnel turbulence flown for the database's banks: each trace of a bank flown along a
flight (:mod:`rocketroll_physics.flown` has the physics: Taylor's frozen field, time
compressed by ``V/V_ref``, the flow angle scaled by ``V_ref/V``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from disturbances.bank import TraceBank
from disturbances.rows import TraceRow, derived_row
from rocketroll_common.arrays import FloatArray
from rocketroll_physics.flown import flow_amplitude, fly_trace, tunnel_time

__all__ = ["flight_bank"]


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
    amplitude = flow_amplitude(middle, v_ref_mps)
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
