"""The flight the tunnel stands in for: a rocket, its motor, and its 1-D vertical ascent.

A sounding rocket like the paper's (5 kg, 1.3 m, "maximum velocity [...]
approximately 600 km/h and it can reach up to 2 km in altitude", §1): its
airspeed ``V(t)``, altitude ``h(t)``, dynamic pressure ``q(t)``, Mach number
and density (:mod:`rocketroll_physics.atmosphere`), and the factors that carry
the tunnel's identified ``a`` and ``α`` to each instant of it
(:mod:`rocketroll_physics.scaling`).

* :class:`AscentSpec`, :data:`DEFAULT_ASCENT`, :data:`SUPERSONIC_ASCENT`,
  :func:`load_ascent_yaml`: a rocket and its motor.
* :func:`simulate_ascent` -> :class:`FlightProfile`: the point-mass vertical
  ascent from the pad to apogee (and on down, if asked);
  :func:`load_profile_csv` and :func:`recorded_profile` read a recorded one;
  :func:`flight_profile` any of them by name.
* :meth:`FlightProfile.scales`: the roll model's gain and damping factors
  along it.
* :func:`plot_profile`: the profile in four panels.

Model (the textbook 1-D point-mass ascent, with the motor's mass model of OpenRocket
and RockSim)::

    m(t)·dV/dt = T(t) − ½·ρ(h)·V²·C_D·A − m(t)·g0,      dh/dt = V
    m(t) = m_dry + m_prop·(1 − I(t)/I_total),          I(t) = ∫₀ᵗ T dt'

flown straight up in still air (airspeed = vertical speed), with a constant,
subsonic drag coefficient, and held on the pad until the thrust exceeds the
weight.  Altitudes are geopotential (the ISA's own coordinate), which is also
why ``g0`` is constant: at 2 km the geometric altitude is 0.6 m higher.

References
----------
S. Niskanen, *Development of an Open Source model rocket simulation software*
(the OpenRocket technical documentation), M.Sc. thesis, Helsinki University of
Technology, 2009: the flight simulation, and the motor's propellant mass
taken as proportional to the impulse still to be delivered (RockSim makes the
same assumption for a motor given as a RASP ``.eng`` thrust curve).
"""

from __future__ import annotations

import csv
import functools
import itertools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field

from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import SettingError, UsageError
from rocketroll_common.text import parse_number
from rocketroll_physics.atmosphere import (
    G0_MPS2,
    ISA_MAX_ALTITUDE_M,
    ISA_MIN_ALTITUDE_M,
    ISA_SEA_LEVEL_DENSITY_KGM3,
    isa,
    isa_density,
)
from rocketroll_physics.scaling import EQ_4_8, TUNNEL_AIRSPEED_MPS, AirspeedScaling, roll_scales

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "DEFAULT_ASCENT",
    "NAMED_ASCENTS",
    "PROFILE_COLUMNS",
    "SUPERSONIC_ASCENT",
    "AscentDocument",
    "AscentSpec",
    "FlightProfile",
    "FlightState",
    "check_ascent_name",
    "flight_profile",
    "load_ascent_yaml",
    "load_profile_csv",
    "plot_profile",
    "recorded_profile",
    "simulate_ascent",
]


