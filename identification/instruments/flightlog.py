"""The virtual tunnel's flight counterpart: a flight log with known truth
(``rocketroll record-flight``).

The tunnel (:mod:`identification.instruments.tunnel`) re-creates the paper's experiment so
that every identification can be checked against the truth.  This module does
the same for the flight the paper's §4 looks ahead to: the rocket of a
:class:`~rocketroll_physics.ascent.FlightProfile` (default: the 5-kg rocket to
603 km/h and 2 km) from the moment it reaches the reference airspeed (the
tunnel's, unless ``--v-ref``; it has left the rail) to apogee -- with Dryden
gusts, to the moment it slows back below ``v_ref`` just before apogee (there
the fins lose their authority while the rolling gust does not, so its
equivalent fin angle grows without bound) -- with

* the roll model of eq. 36/49 at the reference airspeed ``V_ref`` (the
  truth), its gain and damping scaled along the flight by eq. 4-8 or by
  other exponents (torque ``∝ ρV^n``, damping ``∝ ρV^m``:
  :class:`rocketroll_physics.scaling.AirspeedScaling`), integrated exactly
  (:func:`identification.model.simulate`, scales per substep); above Mach
  0.8 (the ``supersonic`` ascent) the fins' torque leaves that law
  (:func:`rocketroll_physics.scaling.fin_compressibility`: outside the model);
* an excitation: a random staircase of fin commands, short dwells (the rocket
  settles in tens of milliseconds at speed), through the servo of eq. 23;
* turbulence flown, from one of the two sources of the flight environment:
  ``tunnel`` -- a stationary ``u_d`` process like the tunnel's
  (:class:`identification.instruments.tunnel.Turbulence`) flown by the law of
  :mod:`rocketroll_physics.flown` (Taylor's frozen field, amplitude
  ``V_ref/max(V, V_ref)``) -- or ``dryden`` -- the MIL-F-8785C roll gust
  ``p_g`` (:mod:`rocketroll_physics.dryden`) as ``α·u_d = p_g``;
* optionally a descent past apogee (``descent``): the rocket falls
  tail-first, the flow over its fins reversed and with it their torque --
  outside the flight model, which fits the ascent only;
* optionally a flight computer's rate loop on the fins (``--loop-gain``), as real
  roll-controlled flights are flown: the command is the excitation plus the gain times
  minus the gyro's rate read ``--loop-delay`` earlier, saturated at the fins' ``--stops``
  (``--schedule none``: the loop alone); flown, like the tunnel's, one logging interval at
  a time by the reference integrator (:func:`identification.instruments.reference.fly_loop`,
  the gain and damping per fine step) and stated in ``loop.*`` metadata;
* flight sensors: a rate gyro with the multiplicative noise of eq. 52, an
  additive floor and a constant bias, optionally an encoder-like quantised
  angle; the airspeed and altitude of the profile (format 1.1), the altitude
  above sea level or, as flight computers log it, above the pad.

The recording's metadata holds the truth (``truth.*`` at ``truth.v_ref_mps``,
``truth.rho_ref_kgm3``) and the exact command; ``ud_true_deg`` is the
disturbance the rocket flew, per sample interval.
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from identification.instruments.reference import (
    Effects,
    GyroReader,
    LoopRun,
    fine_steps,
    fly_loop,
    gust_factor,
    gust_stream,
    simulate_reference,
)
from identification.instruments.tunnel import (
    FinSchedule,
    LoopFlown,
    Turbulence,
    check_dwells,
    check_rocket,
    loop_items,
    loop_setting,
    rocket_params,
    rocket_setting,
    synthetic_recording,
    truth_items,
)
from identification.model import MODEL_NAMES, RollParams, Servo
from identification.model import simulate as simulate_roll
from identification.recordings.flight import SITE_ELEVATION_KEY
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import RocketrollError, SettingError
from rocketroll_common.settings import check, setting, to_argv
from rocketroll_physics.ascent import FlightProfile, check_ascent_name, flight_profile
from rocketroll_physics.atmosphere import ISA_SEA_LEVEL_DENSITY_KGM3
from rocketroll_physics.dryden import roll_gust
from rocketroll_physics.flown import flow_amplitude, fly_trace, tunnel_time
from rocketroll_physics.scaling import (
    MACH_LIMIT,
    TUNNEL_AIRSPEED_MPS,
    AirspeedScaling,
    FlightReference,
    fin_compressibility,
    roll_scales,
)

__all__ = ["AscentError", "FlightLogSpec", "run_flight", "truth_at", "truth_reference"]

#: The tunnel trace's hold interval that the ``tunnel`` turbulence is drawn at, s (the tunnel's Δt).
TUNNEL_DT_S = 0.1
#: The fin command is held at 0° this long after the rail before the staircase starts, s.
LEAD_S = 0.5


@dataclass(frozen=True)
class FlightLogSpec(LoopFlown):
    """Everything that defines one virtual flight; each field is a ``rocketroll record-flight``
    flag.

    The rocket's truth is given at the reference airspeed ``v_ref`` (default:
    the tunnel's 50 km/h) and ISA sea-level density, as the tunnel's
    identification gives it; the defaults are the paper's θ-dependent rocket.
    """

    seed: int = setting(
        0, "random seed; the same seed gives a byte-identical file", ge=0, le=2**63 - 1, always=True
    )
    ascent: str = setting(
        "default",
        "the ascent: default (the 5-kg rocket to about 600 km/h and 2 km), supersonic (on "
        "a bigger motor: Mach 1.04, above Mach 0.8 for 3 s), a rocket YAML or a recorded "
        "V(t) CSV",
        metavar="FLIGHT",
    )
    model: str = setting(
        "theta", "damping model: theta (eq. 49) or constant (eq. 29)", choices=MODEL_NAMES
    )
    alpha: float = rocket_setting("alpha", " at --v-ref")
    beta: float = rocket_setting("beta", " at --v-ref")
    alpha_bar: float | None = rocket_setting("alpha_bar", " at --v-ref")
    beta_bar: float | None = rocket_setting("beta_bar", " at --v-ref")
    v_ref: float = setting(
        TUNNEL_AIRSPEED_MPS,
        "airspeed at which the truth holds (ISA sea-level density); the log starts when the "
        "rocket reaches it",
        gt=0.0,
        le=1000.0,
        unit="m/s",
    )
    torque_exponent: float = setting(
        2.0,
        "n: the fins' torque per degree grows as ρ·V^n (eq. 4-8: 2; canards losing "
        "effectiveness with speed: less)",
        ge=0.0,
        le=4.0,
    )
    damping_exponent: float = setting(
        1.0, "m: the roll damping grows as ρ·V^m (eq. 4-8: 1)", ge=0.0, le=4.0
    )
    servo_rate: float = setting(
        Servo().rate_limit_dps, "servo rate limit (eq. 23)", gt=0.0, le=10_000.0, unit="°/s"
    )
    schedule: Literal["staircase", "none"] = setting(
        "staircase",
        "the excitation: a random fin staircase (--fin-range, --dwell-min, --dwell-max), or "
        "none (0° throughout, only under --loop-gain). Under --loop-gain it is added to the "
        "loop's command",
    )
    fin_range: float = setting(
        20.0, "staircase levels are uniform in ±this", gt=0.5, le=40.0, unit="°"
    )
    dwell_min: float = setting(0.1, "shortest staircase dwell", gt=0.0, le=60.0, unit="s")
    dwell_max: float = setting(0.5, "longest staircase dwell", gt=0.0, le=60.0, unit="s")
    loop_gain: float = loop_setting(
        "loop_gain",
        whose=" (a flight computer's on its canards)",
        excitation="excitation",
        rate="the gyro's rate",
    )
    loop_delay: float = loop_setting(
        "loop_delay",
        reads="the gyro (its noise, floor and bias included; the true rate with --no-gyro)",
    )
    stops: float = loop_setting("stops")
    turbulence: Literal["tunnel", "dryden"] = setting(
        "tunnel",
        "turbulence: the tunnel's u_d process flown (Taylor, amplitude V_ref/V), or the "
        "Dryden roll gust of MIL-F-8785C",
    )
    distribution: Literal["gaussian", "laplace", "student-t"] = setting(
        "gaussian", "marginal of the tunnel process (--turbulence tunnel)"
    )
    turbulence_sd: float = setting(
        Turbulence().sd_deg, "SD of the tunnel process", ge=0.0, le=45.0, unit="°"
    )
    correlation_time: float = setting(
        Turbulence().correlation_time_s,
        "correlation time of the tunnel process, in tunnel time",
        ge=0.0,
        le=600.0,
        unit="s",
    )
    dof: float = setting(Turbulence().dof, "degrees of freedom of the student-t", gt=2.0, le=1000.0)
    severity: Literal["light", "moderate", "severe"] = setting(
        "light", "Dryden gust severity (--turbulence dryden)"
    )
    descent: float = setting(
        0.0,
        "log this long past apogee: the rocket falls tail-first (no recovery device), the "
        "flow over its fins reversed and with it their torque; outside the flight model, "
        "which fits the ascent (--turbulence tunnel)",
        ge=0.0,
        le=60.0,
        unit="s",
    )
    effects: Effects = setting(default_factory=Effects, flatten=True)
    log_dt: float = setting(0.01, "logging interval", ge=0.001, le=0.1, unit="s")
    substeps: int = setting(4, "exact-update substeps per logging interval", ge=1, le=1000)
    gyro_noise: float = setting(
        1.0, "rate gyro's multiplicative noise (eq. 52)", ge=0.0, le=100.0, unit="%"
    )
    gyro_floor: float = setting(0.1, "rate gyro's additive noise SD", ge=0.0, le=1000.0, unit="°/s")
    gyro_bias: float = setting(
        0.0, "rate gyro's constant bias (added to every reading)", ge=-100.0, le=100.0, unit="°/s"
    )
    no_gyro: bool = setting(False, "omit the gyro (needs --encoder-counts)")
    encoder_counts: int = setting(
        0,
        "add a roll angle quantised to this many counts per revolution (0: none)",
        ge=0,
        le=2**24,
    )
    no_altitude: bool = setting(False, "omit the altitude column")
    altitude_above_ground: bool = setting(
        False,
        "log the altitude above the pad, as most flight computers do (the site's elevation "
        "is then only in the metadata: import with --site-elevation)",
    )
    measured_fin: bool = setting(False, "add the actual (measured) fin angle column fin_deg")
    name: str | None = setting(None, "recording name (default flight-<turbulence>-seed<N>)")
    split: Literal["train", "test"] | None = setting(None, "evaluation split in the metadata")

    def __post_init__(self) -> None:
        check(self)
        check_rocket(self.model, self.alpha, self.beta, self.alpha_bar, self.beta_bar)
        if self.no_gyro and self.encoder_counts == 0:
            raise SettingError("no_gyro", "needs an angle (give --encoder-counts, e.g. 4096)")
        check_dwells(self.log_dt, self.dwell_min, self.dwell_max)
        self.check_loop()
        try:  # the name only: reading and simulating the ascent is the flight's work
            check_ascent_name(self.ascent, self.descent)
        except ValueError as exc:
            raise SettingError("ascent", str(exc).removeprefix("flight: ")) from None
        if self.descent > 0.0 and self.turbulence == "dryden":
            raise SettingError(
                "descent",
                "needs --turbulence tunnel (a Dryden log ends where the airspeed falls back "
                "below --v-ref)",
            )

    def scaling(self) -> AirspeedScaling:
        """The truth's airspeed scaling (``n``, ``m``)."""
        return AirspeedScaling(self.torque_exponent, self.damping_exponent)

    def params(self) -> RollParams:
        """The truth at ``v_ref`` and ISA sea-level density."""
        return rocket_params(self.model, self.alpha, self.beta, self.alpha_bar, self.beta_bar)

    def default_name(self) -> str:
        """``flight-<turbulence>-seed<N>`` unless a name was given."""
        return self.name or f"flight-{self.turbulence}-seed{self.seed}"

    def command(self) -> str:
        """The full shell command, e.g. ``rocketroll record-flight --seed 0``."""
        return shlex.join(["rocketroll", "record-flight", *to_argv(self)])


