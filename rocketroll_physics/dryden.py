"""Atmospheric turbulence's roll: the Dryden roll-rate gust ``p_g`` of MIL-F-8785C, flown.

The disturbance database holds turbulence measured in a wind tunnel; this
module gives the free atmosphere's instead, the standard gust model of the
flying-qualities specifications: the **Dryden form** of MIL-F-8785C §3.7 and
MIL-HDBK-1797, as the MATLAB Aerospace Blockset's Dryden block implements it.
Only the component that rolls the rocket is modelled: the rolling gust ``p_g``,
an angular rate (the spanwise gradient of the vertical gust velocity across
the fins).

* :func:`gust_parameters` -> :class:`GustParameters`: turbulence intensity
  ``σ_w`` and scale length ``L_w`` against height and severity.
* :func:`roll_gust_std`, :func:`roll_gust_time_constant`: the standard
  deviation ``σ_p`` (rad/s) and the correlation time ``T`` (s) of ``p_g``.
* :func:`roll_gust`: traces of ``p_g`` (°/s) along a flight, each value the
  exact average of the continuous process over one interval of a time grid.

Intensity and scale length (MIL-F-8785C §3.7.2, as in MATLAB's block)
--------------------------------------------------------------------
Heights ``h`` in feet (1 ft = 0.3048 m), ``W20`` the wind speed at 20 ft:
15 kt light, 30 kt moderate, 45 kt severe (1 kt = 1852/3600 m/s).

* Low altitude, ``h < 1000 ft`` (304.8 m)::

      L_w = h,    σ_w = 0.1·W20

  with ``h`` floored at 10 ft (3.048 m): MIL-F-8785C's low-altitude model
  starts at 10 ft (JSBSim clips there too), and ``L_w → 0`` would make
  ``σ_p`` infinite (``σ_p ∝ L_w^(-1/3)``).
* Medium/high altitude, ``h ≥ 2000 ft`` (609.6 m)::

      L_w = 1750 ft (533.4 m),    σ_w = table(h, probability of exceedance)

  the high-altitude intensity of MIL-F-8785C Figure 7 (MIL-HDBK-1797's
  corresponding figure), linear in altitude between the rows of
  :data:`INTENSITY_TABLE_FTPS` and held at the 80 000-ft value above it;
  light, moderate and severe are the curves of probability of exceedance
  10⁻², 10⁻³ and 10⁻⁵.
* ``1000 ≤ h < 2000 ft``: ``σ_w`` and ``L_w`` linear in ``h`` between their
  low-altitude values at 1000 ft and their high-altitude values at 2000 ft,
  so both are continuous.  (MATLAB's block interpolates its *outputs*
  between the two models; JSBSim, like this module, interpolates the
  parameters.  At the ends of the band they agree.)

The table, σ_w in ft/s, rows the probability of exceedance, columns the
altitude in ft, is that of MATLAB's Dryden block (its generated code's
``h_vec`` / ``sigma_vec``, 7 rows, the exceedance index ``1:7``) and of
JSBSim's ``FGWinds.cpp`` ("Figure 7 from p. 49 of MIL-F-8785C"; its indices
3, 4, 6 are light, moderate, severe).  The seven curves are
2·10⁻¹, 10⁻¹, 10⁻², ..., 10⁻⁶.  The values of the three rows used (ft/s)::

    altitude ft   500  1750  3750  7500  15000 25000 35000 45000 55000 65000 75000 80000
    light 1e-2    6.6   6.9   7.4   6.7   4.6   2.7   0.4   0     0     0     0     0
    moderate 1e-3 8.6   9.6  10.6  10.1   8.0   6.6   5.0   4.2   2.7   0     0     0
    severe 1e-5  15.6  17.6  23.0  23.6  22.1  20.0  16.0  15.1  12.1   7.9   6.2   5.1

The rocket (apogee about 2 km, 6560 ft) uses the columns up to 7500 ft.

The roll gust (MIL-F-8785C Table, Dryden form)
----------------------------------------------
In spatial frequency ``Ω`` (rad/m), with ``b`` the span::

    Φ_p(Ω) = (σ_w²/L_w) · 0.8·(π·L_w/(4b))^(1/3) / (1 + (4b·Ω/π)²)

The specification's spectra are **one-sided**: ``σ² = ∫₀^∞ Φ(Ω) dΩ`` (its
``Φ_u = σ_u²·(2L_u/π)/(1 + (L_u·Ω)²)`` integrates to ``σ_u²`` this way).
With ``∫₀^∞ dΩ/(1 + (aΩ)²) = π/(2a)``, ``a = 4b/π``::

    σ_p² = (σ_w²/L_w)·0.8·(π·L_w/(4b))^(1/3) · π²/(8b)
         = (π²/10) · (π/(4b))^(1/3) · σ_w² / (b·L_w^(2/3))

Flown at airspeed ``V`` through the frozen field (Taylor), ``ω = V·Ω`` and
``Φ_p(ω) = Φ_p(Ω)/V``: a first-order (Ornstein-Uhlenbeck) process of time
constant ``T = 4b/(π·V)`` and variance ``σ_p²``, which does not depend on
``V``.  Cross-check: MATLAB's and MIL-HDBK-1797's forming filter::

    H_p(s) = σ_w·sqrt(0.8/V)·(π/(4b))^(1/6) / (L_w^(1/3)·(1 + (4b/(π·V))·s))

driven by white noise of *one-sided* spectral density 1 in the same
convention (autocorrelation ``π·δ(τ)``) gives
``∫₀^∞ |H_p(jω)|² dω = K²·π/(2T) = σ_p²`` with ``K = H_p(0)``: the same
variance.  (Noise of autocorrelation ``δ(τ)`` through ``H_p`` would give
``σ_p²/π``; the factor π is the convention, not a disagreement.)

The span ``b``: for the rocket the fin span tip to tip, by default
:data:`DEFAULT_SPAN_M` = 0.3 m, an assumption for the 76-mm airframe with
four fins of about 11 cm semi-span each (no fin geometry is recorded).  The
Dryden ``p_g`` was written for wings short compared with ``L_w``, which
holds here by far; but a small ``b`` makes ``p_g`` large and fast: light
turbulence at 2 km gives ``σ_p`` ≈ 0.55 rad/s (31 °/s) with ``T`` ≈ 4 ms at
100 m/s; its average over a 10-ms step has about half that variance
(22 °/s; see below).

Held values: the exact interval average
---------------------------------------
The consumer holds each value constant over one interval of its time grid,
and ``T`` is often shorter than the interval, so :func:`roll_gust` returns
the process's average over each interval, drawn exactly.  Over an interval
of length ``h`` with ``V``, ``h`` (altitude) and so ``T``, ``σ`` held at the
interval's midpoint values, ``φ = exp(-h/T)``, ``x0`` the value at the
interval's start and ``I`` the integral over it (Gillespie 1996)::

    x1 = φ·x0 + e1,               Var(e1) = σ²·(1 − φ²)
    I  = T·(1 − φ)·x0 + e2,       Var(e2) = σ²·T²·(2h/T − 3 + 4φ − φ²)
                                  Cov(e1, e2) = σ²·T·(1 − φ)²

(the stationary covariances ``Cov(x(t), x(s)) = σ²·exp(−|t−s|/T)``
integrated, less the part explained by ``x0``).  The held value is
``I/h``; its stationary variance and the covariance of neighbours are::

    Var(I/h)             = σ²·(2T/h)·(1 − (T/h)·(1 − φ))
    Cov(I_k/h, I_k+1/h)  = σ²·(T/h)²·(1 − φ)²

so for ``T ≪ h`` the held values are nearly independent with variance
``2σ²T/h`` (white noise seen through the hold), and for ``T ≫ h`` they are
the point values.  ``2h/T − 3 + 4φ − φ²`` is ``(2/3)(h/T)³ + ...`` for short
intervals and is summed as a series there (no cancellation).

No airflow
----------
Where the interval's midpoint airspeed is below :data:`STILL_AIR_MPS`
(on the pad, at apogee) ``p_g`` is 0 for that interval: without airflow the
rocket does not move through the gust field and there is no gust rate
(``T`` would be infinite).  The process's state is kept unchanged across
such an interval (the exact limit ``V → 0`` of the spatial process: no
distance is flown), so the field is picked up again where it was left.

References
----------
MIL-F-8785C, *Military Specification: Flying Qualities of Piloted
Airplanes*, U.S. Department of Defense, 5 November 1980, §3.7 (atmospheric
disturbances), §3.7.2 (the Dryden form, the scale lengths and intensities),
Figure 7 (high-altitude intensity against probability of exceedance).

MIL-HDBK-1797, *Flying Qualities of Piloted Aircraft*, U.S. Department of
Defense, 1997: the forming filters and the same intensities.

The MathWorks, Aerospace Blockset, "Dryden Wind Turbulence Model
(Continuous)" (block reference and its ``h_vec`` / ``sigma_vec`` tables).

JSBSim, ``src/models/atmosphere/FGWinds.cpp`` (the same table, 10-ft floor
and parameter interpolation between 1000 and 2000 ft).

D. T. Gillespie, "Exact numerical simulation of the Ornstein-Uhlenbeck
process and its integral", Phys. Rev. E 54 (1996) 2084-2091.

G. I. Taylor, "The spectrum of turbulence", Proc. R. Soc. Lond. A 164
(1938) 476-490 (frozen turbulence).

Examples
--------
>>> rng = np.random.default_rng(0)
>>> edges = np.linspace(0.0, 1.0, 101)  # 10-ms intervals
>>> p_dps = roll_gust(edges, 100.0, 1500.0, severity="moderate", rng=rng, size=8)
>>> p_dps.shape
(8, 100)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import UsageError
from rocketroll_physics.ou import interval_coefficients

__all__ = [
    "DEFAULT_SPAN_M",
    "EXCEEDANCE_PROBABILITY",
    "FT_M",
    "INTENSITY_ALTITUDES_FT",
    "INTENSITY_PROBABILITIES",
    "INTENSITY_TABLE_FTPS",
    "KNOT_MPS",
    "SEVERITIES",
    "STILL_AIR_MPS",
    "W20_KT",
    "GustParameters",
    "Severity",
    "gust_parameters",
    "roll_gust",
    "roll_gust_std",
    "roll_gust_time_constant",
]

#: One foot, m (exact).
FT_M = 0.3048
#: One knot, m/s (exact: one nautical mile, 1852 m, per hour).
KNOT_MPS = 1852.0 / 3600.0

Severity = Literal["light", "moderate", "severe"]
#: The severities, mildest first.
SEVERITIES: tuple[Severity, ...] = ("light", "moderate", "severe")
#: Wind speed at 20 ft, kt, of each severity (low-altitude model: ``σ_w = 0.1·W20``).
W20_KT: dict[str, float] = {"light": 15.0, "moderate": 30.0, "severe": 45.0}
#: Probability of exceedance of each severity (high-altitude model).
EXCEEDANCE_PROBABILITY: dict[str, float] = {"light": 1e-2, "moderate": 1e-3, "severe": 1e-5}

#: Altitudes of :data:`INTENSITY_TABLE_FTPS`'s columns, ft.
INTENSITY_ALTITUDES_FT = (
    500.0, 1750.0, 3750.0, 7500.0, 15000.0, 25000.0,
    35000.0, 45000.0, 55000.0, 65000.0, 75000.0, 80000.0,
)  # fmt: skip
#: Probabilities of exceedance of :data:`INTENSITY_TABLE_FTPS`'s rows.
INTENSITY_PROBABILITIES = (2e-1, 1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6)
#: High-altitude turbulence intensity σ_w, ft/s: MIL-F-8785C Figure 7 as tabulated
#: by MATLAB's Dryden block (``sigma_vec``) and JSBSim (``POE_Table``).
INTENSITY_TABLE_FTPS = (
    (3.2, 2.2, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (4.2, 3.6, 3.3, 1.6, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (6.6, 6.9, 7.4, 6.7, 4.6, 2.7, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0),
    (8.6, 9.6, 10.6, 10.1, 8.0, 6.6, 5.0, 4.2, 2.7, 0.0, 0.0, 0.0),
    (11.8, 13.0, 16.0, 15.1, 11.6, 9.7, 8.1, 8.2, 7.9, 4.9, 3.2, 2.1),
    (15.6, 17.6, 23.0, 23.6, 22.1, 20.0, 16.0, 15.1, 12.1, 7.9, 6.2, 5.1),
    (18.7, 21.5, 28.4, 30.2, 30.7, 31.0, 25.2, 23.1, 17.5, 10.7, 8.4, 7.2),
)

#: Top of the low-altitude model, ft.
_LOW_TOP_FT = 1000.0
#: Bottom of the medium/high-altitude model, ft.
_HIGH_BOTTOM_FT = 2000.0
#: Floor of the low-altitude height, ft.
_MIN_HEIGHT_FT = 10.0
#: Scale length of the medium/high-altitude model, ft.
_HIGH_LENGTH_FT = 1750.0

#: Default span ``b``, m: fin tip to fin tip of the 76-mm airframe with four fins
#: (an assumption: about 11 cm semi-span per fin; no fin geometry is recorded).
DEFAULT_SPAN_M = 0.3
#: Airspeed below which there is no airflow and no gust rate, m/s.
STILL_AIR_MPS = 0.01


# --------------------------------------------------------------------------- validation
def _numbers(name: str, value: ArrayLike) -> FloatArray:
    """``value`` as a float array, or a :class:`UsageError` naming ``name``."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise UsageError(f"{name}: must be numbers, not {value!r}") from None
    bad = ~np.isfinite(arr)
    if np.any(bad):
        raise UsageError(f"{name}: {float(arr[bad].ravel()[0])!r} is not finite")
    return arr


