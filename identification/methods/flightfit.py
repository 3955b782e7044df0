"""Identification of a flight: the roll model at a reference airspeed, from a changing one.

The paper identifies ``a`` and ``α`` at the tunnel's one airspeed (§4) and
names the way to flight: identify the coefficients of eq. 7-8 (``C_P``,
``C_δ``) instead of the lumped ``a``, ``α``, so that the dynamic pressure of
eq. 5 carries them to any airspeed.  This module does that for a recording
with an ``airspeed_mps`` column (format 1.1): it estimates the model **at a
reference airspeed** ``V_ref`` and density ``ρ_ref`` (default: the tunnel's
50 km/h at ISA sea level) with the flight's scaling (eq. 4-8,
:func:`rocketroll_physics.scaling.roll_scales`)::

    α(t) = α₀·V/V_ref,     a(θ, t) = (ᾱ₀·|θ + θ̄| + β̄₀)·ρV/(ρ_ref·V_ref)

so ``β̄₀/(ρ_ref·V_ref)`` is ``S·d²·|C_P|/(4·I)`` and ``β̄₀·α₀/q_ref`` is
``S·d·C_δ/I``: the ``C_P``- and ``C_δ``-like coefficients, reported as such.

Method: maximum likelihood with a Kalman filter on the estimation core
(:mod:`identification.estimation.likelihood`, as :mod:`identification.methods.ml`); the
``flight`` method that runs it on a flight's window and judges it is
:mod:`identification.methods.flight`.  The state is the roll rate ``v``, the roll angle
``φ`` and the turbulence ``w``; the rocket moves by the exact update of
:mod:`identification.model` with the scales of each substep; the turbulence
is the physics of :mod:`rocketroll_physics.flown` and :mod:`rocketroll_physics.dryden`
made a prior: a field frozen in the air (Taylor) that the rocket flies
through, an Ornstein-Uhlenbeck process in *tunnel time* ``τ = ∫V/V_ref dt``
(so its correlation time in flight shrinks like ``V_ref/V``) of SD ``σ_w``
and time constant ``T``, whose flow angle shrinks like ``V_ref/V``::

    u_d = (V_ref / max(V, V_ref)) · w̄,        w̄ = the average of w over the sample interval

(the average exactly, :mod:`rocketroll_physics.ou`).  Above ``V_ref`` the
Dryden gust (``α·u_d = p_g``, an OU process of time constant ``4b/(πV)``:
constant in tunnel time) has this form, its intensity changing with height
and airspeed where the prior's is stationary (``benchmarks/flight_ground_truth.py``
measures what that costs); below ``V_ref`` the prior holds the flow angle's
scale at the tunnel's, which the gust does not (``rocketroll record-flight`` logs
only above ``V_ref``).  Measured: a rate gyro with the multiplicative noise of eq. 52 plus
an additive floor (both estimated), or, without a gyro, the encoder angle
with its quantisation.  The likelihood of the innovations is maximised over
``α₀, θ̄, β̄₀`` (and ``ᾱ₀``), ``σ_w, T`` and the sensor noise by L-BFGS-B; the
Rauch-Tung-Striebel smoother gives ``u_d(t)``, and the model driven by it is
re-simulated against the measured rate (§3.5).

Assumptions, documented: constant ``C_P``, ``C_δ`` and inertia (subsonic,
§4); θ̄ does not change with airspeed; ᾱ and β̄ scale together; the density
is the ISA's at ``altitude_m`` (without that column: ``ρ_ref`` throughout);
the turbulence has mean zero (a mean is indistinguishable from θ̄, as in
the tunnel).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import optimize

from identification import compiled
from identification.compiled import linkage_path
from identification.estimation import statespace
from identification.estimation.likelihood import (
    StateSpaceFit,
    covariance,
    maximise,
    negloglike,
    numerical_hessian,
    posterior_states,
    profile_interval,
    profile_step,
    standard_errors,
    standing_interval,
)
from identification.estimation.statespace import LinearGaussian
from identification.methods.steps import IdentificationError
from identification.model import (
    Rig,
    RollParams,
    Servo,
    SimResult,
    servo_path,
    simulate,
)
from identification.recordings.flight import mean_airspeed, site_elevation
from identification.recordings.recording import Recording, quantum_of
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_physics.atmosphere import ISA_SEA_LEVEL_DENSITY_KGM3, isa
from rocketroll_physics.ou import interval_coefficients
from rocketroll_physics.scaling import (
    EQ_4_8,
    MACH_LIMIT,
    TUNNEL_AIRSPEED_MPS,
    AirspeedScaling,
    roll_scales,
)

if TYPE_CHECKING:
    pass

__all__ = [
    "EQ_4_8_TEST_SIZE",
    "LOG_BOUND",
    "MACH_LIMIT",
    "MIN_DAMPING",
    "SUBSTEPS",
    "FlightFit",
    "FlightInputs",
    "c_coefficients",
    "eq_4_8_test",
    "flight_inputs",
    "identify_flight",
    "identify_flights",
    "measured_rate",
    "rescale",
    "resimulated",
]

#: Exact-update substeps per sample interval (the servo ramp is resolved exactly within each).
SUBSTEPS = 4
#: Smallest damping a(θ) the fit may give anywhere on the flown fin angles, 1/s.
MIN_DAMPING = 1e-3
#: Below this tunnel time per interval (s) the air does not move the field past the rocket.
_STILL = 1e-9
#: Bound on the optimiser's log-parameters (exp(±50) is beyond any physical value).
LOG_BOUND = 50.0
#: Airspeed, as a fraction of the tunnel's, below which the fins have next to no authority.
MIN_AIRSPEED_FRACTION = 0.1
#: Intervals at or above that airspeed a flight needs before it is identified.
MIN_MOVING_INTERVALS = 100
#: The airspeed the turbulence's prior is stated at, m/s: its flow angle holds the tunnel's
#: scale below it and shrinks like ``V_TURB/V`` above, in tunnel time ``∫V/V_TURB dt``.
TURBULENCE_FRAME_MPS = TUNNEL_AIRSPEED_MPS
#: The range the measured exponents ``n`` and ``m`` are searched in.
EXPONENT_BOUNDS = (0.0, 4.0)
#: Size of the likelihood-ratio test of eq. 4-8's exponents (``n = 2``, ``m = 1``).
EQ_4_8_TEST_SIZE = 0.05


@dataclass(frozen=True, eq=False)
class FlightInputs:
    """A flight recording made ready for the filter (:func:`flight_inputs`).

    Attributes
    ----------
    recording : Recording
        The data.
    dt_s : float
        Sample interval, s.
    theta : ndarray, shape (n·SUBSTEPS + 1,)
        Fin angle at the substep edges, ° (the servo of eq. 23 on the commands,
        or the measured fin angle, linear between samples).
    rate_limit_dps : float or None
        The servo's rate (None with a measured fin angle).
    speed_ratio, density_ratio : ndarray, shape (n·SUBSTEPS,)
        ``V/V_ref`` and ``ρ/ρ_ref`` at each substep's midpoint (:meth:`scales`).
    u_per_w : ndarray, shape (n,)
        ``V_T/max(V, V_T)`` at each interval's midpoint: ``u_d`` per unit ``w̄``
        (``V_T`` the turbulence's frame, :data:`TURBULENCE_FRAME_MPS`).
    tunnel_dt_s : ndarray, shape (n,)
        Tunnel time that passes in each interval, ∫V/V_T dt, s.
    rate : ndarray or None
        Gyro roll rate at the samples, °/s.
    angle : ndarray or None
        Roll angle at the samples, ° (used only without a gyro).
    quantum_deg : float
        The angle's quantisation step, ° (0 if none is seen).
    density : str
        Where the flight's air density came from (the ISA density at the logged altitude, or
        ``rho_ref_kgm3`` throughout without one).
    v_ref_mps, rho_ref_kgm3 : float
        The reference the coefficients are given at (by default the airspeed's mean over
        the flight: the coefficients there and the measured exponents are then as little
        correlated as the flight allows).
    """

    recording: Recording
    dt_s: float
    theta: FloatArray
    rate_limit_dps: float | None
    speed_ratio: FloatArray
    density_ratio: FloatArray
    u_per_w: FloatArray
    tunnel_dt_s: FloatArray
    rate: FloatArray | None
    angle: FloatArray | None
    quantum_deg: float
    density: str
    v_ref_mps: float
    rho_ref_kgm3: float
    rig: Rig = field(default_factory=Rig)

    @property
    def n(self) -> int:
        """Number of sample intervals."""
        return int(self.u_per_w.size)

    def scales(self, scaling: AirspeedScaling = EQ_4_8) -> tuple[FloatArray, FloatArray]:
        """The gain's and the damping's factors at each substep's midpoint for
        ``scaling`` (:func:`~rocketroll_physics.scaling.roll_scales`)."""
        return roll_scales(self.speed_ratio, self.density_ratio, 1.0, 1.0, scaling)


def flight_inputs(
    recording: Recording,
    *,
    v_ref_mps: float | None = None,
    rho_ref_kgm3: float = ISA_SEA_LEVEL_DENSITY_KGM3,
    servo_rate_dps: float = Servo().rate_limit_dps,
    rig: Rig | None = None,
) -> FlightInputs:
    """The fin path, the scales and the measurements of a flight recording.

    ``rig`` (default: the recording's own, its ``rig.*`` lines) shapes the fin the model
    sees as :func:`identification.methods.pipeline.measurements` does for a tunnel run: the
    commanded fin through its linkage, and the fin delayed by its sensors' latency.

    The substep grid follows the recorded timestamps (each sample interval cut
    into :data:`SUBSTEPS` equal parts), so a logger's jitter does not slide the
    fin angle and the airspeed against the roll measurements.  ``v_ref_mps``: the
    reference airspeed of the coefficients (default: the airspeed's mean over the
    recording, rounded to 0.1 m/s).

    Raises
    ------
    IdentificationError
        If the recording has no airspeed (not a flight), or flies slower than
        :data:`MIN_AIRSPEED_FRACTION` of the tunnel's on all but fewer than
        :data:`MIN_MOVING_INTERVALS` intervals (the fins move nothing there).
    """
    rig = recording.rig if rig is None else rig
    if recording.airspeed_mps is None:
        raise IdentificationError(
            f"recording {recording.name!r} has no airspeed_mps column: not a flight "
            "(identify it with the tunnel's methods: paper, output-error, ml)"
        )
    time = np.asarray(recording.time_s)
    if v_ref_mps is None:
        v_ref_mps = mean_airspeed([recording])
    if not (math.isfinite(v_ref_mps) and v_ref_mps > 0):
        raise IdentificationError(f"v_ref_mps must be > 0, not {v_ref_mps!r}")
    n = time.size - 1
    dt = recording.dt_s
    h = dt / SUBSTEPS
    fine = np.interp(np.arange(n * SUBSTEPS + 1) / SUBSTEPS, np.arange(n + 1), time)
    middle = 0.5 * (fine[1:] + fine[:-1])
    speed = np.asarray(recording.airspeed_mps)
    speed_mid = 0.5 * (speed[1:] + speed[:-1])
    slow = MIN_AIRSPEED_FRACTION * TURBULENCE_FRAME_MPS
    moving = int(np.count_nonzero(speed_mid >= slow))
    if moving < MIN_MOVING_INTERVALS:
        raise IdentificationError(
            f"recording {recording.name!r}: the airspeed reaches "
            f"{MIN_AIRSPEED_FRACTION:.0%} of the tunnel's ({slow:.3g} m/s) "
            f"on only {moving} of {n} intervals (at least {MIN_MOVING_INTERVALS} needed): "
            "the fins move the rocket too little there to identify it "
            f"(max airspeed {float(speed.max()):.3g} m/s)"
        )
    if recording.altitude_m is not None:
        site = site_elevation(recording)
        density = np.asarray(
            isa(np.interp(middle, time, recording.altitude_m) + site).density_kgm3, dtype=float
        )
        above = f" + the site's {site:g} m" if site else ""
        source = f"the ISA density at the logged altitude{above}, at each instant"
    else:
        density = np.full(middle.size, rho_ref_kgm3)
        source = "ρ_ref throughout, no altitude logged"
    if recording.fin_deg is not None:
        theta = np.interp(fine, time, recording.fin_deg)
        rate_limit = None
    else:
        assert recording.fin_cmd_deg is not None
        command = np.asarray(recording.fin_cmd_deg)
        servo = Servo(rate_limit_dps=servo_rate_dps)
        held = np.repeat(command[:-1], SUBSTEPS)
        if rig.linkage.direct:
            theta = servo_path(held, float(command[0]), h, servo)
        else:
            theta = linkage_path(held, float(command[0]), h, servo, rig.linkage)
        rate_limit = servo_rate_dps
    if rig.latency_s > 0.0:  # late sensors read the rocket the fin drove that long before
        theta = np.interp(fine - rig.latency_s, fine, theta)
    rate = None if recording.roll_rate_dps is None else np.asarray(recording.roll_rate_dps)
    angle = None if recording.roll_deg is None else np.asarray(recording.roll_deg)
    return FlightInputs(
        recording=recording,
        dt_s=dt,
        theta=theta,
        rate_limit_dps=rate_limit,
        speed_ratio=np.interp(middle, time, speed) / v_ref_mps,
        density_ratio=density / rho_ref_kgm3,
        u_per_w=TURBULENCE_FRAME_MPS / np.maximum(speed_mid, TURBULENCE_FRAME_MPS),
        tunnel_dt_s=speed_mid / TURBULENCE_FRAME_MPS * np.diff(time),
        rate=rate,
        angle=angle,
        quantum_deg=0.0 if angle is None else quantum_of(angle),
        density=source,
        v_ref_mps=v_ref_mps,
        rho_ref_kgm3=rho_ref_kgm3,
        rig=rig,
    )


def interval_maps(
    inputs: FlightInputs, params: RollParams, scaling: AirspeedScaling = EQ_4_8
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The exact update over each sample interval with ``u_d = u_per_w·w̄`` held::

        v1 = E·v0 + C0 + C1·w̄,     φ1 = φ0 + A·v0 + B0 + B1·w̄

    composed from the :data:`SUBSTEPS` substeps, each with its airspeed's scales
    (:func:`identification.compiled.interval_maps`, the maximum-likelihood method's).
    """
    gain, damping = inputs.scales(scaling)
    maps = compiled.interval_maps(
        params,
        inputs.theta,
        SUBSTEPS,
        inputs.dt_s / SUBSTEPS,
        gain=gain,
        damping=damping,
        rate_limit_dps=inputs.rate_limit_dps,
    )
    e, per_u, c0, a, per_u_angle, b0 = maps.T
    return e, c0, per_u * inputs.u_per_w, a, b0, per_u_angle * inputs.u_per_w


@dataclass(frozen=True)
class _FlightParameterMap:
    """Which parameters are free, in the optimiser's coordinates: a log for those that
    are positive; those not free are held at :data:`_FIXED` (or ``scaling``'s exponents)."""

    theta_model: bool
    gyro: bool
    #: The exponents held, or None where they are measured.
    scaling: AirspeedScaling | None = EQ_4_8
    #: Whether the gyro's constant bias is estimated (held at 0 otherwise).
    gyro_bias: bool = False

    @property
    def names(self) -> tuple[str, ...]:
        core = ("log_beta_bar", "alpha", "theta_bar") + (("alpha_bar",) if self.theta_model else ())
        exponents = ("torque_exponent", "damping_exponent") if self.scaling is None else ()
        noise: tuple[str, ...] = (
            ("log_gyro_rel", "log_gyro_abs") if self.gyro else ("log_angle_sd",)
        )
        noise += ("gyro_bias",) if self.gyro and self.gyro_bias else ()
        return (*core, *exponents, "log_sigma_w", "log_tau", *noise)

    @property
    def bounds(self) -> list[tuple[float | None, float | None]]:
        """L-BFGS-B's bounds: the exponents' range, the logs' :data:`LOG_BOUND`."""
        return [
            EXPONENT_BOUNDS
            if name.endswith("_exponent")
            else (-LOG_BOUND, LOG_BOUND)
            if name.startswith("log_")
            else (None, None)
            for name in self.names
        ]

    def natural(self, x: FloatArray) -> dict[str, float]:
        values = dict(zip(self.names, (float(v) for v in x), strict=True))
        held = self.scaling or EQ_4_8
        nat = {
            **_FIXED,
            "torque_exponent": held.torque_exponent,
            "damping_exponent": held.damping_exponent,
        }
        for name, value in values.items():
            if name.startswith("log_"):
                nat[name[4:]] = math.exp(min(max(value, -LOG_BOUND), LOG_BOUND))
            else:
                nat[name] = value
        return nat

    def vector(self, nat: dict[str, float]) -> FloatArray:
        values = {**_FIXED, **_NOISE_STARTS, **nat}
        return np.array(
            [
                math.log(values[name[4:]]) if name.startswith("log_") else values[name]
                for name in self.names
            ]
        )


#: The parameters' values where a parameter map does not free them (the sensor a recording lacks
#: has no noise).
_FIXED = {"alpha_bar": 0.0, "gyro_rel": 0.0, "gyro_abs": 0.0, "gyro_bias": 0.0, "angle_sd": 0.0}
#: The sensor noises' starts.
_NOISE_STARTS = {"gyro_rel": 0.01, "gyro_abs": 0.1, "angle_sd": 0.01}


def _scaling(nat: dict[str, float]) -> AirspeedScaling:
    return AirspeedScaling(nat["torque_exponent"], nat["damping_exponent"])


def _params(nat: dict[str, float]) -> RollParams | None:
    if nat["alpha"] == 0.0:
        return None
    return RollParams(nat["alpha"], nat["theta_bar"], nat["beta_bar"], nat["alpha_bar"])


def _system(inputs: FlightInputs, nat: dict[str, float]) -> LinearGaussian | None:
    """The flight as a linear Gaussian state-space model
    (:mod:`identification.estimation.statespace`) of the roll rate, the angle and the
    turbulence ``w``, its system matrices changing with every interval's airspeed; None where
    ``nat`` is not a rocket (α 0, or a damping below :data:`MIN_DAMPING` on the flown fins)."""
    params = _params(nat)
    if params is None:
        return None
    if nat["alpha_bar"] != 0.0:
        low = nat["beta_bar"] + nat["alpha_bar"] * float(
            np.max(np.abs(inputs.theta + nat["theta_bar"])) if nat["alpha_bar"] < 0 else 0.0
        )
        if low < MIN_DAMPING:
            return None
    e, c0, c1, a, b0, b1 = interval_maps(inputs, params, _scaling(nat))
    tau = nat["tau"]
    sigma = nat["sigma_w"]
    moving = inputs.tunnel_dt_s > _STILL
    u = np.where(moving, inputs.tunnel_dt_s / tau, 1.0)
    phi, a1, mean, l21, l22 = interval_coefficients(u)
    phi = np.where(moving, phi, 1.0)
    mean = np.where(moving, mean, 1.0)
    a1, l21, l22 = (np.where(moving, x, 0.0) for x in (a1, l21, l22))
    n = inputs.n
    trans = np.zeros((n + 1, 3, 3))  # the last, after the last sample, is not used
    trans[:n, 0, 0] = e
    trans[:n, 0, 2] = c1 * mean
    trans[:n, 1, 0] = a
    trans[:, 1, 1] = 1.0
    trans[:n, 1, 2] = b1 * mean
    trans[:n, 2, 2] = phi
    offset = np.zeros((n + 1, 3))
    offset[:n, 0] = c0
    offset[:n, 1] = b0
    # The state's shocks: two standard normals per interval (the turbulence's innovation
    # and the part of its interval average that the innovation does not explain).
    noise = np.zeros((n + 1, 3, 2))
    noise[:n, 0, 0] = c1 * sigma * l21
    noise[:n, 0, 1] = c1 * sigma * l22
    noise[:n, 1, 0] = b1 * sigma * l21
    noise[:n, 1, 1] = b1 * sigma * l22
    noise[:n, 2, 0] = sigma * a1
    x0 = np.zeros(3)
    p0 = np.diag([1e4, 1e4, sigma**2])
    if inputs.rate is not None:
        y = inputs.rate - nat["gyro_bias"]
        variance = nat["gyro_abs"] ** 2 + (nat["gyro_rel"] * inputs.rate) ** 2
        observed = np.array([0])
        x0[0] = y[0]
        p0[1, 1] = 1.0  # the angle is not measured: its start does not matter
    else:
        assert inputs.angle is not None
        y = inputs.angle - inputs.angle[0]
        variance = np.full(y.size, inputs.quantum_deg**2 / 12.0 + nat["angle_sd"] ** 2)
        observed = np.array([1])
        p0[1, 1] = variance[0]
    return LinearGaussian(
        y=y[:, None],
        observed=observed,
        obs_var=variance[:, None],
        transition=trans,
        intercept=offset,
        state_cov=noise @ np.swapaxes(noise, 1, 2),
        initial_mean=x0,
        initial_cov=p0,
    )


@dataclass(frozen=True)
class _Flights:
    """Flights of one rocket as the estimation core fits them: the sum of each flight's
    Kalman-filter log-likelihood (``-inf`` where the parameters are no rocket)."""

    flights: Sequence[FlightInputs]
    parameters: _FlightParameterMap

    def loglike(self, nat: dict[str, Any]) -> float:
        low, high = EXPONENT_BOUNDS
        if not all(math.isfinite(v) for v in nat.values()) or not all(
            low <= nat[k] <= high for k in ("torque_exponent", "damping_exponent")
        ):
            return -math.inf
        total = 0.0
        for inputs in self.flights:
            system = _system(inputs, nat)
            if system is None:
                return -math.inf
            total += statespace.loglike(system)
        return total


def measured_rate(inputs: FlightInputs) -> FloatArray:
    """The roll rate the recording measured, °/s at the samples: the gyro, or the angle
    differenced and smoothed (a start for the fit, and what a re-simulation is held to)."""
    if inputs.rate is not None:
        return inputs.rate
    assert inputs.angle is not None
    kernel = np.ones(5) / 5.0
    smooth = np.convolve(np.pad(inputs.angle, 2, mode="edge"), kernel, mode="valid")
    return np.gradient(smooth, inputs.dt_s)


def _equation_error_start(flights: Sequence[FlightInputs]) -> dict[str, float]:
    """Least squares of ``dv/dt = −β̄₀·d·v + β̄₀α₀·d·g·θ + β̄₀α₀θ̄·d·g`` over the flights'
    samples together: the optimiser's start."""
    designs, slopes, steps = [], [], []
    for inputs in flights:
        rate = measured_rate(inputs)
        kernel = np.ones(3) / 3.0
        smooth = np.convolve(np.pad(rate, 1, mode="edge"), kernel, mode="valid")
        slopes.append(np.gradient(smooth, inputs.dt_s))
        at = slice(0, None, SUBSTEPS)
        theta = inputs.theta[at]
        gains, dampings = inputs.scales()
        gain = np.append(gains[at], gains[-1])
        damping = np.append(dampings[at], dampings[-1])
        designs.append(np.column_stack([-damping * smooth, damping * gain * theta, damping * gain]))
        steps.append(np.full(smooth.size, inputs.dt_s))
    design, slope, dt = np.concatenate(designs), np.concatenate(slopes), np.concatenate(steps)
    coef, *_ = np.linalg.lstsq(design, slope, rcond=None)
    beta_bar = float(coef[0]) if coef[0] > MIN_DAMPING else 1.0
    alpha = float(coef[1] / beta_bar) if coef[1] != 0 else 1.0
    theta_bar = float(coef[2] / (beta_bar * alpha))
    resid = slope - design @ coef
    # the third column is d·g: the scale of the turbulence's torque per degree
    scale = np.maximum(design[:, 2] * beta_bar * abs(alpha), 1e-6)
    sigma = float(np.clip(np.std(resid / scale * np.sqrt(dt)), 0.05, 30.0))
    return {"beta_bar": beta_bar, "alpha": alpha, "theta_bar": theta_bar, "sigma_w": sigma}


#: The turbulence time constants (tunnel s) and SDs (°) the likelihood is surveyed on for a start.
_START_TAUS = np.geomspace(0.005, 5.0, 13)
_START_SIGMAS = np.geomspace(0.3, 300.0, 10)


def _turbulence_starts(
    flights: Sequence[FlightInputs], pmap: _FlightParameterMap, rough: dict[str, float]
) -> list[dict[str, float]]:
    """Two starts for the optimiser: the rocket of the equation-error fit with the
    turbulence ``(T, σ_w)`` of the best likelihood on a grid over four decades of ``T``,
    and the best at least a decade of ``T`` away from it.

    The likelihood has a second optimum where a slow turbulence (``T`` of seconds)
    passes for the rocket's own response with a damping many times the true one; a
    fixed start falls into it on some flights (half of ten Dryden flights did), a
    survey of a hundred Kalman passes (a fraction of a second) does not.
    """
    model = _Flights(flights, pmap)
    rows = []
    for tau in _START_TAUS:
        values = [
            negloglike(model, pmap.vector({**rough, "tau": tau, "sigma_w": sd}))
            for sd in _START_SIGMAS
        ]
        j = int(np.argmin(values))
        rows.append((values[j], float(tau), float(_START_SIGMAS[j])))
    first = min(rows)
    apart = [row for row in rows if abs(math.log10(row[1] / first[1])) >= 1.0]
    chosen = [first] + ([min(apart)] if apart else [])
    return [{**rough, "tau": tau, "sigma_w": sd} for _, tau, sd in chosen]


@dataclass(frozen=True, eq=False, kw_only=True)
class FlightFit(StateSpaceFit):
    """The maximum-likelihood fit of one damping model to a flight (:func:`identify_flight`):
    a :class:`~identification.estimation.likelihood.StateSpaceFit` (its ``params`` the
    rocket at ``v_ref_mps`` and ``rho_ref_kgm3``, ``u_d_deg`` the flight's equivalent fin
    angle per sample interval) with the flight's own figures.

    Attributes
    ----------
    turbulence_sd_deg : float
        ``σ_w`` (°): the turbulence's intensity, stationary along the flight.
    turbulence_tau_s : float
        Its time constant ``T``, tunnel seconds.
    gyro_noise_pct, gyro_floor_dps : float or None
        The gyro's estimated relative noise (%, eq. 52) and additive floor.
    std_errors : dict
        Asymptotic standard errors of α, θ̄, β̄ (and ᾱ) from the inverse Hessian.
    rate_dps : ndarray, shape (n + 1,)
        Posterior mean of the roll rate at the samples, °/s.
    estimates : dict
        Every maximised parameter in natural units (the model's, the exponents,
        ``sigma_w``, ``tau`` and the sensor's noise and bias), as a start for a richer model.
    inputs : FlightInputs
        What was fitted.
    flights : int
        How many flights were fitted together (:func:`identify_flights`).
    scaling : AirspeedScaling
        The airspeed scaling of the model: measured, or held (eq. 4-8 unless another was given).
    scaling_measured : bool
        Whether ``scaling`` was estimated (its standard errors are then in
        ``std_errors`` as ``torque_exponent`` and ``damping_exponent``).
    eq_4_8_test : dict or None
        The likelihood-ratio test of eq. 4-8's exponents against the measured ones
        (:func:`eq_4_8_test`), where they were measured.
    gyro_bias_dps : float or None
        The gyro's estimated constant bias, °/s.
    intervals : dict
        A 95 % interval of each reported parameter and of the fin torque per dynamic
        pressure ``torque_per_q`` (:func:`flight_intervals`), each saying whether the
        flight determines it.
    """

    turbulence_sd_deg: float
    turbulence_tau_s: float
    gyro_noise_pct: float | None
    gyro_floor_dps: float | None
    rate_dps: FloatArray
    estimates: dict[str, float]
    inputs: FlightInputs
    flights: int = 1
    scaling: AirspeedScaling = EQ_4_8
    scaling_measured: bool = False
    eq_4_8_test: dict[str, Any] | None = None
    gyro_bias_dps: float | None = None
    intervals: dict[str, dict[str, Any]] = field(default_factory=dict)

    def posterior_draws(self, size: int, seed: int = 0) -> FloatArray:
        """``size`` draws of ``u_d`` per sample interval from its posterior given the flight
        (the simulation smoother of :mod:`identification.estimation.statespace`, at the fit's
        estimates), shape (size, n): each a turbulence the rocket may have flown."""
        _, _, _, _, draws = _smoothed(self.inputs, self.estimates, size, seed)
        return np.asarray(self.inputs.u_per_w * draws)

    def resimulate(self) -> dict[str, float]:
        """§3.5 in flight: the model driven by its ``u_d`` from the first sample, open loop.

        Returns the rate's mean and SD absolute error against the measured
        rate (and the angle's against the measured angle), and the rate's MAE
        as a percentage of the mean measured ``|rate|``.
        """
        inp = self.inputs
        sim = resimulated(inp, self.params, self.u_d_deg, float(self.rate_dps[0]), self.scaling)
        measured = measured_rate(inp) - (self.gyro_bias_dps or 0.0)
        error = np.abs(sim.rate_dps - measured)
        out = {
            "resim_rate_mae_dps": float(error.mean()),
            "resim_rate_sd_dps": float(error.std(ddof=1)),
            "resim_rate_mae_pct": float(100.0 * error.mean() / np.mean(np.abs(measured))),
        }
        if inp.angle is not None:
            angle_error = np.abs(sim.angle_deg - inp.angle)
            out["resim_angle_mae_deg"] = float(angle_error.mean())
            out["resim_angle_sd_deg"] = float(angle_error.std(ddof=1))
        return out


def _names(flights: Sequence[FlightInputs]) -> str:
    return ", ".join(repr(inputs.recording.name) for inputs in flights)


def resimulated(
    inputs: FlightInputs,
    params: RollParams,
    u_d_deg: FloatArray,
    rate0_dps: float,
    scaling: AirspeedScaling = EQ_4_8,
) -> SimResult:
    """§3.5 in flight: the model of ``params`` driven by ``u_d_deg`` (per sample interval)
    open loop from the first sample, along the flight's scales for ``scaling``; a
    :class:`~identification.model.SimResult`."""
    rec = inputs.recording
    limit = inputs.rate_limit_dps
    servo = None if limit is None else Servo(rate_limit_dps=limit)
    fin = rec.fin_deg if servo is None else np.asarray(rec.fin_cmd_deg)[:-1]
    gain, damping = inputs.scales(scaling)
    return simulate(
        params,
        inputs.dt_s,
        np.asarray(fin),
        np.asarray(u_d_deg),
        rate0_dps=rate0_dps,
        angle0_deg=0.0 if inputs.angle is None else float(inputs.angle[0]),
        servo=servo,
        theta0_deg=float(inputs.theta[0]),
        substeps=SUBSTEPS,
        gain=gain,
        damping=damping,
    )


def _maximise(
    flights: Sequence[FlightInputs], pmap: _FlightParameterMap, starts: Sequence[dict[str, float]]
) -> optimize.OptimizeResult:
    """The estimation core's L-BFGS-B from each start (:func:`maximise`); the best, or an
    error that says why it is no rocket."""
    best = maximise(_Flights(flights, pmap), starts)
    nat = pmap.natural(best.x)
    if _params(nat) is None or best.fun >= 1e12:
        if not all(math.isfinite(v) for v in nat.values()):
            what = "the parameters left the real numbers"
        elif _params(nat) is None:
            what = "the gain α went to 0"
        elif any(_system(inputs, nat) is None for inputs in flights):
            what = f"the damping a(θ) fell below {MIN_DAMPING:g} 1/s on the flown fin angles"
        else:
            what = "the likelihood is not finite there (the Kalman filter diverged)"
        shown = ", ".join(f"{k} {v:.3g}" for k, v in nat.items() if k in _SHOWN)
        raise IdentificationError(
            f"recording {_names(flights)}: the flight fit failed from {len(starts)} start(s): "
            f"{what} (at {shown}; L-BFGS-B after {best.nit} iterations: "
            f"{best.message or 'no message'})"
        )
    return best


#: The parameters a failed fit's message shows.
_SHOWN = (
    "alpha",
    "theta_bar",
    "beta_bar",
    "alpha_bar",
    "torque_exponent",
    "damping_exponent",
    "sigma_w",
    "tau",
)


def _smoothed(
    inputs: FlightInputs, nat: dict[str, float], draws: int = 0, seed: int = 0
) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Log-likelihood, smoothed rate at the samples, smoothed ``w̄`` per interval, its
    posterior SD and ``draws`` draws of ``w̄`` from its posterior (the simulation smoother,
    seeded)."""
    params = _params(nat)
    system = _system(inputs, nat)
    assert params is not None and system is not None
    smoothed = statespace.smooth(system)
    e, c0, c1, _, _, _ = interval_maps(inputs, params, _scaling(nat))

    def mean_w(states: FloatArray) -> FloatArray:
        # v1 = E·v0 + C0 + C1·w̄ holds exactly in the model, so it holds for the smoothed
        # means and for each posterior draw of the states.
        rate = states[:, 0]
        return np.where(
            np.abs(c1) > 1e-9 * np.maximum(np.abs(rate[1:]), 1.0),
            (rate[1:] - e * rate[:-1] - c0) / np.where(c1 == 0.0, 1.0, c1),
            states[:-1, 2],
        )

    # Var(w̄) from v1 = E·v0 + C0 + C1·w̄: the smoothed variances of the rates at both ends
    # and their covariance, P[k, k+1 | y] = J[k]·P[k+1 | y] (the RTS lag-one covariance).
    cov, rts = smoothed.cov, smoothed.smoother_gains
    lag = np.einsum("kij,kjl->kil", rts[:-1], cov[1:])[:, 0, 0]
    var = cov[1:, 0, 0] + e**2 * cov[:-1, 0, 0] - 2.0 * e * lag
    tiny = np.abs(c1) <= 1e-9
    sd = np.where(
        tiny,
        np.sqrt(np.maximum(cov[:-1, 2, 2], 0.0)),
        np.sqrt(np.maximum(var, 0.0)) / np.where(tiny, 1.0, np.abs(c1)),
    )
    samples = np.empty((draws, inputs.n))
    if draws:
        for k, states in enumerate(posterior_states(system, smoothed, draws, seed)):
            samples[k] = mean_w(states)
    return smoothed.loglike, smoothed.mean[:, 0], mean_w(smoothed.mean), sd, samples


def identify_flight(
    inputs: FlightInputs,
    model: str = "constant",
    *,
    constant: FlightFit | None = None,
    scaling: AirspeedScaling | None = None,
    gyro_bias: bool = False,
) -> FlightFit:
    """Maximum likelihood of one damping model on a flight (module docstring).

    The constant-damping model starts from an equation-error least-squares fit
    with the turbulence of :func:`_turbulence_starts`; the θ-dependent model starts from the
    constant model's fit with ᾱ₀ = 0 (pass it as ``constant`` if it is at
    hand; otherwise it is fitted first).  ``scaling``: the airspeed exponents held
    (None: measured, with eq. 4-8's tested, :func:`identify_flights`).

    The turbulence's intensity is taken as stationary along the flight.  A second
    pass weighting each second of the flight by the intensity the first pass's
    smoother showed there (the atmosphere's roll gust falls with height near the
    ground, MIL-F-8785C §3.7.2) was tried on the Dryden flights of
    ``benchmarks/flight_ground_truth.py``, and so were four separately estimated
    intensities, and an intensity following MIL-F-8785C's law of height (which
    raised the likelihood of moderate-gust flights by 50-130): none recovered the
    coefficients better.  Several flights of the rocket, fitted together
    (:func:`identify_flights`), do.
    """
    return identify_flights(
        [inputs],
        model,
        constant=None if constant is None else [constant],
        scaling=scaling,
        gyro_bias=gyro_bias,
    )[0]


def eq_4_8_test(loglike_held: float, loglike_measured: float) -> dict[str, Any]:
    """The likelihood-ratio test of eq. 4-8's exponents (``n = 2``, ``m = 1``) against
    exponents measured on the same flights: ``2·(ℓ_measured − ℓ_eq4-8)``, χ² with 2
    degrees of freedom under eq. 4-8, rejected below :data:`EQ_4_8_TEST_SIZE`.

    The χ² holds for a turbulence of the prior's kind; a turbulence that is not
    (a gust whose intensity changes with height) makes it reject too often, which
    ``benchmarks/flight_ground_truth.py --scaling`` measures.
    """
    from scipy import stats

    statistic = max(2.0 * (loglike_measured - loglike_held), 0.0)
    p_value = float(stats.chi2.sf(statistic, 2))
    return {
        "statistic": statistic,
        "dof": 2,
        "p_value": p_value,
        "size": EQ_4_8_TEST_SIZE,
        "rejected": p_value < EQ_4_8_TEST_SIZE,
    }


def _fit_exponents_and_test(
    flights: Sequence[FlightInputs],
    held_map: _FlightParameterMap,
    held: optimize.OptimizeResult,
    extra_starts: Sequence[dict[str, float]],
) -> tuple[_FlightParameterMap, optimize.OptimizeResult, dict[str, Any]]:
    """The exponents freed, from eq. 4-8's optimum (and ``extra_starts``); the test."""
    pmap = dataclasses.replace(held_map, scaling=None)
    starts = [held_map.natural(held.x), *extra_starts]
    best = _maximise(flights, pmap, starts)
    return pmap, best, eq_4_8_test(-float(held.fun), -float(best.fun))


