"""``identify(recording) -> Identification``: the paper's whole pipeline.

Chains the steps of :mod:`identification.methods.steps` (Fig. 9), the noise study of
:mod:`identification.methods.noise` (§3.3) and the disturbance statistics of
:mod:`identification.methods.statistics` (§3.4) into one frozen result.  The result
is what the CLI prints, what ``--json`` writes and what the disturbance
database stores (:meth:`Identification.to_dict` plus the ``u_d`` traces).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from identification.methods.noise import NoiseStudy, noise_study
from identification.methods.statistics import DisturbanceStatistics, disturbance_statistics
from identification.methods.steps import (
    PAPER_SERVO,
    SMOOTHING_WINDOW_S,
    BilinearFit,
    DampingFit,
    DampingVsFin,
    FineGrid,
    IdentificationError,
    PiecewiseLinearFit,
    Resimulation,
    Segments,
    SteadyStateFit,
    bilinear_velocity,
    detect_segments,
    fin_angle_model,
    fine_grid,
    fit_bilinear,
    fit_damping,
    fit_damping_vs_fin,
    fit_piecewise_linear,
    fit_steady_state,
    identify_disturbance,
    measured_angle,
    measured_velocity,
    resimulate,
    smoothing_spread_s,
)
from identification.model import Disturbance, Rig, RollParams, check_model, damping
from identification.recordings.recording import Recording, StatedRig
from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import SettingError
from rocketroll_common.settings import check, check_order, setting

__all__ = [
    "Identification",
    "IdentifyOptions",
    "Measurements",
    "delayed",
    "delayed_fin",
    "fitted_rig",
    "identify",
    "latency_stated",
    "measurements",
    "recover_disturbance",
    "with_latency",
]


@dataclass(frozen=True)
class IdentifyOptions:
    """Settings of :func:`identify`; the defaults are the paper's.

    Attributes
    ----------
    min_step_deg : float
        Smallest fin change that counts as a step (step 1), °.
    max_breakpoint_s : float
        ΔT0 of the bi-linear search (step 4; 4 s).
    breakpoint_resolution_s : float
        Breakpoint search step (step 4; 0.01 s).
    servo_rate_dps : float
        Servo rate limit of eq. 23 (step 5; 0.4 s per 60° = 150 °/s).  Not
        used when the recording has the measured fin angle.
    outlier_level : float
        Bonferroni p-value below which step 7 leaves one step out.
    smoothing_passes : int
        Times the 3-point moving average is applied to the measured velocity
        (§3.2, "several times").
    smoothing_window_s : float
        Span of one moving-average pass, s: the paper's three points at 10 Hz
        (0.3 s); at other sampling rates the number of points follows
        (:func:`identification.methods.steps.smoothing_width`).
    fine_step_s : float
        δt of the interpolated velocity (§2.7.1; 0.01 s = 100 Hz).
    fit_quadratic_damping : bool
        The ``ml`` method also searches a damping growing with the roll rate
        (:func:`identification.methods.ml.quadratic_search`) and keeps the term where its
        likelihood-ratio test admits it at :data:`identification.model.TERM_LEVEL`.
    ud_interval_s : float
        Δt over which ``u_d`` is constant (§2.7.1; 0.1 s).
    noise_levels_pct : tuple of float
        η of the Monte Carlo noise study (§3.3; 1, 2, 5, 10 %).
    noise_runs : int
        Monte Carlo runs per level (100); 0 skips the study.
    noise_seed : int
        Seed of the noise study.
    progress : bool
        Show a progress bar for the noise study.
    """

    min_step_deg: float = setting(
        1.0, "smallest fin change counted as a step", flag="--min-step", gt=0.0, le=90.0, unit="°"
    )
    max_breakpoint_s: float = setting(
        4.0, "ΔT0 of the bi-linear search", flag="--max-breakpoint", gt=0.0, le=600.0, unit="s"
    )
    breakpoint_resolution_s: float = setting(0.01, "breakpoint search step", gt=0.0, cli=False)
    servo_rate_dps: float = setting(
        60.0 / 0.4,
        "servo rate limit for the fin-angle ramp (eq. 23: 150)",
        flag="--servo-rate",
        gt=0.0,
        le=10_000.0,
        unit="°/s",
    )
    outlier_level: float = setting(
        0.05,
        "Bonferroni p below which one step is left out of a(θ)",
        flag="--outlier-level",
        gt=0.0,
        lt=1.0,
    )
    smoothing_passes: int = setting(
        3,
        "3-point moving-average passes on the measured velocity",
        flag="--smoothing-passes",
        ge=0,
        le=1000,
    )
    smoothing_window_s: float = setting(
        SMOOTHING_WINDOW_S,
        "span of one moving-average pass (0.3 s: three points at 10 Hz)",
        flag="--smoothing-window",
        gt=0.0,
        le=600.0,
        unit="s",
    )
    fine_step_s: float = setting(0.01, "δt of the interpolated velocity", gt=0.0, cli=False)
    rig: StatedRig = setting(default_factory=StatedRig, flatten=True)
    fit_quadratic_damping: bool = setting(
        False,
        "the ml method also searches a damping that grows with the roll rate "
        "(a(θ)·(1 + q·|v|/30 °/s)) and keeps it, refitting the rest, where a likelihood-ratio "
        "test admits it at 1 %: the database stores q and the environment replays it",
    )
    ud_interval_s: float = setting(
        0.1, "Δt over which u_d is constant", flag="--ud-interval", gt=0.0, le=600.0, unit="s"
    )
    noise_levels_pct: tuple[float, ...] = setting(
        (1.0, 2.0, 5.0, 10.0),
        "noise levels η of the Monte Carlo study",
        flag="--mc-levels",
        ge=0.0,
        le=100.0,
        unit="%",
    )
    noise_runs: int = setting(
        100, "Monte Carlo runs per noise level; 0 skips the study", flag="--mc-runs", ge=0, le=10**6
    )
    noise_seed: int = setting(0, "seed of the noise study", flag="--mc-seed", ge=0, le=2**63 - 1)
    progress: bool = setting(False, "show a progress bar for the noise study", cli=False)
    v_ref_mps: float | None = setting(
        None,
        "a flight's identification gives a, α at this airspeed and ISA sea-level density "
        "(default: the fitted window's mean airspeed, where the coefficients and the measured "
        "scaling are least correlated)",
        flag="--v-ref",
        metavar="V",
        gt=0.0,
        le=2_000.0,
        unit="m/s",
    )
    scaling: Literal["measured", "eq-4-8"] = setting(
        "measured",
        "a flight's airspeed scaling: measured (fin torque ∝ ρV^n, damping ∝ ρV^m, n and m "
        "estimated, eq. 4-8's n = 2, m = 1 tested) or eq-4-8 (held at the paper's)",
    )
    intervals: Literal["auto", "profile"] = setting(
        "auto",
        "the ml and flight methods' 95 % parameter intervals: auto (the Hessian's ±1.96 SE "
        "where it is positive definite, the profile likelihood's where it is not) or profile "
        "(the profile likelihood's for every parameter: asymmetric, bounded by the "
        "parameter's range; seconds more per model)",
    )
    fit_gyro_bias: bool = setting(
        False,
        "a flight's identification estimates a constant gyro bias (weakly determined in "
        "flight: better subtract one measured on the pad)",
    )
    flight_from: float | None = setting(
        None,
        "a flight's identification fits the recording from this time on (the flights fitted "
        "with it keep theirs)",
        flag="--from",
        metavar="T",
        ge=-1e9,
        le=1e9,
        unit="s",
    )
    flight_to: float | None = setting(
        None, "... and up to this time", flag="--to", metavar="T", ge=-1e9, le=1e9, unit="s"
    )
    min_airspeed_mps: float | None = setting(
        None,
        "a flight's identification fits the longest stretch at or above this airspeed",
        flag="--min-airspeed",
        metavar="V",
        ge=0.0,
        le=2_000.0,
        unit="m/s",
    )
    max_airspeed_mps: float | None = setting(
        None,
        "... and at or below this one",
        flag="--max-airspeed",
        metavar="V",
        gt=0.0,
        le=2_000.0,
        unit="m/s",
    )
    include_supersonic: bool = setting(
        False,
        "a flight's identification fits the samples above Mach 0.8 too (by default it fits "
        "the longest stretch below: the roll model is subsonic); its fit is then weak",
    )

    def __post_init__(self) -> None:
        check(self)
        check_order("flight_from", self.flight_from, self.flight_to, "--to", "s")
        check_order(
            "min_airspeed_mps",
            self.min_airspeed_mps,
            self.max_airspeed_mps,
            "--max-airspeed",
            "m/s",
        )
        if self.breakpoint_resolution_s > self.max_breakpoint_s:
            raise SettingError(
                "max_breakpoint_s",
                f"must be at least the breakpoint search step ({self.breakpoint_resolution_s:g} s)",
            )


@dataclass(frozen=True, eq=False)
class Identification:
    """Every step's result for one recording (paper Fig. 9 and §3).

    Attributes
    ----------
    recording : Recording
        The input.
    options : IdentifyOptions
        The settings used.
    segments : Segments
        Step 1.
    angle_deg, angle_source
        The roll angle used by step 2 and where it came from.
    velocity_dps, velocity_source
        The smoothed measured velocity at the samples (steps 4, 8, 9).
    grid : FineGrid
        The 100 Hz grid; ``velocity_fine`` and ``theta_fine`` live on it.
    theta_source : str
        How the fin angle θ(t) was obtained (step 5).
    piecewise : PiecewiseLinearFit
        Step 2.
    steady : SteadyStateFit
        Step 3.
    bilinear : BilinearFit
        Step 4.
    damping : DampingFit
        Step 6.
    damping_vs_fin : DampingVsFin
        Step 7.
    disturbances : dict
        Step 8, ``{"constant": ..., "theta": ...}``.
    resimulations : dict
        Step 9, same keys.
    statistics : DisturbanceStatistics
        §3.4.
    noise : NoiseStudy or None
        §3.3 (``None`` when ``options.noise_runs == 0``).
    """

    recording: Recording
    options: IdentifyOptions
    segments: Segments
    angle_deg: FloatArray
    angle_source: str
    velocity_dps: FloatArray
    velocity_source: str
    grid: FineGrid
    velocity_fine: FloatArray
    theta_fine: FloatArray
    theta_source: str
    piecewise: PiecewiseLinearFit
    steady: SteadyStateFit
    bilinear: BilinearFit
    bilinear_fine: FloatArray
    damping: DampingFit
    damping_vs_fin: DampingVsFin
    disturbances: dict[str, Disturbance]
    resimulations: dict[str, Resimulation]
    statistics: DisturbanceStatistics
    noise: NoiseStudy | None = field(default=None)

    @property
    def constant_model(self) -> RollParams:
        """The constant-damping model, eq. 29 with eq. 46."""
        return self.damping.params()

    @property
    def theta_model(self) -> RollParams:
        """The θ-dependent model, eq. 49 with eq. 48."""
        return self.damping_vs_fin.params(self.steady.alpha, self.steady.theta_bar_deg)

    def model(self, name: str) -> RollParams:
        """``constant`` or ``theta``."""
        checked_model(name)
        return self.constant_model if name == "constant" else self.theta_model

    @property
    def measurements(self) -> Measurements:
        """What this run started from (steps 1 and 5, §3.2), for other methods."""
        return Measurements(
            steps_found=self.segments,
            velocity_dps=self.velocity_dps,
            velocity_source=self.velocity_source,
            grid=self.grid,
            theta_fine=self.theta_fine,
            theta_source=self.theta_source,
            angle_deg=self.angle_deg,
            angle_source=self.angle_source,
            velocity_fine=self.velocity_fine,
            recording=self.recording,
            servo_rate_dps=_modelled_servo_rate(self.recording, self.options),
        )

    def parameters(self) -> dict[str, float]:
        """The intrinsic parameters, flat (names as in :meth:`to_dict`)."""
        return {
            "alpha": self.steady.alpha,
            "beta_dps": self.steady.beta_dps,
            "theta_bar_deg": self.steady.theta_bar_deg,
            "steady_state_r2": self.steady.r_squared,
            "a_per_s": self.damping.a_per_s,
            "b_per_s2": self.damping.b_per_s2,
            "alpha_bar_per_deg_s": self.damping_vs_fin.alpha_bar_per_deg_s,
            "beta_bar_per_s": self.damping_vs_fin.beta_bar_per_s,
            "damping_vs_fin_r2": self.damping_vs_fin.r_squared,
        }

    def truth(self) -> dict[str, float] | None:
        """Ground truth of a synthetic recording, keyed like :meth:`parameters`.

        For a θ-dependent truth the constant ``a`` has no single true value;
        ``a_per_s`` is then ``a(θ)`` averaged over the steps' fin levels.
        """
        true = self.recording.truth()
        if true is None:
            return None
        a_levels = damping(true, self.segments.step_levels_deg)
        return {
            "alpha": true.alpha,
            "beta_dps": true.beta_dps,
            "theta_bar_deg": true.theta_bar_deg,
            "a_per_s": float(np.mean(a_levels)),
            "b_per_s2": float(np.mean(a_levels)) * true.alpha,
            "alpha_bar_per_deg_s": true.alpha_bar_per_deg_s,
            "beta_bar_per_s": true.beta_bar_per_s,
        }

    def to_dict(self) -> dict[str, Any]:
        """Machine-readable results (JSON-safe; ``u_d`` traces summarised)."""
        seg = self.segments
        out: dict[str, Any] = {
            "recording": {
                "name": self.recording.name,
                "source": self.recording.source,
                "n_samples": self.recording.n_samples,
                "dt_s": self.recording.dt_s,
                "duration_s": self.recording.duration_s,
                "seed": self.recording.seed,
            },
            "options": {
                k: list(v) if isinstance(v, tuple) else v
                for k, v in dataclasses.asdict(self.options).items()
            },
            "sources": {
                "fin_steps": seg.fin_source,
                "angle": self.angle_source,
                "velocity": self.velocity_source,
                "fin_angle": self.theta_source,
            },
            "parameters": self.parameters(),
            "truth": self.truth(),
            "steps": [
                {
                    "start_s": float(seg.time_s[i]),
                    "end_s": float(seg.bounds_s[i + 1]),
                    "fin_deg": float(seg.step_levels_deg[i]),
                    "vss_dps": float(self.piecewise.slopes_dps[i]),
                    "t0_s": float(self.bilinear.t0_s[i]),
                    "a_per_s": float(self.damping.a_steps_per_s[i]),
                    "b_per_s2": float(self.damping.b_steps_per_s2[i]),
                    "outlier": self.damping_vs_fin.outlier == i,
                }
                for i in range(seg.n_steps)
            ],
            "piecewise_rms_deg": self.piecewise.rms_deg,
            "damping_fit_rms_dps": self.damping.rms_dps,
            "damping_vs_fin": {
                "outlier_step": None
                if self.damping_vs_fin.outlier is None
                else self.damping_vs_fin.outlier + 1,
                "outlier_p": self.damping_vs_fin.outlier_p,
                "excluded_steps": [i + 1 for i in self.damping_vs_fin.excluded],
                "rule": self.damping_vs_fin.rule,
            },
            "resimulation": {
                name: {
                    "rate_mae_dps": r.rate_mae_dps,
                    "rate_sd_dps": r.rate_sd_dps,
                    "angle_mae_deg": r.angle_mae_deg,
                    "angle_sd_deg": r.angle_sd_deg,
                }
                for name, r in self.resimulations.items()
            },
            "disturbance": self.statistics.to_dict(),
            "noise_study": None if self.noise is None else self.noise.to_dict(),
        }
        return out


@dataclass(frozen=True, eq=False)
class Measurements:
    """What every estimator on a recording starts from (steps 1 and 5, §3.2).

    Shared by :func:`identify` and every other identification method
    (:mod:`identification.methods`) so all see the same steps, velocity,
    angle and fin angle.

    Attributes
    ----------
    segments : Segments
        Step 1 (a property): the fin steps, or the :class:`IdentificationError`
        that says the recording has none -- raised only for a method that
        reads them (the paper's, output-error); one that does not (ml) still
        runs on ramps-free doublets, chirps and the like.
    velocity_dps, velocity_source
        The smoothed measured roll rate at the samples and where it came from.
    grid : FineGrid
        The 100 Hz grid of §2.7.1.
    theta_fine, theta_source
        The fin angle on the grid (step 5) and how it was obtained.
    angle_deg, angle_source
        The measured roll angle at the samples and where it came from.
    velocity_fine : ndarray
        ``velocity_dps`` interpolated onto the grid.
    recording : Recording
        The recording.
    servo_rate_dps : float or None
        The servo's rate limit the fin angle was modelled with from the commands (step 5);
        None where the fin is measured.
    """

    steps_found: Segments | IdentificationError
    velocity_dps: FloatArray
    velocity_source: str
    grid: FineGrid
    theta_fine: FloatArray
    theta_source: str
    angle_deg: FloatArray
    angle_source: str
    velocity_fine: FloatArray
    recording: Recording
    servo_rate_dps: float | None = None

    @property
    def segments(self) -> Segments:
        """The fin steps (step 1); an :class:`IdentificationError` where there are none."""
        if isinstance(self.steps_found, IdentificationError):
            raise IdentificationError(str(self.steps_found))
        return self.steps_found

    def resimulate(
        self, dist: Disturbance, initial: tuple[float, float] | None = None
    ) -> Resimulation:
        """Step 9 (§3.5): the model driven by ``dist`` against these measurements, from the
        measured state or ``initial`` (rate °/s, angle °)."""
        return resimulate(
            dist,
            self.recording,
            self.grid,
            self.theta_fine,
            self.velocity_dps,
            self.angle_deg,
            initial=initial,
        )

    def require_steps(self) -> None:
        """Refuse a recording with fewer than two fin steps: nothing to fit α and θ̄ on."""
        if self.segments.n_steps < 2:
            raise IdentificationError(
                f"{self.recording.name}: found {self.segments.n_steps} fin step; the "
                "steady-state fit (eq. 16) needs at least two"
            )


def delayed(values: FloatArray, steps: int) -> FloatArray:
    """``values`` ``steps`` samples later, held at the first before (a fin as late sensors'
    readings see it)."""
    if steps == 0:
        return values
    steps = min(steps, values.size)
    return np.concatenate([np.full(steps, values[0]), values[: values.size - steps]])


def delayed_fin(inputs: Measurements, steps: int) -> Measurements:
    """``inputs`` with the fin angle delayed by ``steps`` fine-grid steps (held at its first
    value before): the rocket as late sensors read it is the rocket driven by that fin."""
    if steps == 0:
        return inputs
    return dataclasses.replace(inputs, theta_fine=delayed(inputs.theta_fine, steps))


def with_latency(options: IdentifyOptions | None, latency_s: float) -> IdentifyOptions:
    """``options`` with the sensors' latency stated as ``latency_s``."""
    opts = IdentifyOptions() if options is None else options
    return dataclasses.replace(opts, rig=dataclasses.replace(opts.rig, sensor_latency_s=latency_s))


def latency_stated(recording: Recording, options: IdentifyOptions | None) -> bool:
    """Whether the sensors' latency is stated: by ``identify --sensor-latency`` or the
    recording's ``rig.sensor_latency_s`` line (0 stated is a statement)."""
    stated = (IdentifyOptions() if options is None else options).rig.sensor_latency_s
    return stated is not None or "rig.sensor_latency_s" in recording.metadata


def fitted_rig(rig: Rig, metrics: Mapping[str, Any]) -> Rig:
    """The rig a fit assumed: ``rig`` (stated, or the recording's) with the sensors' latency
    its method found where it admitted one (``metrics["sensor_latency"]``: ``ml`` searches
    one where none is stated); the replay flies the same."""
    found = metrics.get("sensor_latency") or {}
    if not found.get("admitted"):
        return rig
    return dataclasses.replace(rig, latency_s=float(found["estimate_s"]))


def _modelled_servo_rate(recording: Recording, options: IdentifyOptions) -> float | None:
    """The servo's rate limit step 5 models the fin with from the commands; None where the
    recording measures the fin (:func:`~identification.methods.steps.fin_angle_model`)."""
    return None if recording.fin_deg is not None else options.servo_rate_dps


def measurements(recording: Recording, options: IdentifyOptions) -> Measurements:
    """Fin steps (step 1), smoothed velocity (§3.2), 100 Hz grid and fin angle (step 5)."""
    segments: Segments | IdentificationError
    try:
        segments = detect_segments(recording, min_step_deg=options.min_step_deg)
    except IdentificationError as exc:  # for the methods that need steps to say
        segments = exc
    velocity, velocity_source = measured_velocity(
        recording, options.smoothing_passes, options.smoothing_window_s
    )
    grid = fine_grid(recording, options.fine_step_s)
    servo = dataclasses.replace(PAPER_SERVO, rate_limit_dps=options.servo_rate_dps)
    rig = recording.rig_with(options.rig)  # stated here, else by the recording
    theta_fine, theta_source = fin_angle_model(recording, grid, servo, rig.linkage)
    late = math.floor(rig.latency_s / grid.step_s + 0.5)  # to the nearest grid step
    if late > 0:  # what late sensors read is the rocket the fin drove that long before
        theta_fine = delayed(theta_fine, late)
        theta_source += (
            f", delayed {late * grid.step_s:g} s (the sensors' {rig.latency_s:g} s on the "
            f"{grid.step_s:g}-s grid)"
        )
    angle, angle_source = measured_angle(recording)
    velocity_fine = np.interp(grid.time_s, recording.time_s, velocity)
    return Measurements(
        steps_found=segments,
        velocity_dps=velocity,
        velocity_source=velocity_source,
        grid=grid,
        theta_fine=theta_fine,
        theta_source=theta_source,
        angle_deg=angle,
        angle_source=angle_source,
        velocity_fine=velocity_fine,
        recording=recording,
        servo_rate_dps=_modelled_servo_rate(recording, options),
    )


def checked_model(name: str) -> str:
    """``name`` if it names a damping model, else an :class:`IdentificationError`."""
    try:
        return check_model(name)
    except ValueError as exc:
        raise IdentificationError(str(exc)) from None


#: Largest spread of the velocity smoothing
#: (:func:`identification.methods.steps.smoothing_spread_s`) as a fraction of the rocket's
#: time constant 1/a, for the methods that fit the smoothed rate.  The paper's three passes
#: over 0.3 s spread 0.15 s: a fifth to a third of its rocket's 0.5-0.8 s.
SMOOTHING_PER_TIME_CONSTANT = 0.5


def smoothing_for(
    params: RollParams, inputs: Measurements, options: IdentifyOptions
) -> float | None:
    """A velocity smoothing window short against ``params``' time constant, where the
    one of ``options`` is not; ``None`` where it is.

    The moving average of §3.2 is a low-pass filter.  Against a rocket whose time
    constant 1/a is not long next to the filter's spread it reshapes the response being
    fitted (a fast rocket's rate after a fin ramp is smeared over the filter's span), and
    the ``u_d`` of eq. 35-44, recovered from the smoothed rate and the unsmoothed fin,
    takes the difference up in the fin's shape.  The window returned is the longest whose
    spread is at most :data:`SMOOTHING_PER_TIME_CONSTANT` of 1/a, ``a`` the median damping
    along the recording's fin angle (an odd number of samples; one sample, i.e. no
    smoothing, for a rocket faster than the sampling).
    """
    passes, dt = options.smoothing_passes, inputs.recording.dt_s
    typical = float(np.median(damping(params, inputs.theta_fine)))
    if passes == 0 or not typical > 0:
        return None
    limit_s = SMOOTHING_PER_TIME_CONSTANT / typical
    if smoothing_spread_s(dt, passes, options.smoothing_window_s) <= limit_s:
        return None
    width = int(np.floor(np.sqrt(12.0 * limit_s**2 / (passes * dt**2) + 1.0)))
    width = max(1, width if width % 2 else width - 1)
    return round(width * dt, 9)


def model_inputs(recording: Recording, model: str, options: IdentifyOptions | None) -> Measurements:
    """:func:`measurements` for an estimator of one damping model, which ``model`` must
    name (an :class:`IdentificationError` otherwise); ``options`` default to the paper's."""
    checked_model(model)
    return measurements(recording, IdentifyOptions() if options is None else options)


def recover_disturbance(
    inputs: Measurements, params: RollParams, model: str, options: IdentifyOptions
) -> tuple[Disturbance, Resimulation]:
    """Steps 8-9 for given parameters: ``u_d`` (eq. 35-44) and its re-simulation (§3.5).

    Any identification method's parameters get their disturbance this way,
    so the traces and re-simulation errors of all methods compare like for
    like.
    """
    dist = identify_disturbance(
        params,
        model,
        inputs.grid,
        inputs.theta_fine,
        inputs.velocity_fine,
        interval_s=options.ud_interval_s,
    )
    return dist, inputs.resimulate(dist)


def identify(recording: Recording, options: IdentifyOptions | None = None) -> Identification:
    """Run the paper's pipeline (Fig. 9) on a recording.

    Parameters
    ----------
    recording : Recording
        Any format-v1 recording: an encoder and/or a rate gyro, a commanded
        and/or a measured fin angle, with at least two fin steps.
    options : IdentifyOptions, optional
        Settings; the defaults are the paper's.

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        If the recording cannot be identified (e.g. fewer than two fin levels).

    Examples
    --------
    >>> from identification.instruments.bundled import load_bundled
    >>> from identification.methods.pipeline import IdentifyOptions, identify
    >>> result = identify(load_bundled("tunnel-paper-seed0"), IdentifyOptions(noise_runs=0))
    >>> round(result.steady.alpha, 2), result.segments.n_steps
    (0.68, 8)
    """
    opts = IdentifyOptions() if options is None else options
    inputs = measurements(recording, opts)
    segments, grid, theta_fine = inputs.segments, inputs.grid, inputs.theta_fine
    velocity = inputs.velocity_dps
    inputs.require_steps()
    angle, angle_source = inputs.angle_deg, inputs.angle_source
    velocity_fine = inputs.velocity_fine

    # Steps 2-7 on the data after the first deflection (§2.1).
    piecewise = fit_piecewise_linear(
        recording.time_s, angle, segments.bounds_s, angle_source=angle_source
    )
    steady = fit_steady_state(segments.step_levels_deg, piecewise.slopes_dps)
    bilinear = fit_bilinear(
        segments,
        steady,
        grid,
        velocity_fine,
        max_breakpoint_s=opts.max_breakpoint_s,
        resolution_s=opts.breakpoint_resolution_s,
    )
    bilinear_fine, _ = bilinear_velocity(segments, bilinear, grid)
    damping_fit = fit_damping(segments, steady, grid, bilinear_fine, theta_fine)
    vs_fin = fit_damping_vs_fin(
        segments.step_levels_deg,
        damping_fit.a_steps_per_s,
        steady.theta_bar_deg,
        outlier_level=opts.outlier_level,
    )

    # Steps 8-9 on all the data, for both models.
    models = {
        "constant": damping_fit.params(),
        "theta": vs_fin.params(steady.alpha, steady.theta_bar_deg),
    }
    recovered = {name: recover_disturbance(inputs, p, name, opts) for name, p in models.items()}
    disturbances = {name: dist for name, (dist, _) in recovered.items()}
    resims = {name: resim for name, (_, resim) in recovered.items()}
    statistics = disturbance_statistics(disturbances["theta"], disturbances["constant"])
    noise = None
    if opts.noise_runs > 0 and opts.noise_levels_pct:
        noise = noise_study(
            models["constant"],
            grid,
            theta_fine,
            velocity_fine,
            levels_pct=opts.noise_levels_pct,
            runs=opts.noise_runs,
            seed=opts.noise_seed,
            interval_s=opts.ud_interval_s,
            smoothing_passes=opts.smoothing_passes,
            smoothing_window_s=opts.smoothing_window_s,
            progress=opts.progress,
        )
    return Identification(
        recording=recording,
        options=opts,
        segments=segments,
        angle_deg=angle,
        angle_source=angle_source,
        velocity_dps=velocity,
        velocity_source=inputs.velocity_source,
        grid=grid,
        velocity_fine=velocity_fine,
        theta_fine=theta_fine,
        theta_source=inputs.theta_source,
        piecewise=piecewise,
        steady=steady,
        bilinear=bilinear,
        bilinear_fine=bilinear_fine,
        damping=damping_fit,
        damping_vs_fin=vs_fin,
        disturbances=disturbances,
        resimulations=resims,
        statistics=statistics,
        noise=noise,
    )