def _non_negative(name: str, value: ArrayLike, unit: str) -> FloatArray:
    arr = _numbers(name, value)
    if np.any(arr < 0.0):
        raise UsageError(f"{name}: {float(arr[arr < 0.0].ravel()[0]):g} {unit} is negative")
    return arr


def _severity(severity: object) -> str:
    if not isinstance(severity, str) or severity not in SEVERITIES:
        raise UsageError(
            f"severity: must be one of {', '.join(map(repr, SEVERITIES))}, not {severity!r}"
        )
    return severity


def _span(span_m: object) -> float:
    if isinstance(span_m, bool) or not isinstance(span_m, int | float | np.integer | np.floating):
        raise UsageError(f"span_m: must be a number, not {span_m!r}")
    span = float(span_m)
    if not math.isfinite(span) or span <= 0.0:
        raise UsageError(f"span_m: must be a finite length > 0 m, not {span!r}")
    return span


def _scalar_or_array(value: FloatArray) -> FloatArray | float:
    return float(value) if value.ndim == 0 else value


# --------------------------------------------------------------------------- intensity
@dataclass(frozen=True, eq=False)
class GustParameters:
    """Dryden turbulence intensity and scale length of the vertical gust, at some heights.

    Attributes
    ----------
    altitude_m : ndarray
        Height above ground, m, as given (any shape; 0-d for a scalar).
    severity : str
        ``"light"``, ``"moderate"`` or ``"severe"``.
    sigma_w_mps : ndarray
        Turbulence intensity ``σ_w``, m/s, of ``altitude_m``'s shape.
    length_w_m : ndarray
        Scale length ``L_w``, m, of ``altitude_m``'s shape.
    """

    altitude_m: FloatArray
    severity: str
    sigma_w_mps: FloatArray
    length_w_m: FloatArray

    def __repr__(self) -> str:
        if self.altitude_m.ndim == 0:
            return (
                f"GustParameters({self.severity}, h={float(self.altitude_m):.6g} m: "
                f"σ_w={float(self.sigma_w_mps):.6g} m/s, L_w={float(self.length_w_m):.6g} m)"
            )
        return f"GustParameters({self.severity}, {self.altitude_m.size} heights)"