def identify_flights(
    flights: Sequence[FlightInputs],
    model: str = "constant",
    *,
    constant: Sequence[FlightFit] | None = None,
    scaling: AirspeedScaling | None = None,
    gyro_bias: bool = False,
    intervals: str = "auto",
) -> list[FlightFit]:
    """One rocket from several flights: the joint maximum likelihood (the sum of each
    flight's Kalman-filter likelihood) of its parameters at the common reference, and of
    a turbulence and a sensor shared by the flights (one atmosphere's statistics, one
    gyro); each flight's ``u_d`` then from its own smoother.  One fit per flight comes
    back, all with the same parameters, standard errors (from the joint likelihood)
    and ``estimates``; each ``loglike`` is its own flight's.

    ``scaling``: the airspeed exponents ``n``, ``m`` held at these; None (the default)
    measures them: the model is fitted with eq. 4-8's first, then with both exponents
    free from there, and the likelihood-ratio test of eq. 4-8 (:func:`eq_4_8_test`)
    comes with the fit, whose model is the measured one.

    ``constant``: the constant model's fits to these flights (with the same
    ``scaling``), as the θ-dependent model's start (otherwise fitted first).

    ``intervals``: ``auto`` (each parameter's 95 % interval the Hessian's where it is
    positive definite, else the profile likelihood's) or ``profile`` (the profile
    likelihood's for all): :func:`flight_intervals`.

    ``gyro_bias``: estimate a constant bias of the gyro (otherwise it is taken as 0).
    In flight alone it is weakly determined -- it trades against θ̄ where the airspeed
    is low and the rocket slow to respond -- so a bias measured on the pad, subtracted
    before, is better where the log has one.

    Raises
    ------
    IdentificationError
        For no flights, a flight without a roll measurement, flights with different
        measurements (gyro or angle) or different references.
    """
    flights = list(flights)
    if not flights:
        raise IdentificationError("no flights to identify")
    for inputs in flights:
        if inputs.rate is None and inputs.angle is None:
            raise IdentificationError(
                f"recording {inputs.recording.name!r} has neither roll_rate_dps nor roll_deg"
            )
    gyro = flights[0].rate is not None
    if any((inputs.rate is not None) != gyro for inputs in flights):
        raise IdentificationError(
            f"recordings {_names(flights)}: some have a gyro and some only an angle; "
            "fit flights with the same measurements together"
        )
    reference = (flights[0].v_ref_mps, flights[0].rho_ref_kgm3)
    if any((f.v_ref_mps, f.rho_ref_kgm3) != reference for f in flights):
        raise IdentificationError(
            f"recordings {_names(flights)}: prepared at different reference airspeeds or "
            "densities; a joint fit needs one reference"
        )
    held_map = _FlightParameterMap(
        theta_model=model == "theta",
        gyro=gyro,
        scaling=scaling or EQ_4_8,
        gyro_bias=gyro and gyro_bias,
    )
    extra: list[dict[str, float]] = []
    if model == "theta":
        if constant is None:
            constant = identify_flights(flights, "constant", scaling=scaling, gyro_bias=gyro_bias)
        elif len(constant) != len(flights) or any(
            c.model != "constant" or c.inputs is not f
            for c, f in zip(constant, flights, strict=False)
        ):
            raise ValueError("constant must be the constant model's fits to the same inputs")
        start = {**constant[0].estimates, "alpha_bar": 0.0}
        held = _maximise(flights, held_map, [start])
        extra = [start]
    elif model == "constant":
        rough = {**_equation_error_start(flights), "alpha_bar": 0.0}
        held = _maximise(flights, held_map, _turbulence_starts(flights, held_map, rough))
    else:
        raise ValueError(f"model must be 'constant' or 'theta', not {model!r}")
    test: dict[str, Any] | None = None
    if scaling is None:
        pmap, best, test = _fit_exponents_and_test(flights, held_map, held, extra)
    else:
        pmap, best = held_map, held
    nat = pmap.natural(best.x)
    params = _params(nat)
    assert params is not None
    objective = functools.partial(negloglike, _Flights(flights, pmap))
    cov = covariance(numerical_hessian(objective, best.x))
    errors = _standard_errors(cov, pmap, params)
    q_ref = 0.5 * flights[0].rho_ref_kgm3 * flights[0].v_ref_mps ** 2
    found_intervals = flight_intervals(objective, pmap, best.x, cov, q_ref, intervals)
    fits = []
    for inputs in flights:
        loglike, rate, mean_w, sd_w, _ = _smoothed(inputs, nat)
        fits.append(
            FlightFit(
                model=model,
                params=params,
                turbulence_sd_deg=nat["sigma_w"],
                turbulence_tau_s=nat["tau"],
                gyro_noise_pct=100.0 * nat["gyro_rel"] if gyro else None,
                gyro_floor_dps=nat["gyro_abs"] if gyro else None,
                loglike=loglike,
                std_errors=errors,
                time_s=inputs.recording.time_s,
                interval_s=inputs.dt_s,
                u_d_deg=readonly_array(inputs.u_per_w * mean_w),
                u_d_sd_deg=readonly_array(inputs.u_per_w * sd_w),
                rate_dps=readonly_array(rate),
                converged=bool(best.success),
                estimates=nat,
                inputs=inputs,
                flights=len(flights),
                scaling=_scaling(nat),
                scaling_measured=scaling is None,
                eq_4_8_test=test,
                gyro_bias_dps=nat["gyro_bias"] if held_map.gyro_bias else None,
                intervals=found_intervals,
            )
        )
    return fits