# --------------------------------------------------------------------------- the rocket
def _finite(name: str, value: Any) -> float:
    """``value`` as a float, or a :class:`SettingError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise SettingError(name, f"must be a number, not {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise SettingError(name, f"must be finite, not {number!r}")
    return number


@dataclass(frozen=True)
class AscentSpec:
    """A sounding rocket and its motor, for :func:`simulate_ascent`.

    Attributes
    ----------
    dry_mass_kg : float
        Mass without propellant (airframe, avionics, empty motor case), kg, > 0.
    propellant_mass_kg : float
        Propellant at liftoff, kg, > 0; burnt in proportion to the impulse
        delivered.
    thrust_time_s : tuple of float
        Knots of the thrust curve, s: starting at 0, strictly increasing, at
        least two; the last is burnout.
    thrust_n : tuple of float
        Thrust at each knot, N, ≥ 0, linear in between; 0 at the last knot.
    drag_coefficient : float
        ``C_D``, constant (subsonic), on the reference area, ≥ 0.
    diameter_m : float
        Body diameter, m, > 0; reference area ``π·d²/4``.
    length_m : float
        Overall length, m, > 0 (informational: the paper's rocket is 1.3 m).
    launch_altitude_m : float
        Altitude of the pad, geopotential m above sea level, in the ISA's range.

    Raises
    ------
    rocketroll_common.errors.SettingError
        (a :class:`UsageError`) naming the field and what is wrong.
    """

    dry_mass_kg: float
    propellant_mass_kg: float
    thrust_time_s: tuple[float, ...]
    thrust_n: tuple[float, ...]
    drag_coefficient: float
    diameter_m: float
    length_m: float = 1.3
    launch_altitude_m: float = 0.0

    def __post_init__(self) -> None:
        for name, low, strict in (
            ("dry_mass_kg", 0.0, True),
            ("propellant_mass_kg", 0.0, True),
            ("drag_coefficient", 0.0, False),
            ("diameter_m", 0.0, True),
            ("length_m", 0.0, True),
        ):
            value = _finite(f"AscentSpec.{name}", getattr(self, name))
            if value < low or (strict and value == low):
                raise SettingError(
                    f"AscentSpec.{name}",
                    f"must be {'>' if strict else '>='} {low:g}, not {value:g}",
                )
            object.__setattr__(self, name, value)
        altitude = _finite("AscentSpec.launch_altitude_m", self.launch_altitude_m)
        if not ISA_MIN_ALTITUDE_M <= altitude < ISA_MAX_ALTITUDE_M:
            raise SettingError(
                "AscentSpec.launch_altitude_m",
                f"{altitude:g} m is outside the standard atmosphere's range "
                f"[{ISA_MIN_ALTITUDE_M:g}, {ISA_MAX_ALTITUDE_M:g}) m",
            )
        object.__setattr__(self, "launch_altitude_m", altitude)
        for name in ("thrust_time_s", "thrust_n"):
            raw = getattr(self, name)
            if isinstance(raw, str | bytes) or not isinstance(raw, Sequence | np.ndarray):
                raise SettingError(f"AscentSpec.{name}", f"must be a sequence, not {raw!r}")
            values = tuple(_finite(f"AscentSpec.{name}[{i}]", v) for i, v in enumerate(raw))
            object.__setattr__(self, name, values)
        times, thrust = self.thrust_time_s, self.thrust_n
        if len(times) != len(thrust):
            raise SettingError(
                "AscentSpec.thrust_n",
                f"has {len(thrust)} values for {len(times)} knots in thrust_time_s",
            )
        if len(times) < 2:
            raise SettingError("AscentSpec.thrust_time_s", "needs at least two knots")
        if times[0] != 0.0:
            raise SettingError(
                "AscentSpec.thrust_time_s", f"must start at 0 s (ignition), not {times[0]:g}"
            )
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise SettingError(
                    "AscentSpec.thrust_time_s",
                    f"must increase strictly: knot {i} ({times[i]:g} s) is not after "
                    f"knot {i - 1} ({times[i - 1]:g} s)",
                )
        for i, value in enumerate(thrust):
            if value < 0.0:
                raise SettingError("AscentSpec.thrust_n", f"knot {i} is negative ({value:g} N)")
        if thrust[-1] != 0.0:
            raise SettingError(
                "AscentSpec.thrust_n",
                f"must end at 0 N (burnout), not {thrust[-1]:g} N at {times[-1]:g} s",
            )
        if self.total_impulse_ns <= 0.0:
            raise SettingError("AscentSpec.thrust_n", "the motor delivers no impulse")

    # -- derived quantities
    @property
    def burnout_s(self) -> float:
        """Time of the last thrust knot (thrust 0), s."""
        return self.thrust_time_s[-1]

    @property
    def liftoff_mass_kg(self) -> float:
        """Dry plus propellant mass, kg."""
        return self.dry_mass_kg + self.propellant_mass_kg

    @property
    def reference_area_m2(self) -> float:
        """``π·d²/4``, m²."""
        return math.pi * self.diameter_m**2 / 4.0

    @property
    def total_impulse_ns(self) -> float:
        """``∫ T dt`` over the burn, N·s (trapezoid: exact for the piecewise-linear curve)."""
        return float(self._knot_impulse()[-1])

    def _knot_impulse(self) -> FloatArray:
        times = np.asarray(self.thrust_time_s)
        thrust = np.asarray(self.thrust_n)
        steps = 0.5 * (thrust[1:] + thrust[:-1]) * np.diff(times)
        return np.concatenate([[0.0], np.cumsum(steps)])

    def thrust_at(self, t_s: ArrayLike) -> FloatArray:
        """Thrust, N, at times ``t_s`` (s from ignition; 0 before ignition and after burnout)."""
        t = np.asarray(t_s, dtype=float)
        return np.interp(t, self.thrust_time_s, self.thrust_n, left=0.0, right=0.0)

    def impulse_at(self, t_s: ArrayLike) -> FloatArray:
        """Impulse delivered by ``t_s``, N·s: exact (quadratic) within each linear piece."""
        times = np.asarray(self.thrust_time_s)
        thrust = np.asarray(self.thrust_n)
        t = np.clip(np.asarray(t_s, dtype=float), 0.0, times[-1])
        i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
        tau = t - times[i]
        slope = (thrust[i + 1] - thrust[i]) / (times[i + 1] - times[i])
        return np.asarray(self._knot_impulse()[i] + thrust[i] * tau + 0.5 * slope * tau**2)

    def mass_at(self, t_s: ArrayLike) -> FloatArray:
        """Mass, kg: ``m_dry + m_prop·(1 − I(t)/I_total)`` (OpenRocket's and RockSim's model)."""
        burnt = self.impulse_at(t_s) / self.total_impulse_ns
        return np.asarray(self.dry_mass_kg + self.propellant_mass_kg * (1.0 - burnt))


#: A 5-kg, 1.3-m sounding rocket like the paper's (§1: "maximum velocity [...]
#: approximately 600 km/h", apogee "up to 2 km").  :func:`simulate_ascent` flies
#: it to a peak of 603 km/h (167.6 m/s, Mach 0.50, max q 15.8 kPa) at 6.9 s and
#: an apogee of 2.01 km at 21.4 s.
#:
#: It is a plausible stand-in, not a measured rocket or motor: the paper gives
#: only the mass, the length, the peak speed and the apogee, and these numbers
#: were tuned by simulation to meet the last two.  Airframe 76 mm in diameter
#: (a common "3-inch" body tube) with ``C_D = 0.42``; 4.35 kg dry plus 0.65 kg
#: of propellant (a specific impulse of 196 s, usual for composite propellant).
#: The motor is a J-class (640-1280 N·s) boost-sustain curve of 1252 N·s: a
#: 0.6-s boost of about 800 N to 104 m/s, then a 6-s sustain plateau of
#: 108-120 N, a little above weight plus drag, that carries the rocket to its
#: peak speed at the tail-off (burnout 7.2 s at 940 m).  A short (2-3 s) burn
#: cannot meet both of the paper's numbers: even without drag, a rocket that
#: peaks at 167 m/s coasts only ``V²/2g`` = 1.4 km, and a short burn adds a few
#: hundred metres, so the burn must be long and slow.
DEFAULT_ASCENT = AscentSpec(
    dry_mass_kg=4.35,
    propellant_mass_kg=0.65,
    thrust_time_s=(0.0, 0.05, 0.3, 0.6, 0.8, 6.8, 7.2),
    thrust_n=(0.0, 860.0, 800.0, 740.0, 120.0, 108.0, 0.0),
    drag_coefficient=0.42,
    diameter_m=0.076,
    length_m=1.3,
    launch_altitude_m=0.0,
)

#: The same airframe on a K-class motor (1940 N·s: 800 N for 2.5 s): briefly supersonic,
#: peak Mach 1.04 at 2.5 s, above Mach 0.8 from 1.9 s to 5.0 s, apogee 3.4 km at 24.5 s --
#: a flight with a supersonic stretch for the virtual flight recorder (``--ascent
#: supersonic``).  A stand-in like :data:`DEFAULT_ASCENT`, its drag coefficient held at
#: the subsonic 0.42 (a real one rises through Mach 1).
SUPERSONIC_ASCENT = AscentSpec(
    dry_mass_kg=4.35,
    propellant_mass_kg=1.0,
    thrust_time_s=(0.0, 0.05, 2.4, 2.5),
    thrust_n=(0.0, 800.0, 800.0, 0.0),
    drag_coefficient=0.42,
    diameter_m=0.076,
    length_m=1.3,
    launch_altitude_m=0.0,
)
#: The ascents :func:`flight_profile` knows by name.
NAMED_ASCENTS: Mapping[str, AscentSpec] = MappingProxyType(
    {"default": DEFAULT_ASCENT, "supersonic": SUPERSONIC_ASCENT}
)


# --------------------------------------------------------------------------- the profile
def _column(values: ArrayLike) -> FloatArray:
    return readonly_array(np.asarray(values, dtype=float))


@dataclass(frozen=True, eq=False)
class FlightState:
    """A :class:`FlightProfile` interpolated at some times (:meth:`FlightProfile.at`).

    Each field is a float for a scalar time, else an array of the times' shape;
    units as in :class:`FlightProfile`.
    """

    t_s: FloatArray | float
    altitude_m: FloatArray | float
    airspeed_mps: FloatArray | float
    mass_kg: FloatArray | float
    density_kgm3: FloatArray | float
    dynamic_pressure_pa: FloatArray | float
    mach: FloatArray | float


#: The columns of a :class:`FlightProfile` (and of a :class:`FlightState`), in order.
PROFILE_COLUMNS = (
    "t_s",
    "altitude_m",
    "airspeed_mps",
    "mass_kg",
    "density_kgm3",
    "dynamic_pressure_pa",
    "mach",
)


@dataclass(frozen=True, eq=False)
class FlightProfile:
    """Airspeed, altitude and air of one ascent, sampled in time.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Time from ignition (or the recording's clock), s, increasing.
    altitude_m : ndarray, shape (n,)
        Geopotential altitude above sea level, m.
    airspeed_mps : ndarray, shape (n,)
        Airspeed ``V``, m/s, ≥ 0.
    mass_kg : ndarray, shape (n,)
        Rocket mass, kg (NaN when unknown: a recorded profile).
    density_kgm3 : ndarray, shape (n,)
        ISA density ``ρ(h)``, kg/m³.
    dynamic_pressure_pa : ndarray, shape (n,)
        ``q = ½·ρ·V²`` (eq. 5), Pa.
    mach : ndarray, shape (n,)
        ``V / a(h)``.
    burnout_s : float
        End of thrust, s (NaN when unknown).
    apogee_s, apogee_m : float
        Time, s, and altitude, m, of the highest point.
    max_speed_mps : float
        Highest airspeed, m/s.
    source : str
        Where the profile came from (the simulation and its rocket, or a file).

    Arrays are read-only; all have one length (≥ 2).
    """

    t_s: FloatArray
    altitude_m: FloatArray
    airspeed_mps: FloatArray
    mass_kg: FloatArray
    density_kgm3: FloatArray
    dynamic_pressure_pa: FloatArray
    mach: FloatArray
    burnout_s: float
    apogee_s: float
    apogee_m: float
    max_speed_mps: float
    source: str

    def __post_init__(self) -> None:
        n = np.size(self.t_s)
        for name in PROFILE_COLUMNS:
            column = _column(getattr(self, name))
            if column.ndim != 1 or column.size != n:
                raise UsageError(
                    f"FlightProfile.{name}: must be 1-D with {n} samples like t_s, "
                    f"not of shape {column.shape}"
                )
            object.__setattr__(self, name, column)
        if n < 2:
            raise UsageError(f"FlightProfile.t_s: needs at least 2 samples, not {n}")
        if not (np.all(np.isfinite(self.t_s)) and np.all(np.diff(self.t_s) > 0)):
            raise UsageError("FlightProfile.t_s: must be finite and strictly increasing")
        if not (np.all(np.isfinite(self.airspeed_mps)) and np.all(self.airspeed_mps >= 0)):
            raise UsageError("FlightProfile.airspeed_mps: must be finite and >= 0")
        for name in ("burnout_s", "apogee_s", "apogee_m", "max_speed_mps"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def __repr__(self) -> str:
        return (
            f"FlightProfile(n={self.t_s.size}, t=[{self.t_s[0]:g}, {self.t_s[-1]:g}] s, "
            f"max V={self.max_speed_mps:.1f} m/s ({self.max_speed_mps * 3.6:.0f} km/h), "
            f"apogee={self.apogee_m:.0f} m at {self.apogee_s:.2f} s, "
            f"burnout={self.burnout_s:.2f} s, max Mach={self.max_mach:.3f}, "
            f"source={self.source!r})"
        )

    @property
    def max_mach(self) -> float:
        """Highest Mach number."""
        return float(np.max(self.mach))

    @property
    def max_dynamic_pressure_pa(self) -> float:
        """Highest dynamic pressure ("max q"), Pa."""
        return float(np.max(self.dynamic_pressure_pa))

    def at(self, t_s: ArrayLike) -> FlightState:
        """Every column linearly interpolated (:func:`numpy.interp`) at ``t_s``.

        Parameters
        ----------
        t_s : float or array_like
            Times, s, finite.  Before the first sample or after the last the
            first or last sample is held (a profile ends at apogee, or its
            descent's end).

        Returns
        -------
        FlightState
            Floats for a scalar ``t_s``, arrays of its shape otherwise.
        """
        t = np.asarray(t_s, dtype=float)
        if not np.all(np.isfinite(t)):
            raise UsageError("t_s: times must be finite")
        values = {name: np.interp(t, self.t_s, getattr(self, name)) for name in PROFILE_COLUMNS}
        values["t_s"] = t
        if t.ndim == 0:
            return FlightState(**{k: float(v) for k, v in values.items()})
        return FlightState(**values)

    def window(self, v_ref_mps: float, *, until: str = "apogee") -> tuple[float, float]:
        """From the moment the airspeed first reaches ``v_ref_mps`` (the rocket has left its
        rail, the fins have the authority identified at that airspeed) to apogee, s.

        Parameters
        ----------
        v_ref_mps : float
            The reference airspeed, m/s.
        until : {"apogee", "slow"}
            ``apogee`` (the environments' episode) or ``slow``: the moment the
            airspeed falls back below ``v_ref_mps`` on the way up (the flight
            recorder's log: below ``v_ref`` the rolling gust of Dryden's model,
            taken as a flow angle, outgrows the fins' authority without bound).

        Raises
        ------
        ValueError
            If the profile never reaches ``v_ref_mps``, or reaches it only at apogee.
        """
        if until not in ("apogee", "slow"):
            raise ValueError(f"until must be 'apogee' or 'slow', not {until!r}")
        fast = np.flatnonzero(self.airspeed_mps >= v_ref_mps)
        if fast.size == 0:
            raise ValueError(
                f"flight: {self.source} never reaches the reference airspeed "
                f"{v_ref_mps:.1f} m/s (its fastest: {self.max_speed_mps:.1f} m/s)"
            )
        apogee = float(self.apogee_s if math.isfinite(self.apogee_s) else self.t_s[-1])
        start = self._crossing(int(fast[0]), v_ref_mps)
        if until == "slow":
            after = np.flatnonzero(self.airspeed_mps[fast[0] :] < v_ref_mps)
            end = apogee if after.size == 0 else self._crossing(int(fast[0] + after[0]), v_ref_mps)
        else:
            end = apogee
        end = min(end, apogee)
        if not end > start:
            where = "is at apogee" if end == apogee else "falls back below it"
            raise ValueError(
                f"flight: {self.source} reaches the reference airspeed {v_ref_mps:.1f} m/s "
                f"at {start:.2f} s and {where} at {end:.2f} s: no time to fly"
            )
        return start, end

    def _crossing(self, k: int, speed: float) -> float:
        """Where the airspeed crosses ``speed`` between samples ``k - 1`` and ``k``, s."""
        if k == 0:
            return float(self.t_s[0])
        t0, t1 = self.t_s[k - 1], self.t_s[k]
        v0, v1 = self.airspeed_mps[k - 1], self.airspeed_mps[k]
        return float(t0 + (t1 - t0) * (speed - v0) / (v1 - v0))

    def scales(
        self,
        v_ref_mps: float = TUNNEL_AIRSPEED_MPS,
        rho_ref_kgm3: float = ISA_SEA_LEVEL_DENSITY_KGM3,
        scaling: AirspeedScaling = EQ_4_8,
    ) -> tuple[FloatArray, FloatArray]:
        """Gain and damping factors of the roll model at each sample (:func:`roll_scales`).

        Parameters
        ----------
        v_ref_mps : float
            Airspeed at which ``a`` and ``α`` were identified, m/s (default: the
            tunnel's 50 km/h, paper §4).
        rho_ref_kgm3 : float
            Density there, kg/m³ (default: ISA sea level).
        scaling : AirspeedScaling
            The exponents (default eq. 4-8's).

        Returns
        -------
        gain, damping : ndarray, shape (n,)
            ``α(t)/α0 = V/V_ref`` and ``a(t)/a0 = ρV/(ρ_ref·V_ref)`` (eq. 4-8).

        Notes
        -----
        From eq. 4-8 (derived in :func:`roll_scales`): the damping constant
        ``c = q·S·d²·|C_P|/(2·v_M) ∝ ρ·V`` and the fin torque constant
        ``b = q·S·d·C_δ ∝ ρ·V²`` with ``q = ½·ρ·V²`` (eq. 5), so
        ``a = c/I ∝ ρ·V`` and ``α = b/c ∝ V``.
        """
        return roll_scales(self.airspeed_mps, self.density_kgm3, v_ref_mps, rho_ref_kgm3, scaling)


# --------------------------------------------------------------------------- simulation
def _liftoff_s(spec: AscentSpec) -> float:
    """First time the thrust exceeds the weight (the rocket leaves the pad), s."""
    from scipy.optimize import brentq

    def excess(t: ArrayLike) -> FloatArray:
        return np.asarray(spec.thrust_at(t) - spec.mass_at(t) * G0_MPS2)

    grid = np.linspace(0.0, spec.burnout_s, 20_001)
    above = excess(grid) > 0
    if not np.any(above):
        raise UsageError(
            f"AscentSpec: the thrust never exceeds the liftoff weight "
            f"({spec.liftoff_mass_kg * G0_MPS2:.1f} N, peak thrust {max(spec.thrust_n):g} N): "
            "the rocket does not leave the pad"
        )
    k = int(np.argmax(above))
    if k == 0:
        return 0.0
    return float(brentq(lambda t: float(excess(t)), grid[k - 1], grid[k], xtol=1e-12))


def _sampled(
    pieces: list[tuple[float, float, Any]],
    dt_s: float,
    apogee_s: float,
    end_s: float,
    pad_m: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The solver's dense pieces ``(start, end, solution)`` on the grid of ``dt_s`` from
    ignition, with the apogee and the end: times, altitude (the pad's before liftoff) and
    airspeed (``|V|`` falling)."""
    n = int(np.floor(end_s / dt_s * (1 + 1e-12)))
    grid = dt_s * np.arange(n + 1)
    t: FloatArray = np.unique(np.append(grid[grid < end_s - 1e-9 * dt_s], [apogee_s, end_s]))
    altitude = np.full(t.shape, pad_m)
    speed = np.zeros(t.shape)
    for start, end, dense in pieces:
        inside = (t >= start) & (t <= end)
        if np.any(inside):
            states = dense(t[inside])
            altitude[inside] = states[0]
            speed[inside] = states[1]
    speed[t == apogee_s] = 0.0  # the apogee event: V = 0 to the solver's tolerance
    speed = np.where(t > apogee_s, np.abs(speed), np.maximum(speed, 0.0))
    return t, altitude, speed


def _simulated_profile(
    spec: AscentSpec,
    t: FloatArray,
    altitude: FloatArray,
    speed: FloatArray,
    apogee_s: float,
    apogee_m: float,
) -> FlightProfile:
    """A simulated flight's profile from its sampled altitude and airspeed."""
    if altitude.max() > ISA_MAX_ALTITUDE_M:
        raise UsageError(
            f"AscentSpec: the rocket climbs to {altitude.max():.0f} m, above the standard "
            f"atmosphere's {ISA_MAX_ALTITUDE_M:g} m"
        )
    air = isa(altitude)
    density = np.asarray(air.density_kgm3)
    return FlightProfile(
        t_s=t,
        altitude_m=altitude,
        airspeed_mps=speed,
        mass_kg=spec.mass_at(t),
        density_kgm3=density,
        dynamic_pressure_pa=0.5 * density * speed**2,
        mach=speed / np.asarray(air.speed_of_sound_mps),
        burnout_s=spec.burnout_s,
        apogee_s=apogee_s,
        apogee_m=apogee_m,
        max_speed_mps=float(speed.max()),
        source=(
            f"simulated: 1-D vertical ascent, {spec.liftoff_mass_kg:g} kg, "
            f"{spec.total_impulse_ns:.0f} N·s, C_D {spec.drag_coefficient:g}, "
            f"d {spec.diameter_m * 1000:g} mm"
        ),
    )


def simulate_ascent(
    spec: AscentSpec = DEFAULT_ASCENT, dt_s: float = 0.01, descent_s: float = 0.0
) -> FlightProfile:
    """Fly ``spec`` straight up from the pad to apogee (and on down for ``descent_s``).

    Parameters
    ----------
    spec : AscentSpec
        The rocket and its motor (default: :data:`DEFAULT_ASCENT`).
    dt_s : float
        Sampling interval of the profile, s, in (0, 1].
    descent_s : float
        Seconds flown on past apogee, falling tail-first on the same 1-D
        equation with the drag reversed (no recovery device); the airspeed
        there is the fall's speed, ``|V|``.  Default 0: the profile ends at
        apogee.

    Returns
    -------
    FlightProfile
        Samples every ``dt_s`` from ignition (t = 0) and the apogee itself
        (the last sample without a descent, so the last interval is at most
        ``dt_s``).  ``source`` says ``simulated``.

    Raises
    ------
    UsageError
        If ``spec`` is not an :class:`AscentSpec`, ``dt_s`` is out of range, the
        rocket never leaves the pad, falls back before burnout, or climbs
        above the ISA's 20 km.

    Notes
    -----
    The 1-D point-mass ascent (the motor's mass as in OpenRocket and RockSim)::

        m(t)·dV/dt = T(t) − ½·ρ(h)·V²·C_D·A − m(t)·g0,     dh/dt = V
        m(t) = m_dry + m_prop·(1 − I(t)/I_total)

    ``ρ(h)`` from :func:`isa`.  The rocket stays on the pad (``V = 0``) until
    ``T > m·g0``.  :func:`scipy.integrate.solve_ivp` (DOP853, rtol 1e-10)
    integrates each linear piece of the thrust curve separately, so its
    kinks are never stepped over, and the coast until ``V = 0`` (a terminal
    event); the profile is the solver's dense output on the time grid.

    References
    ----------
    Niskanen (2009), the OpenRocket technical documentation; the paper, §1
    (a 5-kg, 1.3-m rocket, about 600 km/h and 2 km) and eq. 5 (``q``).

    Examples
    --------
    >>> profile = simulate_ascent(DEFAULT_ASCENT)
    >>> round(profile.max_speed_mps * 3.6, -1), round(profile.apogee_m, -2)
    (600.0, 2000.0)
    """
    from scipy.integrate import solve_ivp

    if not isinstance(spec, AscentSpec):
        raise UsageError(f"spec: must be an AscentSpec, not {type(spec).__name__}")
    if not (isinstance(dt_s, int | float) and math.isfinite(dt_s) and 0 < dt_s <= 1.0):
        raise UsageError(f"dt_s: must be in (0, 1] s, not {dt_s!r}")
    if not (isinstance(descent_s, int | float) and 0.0 <= descent_s <= 600.0):
        raise UsageError(f"descent_s: must be in [0, 600] s, not {descent_s!r}")

    area_cd = spec.reference_area_m2 * spec.drag_coefficient
    knots_t = np.asarray(spec.thrust_time_s)
    knots_f = np.asarray(spec.thrust_n)

    def rhs(t: float, y: FloatArray) -> list[float]:
        h, v = float(y[0]), float(y[1])
        thrust = float(np.interp(t, knots_t, knots_f, left=0.0, right=0.0))
        mass = float(spec.mass_at(t))
        drag = 0.5 * isa_density(h) * v * abs(v) * area_cd
        return [v, (thrust - drag) / mass - G0_MPS2]

    def stops(t: float, y: FloatArray) -> float:
        return float(y[1])

    stops.terminal = True  # type: ignore[attr-defined]
    stops.direction = -1  # type: ignore[attr-defined]

    liftoff = _liftoff_s(spec)
    edges = [liftoff, *(float(t) for t in knots_t if t > liftoff)]
    y = np.array([spec.launch_altitude_m, 0.0])
    pieces = []
    options: dict[str, Any] = {"method": "DOP853", "rtol": 1e-10, "atol": [1e-7, 1e-9]}
    for start, end in itertools.pairwise(edges):
        sol = solve_ivp(rhs, (start, end), y, dense_output=True, events=stops, **options)
        if sol.status == 1:
            raise UsageError(
                f"AscentSpec: the rocket stops climbing at {float(sol.t_events[0][0]):.2f} s, "
                f"before burnout ({spec.burnout_s:g} s): the thrust falls below the weight "
                "(a 1-D ascent cannot fly that)"
            )
        pieces.append((start, end, sol.sol))
        y = sol.y[:, -1]
    burnout_speed = float(y[1])
    horizon = spec.burnout_s + burnout_speed / G0_MPS2 + 10.0  # drag only shortens the coast
    coast = solve_ivp(rhs, (spec.burnout_s, horizon), y, dense_output=True, events=stops, **options)
    if coast.status != 1:  # pragma: no cover - the horizon bounds the coast
        raise RuntimeError("simulate_ascent: the coast did not reach apogee")
    apogee_s = float(coast.t_events[0][0])
    pieces.append((spec.burnout_s, apogee_s, coast.sol))
    end_s = apogee_s
    if descent_s > 0.0:
        end_s = apogee_s + descent_s
        top = np.array([float(coast.y_events[0][0][0]), 0.0])
        fall = solve_ivp(rhs, (apogee_s, end_s), top, dense_output=True, **options)
        pieces.append((apogee_s, end_s, fall.sol))

    t, altitude, speed = _sampled(pieces, dt_s, apogee_s, end_s, spec.launch_altitude_m)
    return _simulated_profile(spec, t, altitude, speed, apogee_s, float(coast.y_events[0][0][0]))


# --------------------------------------------------------------------------- user files
#: YAML keys of :func:`load_ascent_yaml` -> AscentSpec field (the thrust curve is one key).
class AscentDocument(BaseModel):
    """An ascent YAML file as written (:func:`load_ascent_yaml`): its keys and their types;
    the ranges are :class:`AscentSpec`'s.  Its JSON Schema is
    ``docs/schemas/ascent.schema.json``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    dry_mass_kg: float = Field(description="mass without propellant, kg (> 0)")
    propellant_mass_kg: float = Field(description="propellant at lift-off, kg (> 0)")
    thrust_curve: list[tuple[float, float]] = Field(
        description="[t_s, thrust_n] pairs from 0 s, ending at 0 N"
    )
    drag_coefficient: float = Field(description="axial drag coefficient (>= 0)")
    diameter_m: float = Field(description="body diameter, m (> 0)")
    length_m: float = Field(1.3, description="body length, m (> 0)")
    launch_altitude_m: float = Field(0.0, description="launch site above sea level, m")


def load_ascent_yaml(path: str | os.PathLike[str]) -> AscentSpec:
    """An :class:`AscentSpec` from a small YAML file.

    Parameters
    ----------
    path : str or path-like
        A YAML mapping whose keys are the :class:`AscentSpec` fields, the
        thrust curve as a list of ``[t_s, thrust_n]`` pairs under
        ``thrust_curve``::

            dry_mass_kg: 4.35
            propellant_mass_kg: 0.65
            drag_coefficient: 0.42
            diameter_m: 0.076
            length_m: 1.3            # optional (1.3)
            launch_altitude_m: 0.0   # optional (0)
            thrust_curve:            # [s, N], from 0 s, ending at 0 N
              - [0.0, 0.0]
              - [0.05, 860.0]
              ...

    Returns
    -------
    AscentSpec

    Raises
    ------
    UsageError
        Naming the file, the line where known, and the key: unreadable or
        invalid YAML, a missing or unknown key, a value of the wrong type
        (:class:`AscentDocument`) or out of range (:class:`AscentSpec`).

    Examples
    --------
    ``identification/data/ascent-default.yml`` is :data:`DEFAULT_ASCENT`.
    """
    from rocketroll_common.specs import load_yaml, place, validated

    where = os.fspath(path)
    document, lines = load_yaml(path)
    doc = validated(AscentDocument, document, where, lines)

    def at(key: str) -> str:
        return place(where, lines, (key,))

    values = doc.model_dump(exclude={"thrust_curve"})
    try:
        return AscentSpec(
            thrust_time_s=tuple(pair[0] for pair in doc.thrust_curve),
            thrust_n=tuple(pair[1] for pair in doc.thrust_curve),
            **values,
        )
    except SettingError as exc:
        name, _, knot = exc.setting.removeprefix("AscentSpec.").partition("[")
        if name.startswith("thrust_"):
            part = "times" if name == "thrust_time_s" else "thrusts"
            part += f" (pair {knot.rstrip(']')})" if knot else ""
            raise UsageError(f"{at('thrust_curve')}: thrust_curve {part}: {exc.problem}") from None
        raise UsageError(f"{at(name)}: {name}: {exc.problem}") from None


def load_profile_csv(
    path: str | os.PathLike[str], *, launch_altitude_m: float = 0.0
) -> FlightProfile:
    """A :class:`FlightProfile` from a recorded airspeed log (CSV).

    Parameters
    ----------
    path : str or path-like
        Comma-separated text with a header row naming the columns ``time_s``
        and ``airspeed_mps`` (m/s, ≥ 0) and optionally ``altitude_m``
        (geopotential m above sea level).  Other columns are ignored; blank
        lines and lines starting with ``#`` are skipped.  Times increase
        strictly; at least two rows.
    launch_altitude_m : float
        Altitude of the first sample, m, when the file has no ``altitude_m``.

    Returns
    -------
    FlightProfile
        Without ``altitude_m`` the altitude is the cumulative trapezoid of the
        airspeed (a vertical flight) from ``launch_altitude_m``; density, ``q``
        and Mach from :func:`isa` at that altitude; mass and burnout NaN;
        apogee the highest sample.

    Raises
    ------
    UsageError
        Naming the file and, for a bad cell, its line: a missing column, a
        cell that is not a number, a time that does not increase, a negative
        airspeed, an altitude outside the ISA's range.
    """
    from scipy.integrate import cumulative_trapezoid

    where = os.fspath(path)
    try:
        with open(path, encoding="utf-8", newline="") as handle:
            reader = csv.reader(handle)
            raw = [(reader.line_num, row) for row in reader]  # line_num: where the row ends
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UsageError(f"{where}: cannot read: {exc}") from exc
    rows = [(n, r) for n, r in raw if r and any(c.strip() for c in r)]
    rows = [(n, r) for n, r in rows if not r[0].lstrip().startswith("#")]
    if not rows:
        raise UsageError(f"{where}: empty: expected a header row with time_s,airspeed_mps")
    header_line, header = rows[0]
    names = [cell.strip() for cell in header]
    for name in ("time_s", "airspeed_mps"):
        if name not in names:
            raise UsageError(
                f"{where}:{header_line}: missing column {name!r} (header: {', '.join(names)})"
            )
    wanted = [c for c in ("time_s", "airspeed_mps", "altitude_m") if c in names]
    for name in wanted:
        if names.count(name) > 1:
            raise UsageError(f"{where}:{header_line}: column {name!r} appears more than once")
    index = {name: names.index(name) for name in wanted}
    data: dict[str, list[float]] = {name: [] for name in wanted}
    lines = []
    for lineno, row in rows[1:]:
        if len(row) != len(names):
            raise UsageError(
                f"{where}:{lineno}: {len(row)} cells for the header's {len(names)} columns"
            )
        for name in wanted:
            cell = row[index[name]]
            try:
                value = parse_number(cell)
            except ValueError:
                raise UsageError(f"{where}:{lineno}: {name} is {cell!r}, not a number") from None
            if not math.isfinite(value):
                raise UsageError(f"{where}:{lineno}: {name} is {cell.strip()}, not finite")
            data[name].append(value)
        lines.append(lineno)
    if len(lines) < 2:
        raise UsageError(f"{where}: needs at least 2 data rows, has {len(lines)}")
    t = np.asarray(data["time_s"])
    speed = np.asarray(data["airspeed_mps"])
    for k in np.flatnonzero(np.diff(t) <= 0)[:1]:
        raise UsageError(
            f"{where}:{lines[k + 1]}: time_s {t[k + 1]:g} does not increase (previous {t[k]:g})"
        )
    for k in np.flatnonzero(speed < 0)[:1]:
        raise UsageError(f"{where}:{lines[k]}: airspeed_mps {speed[k]:g} is negative")
    if "altitude_m" in data:
        altitude = np.asarray(data["altitude_m"])
        origin = f"{where} (time_s, airspeed_mps, altitude_m)"
    else:
        start = _finite("launch_altitude_m", launch_altitude_m)
        altitude = start + cumulative_trapezoid(speed, t, initial=0.0)
        origin = f"{where} (time_s, airspeed_mps; altitude integrated from {start:g} m)"
    outside = (altitude < ISA_MIN_ALTITUDE_M) | (altitude > ISA_MAX_ALTITUDE_M)
    for k in np.flatnonzero(outside)[:1]:
        raise UsageError(
            f"{where}:{lines[k]}: altitude {altitude[k]:g} m is outside the standard "
            f"atmosphere's range [{ISA_MIN_ALTITUDE_M:g}, {ISA_MAX_ALTITUDE_M:g}] m"
        )
    return recorded_profile(t, speed, altitude, f"recorded: {origin}")


def recorded_profile(
    t_s: ArrayLike, airspeed_mps: ArrayLike, altitude_m: ArrayLike, source: str
) -> FlightProfile:
    """A :class:`FlightProfile` of a logged flight: its times, airspeed (m/s) and altitude
    above sea level (m), checked by the caller; density, ``q`` and Mach from :func:`isa`;
    mass and burnout unknown (NaN); apogee the highest sample."""
    t = np.asarray(t_s, dtype=float)
    speed = np.asarray(airspeed_mps, dtype=float)
    altitude = np.asarray(altitude_m, dtype=float)
    air = isa(altitude)
    density = np.asarray(air.density_kgm3)
    top = int(np.argmax(altitude))
    return FlightProfile(
        t_s=t,
        altitude_m=altitude,
        airspeed_mps=speed,
        mass_kg=np.full(t.shape, np.nan),
        density_kgm3=density,
        dynamic_pressure_pa=0.5 * density * speed**2,
        mach=speed / np.asarray(air.speed_of_sound_mps),
        burnout_s=math.nan,
        apogee_s=float(t[top]),
        apogee_m=float(altitude[top]),
        max_speed_mps=float(speed.max()),
        source=source,
    )


# --------------------------------------------------------------------------- figure
def plot_profile(profile: FlightProfile) -> Figure:
    """The profile in four panels sharing the time axis: V, h, q and Mach.

    Parameters
    ----------
    profile : FlightProfile

    Returns
    -------
    matplotlib.figure.Figure
        On a headless Agg canvas (:mod:`rocketroll_common.plotting`): four axes
        (airspeed in km/h with m/s on a secondary scale, altitude in m,
        dynamic pressure in kPa, Mach), dashed lines at burnout (when known)
        and apogee.  Save it with :func:`rocketroll_common.plotting.png_bytes`.
    """
    from rocketroll_common.plotting import new_figure

    if not isinstance(profile, FlightProfile):
        raise UsageError(f"profile: must be a FlightProfile, not {type(profile).__name__}")
    fig = new_figure(figsize=(7.5, 8.0), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True)
    t = profile.t_s
    panels = (
        (profile.airspeed_mps * 3.6, "airspeed V (km/h)"),
        (profile.altitude_m, "altitude h (m)"),
        (profile.dynamic_pressure_pa / 1000.0, "dynamic pressure q (kPa)"),
        (profile.mach, "Mach"),
    )
    for ax, (values, label) in zip(axes, panels, strict=True):
        ax.plot(t, values, color="C0", lw=1.5)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        marks = [(profile.burnout_s, "burnout", "C1"), (profile.apogee_s, "apogee", "C2")]
        for when, name, color in marks:
            if math.isfinite(when):
                ax.axvline(when, color=color, ls="--", lw=1.0, label=name)
    axes[0].secondary_yaxis("right", functions=(lambda x: x / 3.6, lambda x: x * 3.6)).set_ylabel(
        "m/s"
    )
    axes[0].legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(
        f"Flight profile: max {profile.max_speed_mps * 3.6:.0f} km/h, apogee "
        f"{profile.apogee_m:.0f} m, max Mach {profile.max_mach:.2f}\n{profile.source}",
        fontsize="medium",
    )
    return fig


# --------------------------------------------------------------------------- by name
def flight_profile(name: str, descent_s: float = 0.0) -> FlightProfile:
    """The ascent called ``name``: ``"default"`` (:data:`DEFAULT_ASCENT` simulated) or
    another of :data:`NAMED_ASCENTS` (``"supersonic"``), a rocket-and-motor YAML
    (``.yml``/``.yaml``, :func:`load_ascent_yaml`, simulated) or a recorded ``V(t)`` CSV
    (:func:`load_profile_csv`).  Cached per file state.

    ``descent_s`` flies a simulated ascent on past apogee (:func:`simulate_ascent`).

    Raises
    ------
    ValueError
        ``flight: NAME: problem`` for a name that is none of these, a file that
        cannot be read (the loaders' own errors for a bad file), or a descent asked of
        a recorded profile.
    """
    if name in NAMED_ASCENTS:
        return _profile(name, 0, 0, descent_s)
    check_ascent_name(name, descent_s)
    path = Path(name)
    try:
        stat = os.stat(path)
    except OSError as exc:
        raise ValueError(f"flight: {name}: {exc.strerror or 'cannot be read'}") from None
    return _profile(str(path.resolve()), stat.st_mtime_ns, stat.st_size, descent_s)


def check_ascent_name(name: str, descent_s: float = 0.0) -> None:
    """Refuse (``ValueError``, as :func:`flight_profile` words it) an ascent ``name`` that is
    none of :data:`NAMED_ASCENTS` nor an existing ``.yml``/``.yaml``/``.csv`` file, or a
    descent asked of a recorded profile; reads and simulates nothing."""
    if name in NAMED_ASCENTS:
        return
    path = Path(name)
    if path.suffix.lower() not in (".yml", ".yaml", ".csv"):
        raise ValueError(
            f"flight: {name!r} is none of {', '.join(map(repr, NAMED_ASCENTS))}, a .yml/.yaml "
            "rocket or a .csv profile"
        )
    if descent_s > 0.0 and path.suffix.lower() == ".csv":
        raise ValueError(
            f"flight: {name}: a recorded profile ends where its log ends; a descent past "
            "apogee needs a simulated ascent (default or a rocket YAML)"
        )
    if not path.is_file():
        raise ValueError(f"flight: {name}: no such file")


@functools.lru_cache(maxsize=8)
def _profile(name: str, mtime_ns: int, size: int, descent_s: float = 0.0) -> FlightProfile:
    del mtime_ns, size  # the cache key: a changed file is read again
    if name in NAMED_ASCENTS:
        return simulate_ascent(NAMED_ASCENTS[name], descent_s=descent_s)
    if name.lower().endswith(".csv"):
        return load_profile_csv(name)
    return simulate_ascent(load_ascent_yaml(name), descent_s=descent_s)