def _high_sigma_ftps(h_ft: FloatArray, severity: str) -> FloatArray:
    """Table intensity, ft/s, linear in altitude, held beyond the table's ends."""
    row = INTENSITY_TABLE_FTPS[INTENSITY_PROBABILITIES.index(EXCEEDANCE_PROBABILITY[severity])]
    return np.interp(h_ft, INTENSITY_ALTITUDES_FT, row)


def _parameters_ft(h_ft: FloatArray, severity: str) -> tuple[FloatArray, FloatArray]:
    """``σ_w`` (ft/s) and ``L_w`` (ft) at heights ``h_ft`` (ft, ≥ 0), unchecked."""
    sigma_low = 0.1 * W20_KT[severity] * KNOT_MPS / FT_M
    sigma_2000 = float(_high_sigma_ftps(np.asarray(_HIGH_BOTTOM_FT), severity))
    share = np.clip((h_ft - _LOW_TOP_FT) / (_HIGH_BOTTOM_FT - _LOW_TOP_FT), 0.0, 1.0)
    low = h_ft < _LOW_TOP_FT
    high = h_ft >= _HIGH_BOTTOM_FT
    sigma = np.where(
        high,
        _high_sigma_ftps(h_ft, severity),
        np.where(low, sigma_low, sigma_low + share * (sigma_2000 - sigma_low)),
    )
    length = np.where(
        high,
        _HIGH_LENGTH_FT,
        np.where(
            low,
            np.maximum(h_ft, _MIN_HEIGHT_FT),
            _LOW_TOP_FT + share * (_HIGH_LENGTH_FT - _LOW_TOP_FT),
        ),
    )
    return sigma, length