#: Standard errors reported, by the optimiser's name: (the name reported, whether it is a log).
_REPORTED = {
    "alpha": ("alpha", False),
    "theta_bar": ("theta_bar_deg", False),
    "log_beta_bar": ("beta_bar_per_s", True),
    "alpha_bar": ("alpha_bar_per_deg_s", False),
    "torque_exponent": ("torque_exponent", False),
    "damping_exponent": ("damping_exponent", False),
}


def _standard_errors(
    cov: FloatArray | None, pmap: _FlightParameterMap, params: RollParams
) -> dict[str, float]:
    """The asymptotic standard errors of the model's parameters (and the measured
    exponents) from the estimates' covariance; empty where any is not positive."""
    names = [name for name in _REPORTED if name in pmap.names]
    index = [pmap.names.index(name) for name in names]
    reported = [_REPORTED[name] for name in names]
    block = None if cov is None else cov[np.ix_(index, index)]
    se, _ = standard_errors(block, [shown for shown, _ in reported])
    if not all(math.isfinite(v) for v in se.values()):
        return {}
    return {
        shown: params.beta_bar_per_s * se[shown] if is_log else se[shown]
        for shown, is_log in reported
    }


#: The physical range of the reported parameters' profiles (an asymmetry within a right
#: angle of the fins' zero); the optimiser's bounds hold the others.
_PROFILE_LIMITS = {"theta_bar": (-90.0, 90.0)}