class AscentError(RocketrollError, ValueError):
    """The ascent of a virtual flight cannot be read or is too short to log (the command
    line names its ``--ascent`` before the message)."""


def _turbulence(
    spec: FlightLogSpec,
    profile: FlightProfile,
    edges: FloatArray,
    gain_mid: FloatArray,
    rng: np.random.Generator,
) -> FloatArray:
    """``u_d`` per logging interval along the flight, °."""
    along = profile.at(edges)
    speed = np.asarray(along.airspeed_mps)
    if spec.turbulence == "tunnel":
        tau = tunnel_time(edges - edges[0], speed, spec.v_ref)
        process = Turbulence(
            distribution=spec.distribution,
            sd_deg=spec.turbulence_sd,
            correlation_time_s=spec.correlation_time,
            dof=spec.dof,
        )
        u = process.sample(math.ceil(tau[-1] / TUNNEL_DT_S) + 2, TUNNEL_DT_S, rng)
        middle = 0.5 * (speed[1:] + speed[:-1])
        return fly_trace(u, TUNNEL_DT_S, 0.0, tau, flow_amplitude(middle, spec.v_ref))
    height = np.maximum(np.asarray(along.altitude_m) - profile.altitude_m[0], 0.0)
    gust = roll_gust(edges, speed, height, severity=spec.severity, rng=rng)
    return np.asarray(gust / (spec.params().alpha * np.maximum(gain_mid, 1e-3)))