def gust_parameters(altitude_m: ArrayLike, severity: Severity = "light") -> GustParameters:
    """Turbulence intensity ``σ_w`` and scale length ``L_w`` of MIL-F-8785C (Dryden form).

    Parameters
    ----------
    altitude_m : float or array_like
        Height above ground, m, ≥ 0, any shape (the specification's ``h``;
        for an :class:`rocketroll_physics.ascent.FlightProfile` its
        ``altitude_m`` less the launch altitude).
    severity : {"light", "moderate", "severe"}
        Low altitude: wind at 20 ft of 15, 30, 45 kt; medium/high altitude:
        probability of exceedance 10⁻², 10⁻³, 10⁻⁵.

    Returns
    -------
    GustParameters
        Read-only arrays of ``altitude_m``'s shape.

    Raises
    ------
    UsageError
        Naming the argument: an altitude negative or not finite, an unknown
        severity.

    Notes
    -----
    With ``h`` in ft: below 1000 ft ``L_w = max(h, 10 ft)``,
    ``σ_w = 0.1·W20``; from 2000 ft ``L_w = 1750 ft`` and ``σ_w`` from
    :data:`INTENSITY_TABLE_FTPS` (linear in altitude); in between both
    linear in ``h`` from their 1000-ft to their 2000-ft values.  See the
    module docstring for the table and its source.

    References
    ----------
    MIL-F-8785C §3.7.2 and Figure 7; MATLAB Aerospace Blockset, Dryden Wind
    Turbulence Model (Continuous).

    Examples
    --------
    >>> p = gust_parameters(100 * FT_M, "light")  # 100 ft
    >>> round(float(p.length_w_m), 2), round(float(p.sigma_w_mps), 4)  # 100 ft, 1.5 kt
    (30.48, 0.7717)
    >>> round(float(gust_parameters(7500 * FT_M, "severe").sigma_w_mps) / FT_M, 6)
    23.6
    """
    level = _severity(severity)
    h_m = _non_negative("altitude_m", altitude_m, "m")
    sigma_ftps, length_ft = _parameters_ft(h_m / FT_M, level)
    return GustParameters(
        altitude_m=readonly_array(h_m),
        severity=level,
        sigma_w_mps=readonly_array(sigma_ftps * FT_M),
        length_w_m=readonly_array(length_ft * FT_M),
    )


