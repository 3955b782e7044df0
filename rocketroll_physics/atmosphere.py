"""The International Standard Atmosphere, 0-20 km: the air a rocket flies through.

* :func:`isa` -> :class:`Atmosphere`: temperature, pressure, density and the
  speed of sound at a geopotential altitude (ISO 2533:1975 / U.S. Standard
  Atmosphere 1976, troposphere and the isothermal layer above it).

References
----------
ISO 2533:1975, *Standard Atmosphere*. International Organization for
Standardization, Geneva, 1975.

*U.S. Standard Atmosphere, 1976*. NOAA, NASA and USAF, NOAA-S/T 76-1562,
Washington D.C., 1976.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import UsageError

__all__ = [
    "G0_MPS2",
    "ISA_MAX_ALTITUDE_M",
    "ISA_MIN_ALTITUDE_M",
    "ISA_SEA_LEVEL_DENSITY_KGM3",
    "Atmosphere",
    "isa",
    "isa_density",
]

# --------------------------------------------------------------------------- ISA constants
# ISO 2533:1975 / U.S. Standard Atmosphere 1976: the defining constants.
#: Standard acceleration of gravity, m/s².
G0_MPS2 = 9.80665
#: Specific gas constant of dry air, J/(kg·K) (R* / M0 = 8314.32 / 28.9644).
R_AIR_JPKGK = 287.05287
#: Ratio of specific heats of air.
GAMMA_AIR = 1.4
#: Sea-level temperature, K.
T0_K = 288.15
#: Sea-level pressure, Pa.
P0_PA = 101_325.0
#: Temperature lapse rate of the troposphere, K/m.
LAPSE_K_PER_M = 0.0065
#: Base of the isothermal layer (tropopause), geopotential m.
TROPOPAUSE_M = 11_000.0
#: Highest altitude :func:`isa` covers (top of the isothermal layer), m.
ISA_MAX_ALTITUDE_M = 20_000.0
#: Lowest altitude :func:`isa` accepts, m: below the lowest dry land (the Dead Sea
#: shore, about -430 m); the troposphere's formula itself holds further down.
ISA_MIN_ALTITUDE_M = -500.0
#: Temperature of the isothermal layer, K.
T11_K = T0_K - LAPSE_K_PER_M * TROPOPAUSE_M
#: Pressure at the tropopause, Pa (22 632.06).
P11_PA = P0_PA * (T11_K / T0_K) ** (G0_MPS2 / (LAPSE_K_PER_M * R_AIR_JPKGK))
#: ISA sea-level density, kg/m³ (1.2250): the tunnel's reference density ρ0.
ISA_SEA_LEVEL_DENSITY_KGM3 = P0_PA / (R_AIR_JPKGK * T0_K)


# --------------------------------------------------------------------------- atmosphere
@dataclass(frozen=True, eq=False)
class Atmosphere:
    """The ISA at some altitudes (floats for a scalar altitude, else arrays of its shape).

    Attributes
    ----------
    temperature_k : float or ndarray
        Air temperature, K.
    pressure_pa : float or ndarray
        Static pressure, Pa.
    density_kgm3 : float or ndarray
        Air density ρ, kg/m³.
    speed_of_sound_mps : float or ndarray
        Speed of sound ``sqrt(γ·R·T)``, m/s.
    """

    temperature_k: FloatArray | float
    pressure_pa: FloatArray | float
    density_kgm3: FloatArray | float
    speed_of_sound_mps: FloatArray | float

    def __repr__(self) -> str:
        def show(value: FloatArray | float) -> str:
            return f"{value:.6g}" if isinstance(value, float) else f"array{np.shape(value)}"

        return (
            f"Atmosphere(T={show(self.temperature_k)} K, p={show(self.pressure_pa)} Pa, "
            f"ρ={show(self.density_kgm3)} kg/m³, a={show(self.speed_of_sound_mps)} m/s)"
        )


def _isa_arrays(h: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """T, p, ρ, a at geopotential altitudes ``h`` (m), unchecked (both layers)."""
    low = h <= TROPOPAUSE_M
    temperature = np.where(low, T0_K - LAPSE_K_PER_M * h, T11_K)
    exponent = G0_MPS2 / (LAPSE_K_PER_M * R_AIR_JPKGK)
    pressure = np.where(
        low,
        P0_PA * (temperature / T0_K) ** exponent,
        P11_PA * np.exp(-G0_MPS2 * (h - TROPOPAUSE_M) / (R_AIR_JPKGK * T11_K)),
    )
    density = pressure / (R_AIR_JPKGK * temperature)
    speed = np.sqrt(GAMMA_AIR * R_AIR_JPKGK * temperature)
    return temperature, pressure, density, speed


def isa_density(h: float) -> float:
    """ρ at one altitude (m), clipped into the ISA's range: the integrator's hot path."""
    h = min(max(h, ISA_MIN_ALTITUDE_M), ISA_MAX_ALTITUDE_M)
    if h <= TROPOPAUSE_M:
        t = T0_K - LAPSE_K_PER_M * h
        p = P0_PA * (t / T0_K) ** (G0_MPS2 / (LAPSE_K_PER_M * R_AIR_JPKGK))
    else:
        t = T11_K
        p = P11_PA * math.exp(-G0_MPS2 * (h - TROPOPAUSE_M) / (R_AIR_JPKGK * T11_K))
    return p / (R_AIR_JPKGK * t)


def isa(h_m: ArrayLike) -> Atmosphere:
    """The International Standard Atmosphere at geopotential altitude ``h_m``.

    Parameters
    ----------
    h_m : float or array_like
        Geopotential altitude, m, in [-500, 20 000] (troposphere and the
        isothermal layer above it).  Any shape.

    Returns
    -------
    Atmosphere
        Temperature, pressure, density and speed of sound: floats for a scalar
        ``h_m``, arrays of its shape otherwise.

    Raises
    ------
    UsageError
        If an altitude is not finite or lies outside [-500, 20 000] m.

    Notes
    -----
    Troposphere (``h ≤ 11 km``), with ``L = 0.0065 K/m``::

        T = T0 − L·h,    p = p0·(T/T0)^(g0/(L·R))

    Isothermal layer (11-20 km)::

        T = T11 = 216.65 K,    p = p11·exp(−g0·(h − 11 000)/(R·T11))

    and ``ρ = p/(R·T)``, ``a = sqrt(γ·R·T)``, with T0 = 288.15 K,
    p0 = 101 325 Pa, R = 287.05287 J/(kg·K), g0 = 9.80665 m/s², γ = 1.4.
    The altitude is geopotential; the geometric altitude ``z = r·h/(r − h)``
    (``r`` = 6 356 766 m) is 0.6 m higher at 2 km.

    References
    ----------
    ISO 2533:1975, *Standard Atmosphere* (the same model up to 32 km).
    *U.S. Standard Atmosphere, 1976*, NOAA-S/T 76-1562, Part 1 (the
    equations) and Part 4 (the tables, to which the tests compare).

    Examples
    --------
    >>> round(isa(0.0).density_kgm3, 4), round(isa(11_000.0).temperature_k, 2)
    (1.225, 216.65)
    """
    h = np.asarray(h_m, dtype=float)
    bad = ~np.isfinite(h) | (h < ISA_MIN_ALTITUDE_M) | (h > ISA_MAX_ALTITUDE_M)
    if np.any(bad):
        value = float(h.ravel()[int(np.argmax(bad.ravel()))])
        raise UsageError(
            f"h_m: {value:g} m is outside the standard atmosphere's range "
            f"[{ISA_MIN_ALTITUDE_M:g}, {ISA_MAX_ALTITUDE_M:g}] m (troposphere and the "
            "isothermal layer)"
        )
    columns = _isa_arrays(h)
    if h.ndim == 0:
        return Atmosphere(*(float(c) for c in columns))
    return Atmosphere(*columns)
