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

import numpy as np
from numpy.typing import ArrayLike

from rocketroll_common.arrays import FloatArray

__all__ = ["flow_amplitude", "fly_trace", "interval_means", "tunnel_time"]


def interval_means(u_deg: FloatArray, dt_s: float, edges_s: FloatArray) -> FloatArray:
    """The exact average of a trace held ``dt_s`` per sample over each interval between
    consecutive ``edges_s`` (s from its first sample; a zero-width interval: the value
    there).  Linear interpolation of the running integral is exact for a held signal."""
    u = np.asarray(u_deg, dtype=float)
    edges = np.asarray(edges_s, dtype=float)
    grid = dt_s * np.arange(u.size + 1)
    integral = np.concatenate([[0.0], np.cumsum(u) * dt_s])  # ∫u, exact at the sample edges
    at = np.interp(edges, grid, integral)
    width = np.diff(edges)
    return np.asarray(
        np.where(
            width > 0,
            np.diff(at) / np.where(width > 0, width, 1.0),
            np.interp(edges[:-1], grid[:-1], u),
        )
    )


def tunnel_time(edges_s: FloatArray, airspeed_mps: FloatArray, v_ref_mps: float) -> FloatArray:
    """τ at each of ``edges_s``: the tunnel time that has passed, ∫ V/V_ref dt (trapezoid).

    ``airspeed_mps`` is the airspeed at each edge (m/s, ≥ 0); τ starts at 0.
    """
    ratio = np.asarray(airspeed_mps, dtype=float) / v_ref_mps
    steps = 0.5 * (ratio[1:] + ratio[:-1]) * np.diff(edges_s)
    return np.concatenate([[0.0], np.cumsum(steps)])


def flow_amplitude(airspeed_mps: ArrayLike, v_ref_mps: float) -> FloatArray:
    """The flown law's amplitude at each airspeed: ``V_ref / max(V, V_ref)``.  A frozen
    gust's flow angle at the rocket falls as ``1/V``, and the tunnel's traces hold it at
    ``V_ref``: faster flight scales them by this, slower keeps the tunnel's scale.  A
    recorded ``u_d`` divided by it is the field at the tunnel's scale again."""
    return np.asarray(v_ref_mps / np.maximum(np.asarray(airspeed_mps, dtype=float), v_ref_mps))


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
        ``V_ref / max(V, V_ref)`` at each flown sample (:func:`flow_amplitude`).

    Returns
    -------
    ndarray, shape (m,)
        The flown ``u_d``, °.
    """
    return np.asarray(interval_means(u_deg, dt_s, start_s + np.asarray(tau_s)) * amplitude)