# --------------------------------------------------------------------------- roll gust
def _roll_sigma(sigma_w: FloatArray, length_w: FloatArray, span: float) -> FloatArray:
    """``σ_p`` (rad/s) from ``σ_w``, ``L_w`` and ``b`` in any one unit of length."""
    factor = (math.pi**2 / 10.0) * (math.pi / (4.0 * span)) ** (1.0 / 3.0) / span
    return sigma_w * np.sqrt(factor / length_w ** (2.0 / 3.0))


def roll_gust_std(
    airspeed_mps: ArrayLike,
    altitude_m: ArrayLike,
    severity: Severity = "light",
    span_m: float = DEFAULT_SPAN_M,
) -> FloatArray | float:
    """Standard deviation ``σ_p`` of the Dryden roll-rate gust ``p_g``, rad/s.

    Parameters
    ----------
    airspeed_mps : float or array_like
        Airspeed ``V``, m/s, ≥ 0.  ``σ_p`` does not depend on it, except that
        below :data:`STILL_AIR_MPS` there is no gust rate (0).
    altitude_m : float or array_like
        Height above ground, m, ≥ 0; broadcast with ``airspeed_mps``.
    severity : {"light", "moderate", "severe"}
    span_m : float
        Span ``b``, m, > 0: the fin span tip to tip (default 0.3 m, an
        assumption for the 76-mm airframe with four fins).

    Returns
    -------
    float or ndarray
        ``σ_p``, rad/s: a float for scalar inputs, else of the broadcast shape.

    Raises
    ------
    UsageError
        Naming the argument: a negative or non-finite airspeed or altitude,
        shapes that do not broadcast, an unknown severity, a span ≤ 0.

    Notes
    -----
    MIL-F-8785C's one-sided spectrum ``Φ_p(Ω) = (σ_w²/L_w)·0.8·(πL_w/(4b))^(1/3)
    / (1 + (4bΩ/π)²)`` integrated over ``Ω ∈ [0, ∞)``::

        σ_p² = (π²/10)·(π/(4b))^(1/3)·σ_w² / (b·L_w^(2/3))

    which ``∫₀^∞ |H_p(jω)|² dω`` of MATLAB's forming filter reproduces (module
    docstring).

    References
    ----------
    MIL-F-8785C §3.7.2 (the ``p_g`` spectrum, Dryden form); MIL-HDBK-1797.

    Examples
    --------
    >>> round(roll_gust_std(100.0, 2000.0, "light"), 3)  # rad/s, b = 0.3 m
    0.55
    """
    level = _severity(severity)
    span = _span(span_m)
    speed = _non_negative("airspeed_mps", airspeed_mps, "m/s")
    h_m = _non_negative("altitude_m", altitude_m, "m")
    try:
        speed, h_m = np.broadcast_arrays(speed, h_m)
    except ValueError:
        raise UsageError(
            f"altitude_m: shape {h_m.shape} does not broadcast with airspeed_mps's {speed.shape}"
        ) from None
    sigma_ftps, length_ft = _parameters_ft(h_m / FT_M, level)
    sigma = _roll_sigma(sigma_ftps * FT_M, length_ft * FT_M, span)
    return _scalar_or_array(np.where(speed < STILL_AIR_MPS, 0.0, sigma))