def flight_intervals(
    objective: Callable[[FloatArray], float],
    pmap: _FlightParameterMap,
    x_hat: FloatArray,
    cov: FloatArray | None,
    q_ref: float,
    mode: str = "auto",
) -> dict[str, dict[str, Any]]:
    """A 95 % interval of each reported parameter (:data:`_REPORTED`'s names) and of the
    fin torque per dynamic pressure at the reference, ``torque_per_q = β̄₀·α₀/q``, the figure
    that compares across windows and flights whatever their reference airspeed.

    The Hessian's (``method: hessian``, the torque's by the delta method, a log-parameter's
    on its log) where ``mode`` is ``auto``, its variance is positive and the interval holds
    (:func:`~identification.estimation.likelihood.standing_interval`: within the bounds, the
    gain's and the torque's sign told); else the profile likelihood's
    (:func:`~identification.estimation.likelihood.profile_interval`: in the optimiser's
    coordinates, within their bounds; the torque profiled as a coordinate in place of α)."""
    names = pmap.names
    bounds = pmap.bounds
    var = np.full(len(names), np.nan) if cov is None else np.diag(cov)
    out: dict[str, dict[str, Any]] = {}
    for name, (shown, is_log) in _REPORTED.items():
        if name not in names:
            continue
        i = names.index(name)
        estimate = float(x_hat[i])
        se = math.sqrt(var[i]) if var[i] > 0 else math.nan
        low, high = bounds[i]
        limits = _PROFILE_LIMITS.get(
            name, (-math.inf if low is None else low, math.inf if high is None else high)
        )
        wald = standing_interval(estimate, se, limits, signed=name == "alpha", log=is_log)
        if mode == "auto" and wald is not None:
            out[shown] = wald
            continue
        step = profile_step(estimate, se)
        found = profile_interval(objective, x_hat, i, step=step, limits=limits, bounds=bounds)
        out[shown] = found.as_dict(math.exp if is_log else None)
    out["torque_per_q"] = _torque_interval(objective, pmap, x_hat, cov, q_ref, mode)
    return out