def _logged(spec: FlightLogSpec) -> tuple[FlightProfile, float, float, FloatArray]:
    """The flight's profile, the logged window's start and end (s) and the sample times."""
    try:
        profile = flight_profile(spec.ascent, spec.descent)
        # Dryden's rolling gust does not fade with the airspeed while the fins' authority
        # does: near apogee its equivalent fin angle grows without bound, so a Dryden log
        # ends where the airspeed falls back below v_ref (the tunnel's law holds the flow
        # angle at the tunnel's scale there, defined to apogee).
        until = "slow" if spec.turbulence == "dryden" else "apogee"
        start, end = profile.window(spec.v_ref, until=until)
    except ValueError as exc:
        raise AscentError(str(exc)) from None
    if spec.descent > 0.0:
        end = float(profile.t_s[-1])  # apogee + descent
    n = math.floor((end - start) / spec.log_dt + 1e-9)
    if n < 50:
        raise AscentError(
            f"flight: {profile.source} spends {end - start:.2f} s above --v-ref "
            f"{spec.v_ref:g} m/s: fewer than 50 samples of {spec.log_dt:g} s"
        )
    time: FloatArray = np.asarray(start + spec.log_dt * np.arange(n + 1), dtype=np.float64)
    return profile, start, end, time


def _metadata(
    spec: FlightLogSpec,
    profile: FlightProfile,
    start: float,
    params: RollParams,
    scaling: AirspeedScaling,
    servo: Servo,
    flown: LoopRun | None,
) -> list[tuple[str, object]]:
    """A virtual flight's metadata: the command, the flight, the loop (``flown``, None in
    open loop), the truth and the sensors.  The fins' range (``truth.fin_range_deg``) is
    stated where it is not the eq. 23 servo's, which a log of the servo's rate alone implies
    (:meth:`~identification.recordings.recording.Recording.fin_range`), and under a loop."""
    effects = spec.effects
    loop: list[tuple[str, object]] = []
    if flown is not None:
        sensor = "the true roll rate" if spec.no_gyro else "roll_rate_dps"
        loop = [
            ("flight.schedule", spec.schedule),
            *loop_items(spec.rate_loop(), flown.delay_s, sensor, "flight.schedule"),
        ]
    fins: list[tuple[str, object]] = []
    if flown is not None or servo.range_deg != Servo().range_deg:
        fins.append(("truth.fin_range_deg", servo.range_deg))
    meta: list[tuple[str, object]] = [
        ("notes", "virtual flight (synthetic data with known ground truth)"),
        ("command", spec.command()),
        ("seed", spec.seed),
        ("flight.ascent", profile.source),
        ("flight.start_s", round(start, 9)),
        ("flight.apogee_s", round(profile.apogee_s, 9)),
        *loop,
        *truth_items(spec.model, params),
        ("truth.v_ref_mps", spec.v_ref),
        ("truth.rho_ref_kgm3", ISA_SEA_LEVEL_DENSITY_KGM3),
        ("truth.torque_exponent", scaling.torque_exponent),
        ("truth.damping_exponent", scaling.damping_exponent),
        ("truth.servo_rate_dps", servo.rate_limit_dps),
        *fins,
        ("truth.turbulence", "tunnel-flown" if spec.turbulence == "tunnel" else "dryden"),
    ]
    if spec.descent > 0.0:
        meta.append(("flight.descent", "tail-first after apogee: the fins' torque reversed"))
    if effects.any:  # the truth outside the model
        meta += effects.metadata("flight")
    if profile.max_mach > MACH_LIMIT:
        meta.append(
            ("flight.compressibility", "fin torque x fin_compressibility(Mach) above Mach 0.8")
        )
    if spec.turbulence == "tunnel":
        meta += [
            ("flight.turbulence_distribution", spec.distribution),
            ("truth.turbulence_sd_deg", spec.turbulence_sd),
            ("truth.turbulence_tau_s", spec.correlation_time),
        ]
    else:
        meta.append(("flight.gust_severity", spec.severity))
    if not spec.no_gyro:
        meta += [
            ("sensor.gyro_noise_pct", spec.gyro_noise),
            ("sensor.gyro_floor_dps", spec.gyro_floor),
            ("sensor.gyro_bias_dps", spec.gyro_bias),
        ]
    if spec.encoder_counts:
        meta.append(("sensor.encoder_counts", spec.encoder_counts))
    if spec.altitude_above_ground and not spec.no_altitude:
        meta.append((SITE_ELEVATION_KEY, float(profile.altitude_m[0])))
    if spec.split is not None:
        meta.append(("split", spec.split))
    return meta