def roll_gust_time_constant(
    airspeed_mps: ArrayLike, span_m: float = DEFAULT_SPAN_M
) -> FloatArray | float:
    """Correlation time ``T = 4b/(π·V)`` of the roll-rate gust, s.

    Parameters
    ----------
    airspeed_mps : float or array_like
        Airspeed ``V``, m/s, ≥ 0, any shape.
    span_m : float
        Span ``b``, m, > 0 (default 0.3 m, see :func:`roll_gust_std`).

    Returns
    -------
    float or ndarray
        ``T``, s; ``inf`` below :data:`STILL_AIR_MPS` (no airflow).

    Raises
    ------
    UsageError
        Naming the argument: a negative or non-finite airspeed, a span ≤ 0.

    Notes
    -----
    The break of ``Φ_p(Ω)`` is at ``Ω = π/(4b)``: a correlation length
    ``4b/π`` in space, passed at ``V``.

    Examples
    --------
    >>> round(roll_gust_time_constant(100.0) * 1000, 3)  # ms, b = 0.3 m
    3.82
    """
    span = _span(span_m)
    speed = _non_negative("airspeed_mps", airspeed_mps, "m/s")
    moving = speed >= STILL_AIR_MPS
    time = np.full(speed.shape, np.inf)
    time[moving] = 4.0 * span / (math.pi * speed[moving])
    return _scalar_or_array(time)