def _torque_interval(
    objective: Callable[[FloatArray], float],
    pmap: _FlightParameterMap,
    x_hat: FloatArray,
    cov: FloatArray | None,
    q_ref: float,
    mode: str,
) -> dict[str, Any]:
    """:func:`flight_intervals`' interval of ``β̄₀·α₀/q``: the coordinates with α replaced by
    the torque ``T`` (``α = T·q/β̄₀``)."""
    i_l, i_a = pmap.names.index("log_beta_bar"), pmap.names.index("alpha")
    beta = math.exp(float(x_hat[i_l]))
    torque = beta * float(x_hat[i_a]) / q_ref
    gradient = np.zeros(x_hat.size)
    gradient[i_l], gradient[i_a] = torque, beta / q_ref
    var = math.nan if cov is None else float(gradient @ cov @ gradient)
    se = math.sqrt(var) if var > 0 else math.nan
    wald = standing_interval(torque, se, (-math.inf, math.inf), signed=True)
    if mode == "auto" and wald is not None:
        return wald

    def to_x(y: FloatArray) -> FloatArray:
        x = np.array(y, dtype=float)
        x[i_a] = y[i_a] * q_ref / math.exp(y[i_l])
        return x

    y_hat = np.array(x_hat, dtype=float)
    y_hat[i_a] = torque
    step = se if var > 0 else 0.1 * abs(torque) or 1e-9
    found = profile_interval(
        lambda y: objective(to_x(y)),
        y_hat,
        i_a,
        step=step,
        bounds=pmap.bounds,
        max_doublings=20,
    )
    return found.as_dict()


