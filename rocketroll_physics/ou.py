"""The Ornstein-Uhlenbeck process over one interval: its end value and its average, exactly.

An OU process ``x`` of time constant ``T`` and stationary SD ``σ``, observed
at the start ``x0`` of an interval of length ``h``, has at the end ``x1`` and
over it the average ``I/h`` jointly Gaussian given ``x0`` (Gillespie 1996).
With ``z1``, ``z2`` independent standard normals and ``u = h/T``::

    x1  = phi·x0 + σ·a1·z1
    I/h = mean·x0 + σ·(l21·z1 + l22·z2)

:func:`interval_coefficients` gives ``phi, a1, mean, l21, l22``.  The Dryden
gust generator (:mod:`rocketroll_physics.dryden`) draws with them, and the flight
identification (:mod:`identification.methods.flightfit`) filters with them, so the
turbulence both hold is one process.

References
----------
D. T. Gillespie, "Exact numerical simulation of the Ornstein-Uhlenbeck
process and its integral", Phys. Rev. E 54 (1996) 2084-2091.
"""

from __future__ import annotations

import math

import numpy as np

from rocketroll_common.arrays import FloatArray

__all__ = ["integral_variance", "interval_coefficients"]

#: Below this ``h/T`` the conditional variance of the integral is summed as a series.
SERIES_BELOW = 0.1
SERIES_TERMS = 16


def integral_variance(u: FloatArray) -> FloatArray:
    """``2u − 3 + 4e^(−u) − e^(−2u)``: Var(integral | start) / (σ²T²), ``u = h/T > 0``."""
    direct = 2.0 * u - 3.0 + 4.0 * np.exp(-u) - np.exp(-2.0 * u)
    small = np.minimum(u, SERIES_BELOW)
    series = np.zeros_like(u)
    for n in range(SERIES_TERMS, 2, -1):  # Σ (−1)ⁿ(4 − 2ⁿ)/n! uⁿ, n ≥ 3, by Horner
        series = (series + (-1) ** n * (4.0 - 2.0**n) / math.factorial(n)) * small
    series *= small**2
    return np.where(u < SERIES_BELOW, series, direct)


def interval_coefficients(
    u: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The exact one-interval update, in units of σ, for ``u = h/T > 0``.

    With ``z1``, ``z2`` independent standard normals::

        x1  = phi·x0 + σ·a1·z1
        I/h = mean·x0 + σ·(l21·z1 + l22·z2)
    """
    phi = np.exp(-u)
    gap = -np.expm1(-u)  # 1 − φ, accurate for small u
    a1 = np.sqrt(-np.expm1(-2.0 * u))  # sqrt(1 − φ²)
    mean = gap / u
    l21 = gap**2 / (u * a1)  # Cov(e1, e2)/h / (σ²·a1)
    schur = integral_variance(u) - gap**3 / (1.0 + phi)  # Var(e2 | e1) / (σ²T²)
    l22 = np.sqrt(np.maximum(schur, 0.0)) / u
    return phi, a1, mean, l21, l22