def _edge_values(name: str, value: ArrayLike, n_edges: int, unit: str) -> FloatArray:
    arr = _non_negative(name, value, unit)
    if arr.ndim == 0:
        return np.full(n_edges, float(arr))
    if arr.shape != (n_edges,):
        raise UsageError(
            f"{name}: shape {arr.shape} does not match edges_s's ({n_edges},): give one "
            "value per edge, or one number"
        )
    return arr


def roll_gust(
    edges_s: ArrayLike,
    airspeed_mps: ArrayLike,
    altitude_m: ArrayLike,
    *,
    severity: Severity = "light",
    span_m: float = DEFAULT_SPAN_M,
    rng: np.random.Generator,
    size: int | None = None,
) -> FloatArray:
    """Traces of the Dryden roll-rate gust ``p_g``, each value its exact average over an interval.

    Parameters
    ----------
    edges_s : array_like, shape (n_edges,)
        Times of the intervals' edges, s, strictly increasing, at least two
        (usually a uniform grid).
    airspeed_mps : float or array_like, shape (n_edges,)
        Airspeed ``V`` at each edge, m/s, ≥ 0, or one number for all.
    altitude_m : float or array_like, shape (n_edges,)
        Height above ground at each edge, m, ≥ 0, or one number for all.
    severity : {"light", "moderate", "severe"}
        See :func:`gust_parameters`.
    span_m : float
        Span ``b``, m, > 0 (default 0.3 m, see :func:`roll_gust_std`).
    rng : numpy.random.Generator
        The source of all randomness.
    size : int, optional
        Number of independent traces; ``None`` (default) for one trace
        without the leading axis.

    Returns
    -------
    ndarray, shape (n_edges - 1,) or (size, n_edges - 1)
        ``p_g``, °/s: value ``j`` is the average of the continuous process over
        ``[edges_s[j], edges_s[j+1]]``, to be held over that interval.  0 where
        the interval's midpoint airspeed is below :data:`STILL_AIR_MPS`.

    Raises
    ------
    UsageError
        Naming the argument: edges not strictly increasing or fewer than two,
        a negative or non-finite airspeed or altitude, an airspeed or altitude
        array not of ``edges_s``'s shape, an unknown severity, a span ≤ 0,
        ``rng`` not a Generator, ``size`` not a positive integer.

    Notes
    -----
    Within each interval ``V`` and the altitude are held at the midpoint
    (the mean of the two edges' values), and with them ``T = 4b/(πV)`` and
    ``σ_p`` (:func:`roll_gust_std`).  The process is then an
    Ornstein-Uhlenbeck process, and the pair (value at the interval's end,
    integral over it) given the value at its start is drawn from its exact
    joint Gaussian (module docstring, Gillespie 1996).  The first start is
    drawn from the stationary distribution of the first interval (``σ_p`` of
    its altitude, with or without airflow: the field is there).  Intervals
    without airflow give 0 and leave the state unchanged.  The loop runs over
    intervals; traces are vectorised.  Two normals per trace and interval
    are drawn whatever the airspeed, so the same ``rng`` state gives the same
    traces.

    References
    ----------
    MIL-F-8785C §3.7.2; D. T. Gillespie, Phys. Rev. E 54 (1996) 2084.

    Examples
    --------
    >>> edges = np.linspace(0.0, 0.05, 6)
    >>> p = roll_gust(edges, [0, 0, 50, 60, 70, 80], 0.0, rng=np.random.default_rng(1))
    >>> p.shape, float(p[0])  # no airflow in the first interval
    ((5,), 0.0)
    """
    edges = _numbers("edges_s", edges_s)
    if edges.ndim != 1 or edges.size < 2:
        raise UsageError(
            f"edges_s: must be a 1-D array of at least 2 times, not shape {edges.shape}"
        )
    steps = np.diff(edges)
    for k in np.flatnonzero(steps <= 0.0)[:1]:
        raise UsageError(
            f"edges_s: must increase strictly: edge {k + 1} ({edges[k + 1]:g} s) is not after "
            f"edge {k} ({edges[k]:g} s)"
        )
    level = _severity(severity)
    span = _span(span_m)
    speed = _edge_values("airspeed_mps", airspeed_mps, edges.size, "m/s")
    height = _edge_values("altitude_m", altitude_m, edges.size, "m")
    if not isinstance(rng, np.random.Generator):
        raise UsageError(f"rng: must be a numpy.random.Generator, not {type(rng).__name__}")
    if size is None:
        traces = 1
    elif isinstance(size, bool) or not isinstance(size, int | np.integer) or size < 1:
        raise UsageError(f"size: must be a positive integer or None, not {size!r}")
    else:
        traces = int(size)

    speed_mid = 0.5 * (speed[1:] + speed[:-1])
    height_mid = 0.5 * (height[1:] + height[:-1])
    sigma_ftps, length_ft = _parameters_ft(height_mid / FT_M, level)
    sigma = _roll_sigma(sigma_ftps * FT_M, length_ft * FT_M, span)
    moving = speed_mid >= STILL_AIR_MPS
    u = np.where(moving, steps * math.pi * np.maximum(speed_mid, STILL_AIR_MPS) / (4.0 * span), 1.0)
    phi, a1, mean, l21, l22 = interval_coefficients(u)
    # Without airflow: output 0, state unchanged.
    phi = np.where(moving, phi, 1.0)
    noise_state = np.where(moving, sigma * a1, 0.0)
    mean = np.where(moving, mean, 0.0)
    noise_1 = np.where(moving, sigma * l21, 0.0)
    noise_2 = np.where(moving, sigma * l22, 0.0)

    out = np.empty((traces, steps.size))
    state = sigma[0] * rng.standard_normal(traces)
    for j in range(steps.size):
        z = rng.standard_normal((2, traces))
        out[:, j] = mean[j] * state + noise_1[j] * z[0] + noise_2[j] * z[1]
        state = phi[j] * state + noise_state[j] * z[0]
    out[:, ~moving] = 0.0
    np.degrees(out, out=out)
    return out[0] if size is None else out