def c_coefficients(
    params: RollParams,
    v_ref_mps: float = TUNNEL_AIRSPEED_MPS,
    rho_ref_kgm3: float = ISA_SEA_LEVEL_DENSITY_KGM3,
) -> dict[str, float]:
    """The coefficients behind ``a`` and ``α`` that do not depend on the airspeed (eq. 7-8).

    ``damping_per_rho_v = β̄/(ρ·V) = S·d²·|C_P|/(4·I)`` (m²/kg: the ``C_P``-like
    coefficient) and ``torque_per_q = β̄·α/q = S·d·C_δ/I`` ((°/s²)/° per Pa: the
    ``C_δ``-like one), with ``q = ½·ρ·V²`` at the reference.
    """
    q = 0.5 * rho_ref_kgm3 * v_ref_mps**2
    return {
        "damping_per_rho_v": params.beta_bar_per_s / (rho_ref_kgm3 * v_ref_mps),
        "torque_per_q": params.beta_bar_per_s * params.alpha / q,
    }


def rescale(
    params: RollParams,
    from_ref: tuple[float, float],
    to_ref: tuple[float, float],
    scaling: AirspeedScaling = EQ_4_8,
) -> RollParams:
    """The same rocket's parameters at another reference ``(V m/s, ρ kg/m³)`` (by
    ``scaling``, default eq. 4-8)."""
    (v1, rho1), (v2, rho2) = from_ref, to_ref
    gain, damping = roll_scales(v2, rho2, v1, rho1, scaling)
    return params.scaled(float(gain), float(damping))
