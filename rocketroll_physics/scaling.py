"""How the identified roll model carries from its reference airspeed to flight.

The paper identifies the roll model at one operating point, the wind tunnel's
airspeed of "roughly 50 km/h" at sea-level density (§4).  In flight the
airspeed ``V`` and the density ``ρ`` change, and with them the coefficients of
eq. 7-8 (§4: "the dynamic pressure q in equation (5) will also increase").

* :class:`AirspeedScaling` (:data:`EQ_4_8`: fin torque ``∝ ρV²``, damping
  ``∝ ρV``; measured exponents ``n``, ``m`` otherwise) and
  :func:`roll_scales`: the factors on ``α`` and ``a`` at each ``(V, ρ)``.
* :class:`FlightReference`: where an identified rocket holds (its ``V_ref``,
  ``ρ_ref``) and how it scales from there.
* :data:`MACH_LIMIT`: above Mach 0.8 the scaling (constant coefficients,
  subsonic aerodynamics) does not hold; :func:`fin_compressibility` is the
  virtual flight recorder's truth beyond it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import UsageError
from rocketroll_physics.atmosphere import ISA_SEA_LEVEL_DENSITY_KGM3

__all__ = [
    "EQ_4_8",
    "MACH_LIMIT",
    "SUPERSONIC_FROM_MACH",
    "TUNNEL_AIRSPEED_MPS",
    "AirspeedScaling",
    "FlightReference",
    "fin_compressibility",
    "roll_scales",
]

#: Mach number above which the roll model (eq. 4-8 at constant coefficients: subsonic
#: aerodynamics, the paper's §4) does not hold: the flight method leaves such samples out
#: unless asked, and a flight environment whose profile goes past it warns.
MACH_LIMIT = 0.8

#: The wind tunnel's airspeed, m/s: "roughly 50 km/h" (paper §4).  The
#: identified ``a`` and ``α`` hold at this airspeed and sea-level density.
TUNNEL_AIRSPEED_MPS = 50.0 / 3.6


@dataclass(frozen=True)
class AirspeedScaling:
    """How the fins' torque and the roll damping grow with the airspeed: ``∝ ρ·V^n`` and
    ``∝ ρ·V^m``.

    Eq. 4-8 at constant coefficients give ``n = 2`` (the dynamic pressure) and
    ``m = 1`` (the damping's ``q/v_M``): :data:`EQ_4_8`.  A real airframe need
    not follow them -- canards whose effectiveness falls with the airspeed
    (flow separation, aeroelastic twist, the body's interference) give a smaller
    ``n`` -- and the flight method measures both
    (:mod:`identification.methods.flightfit`).  The identified model's gain ``α``
    (torque per damping) then scales as ``V^(n−m)`` and its damping ``a`` as
    ``ρ·V^m``.

    Attributes
    ----------
    torque_exponent : float
        ``n``: the fins' torque per degree ``∝ ρ·V^n``.
    damping_exponent : float
        ``m``: the damping ``a ∝ ρ·V^m``.
    """

    torque_exponent: float = 2.0
    damping_exponent: float = 1.0

    def __post_init__(self) -> None:
        for name in ("torque_exponent", "damping_exponent"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 4.0):
                raise UsageError(f"{name}: must be in [0, 4], not {value!r}")

    @property
    def is_eq_4_8(self) -> bool:
        """Whether these are the exponents of eq. 4-8 (``n = 2``, ``m = 1``)."""
        return self == EQ_4_8

    def label(self) -> str:
        """``n 2, m 1`` (with eq. 4-8 named when it is that)."""
        text = f"n {self.torque_exponent:.3g}, m {self.damping_exponent:.3g}"
        return text + (" (eq. 4-8)" if self.is_eq_4_8 else "")


#: The scaling of eq. 4-8 at constant ``C_P``, ``C_δ``: torque ``∝ ρV²``, damping ``∝ ρV``.
EQ_4_8 = AirspeedScaling()


@dataclass(frozen=True)
class FlightReference:
    """Where a flight-identified rocket's parameters hold and how they scale from there:
    the reference airspeed and density and the airspeed scaling (measured or held).

    A tunnel identification has none (it holds at the tunnel's airspeed, scaled by eq. 4-8
    in flight); a flight fit stores one with its parameters.
    """

    v_ref_mps: float
    rho_ref_kgm3: float
    scaling: AirspeedScaling = EQ_4_8

    def __post_init__(self) -> None:
        for name in ("v_ref_mps", "rho_ref_kgm3"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise UsageError(f"{name}: must be finite and > 0, not {value!r}")

    def scales(
        self, airspeed_mps: ArrayLike, density_kgm3: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """The gain's and the damping's factors at ``airspeed_mps`` and ``density_kgm3``
        (:func:`roll_scales` from this reference)."""
        return roll_scales(
            airspeed_mps, density_kgm3, self.v_ref_mps, self.rho_ref_kgm3, self.scaling
        )

    @classmethod
    def from_metrics(cls, metrics: Mapping[str, Any]) -> FlightReference | None:
        """The reference a flight fit's metrics record (``v_ref_mps``, ``rho_ref_kgm3``,
        ``torque_exponent``, ``damping_exponent``); None for a tunnel fit's."""
        if "v_ref_mps" not in metrics or "rho_ref_kgm3" not in metrics:
            return None
        return cls(
            float(metrics["v_ref_mps"]),
            float(metrics["rho_ref_kgm3"]),
            AirspeedScaling(
                float(metrics.get("torque_exponent", 2.0)),
                float(metrics.get("damping_exponent", 1.0)),
            ),
        )


def roll_scales(
    airspeed_mps: ArrayLike,
    density_kgm3: ArrayLike,
    v_ref_mps: float = TUNNEL_AIRSPEED_MPS,
    rho_ref_kgm3: float = ISA_SEA_LEVEL_DENSITY_KGM3,
    scaling: AirspeedScaling = EQ_4_8,
) -> tuple[FloatArray, FloatArray]:
    """How the identified roll model's gain ``α`` and damping ``a`` scale with ``V`` and ``ρ``.

    Parameters
    ----------
    airspeed_mps : array_like
        Airspeed ``V``, m/s, ≥ 0.
    density_kgm3 : array_like
        Air density ``ρ``, kg/m³, > 0 (broadcast against ``airspeed_mps``).
    v_ref_mps : float
        Airspeed of the identification, m/s (the tunnel's 50 km/h).
    rho_ref_kgm3 : float
        Density of the identification, kg/m³ (ISA sea level).
    scaling : AirspeedScaling
        The exponents (default eq. 4-8's).

    Returns
    -------
    gain : ndarray
        ``α/α0 = (V/V_ref)^(n−m)`` (eq. 4-8: ``V/V_ref``).
    damping : ndarray
        ``a/a0 = (ρ/ρ_ref)·(V/V_ref)^m`` (eq. 4-8: ``ρ·V/(ρ_ref·V_ref)``).

    Notes
    -----
    Eq. 7-8 with the dynamic pressure of eq. 5, ``q = ½·ρ·v_M²``::

        I·dv/dt = −c·v + b·θ + τ_d,   c = q·S·d²·|C_P|/(2·v_M) = ρ·v_M·S·d²·|C_P|/4,
                                      b = q·S·d·C_δ = ½·ρ·v_M²·S·d·C_δ

    so ``c ∝ ρ·V`` and ``b ∝ ρ·V²`` at constant coefficients ``C_P``, ``C_δ``
    (subsonic: the paper's §4 warns they change past about Mach 0.8).  The
    identified model (eq. 21-22, 30) has ``a = c/I`` and ``α = b/c``::

        a ∝ ρ·V,     α ∝ V,     a·α = b/I ∝ ρ·V²

    with the inertia ``I`` taken as constant (the burning propellant changes it
    a little).  At the tunnel's operating point both factors are 1.

    References
    ----------
    The paper, eq. 4-8 and §4 ("the dynamic pressure q in equation (5) will
    also increase"; the tunnel's airspeed "roughly 50 km/h").

    Examples
    --------
    >>> gain, damping = roll_scales(600 / 3.6, ISA_SEA_LEVEL_DENSITY_KGM3)
    >>> round(float(gain), 6), round(float(damping), 6)
    (12.0, 12.0)
    """
    if not (math.isfinite(v_ref_mps) and v_ref_mps > 0):
        raise UsageError(f"v_ref_mps: must be finite and > 0, not {v_ref_mps!r}")
    if not (math.isfinite(rho_ref_kgm3) and rho_ref_kgm3 > 0):
        raise UsageError(f"rho_ref_kgm3: must be finite and > 0, not {rho_ref_kgm3!r}")
    speed = np.asarray(airspeed_mps, dtype=float)
    density = np.asarray(density_kgm3, dtype=float)
    if not (np.all(np.isfinite(speed)) and np.all(speed >= 0)):
        raise UsageError("airspeed_mps: must be finite and >= 0")
    if not (np.all(np.isfinite(density)) and np.all(density > 0)):
        raise UsageError("density_kgm3: must be finite and > 0")
    ratio = speed / v_ref_mps
    if scaling.is_eq_4_8:  # exact, and no power of 0
        return np.asarray(ratio), np.asarray(ratio * density / rho_ref_kgm3)
    n, m = scaling.torque_exponent, scaling.damping_exponent
    # a gain exponent below 0 would make the fins' gain unbounded at rest: held at 1e-6 V_ref
    held = np.maximum(ratio, 1e-6) if n < m else ratio
    gain = np.power(held, n - m)
    return np.asarray(gain), np.asarray(np.power(ratio, m) * density / rho_ref_kgm3)


#: Mach number from which :func:`fin_compressibility` follows Ackeret's supersonic law.
SUPERSONIC_FROM_MACH = 1.2


def fin_compressibility(mach: ArrayLike) -> FloatArray:
    """A factor on the fins' torque per degree beyond the subsonic scaling: the virtual
    flight recorder's truth above :data:`MACH_LIMIT`, outside the roll model (whose
    coefficients are constant: the paper's §4).

    1 up to Mach 0.8; from Mach 1.2, Ackeret's thin-aerofoil law, the lift slope
    ``∝ 1/√(M² − 1)``, scaled to ``√(1 − 0.8²)/√(M² − 1)`` (0.90 at Mach 1.2, 0.45
    at 1.67); linear across the transonic band between, where neither law holds.  A
    stylised truth: real fins' transonic lift depends on their section and planform.

    Examples
    --------
    >>> [round(float(k), 3) for k in fin_compressibility([0.5, 0.8, 1.0, 1.2, 2.0])]
    [1.0, 1.0, 0.952, 0.905, 0.346]
    """
    m = np.asarray(mach, dtype=float)
    if not (np.all(np.isfinite(m)) and np.all(m >= 0)):
        raise UsageError("mach: must be finite and >= 0")
    subsonic_beta = math.sqrt(1.0 - MACH_LIMIT**2)

    def ackeret(x: FloatArray) -> FloatArray:
        return np.asarray(subsonic_beta / np.sqrt(np.maximum(x**2 - 1.0, 1e-12)))

    top = float(ackeret(np.asarray(SUPERSONIC_FROM_MACH)))
    across = 1.0 + (top - 1.0) * (m - MACH_LIMIT) / (SUPERSONIC_FROM_MACH - MACH_LIMIT)
    factor = np.where(m <= MACH_LIMIT, 1.0, np.where(m < SUPERSONIC_FROM_MACH, across, 0.0))
    return np.asarray(np.where(m >= SUPERSONIC_FROM_MACH, ackeret(m), factor))