def run_flight(spec: FlightLogSpec) -> Recording:
    """Fly the virtual flight and log it.

    Returns
    -------
    Recording
        ``source = synthetic``, format 1.1: ``fin_cmd_deg``, ``roll_rate_dps``
        (unless ``no_gyro``), the optional ``fin_deg`` and ``roll_deg``,
        ``airspeed_mps``, ``altitude_m`` (unless ``no_altitude``) and the
        ground-truth ``ud_true_deg``; the metadata carries the truth and the
        exact command (and, under a loop, the controller: ``loop.*``).

    Raises
    ------
    AscentError
        For an ascent that cannot be read, or spends fewer than 50 logging
        intervals above ``v_ref``.
    """
    children = np.random.SeedSequence(spec.seed).spawn(3)
    rng_schedule, rng_turbulence, rng_sensor = (np.random.default_rng(c) for c in children)
    profile, start, end, time = _logged(spec)
    n = time.size - 1
    excitation = _excitation(spec, time - start, end - start, rng_schedule)
    scaling = spec.scaling()

    def true_scales(t_s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """The true rocket's gain and damping factors at the times ``t_s``."""
        at = profile.at(t_s)
        gain, damping = roll_scales(
            at.airspeed_mps, at.density_kgm3, spec.v_ref, ISA_SEA_LEVEL_DENSITY_KGM3, scaling
        )
        # Past Mach 0.8 the fins' torque per degree leaves the subsonic law (outside the
        # model); falling tail-first, the flow meets the fins from behind: it reverses.
        sign = np.where(np.asarray(t_s) > profile.apogee_s, -1.0, 1.0)
        return sign * fin_compressibility(at.mach) * np.asarray(gain), np.asarray(damping)

    h = spec.log_dt / spec.substeps
    gain, damping = true_scales(start + h * (np.arange(n * spec.substeps) + 0.5))
    gain_mid, _ = roll_scales(
        profile.at(time[:-1] + 0.5 * spec.log_dt).airspeed_mps, 1.0, spec.v_ref, 1.0, scaling
    )
    u_d = _turbulence(spec, profile, time, np.asarray(gain_mid), rng_turbulence)
    params = spec.params()
    servo = spec.servo()
    effects = spec.effects
    if effects.any:  # the turbulence's intensity wanders (a no-op unless --gust-sd)
        u_d = u_d * gust_factor(u_d.size, spec.log_dt, effects, gust_stream(spec.seed))
    per, fine_h = fine_steps(spec.log_dt)
    gyro: FloatArray | None = None
    flown: LoopRun | None = None
    if spec.closed_loop or effects.any:  # the reference integrator, the scales per fine step
        fine_gain, fine_damping = true_scales(start + fine_h * (np.arange(n * per) + 0.5))
    if spec.closed_loop:  # the fins under the rate loop
        flown = fly_loop(
            params, effects, spec.rate_loop(), excitation, u_d, spec.log_dt,
            rate_limit_dps=servo.rate_limit_dps, u_start_deg=float(u_d[0]),
            gyro=None if spec.no_gyro else _gyro(spec, n, rng_sensor),
            gain=fine_gain, damping=fine_damping,
        )  # fmt: skip
        command, fin, rate, angle, gyro = (
            flown.command, flown.fin, flown.rate, flown.angle, flown.gyro
        )  # fmt: skip
    else:
        command = np.asarray(np.clip(excitation, -spec.stops, spec.stops), dtype=float)
        if effects.any:  # a rocket outside the model: the reference integrator, its own grid
            ref = simulate_reference(
                params, spec.log_dt, command[:-1], u_d, effects,
                rate_limit_dps=servo.rate_limit_dps, fin_range_deg=servo.range_deg,
                rate0_dps=float(params.steady_rate(command[0], u_d[0]) * gain[0]),  # as below
                gain=fine_gain, damping=fine_damping,
            )  # fmt: skip
            fin, rate, angle = ref.fin_deg, ref.rate_dps, ref.angle_deg
        else:
            sim = simulate_roll(
                params,
                spec.log_dt,
                command[:-1],
                u_d,
                servo=servo,
                substeps=spec.substeps,
                t0_s=float(time[0]),
                gain=gain,
                damping=damping,
            )
            fin, rate, angle = sim.fin_deg, sim.rate_dps, sim.angle_deg
    columns: dict[str, FloatArray] = {"fin_cmd_deg": command}
    if spec.measured_fin:
        columns["fin_deg"] = fin
    if spec.encoder_counts:
        resolution = 360.0 / spec.encoder_counts
        columns["roll_deg"] = np.floor(angle / resolution + 1e-9) * resolution
    if not spec.no_gyro:
        if gyro is None:
            eps = rng_sensor.standard_normal((2, rate.size))
            gyro = (
                (1.0 + spec.gyro_noise / 100.0 * eps[0]) * rate
                + spec.gyro_floor * eps[1]
                + spec.gyro_bias
            )
        columns["roll_rate_dps"] = gyro
    at = profile.at(time)
    columns["airspeed_mps"] = np.asarray(at.airspeed_mps)
    if not spec.no_altitude:
        pad = float(profile.altitude_m[0]) if spec.altitude_above_ground else 0.0
        columns["altitude_m"] = np.asarray(at.altitude_m) - pad
    columns["ud_true_deg"] = np.append(u_d, u_d[-1])

    meta = _metadata(spec, profile, start, params, scaling, servo, flown)
    return synthetic_recording(spec.default_name(), time, meta, columns)


def _excitation(
    spec: FlightLogSpec, since_s: FloatArray, span_s: float, rng: np.random.Generator
) -> FloatArray:
    """The excitation at each sample, ``since_s`` after the log's start (``span_s`` long):
    the staircase (from ``rng``), or 0° (``none``)."""
    if spec.schedule == "none":
        return np.zeros(since_s.size)
    steps = math.ceil(span_s / spec.dwell_min) + 1
    schedule = FinSchedule.staircase(
        rng,
        steps,
        range_deg=spec.fin_range,
        dwell_s=(spec.dwell_min, spec.dwell_max),
        lead_s=LEAD_S,
        min_step_deg=min(5.0, spec.fin_range),
        grid_s=spec.log_dt,
    )
    return np.asarray(schedule.command(since_s))


def _gyro(spec: FlightLogSpec, n: int, rng: np.random.Generator) -> GyroReader:
    """The flight's gyro as the loop reads it: eq. 52's noise, the floor and the bias, from
    the sensor stream -- the ``n + 1`` logged readings' draws first (the open loop's), then
    those of the controller's own readings between samples."""
    eps_log = rng.standard_normal((2, n + 1))
    eps_own = rng.standard_normal((2, n + 1))
    noise = spec.gyro_noise / 100.0

    def read(rate: float, k: int, own: bool) -> float:
        eps = eps_own if own else eps_log
        return float(
            (1.0 + noise * eps[0, k]) * rate + spec.gyro_floor * eps[1, k] + spec.gyro_bias
        )

    return read


def truth_reference(recording: Recording) -> FlightReference:
    """Where a virtual flight's truth holds and how it scales: its ``truth.v_ref_mps``,
    ``truth.rho_ref_kgm3`` and true exponents (eq. 4-8's where a log predates them).

    Raises
    ------
    ValueError
        If the recording holds no truth (not a virtual flight).
    """
    facts = {
        key.removeprefix("truth."): value
        for key, value in recording.metadata.items()
        if key.startswith("truth.")
    }
    reference = FlightReference.from_metrics(facts)
    if recording.truth() is None or reference is None:
        raise ValueError(f"recording {recording.name!r} holds no flight truth")
    return reference


def truth_at(
    recording: Recording, v_ref_mps: float, rho_ref_kgm3: float = ISA_SEA_LEVEL_DENSITY_KGM3
) -> RollParams:
    """A virtual flight's true rocket at the reference ``(v_ref_mps, rho_ref_kgm3)``: its
    ``truth.*`` carried there by its true scaling (:func:`truth_reference`).

    Raises
    ------
    ValueError
        If the recording holds no truth (not a virtual flight).
    """
    reference = truth_reference(recording)
    truth = recording.truth()
    assert truth is not None
    gain, damping = reference.scales(v_ref_mps, rho_ref_kgm3)
    return truth.scaled(float(gain), float(damping))
