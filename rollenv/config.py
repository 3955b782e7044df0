"""Every setting of a RocketRoll environment: :class:`RollConfig`, a frozen dataclass
validated once, and the vocabularies of its options (tasks, disturbances, setpoints,
splits, sensors, a flight's turbulence).  :mod:`rollenv.core` steps environments of a
configuration; the Gymnasium environments, the command line and training make theirs
from the same class.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from disturbances.bank import TraceBank
from identification.methods import METHODS, has_posterior
from identification.model import (
    MODEL_NAMES,
    RIG_KEYS,
    Rig,
    Servo,
)
from rocketroll_common.settings import check, setting
from rollenv.flight import STORED_PREFIX, FlightSchedule, flight_schedule, for_flight
from rollenv.layout import (
    Cfg,
    Link,
    Obs,
)

FloatArray = NDArray[np.float64]

__all__ = [
    "ANGLE_SENSORS",
    "DISTURBANCES",
    "FLIGHT_TURBULENCE",
    "GUST_SEVERITIES",
    "MAX_EPISODE_S",
    "SETPOINTS",
    "SPLITS",
    "TASKS",
    "TUNNEL_EPISODE_S",
    "RollConfig",
    "config_fields",
    "observation_bounds",
]


TASKS = ("angle", "rate")


DISTURBANCES = ("replay", "surrogate", "posterior", "none")


SETPOINTS = ("steps", "zero")


SPLITS = ("train", "test")


ANGLE_SENSORS = ("encoder", "gyro")


FLIGHT_TURBULENCE = ("tunnel", "dryden", "recorded")


GUST_SEVERITIES = ("light", "moderate", "severe")


#: Episode length of the tunnel (no ``flight``), s.
TUNNEL_EPISODE_S = 60.0


#: The largest value of the configuration's unbounded options: a gyro noise of 100 % (the
#: paper studies 10 %), ten times the identified turbulence, a starting angle of half a turn.
_UPPER = {"gyro_noise_pct": 100.0, "disturbance_scale": 10.0, "initial_angle_deg": 180.0}


#: The longest episode, s (a day: an episode's history is kept in memory).
MAX_EPISODE_S = 86_400.0


@dataclass(frozen=True)
class RollConfig:
    """Every setting of a RocketRoll environment (see :class:`rollenv.env.RocketRollEnv`).

    Attributes
    ----------
    task : str
        ``"angle"`` (hold the roll angle at a setpoint) or ``"rate"`` (track
        a roll-rate setpoint).
    dt_s : float
        Control step, s: one action is held this long.
    substep_s : float
        Integration substep δt, s (the paper's 0.01 s); ``dt_s`` must be a
        whole number of substeps and so must the traces' Δt.
    episode_s : float or None
        Episode length, s; the environment truncates after
        ``round(episode_s / dt_s)`` steps.  Default (None): 60 s in the
        tunnel, the whole flight (to apogee) with ``flight``; a flight may be
        cut shorter, not longer.
    rate_limit_dps, fin_range_deg : float
        Servo slew-rate limit (eq. 23: 150 °/s) and fin range (±40°).
    sensors : bool
        Sensor model on: encoder quantisation (or the integrated gyro) and
        gyro noise.  Off: the observation holds the true angle and rate (as
        late as ``sensor_latency_s`` says: the delay is the rig's, not the
        sensors' noise).
    angle_sensor : str
        Where the measured angle comes from: ``"encoder"`` (the tunnel rig's
        shaft encoder, quantised) or ``"gyro"`` (a flight computer: the gyro's
        readings summed over each control step, ``φ̂ += Δt·v̂``, from the true
        angle at the start -- noise and the rectangle rule make it drift).
    flight : str or None
        None: the wind tunnel (constant airspeed).  Else the ascent the rocket
        flies (:func:`rollenv.flight.flight_profile`: ``"default"``, a rocket
        YAML or a recorded ``V(t)`` CSV): the episode runs from 50 km/h to
        apogee and the rocket's gain and damping follow the airspeed and air
        density every control step (:mod:`rollenv.flight`).
    flight_turbulence : str
        With ``flight``: ``"tunnel"`` (default) flies the database's traces
        (``disturbance`` chooses which), time-compressed and scaled by
        :mod:`rocketroll_physics.flown`; ``"dryden"`` draws the standard
        atmosphere's roll gust instead (:mod:`rocketroll_physics.dryden`);
        ``"recorded"`` replays a stored flight's own ``u_d`` (with
        ``recording`` naming a flight in the database, the environment flies
        that rocket: :func:`rollenv.bank.stored_flight_config`).
    profile : str or None
        Another ascent to fly instead of ``flight``'s (a ``flight`` name: ``"default"``,
        ``"supersonic"``, a rocket YAML or a ``V(t)`` CSV): for a stored flight
        (``recording`` naming a flight in the database) that rocket on it, its recorded
        ``u_d`` flown anew by height (:func:`rollenv.flight.reflown`).  Default (None):
        ``flight``'s own.
    gust_severity : str
        ``"light"``, ``"moderate"`` or ``"severe"`` (the Dryden model's
        turbulence levels; ``flight_turbulence="dryden"`` only).
    encoder_counts : int
        Encoder counts per revolution (256: 1.40625° resolution); 0 turns
        quantisation off.
    gyro_noise_pct : float
        η of eq. 52: measured rate ``(1 + η/100·ε)·v``, ε ~ N(0, 1); 0 is none.
    gyro_range_dps : float
        Gyro full scale: the measured rate is clipped to ±this, °/s.
    disturbance : str or None
        ``"posterior"`` posterior draws of ``u_d`` (a method with a
        posterior: ``method="ml"``), ``"replay"`` the identified ``u_d``
        traces (for ``ml``: the posterior mean), ``"surrogate"`` surrogate
        traces, or ``"none"`` (``u_d = 0``, the rocket still one of the
        database's).  Default (None): ``"posterior"`` for a method with a
        posterior, else ``"replay"`` -- so by default ml's posterior draws,
        which ``benchmarks/closed_loop.py`` finds the replay whose scores
        predict the true rocket's best.
    disturbance_scale : float
        Factor on ``u_d``.
    model : str
        ``"theta"`` (eq. 49, a(θ)) or ``"constant"`` damping (eq. 29).
    method : str
        The identification method whose parameters and ``u_d`` traces are
        replayed: ``"ml"`` (default), ``"paper"``, ``"output-error"``, or any
        registered one (:data:`identification.methods.METHODS`).
    split : str
        Database split the traces come from: ``"train"`` or ``"test"``.
    recording : str or None
        Only the traces of the recording of this name (as ``rocketroll db
        list`` shows it; it must be in ``split``).  Default (None): every
        recording of the split.
    domain_randomization : bool
        Draw α, θ̄, β̄ and ᾱ at each reset uniformly over the range found in
        the bank instead of using the trace's own; a draw whose damping
        a(θ) is not positive over the whole fin range is drawn again.
    setpoint : str
        ``"steps"``: 0 for the first ``setpoint_period_s``, then a new value
        uniform in ±``setpoint_range`` every period; ``"zero"``: always 0.
    setpoint_period_s : float
        Time between setpoint steps, s.
    setpoint_range : float or None
        Largest setpoint, ° (angle task) or °/s (rate task); default 90° or
        10 °/s.
    initial_angle_deg : float
        The roll angle starts uniform in ±this, °.
    error_scale, rate_scale_dps : float or None
        Reward normalisers (default 10° or 5 °/s for the error, 10 °/s).
    rate_weight, fin_weight : float
        Reward weights of the roll-rate term (angle task only) and the fin
        travel term.
    servo_lag_s, backlash_deg : float or None
        The fin's linkage beyond eq. 23's servo: a first-order lag of the fin
        behind the rate-limited servo (time constant, s) and play between them
        (°, the fin stays put until its drive is half of it away); 0 is none.
    sensor_latency_s : float or None
        Delay of the roll sensors (encoder and gyro): they read the rocket as it
        was this long ago, s; 0 is none.  For each of the three, None (the
        default) is each rocket's own: the rig its identification assumed (the
        recording's ``rig.*`` or ``rocketroll identify``'s flags, and the latency an
        ``ml`` fit found where none was stated; :class:`identification.model.Rig`), none
        for a rocket without one.
    """

    task: str = setting("angle", choices=TASKS, cli=False)
    dt_s: float = setting(0.1, gt=0, cli=False)
    substep_s: float = setting(0.01, gt=0, cli=False)
    episode_s: float | None = setting(None, gt=0, cli=False)
    rate_limit_dps: float = setting(Servo().rate_limit_dps, gt=0, cli=False)
    fin_range_deg: float = setting(Servo().range_deg, gt=0, cli=False)
    sensors: bool = setting(True, cli=False)
    encoder_counts: int = setting(256, ge=0, cli=False)
    gyro_noise_pct: float = setting(2.0, ge=0, le=_UPPER["gyro_noise_pct"], cli=False)
    gyro_range_dps: float = setting(250.0, gt=0, cli=False)
    angle_sensor: str = setting("encoder", choices=ANGLE_SENSORS, cli=False)
    flight: str | None = setting(None, cli=False)
    flight_turbulence: str = setting("tunnel", choices=FLIGHT_TURBULENCE, cli=False)
    profile: str | None = setting(None, cli=False)
    gust_severity: str = setting("light", choices=GUST_SEVERITIES, cli=False)
    disturbance: str | None = setting(None, choices=DISTURBANCES, cli=False)
    disturbance_scale: float = setting(1.0, ge=0, le=_UPPER["disturbance_scale"], cli=False)
    model: str = setting("theta", choices=MODEL_NAMES, cli=False)
    method: str = setting("ml", cli=False)
    split: str = setting("train", choices=SPLITS, cli=False)
    recording: str | None = setting(None, cli=False)
    domain_randomization: bool = setting(False, cli=False)
    setpoint: str = setting("steps", choices=SETPOINTS, cli=False)
    setpoint_period_s: float = setting(10.0, gt=0, cli=False)
    setpoint_range: float | None = setting(None, gt=0, cli=False)
    initial_angle_deg: float = setting(0.0, ge=0, le=_UPPER["initial_angle_deg"], cli=False)
    error_scale: float | None = setting(None, gt=0, cli=False)
    rate_scale_dps: float = setting(10.0, gt=0, cli=False)
    rate_weight: float = setting(0.1, ge=0, cli=False)
    fin_weight: float = setting(0.1, ge=0, cli=False)
    servo_lag_s: float | None = setting(None, cli=False)
    backlash_deg: float | None = setting(None, cli=False)
    sensor_latency_s: float | None = setting(None, cli=False)

    def __post_init__(self) -> None:
        if self.disturbance is None:
            resolved = "posterior" if has_posterior(self.method) else "replay"
            object.__setattr__(self, "disturbance", resolved)
        check(self)  # types, choices and bounds, as the fields declare them
        if self.recording is not None and not (
            isinstance(self.recording, str) and self.recording.strip()
        ):
            raise TypeError(f"recording must be a recording's name, got {self.recording!r}")
        if self.flight is not None and not isinstance(self.flight, str):
            raise TypeError(f"flight must be a profile name or path, got {self.flight!r}")
        self._resolve_episode()
        if self.episode_s is not None and self.episode_s > MAX_EPISODE_S:
            raise ValueError(
                f"episode_s must be at most {MAX_EPISODE_S:g} s, got {self.episode_s!r}"
            )
        Rig.resolved(self._rig_settings(), {})  # the bounds of Rig, named by setting
        try:
            METHODS.check(self.method)
        except ValueError as exc:
            raise ValueError(f"method: {exc}") from None
        substeps = self.dt_s / self.substep_s
        if abs(substeps - round(substeps)) > 1e-9 * substeps or round(substeps) < 1:
            raise ValueError(
                f"dt_s = {self.dt_s:g} s must be a whole number of substeps of {self.substep_s:g} s"
            )
        steps = self.episode_length_s / self.dt_s
        if round(steps) < 1 or abs(steps - round(steps)) > 1e-9 * steps:
            raise ValueError(
                f"episode_s = {self.episode_s:g} s must be a whole number of control steps "
                f"of {self.dt_s:g} s"
            )

    def _resolve_episode(self) -> None:
        """``episode_s`` from the tunnel's default or the flight's length (a given one no
        longer than the flight)."""
        given = self.episode_s
        if given is not None and (
            isinstance(given, bool) or not isinstance(given, numbers.Real) or not given > 0
        ):
            raise ValueError(f"episode_s must be a positive number, got {given!r}")
        if self.flight is None:
            object.__setattr__(self, "episode_s", TUNNEL_EPISODE_S if given is None else given)
            return
        for name in ("dt_s", "substep_s"):  # the schedule needs them; checked again below
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        full = self.flight_schedule
        assert full is not None
        if given is None:
            object.__setattr__(self, "episode_s", full.duration_s)
        elif given > full.duration_s + 1e-9:
            raise ValueError(
                f"episode_s = {given:g} s is longer than the flight ({full.duration_s:g} s "
                f"of {full.profile.source} from {full.v_ref_mps * 3.6:.0f} km/h to apogee): "
                f"give episode_s={full.duration_s:g} or less, or leave it out for the whole "
                "flight"
            )

    # ------------------------------------------------------------ derived values
    @property
    def episode_length_s(self) -> float:
        """``episode_s``, resolved (a float once the configuration exists)."""
        assert self.episode_s is not None
        return float(self.episode_s)

    @property
    def flies_stored_flight(self) -> bool:
        """Whether ``flight`` is a flight stored in a database, flown as that rocket
        (:func:`rollenv.flight.stored_flight_name`)."""
        return self.flight is not None and self.flight.startswith(STORED_PREFIX)

    @property
    def flight_schedule(self) -> FlightSchedule | None:
        """The flight on this configuration's grid (None in the tunnel)."""
        if self.flight is None:
            return None
        return flight_schedule(
            self.flight, self.dt_s, self.substep_s, model=self.model, profile=self.profile
        )

    def flights(self, bank: TraceBank) -> TraceBank:
        """The traces this configuration replays from ``bank``: ``bank`` itself in the
        tunnel; in flight its flights (:func:`rollenv.flight.for_flight`: the tunnel traces
        flown or Dryden's gusts, one episode each; cached)."""
        schedule = self.flight_schedule
        if schedule is None:
            return bank
        return for_flight(
            bank,
            schedule,
            steps=self.max_episode_steps,
            substeps=self.substeps,
            turbulence=self.flight_turbulence,
            severity=self.gust_severity,
            split=self.split,
        )

    @property
    def substeps(self) -> int:
        """Substeps per control step."""
        return round(self.dt_s / self.substep_s)

    @property
    def max_episode_steps(self) -> int:
        """Control steps per episode."""
        return round(self.episode_length_s / self.dt_s)

    @property
    def setpoint_max(self) -> float:
        """The largest setpoint, ° or °/s."""
        if self.setpoint_range is not None:
            return float(self.setpoint_range)
        return 90.0 if self.task == "angle" else 10.0

    @property
    def error_norm(self) -> float:
        """Error normaliser of the reward, ° or °/s."""
        if self.error_scale is not None:
            return float(self.error_scale)
        return 10.0 if self.task == "angle" else 5.0

    @property
    def setpoint_period_steps(self) -> int:
        """Control steps between setpoint steps (at least one)."""
        return max(1, round(self.setpoint_period_s / self.dt_s))

    @property
    def setpoint_segments(self) -> int:
        """Setpoint values per episode."""
        return -(-self.max_episode_steps // self.setpoint_period_steps)

    @property
    def encoder_resolution_deg(self) -> float:
        """One encoder count, ° (0 without quantisation: no sensors, no counts, or the angle
        from the gyro)."""
        encoder = self.sensors and self.encoder_counts and self.angle_sensor == "encoder"
        return 360.0 / self.encoder_counts if encoder else 0.0

    def _rig_settings(self) -> dict[str, float | None]:
        """The rig's settings by name (None: each rocket's own)."""
        return {name: getattr(self, name) for name, _ in RIG_KEYS.values()}

    def rig_of(self, own: Rig) -> Rig:
        """The rig a rocket whose own is ``own`` flies here: each setting given, else its own."""
        given = self._rig_settings()
        chosen: dict[str, float] = {}
        for f, (name, _) in RIG_KEYS.items():
            value = given[name]
            if value is not None:
                chosen[f] = value
        return dataclasses.replace(own, **chosen)

    def with_rig(self, rig: Rig) -> RollConfig:
        """These settings with every rocket flying ``rig`` (its settings all given)."""
        return dataclasses.replace(
            self, **{name: getattr(rig, f) for f, (name, _) in RIG_KEYS.items()}
        )

    @property
    def servo(self) -> Servo:
        """The servo of eq. 23 with this rate limit and range."""
        return Servo(self.rate_limit_dps, self.fin_range_deg)

    def kernel_settings(self) -> FloatArray:
        """The scalars the kernels read, packed in one array (see :class:`rollenv.layout.Cfg`)."""
        cfg = np.zeros(len(Cfg))
        cfg[Cfg.SUBSTEPS] = self.substeps
        cfg[Cfg.H] = self.substep_s
        cfg[Cfg.MAX_MOVE] = self.rate_limit_dps * self.substep_s
        cfg[Cfg.FIN_RANGE] = self.fin_range_deg
        cfg[Cfg.TASK_RATE] = 1.0 if self.task == "rate" else 0.0
        cfg[Cfg.ENCODER_RES] = self.encoder_resolution_deg
        cfg[Cfg.GYRO_ETA] = self.gyro_noise_pct / 100.0 if self.sensors else 0.0
        cfg[Cfg.GYRO_RANGE] = self.gyro_range_dps
        cfg[Cfg.ERROR_NORM] = self.error_norm
        cfg[Cfg.RATE_NORM] = self.rate_scale_dps
        cfg[Cfg.RATE_WEIGHT] = self.rate_weight if self.task == "angle" else 0.0
        cfg[Cfg.FIN_WEIGHT] = self.fin_weight
        cfg[Cfg.TRAVEL_NORM] = self.rate_limit_dps * self.dt_s
        cfg[Cfg.U_SCALE] = 0.0 if self.disturbance == "none" else self.disturbance_scale
        cfg[Cfg.SETPOINT_PERIOD] = self.setpoint_period_steps
        cfg[Cfg.ERROR_MAX] = observation_bounds(self)[0][Obs.ERROR]
        cfg[Cfg.U_PER] = 1.0  # set by RollBatch from the bank's Δt
        cfg[Cfg.ANGLE_GYRO] = 1.0 if self.sensors and self.angle_sensor == "gyro" else 0.0
        return cfg

    def link_row(self, own: Rig) -> FloatArray:
        """The kernel's :class:`~rollenv.layout.Link` row of a rocket whose rig is ``own``."""
        rig = self.rig_of(own)
        row = np.zeros(len(Link))
        row[Link.DECAY], row[Link.RAMP], row[Link.HALF] = rig.linkage.coefficients(self.substep_s)
        row[Link.LATENCY] = rig.latency_s / self.substep_s
        return row


def observation_bounds(config: RollConfig) -> tuple[FloatArray, FloatArray]:
    """Finite ``(high, low)`` of the observation: error, rate, fin, command."""
    high = np.zeros(len(Obs))
    high[Obs.ERROR] = 180.0 if config.task == "angle" else 2.0 * config.gyro_range_dps
    high[Obs.RATE] = config.gyro_range_dps
    high[Obs.FIN] = config.fin_range_deg
    high[Obs.COMMAND] = config.fin_range_deg
    return high, -high


def config_fields() -> tuple[str, ...]:
    """Names a user may set (the constructor's keyword arguments)."""
    return tuple(f.name for f in fields(RollConfig) if f.init)
