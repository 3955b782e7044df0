"""The ``flight`` identification method: the part of a flight the roll model holds for, the
flight fit (:mod:`identification.methods.flightfit`) on it, and how far it can be trusted.

A flight log goes on past apogee, through supersonic stretches and slow ones;
:func:`flight_window` keeps the ascent, the user's time and airspeed window and
the subsonic part.  :func:`flight_method` fits the models there (alone or with
other flights, ``--together``), predicts a held-out part of the flight
(:func:`held_out_prediction`) and judges each fit (:func:`flight_adequacy`) with
the tunnel's figures and limits where they apply and the flight's own failures,
each reason in the user's terms.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from identification.methods import ModelFit
from identification.methods.diagnosis import Diagnosis, diagnose, logged_fin
from identification.methods.flightfit import (
    EXPONENT_BOUNDS,
    LOG_BOUND,
    MIN_DAMPING,
    MIN_MOVING_INTERVALS,
    SUBSTEPS,
    FlightFit,
    FlightInputs,
    c_coefficients,
    flight_inputs,
    identify_flights,
    measured_rate,
    rescale,
    resimulated,
)
from identification.methods.steps import IdentificationError
from identification.model import RollParams
from identification.recordings.flight import mach_numbers, mean_airspeed
from identification.recordings.recording import FinRange, Recording, RecordingError
from rocketroll_common.arrays import FloatArray
from rocketroll_physics.atmosphere import ISA_SEA_LEVEL_DENSITY_KGM3
from rocketroll_physics.scaling import EQ_4_8, MACH_LIMIT, TUNNEL_AIRSPEED_MPS, AirspeedScaling

if TYPE_CHECKING:
    from identification.methods import Context
    from identification.methods.pipeline import IdentifyOptions

__all__ = [
    "HELD_OUT_SPLIT",
    "FlightWindow",
    "apogee_index",
    "flight_adequacy",
    "flight_method",
    "flight_window",
    "held_out_prediction",
    "longest_stretch",
    "model_only_r2",
    "model_only_r2_of",
    "subsonic_part",
]


#: A fitted damping within this factor of :data:`MIN_DAMPING` (at its smallest over the
#: flown fin angles) sits on the bound the fit keeps it above.
ON_BOUND_FACTOR = 2.0


#: Sensor noises the fit may drive to its bound: a sensor without that noise, not a
#: parameter the flight fails to determine.
_SENSOR_NOISE = ("gyro_rel", "gyro_abs", "angle_sd")


def flight_adequacy(result: FlightFit, fin_range: FinRange | None = None) -> dict[str, Any]:
    """How far a flight fit can be trusted, with the tunnel's figures and limits
    (:mod:`identification.methods.adequacy`) where they apply, and the flight's own failures.

    * **a parameter on a bound** -- the damping at its floor (:data:`MIN_DAMPING`: the
      fit makes the rocket an integrator) or a log-parameter at the optimiser's bound:
      unreliable, the flight does not determine it;
    * **no standard errors** (the likelihood's Hessian not positive definite at the fit):
      unreliable;
    * the model **without** ``u_d`` against the measured rate (R², along the flight's
      scales), ``u_d`` against the fins' range (``fin_range``; default the fitted
      recording's, :meth:`~identification.recordings.recording.Recording.fin_range`: stated,
      else the log's largest ``|fin|``, named in the reason) and α's relative standard
      error, with the
      tunnel's weak and unreliable limits (:data:`~identification.methods.adequacy.RATE_R2`,
      :data:`~identification.methods.adequacy.UD_RANGE`,
      :data:`~identification.methods.adequacy.ALPHA_REL_SE`);
    * a fin under 1° all flight (:meth:`~identification.methods.adequacy.Findings.fin_unit`):
      unreliable;
    * the optimiser not reporting convergence: weak;
    * the fin acting later than the model (:func:`identification.methods.adequacy.suspects`):
      suspected, not judged; the turbulence's intensity is not (in flight it changes with
      the airspeed by the model itself).

    Returns the figures the adequacy table prints (``rate_r2``, ``ud_range_fraction``,
    ``alpha_rel_se``; the tunnel's ``ahead_r2`` and ``fin_share`` are None), the fins' range
    and where it comes from (``fin_range_deg``, ``fin_range_source``), ``on_bound``,
    ``fin_delay_s``, ``fin_delay_z``, ``suspected``, ``verdict`` and ``reasons``,
    JSON-safe.
    """
    from identification.methods.adequacy import ALPHA_REL_SE, UD_RANGE, Findings, suspects

    params, inputs = result.params, result.inputs
    found = Findings()
    bad, weak = found.bad, found.weak
    flown = np.abs(inputs.theta + params.theta_bar_deg)
    slope = params.alpha_bar_per_deg_s
    lowest = params.beta_bar_per_s + (slope * float(np.max(flown)) if slope < 0 else 0.0)
    on_bound = []
    if lowest <= ON_BOUND_FACTOR * MIN_DAMPING:
        on_bound.append("damping")
        bad.append(
            f"the damping sits on its lower bound (a(θ) {lowest:.2g} 1/s, the fit keeps it "
            f"above {MIN_DAMPING:g}): the flight does not determine it (an integrator)"
        )
    for name, value in result.estimates.items():
        at_bound = value > 0 and abs(abs(math.log(value)) - LOG_BOUND) < 1e-6
        if name.endswith("_exponent"):
            at_bound = result.scaling_measured and (
                min(abs(value - edge) for edge in EXPONENT_BOUNDS) < 1e-6
            )
        if at_bound and name not in _SENSOR_NOISE:
            on_bound.append(name)
            bad.append(f"{name} sits on the optimiser's bound: the flight does not determine it")
    errors = result.std_errors
    if not errors or not all(math.isfinite(v) for v in errors.values()):
        bad.append(
            "no standard errors (the likelihood's Hessian is not positive definite at the fit): "
            "the flight does not determine the parameters"
        )
    alpha_se = errors.get("alpha", math.nan)
    rel_se = abs(alpha_se / params.alpha) if math.isfinite(alpha_se) and params.alpha else math.nan
    rate_r2 = model_only_r2(result)
    p99 = float(np.percentile(np.abs(result.u_d_deg), 99.0))
    fins = inputs.recording.fin_range() if fin_range is None else fin_range

    found.fin_unit(inputs.recording)
    found.rate_r2(rate_r2)
    found.check(
        p99 / fins.deg,
        UD_RANGE,
        f"u_d reaches {p99:.3g}° (99th percentile), {p99 / fins.deg:.2g} of the fins' "
        f"{fins}: model error, not turbulence{fins.hint}",
        True,
    )
    if math.isfinite(rel_se):
        found.check(rel_se, ALPHA_REL_SE, f"α's standard error is {100 * rel_se:.3g} % of it", True)
    if not result.converged:
        weak.append("the optimiser did not report convergence")
    fin = np.asarray(inputs.theta[::SUBSTEPS], dtype=float)  # at the readings
    u = np.asarray(result.u_d_deg, dtype=float)
    delay_s, delay_z, _, suspected = suspects(
        u, fin, inputs.dt_s, inputs.rate_limit_dps is None, None
    )

    why = _diagnosis(inputs, u, fins)

    def safe(value: float) -> float | None:
        return value if math.isfinite(value) else None

    return {
        "rate_source": "gyro" if inputs.rate is not None else "velocity from the angle",
        "rate_r2": safe(rate_r2),
        "ahead_r2": None,
        "fin_share": None,
        "ud_p99_deg": p99,
        "ud_range_fraction": p99 / fins.deg,
        **fins.as_dict(),
        "alpha_rel_se": safe(rel_se),
        "on_bound": on_bound,
        "fin_delay_s": safe(delay_s),
        "fin_delay_z": safe(delay_z),
        "suspected": suspected,
        "verdict": found.verdict,
        "reasons": list(found.reasons),
        "diagnosis": why.as_dict(),
    }


def _diagnosis(inputs: FlightInputs, u: FloatArray, fins: FinRange) -> Diagnosis:
    """:func:`~identification.methods.diagnosis.diagnose` on a flight: the regressors of its
    one-step equation are the fin's torque ``q·δ``, the damping's ``ρV·p`` and a constant
    torque ``q`` (``q`` and ``ρV`` relative to the reference)."""
    n = inputs.n
    fin = logged_fin(inputs.recording)  # a loop acts on the command, not the modelled fin
    speed = np.asarray(inputs.speed_ratio[::SUBSTEPS][:n], dtype=float)
    density = np.asarray(inputs.density_ratio[::SUBSTEPS][:n], dtype=float)
    q = density * speed**2
    rate = np.asarray(measured_rate(inputs), dtype=float)[:n]
    return diagnose(
        fin[:n],
        rate,
        inputs.dt_s,
        fins,
        turbulence_sd_deg=float(np.std(u)),
        regressors={
            "q·δ (the fin's torque)": q * fin[:n],
            "ρV·p (the damping)": density * speed * rate,
            "q (a constant torque)": q,
        },
    )


def longest_stretch(recording: Recording, keep: ArrayLike, why: str) -> Recording:
    """The longest stretch of ``recording`` whose samples ``keep`` says (a boolean per
    sample); the recording itself where it keeps every sample.

    Raises
    ------
    IdentificationError
        Where no stretch is kept, or the longest is shorter than
        :data:`MIN_MOVING_INTERVALS` samples (``why`` says what was kept).
    """
    time = np.asarray(recording.time_s)
    below = np.asarray(keep, dtype=bool)
    if bool(np.all(below)):
        return recording
    best, start, best_span = (0, 0), None, -1.0
    for k, ok in enumerate([*below.tolist(), False]):
        if ok and start is None:
            start = k
        elif not ok and start is not None:
            span = float(time[k - 1] - time[start])
            if span > best_span:
                best, best_span = (start, k), span
            start = None
    if best_span <= 0.0:
        raise IdentificationError(f"recording {recording.name!r}: no samples {why}")
    first, stop = best
    end = float(time[stop]) if stop < time.size else float(time[-1]) + 1.0
    try:
        part = recording.part(float(time[first]), end)
    except RecordingError:
        part = None
    if part is None or part.n_samples < MIN_MOVING_INTERVALS:
        raise IdentificationError(
            f"recording {recording.name!r}: its longest stretch {why} lasts "
            f"{best_span:.3g} s ({stop - first} samples), too short to fit"
        )
    return part


def _span(recording: Recording) -> float:
    return float(recording.time_s[-1] - recording.time_s[0])


def subsonic_part(recording: Recording, limit: float = MACH_LIMIT) -> tuple[Recording, float]:
    """The longest stretch of ``recording`` whose Mach number (its airspeed over the ISA
    speed of sound at its altitude, or at sea level without one) stays at or below
    ``limit``, and how many seconds of the log it leaves out; the recording itself and 0
    where it never goes above."""
    mach = mach_numbers(recording)
    try:
        part = longest_stretch(recording, mach <= limit, f"at or below Mach {limit:g}")
    except IdentificationError as exc:
        raise IdentificationError(
            f"{exc} (peak Mach {float(mach.max()):.2f}); the roll model is subsonic "
            "(--include-supersonic fits it anyway)"
        ) from None
    return part, _span(recording) - _span(part)


def apogee_index(recording: Recording) -> int | None:
    """The sample of a flight's apogee where its log goes on past it, else None.

    With an altitude column: its highest sample, where the altitude falls by more than
    5 m (and 1 % of the climb) after it.  Without one: the slowest sample after the
    fastest, where the airspeed drops below a tenth of the fastest and picks up again by
    more than 5 m/s (and a tenth of the fastest) after it -- the fall.
    """
    if recording.altitude_m is not None:
        height = np.asarray(recording.altitude_m)
        top = int(np.argmax(height))
        drop = float(height[top] - height[top:].min())
        return top if drop > max(5.0, 0.01 * float(height[top] - height.min())) else None
    assert recording.airspeed_mps is not None
    speed = np.asarray(recording.airspeed_mps)
    fastest = int(np.argmax(speed))
    slowest = fastest + int(np.argmin(speed[fastest:]))
    peak = float(speed[fastest])
    if speed[slowest] < 0.1 * peak and speed[slowest:].max() > speed[slowest] + max(
        5.0, 0.1 * peak
    ):
        return slowest
    return None


@dataclass(frozen=True)
class FlightWindow:
    """The part of a flight the flight method fits (:func:`flight_window`) and what the
    model's limits left out of the rest, s."""

    part: Recording
    supersonic_excluded_s: float = 0.0
    descent_excluded_s: float = 0.0


def flight_window(recording: Recording, options: IdentifyOptions) -> FlightWindow:
    """The part of a flight the flight method fits: the ascent (the log to apogee, where it
    goes on past it: :func:`apogee_index`; falling, the rocket no longer flies into the
    flow its fins were identified in), then the options' time window (``--from``,
    ``--to``), then the longest stretch within their airspeed range (``--min-airspeed``,
    ``--max-airspeed``), then at or below :data:`MACH_LIMIT` (unless
    ``--include-supersonic``); and how many seconds the descent and the Mach limit left
    out."""
    part = recording
    top = apogee_index(recording)
    descent = 0.0
    if top is not None:
        part = recording.part(float(recording.time_s[0]), float(recording.time_s[top + 1]))
        descent = _span(recording) - _span(part)
    if options.flight_from is not None or options.flight_to is not None:
        t0 = float(recording.time_s[0]) if options.flight_from is None else options.flight_from
        t1 = float(recording.time_s[-1]) + 1.0 if options.flight_to is None else options.flight_to
        try:
            part = recording.part(t0, t1)
        except RecordingError as exc:
            raise IdentificationError(
                f"recording {recording.name!r}: --from/--to leave nothing to fit ({exc})"
            ) from None
        if part.n_samples < MIN_MOVING_INTERVALS:
            raise IdentificationError(
                f"recording {recording.name!r}: --from/--to keep {part.n_samples} samples "
                f"(at least {MIN_MOVING_INTERVALS} needed)"
            )
    low, high = options.min_airspeed_mps, options.max_airspeed_mps
    if low is not None or high is not None:
        speed = np.asarray(part.airspeed_mps)
        keep = (speed >= (low or 0.0)) & (speed <= (math.inf if high is None else high))
        shown = f"[{low or 0:g}, {'∞' if high is None else f'{high:g}'}] m/s"
        part = longest_stretch(part, keep, f"with the airspeed in {shown}")
    if options.include_supersonic:
        return FlightWindow(part, 0.0, descent)
    part, supersonic = subsonic_part(part)
    return FlightWindow(part, supersonic, descent)


#: The share of a flight's fitted window the held-out check fits; it predicts the rest.
HELD_OUT_SPLIT = 0.7


def model_only_r2_of(
    inputs: FlightInputs,
    params: RollParams,
    scaling: AirspeedScaling = EQ_4_8,
    gyro_bias_dps: float | None = None,
) -> float:
    """R² of the measured rate (less the gyro's bias) by ``params``' model without ``u_d``
    over ``inputs`` along ``scaling``, from the first measured rate."""
    from identification.methods.adequacy import r_squared

    measured = measured_rate(inputs) - (gyro_bias_dps or 0.0)
    sim = resimulated(inputs, params, np.zeros(inputs.n), float(measured[0]), scaling)
    return r_squared(np.asarray(sim.rate_dps), measured)


def model_only_r2(fit: FlightFit, inputs: FlightInputs | None = None) -> float:
    """R² of the measured rate by ``fit``'s model without ``u_d`` (its scaling, less its
    gyro bias) over ``inputs`` (default: the flight it fitted), from the first measured rate."""
    return model_only_r2_of(
        fit.inputs if inputs is None else inputs, fit.params, fit.scaling, fit.gyro_bias_dps
    )


def held_out_prediction(
    inputs: FlightInputs,
    models: Sequence[str],
    servo_rate_dps: float,
    scaling: AirspeedScaling | None = None,
    gyro_bias: bool = False,
) -> tuple[dict[str, dict[str, Any]], FlightInputs | None]:
    """Each model fitted to the first :data:`HELD_OUT_SPLIT` of the flight's window and
    judged on the rest, which it did not see: the model without ``u_d`` over the later part
    (its rate R², from the measured rate where the part starts), beside the full fit's on
    the same samples (:func:`flight_method` adds it).  Per model ``{"from_s",
    "rate_r2"}``, or ``{"skipped": reason}`` where a part is too short or the fit fails;
    and the later part's inputs (None where it could not be cut).  ``scaling`` as for
    :func:`identify_flights` (the first part's exponents measured on it alone where None)."""
    rec = inputs.recording
    t0, t1 = float(rec.time_s[0]), float(rec.time_s[-1])
    split = t0 + HELD_OUT_SPLIT * (t1 - t0)
    try:
        early = flight_inputs(
            rec.part(t0, split),
            v_ref_mps=inputs.v_ref_mps,
            servo_rate_dps=servo_rate_dps,
            rig=inputs.rig,
        )
        late = flight_inputs(
            rec.part(split, t1 + 1.0),
            v_ref_mps=inputs.v_ref_mps,
            servo_rate_dps=servo_rate_dps,
            rig=inputs.rig,
        )
    except (IdentificationError, RecordingError) as exc:
        skipped = {"skipped": f"a part is too short to fit ({exc})"}
        return {model: dict(skipped) for model in models}, None
    out: dict[str, dict[str, Any]] = {}
    constant: list[FlightFit] | None = None
    for model in sorted(models, key=lambda m: m != "constant"):
        try:
            fitted = identify_flights(
                [early], model, constant=constant, scaling=scaling, gyro_bias=gyro_bias
            )
        except IdentificationError as exc:
            out[model] = {"skipped": f"the first part's fit failed ({exc})"}
            continue
        if model == "constant":
            constant = fitted
        out[model] = {"from_s": split, "rate_r2": model_only_r2(fitted[0], late)}
    return out, late


def _judge_held_out(
    adequacy: dict[str, Any],
    held_out: dict[str, Any] | None,
    fit: FlightFit,
    late: FlightInputs | None,
) -> None:
    """Add the held-out prediction to a flight fit's adequacy: its figures, and a reason
    where the model without ``u_d`` predicts the unseen part worse than the adequacy's
    rate limits (:data:`~identification.methods.adequacy.RATE_R2`)."""
    from identification.methods.adequacy import RATE_R2, beyond

    if held_out is None:
        return
    adequacy["held_out"] = dict(held_out)
    r2 = held_out.get("rate_r2")
    if r2 is None or late is None or not math.isfinite(r2):
        return
    adequacy["held_out"]["full_fit_rate_r2"] = model_only_r2(fit, late)
    text = (
        f"fitted on the flight to {held_out['from_s']:.3g} s, the model without u_d predicts "
        f"the rest to R² {r2:.2f}"
    )
    _add_reason(adequacy, text, beyond(r2, RATE_R2, above=False))


def _add_reason(adequacy: dict[str, Any], text: str, severity: int) -> None:
    """``text`` among a judged fit's reasons, its verdict at least as bad as ``severity``
    (1 weak, 2 unreliable; 0 adds nothing)."""
    from identification.methods.adequacy import VERDICTS

    if severity:
        adequacy["reasons"] = [*adequacy["reasons"], text]
        worst = max(VERDICTS.index(adequacy["verdict"]), severity)
        adequacy["verdict"] = VERDICTS[worst]


def _at_tunnel(fit: FlightFit) -> dict[str, float]:
    """The fit's rocket carried to the tunnel's airspeed and ISA sea level by its scaling,
    to set beside a tunnel identification (an extrapolation where the flight flew faster)."""
    inputs = fit.inputs
    params = rescale(
        fit.params,
        (inputs.v_ref_mps, inputs.rho_ref_kgm3),
        (TUNNEL_AIRSPEED_MPS, ISA_SEA_LEVEL_DENSITY_KGM3),
        fit.scaling,
    )
    return {
        "v_ref_mps": TUNNEL_AIRSPEED_MPS,
        "alpha": params.alpha,
        "beta_bar_per_s": params.beta_bar_per_s,
        "alpha_bar_per_deg_s": params.alpha_bar_per_deg_s,
    }


def flight_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """The ``flight`` identification method: :func:`identify_flights` per model on the
    recording and the flights fitted with it (``--together``), at the options' reference
    airspeed (``--v-ref``; default the window's mean) and scaling (``--scaling``: measured
    unless eq-4-8); the recording's fit."""
    options = context.options
    scaling = None if options.scaling == "measured" else EQ_4_8
    recordings = [context.recording, *context.together]
    cut = [flight_window(recording, options) for recording in recordings]
    recordings = [window.part for window in cut]
    v_ref = options.v_ref_mps or mean_airspeed(recordings)
    flights = [
        flight_inputs(
            recording,
            v_ref_mps=v_ref,
            servo_rate_dps=options.servo_rate_dps,
            rig=recording.rig_with(options.rig),
        )
        for recording in recordings
    ]
    inputs = flights[0]
    fits: dict[str, ModelFit] = {}
    constant: list[FlightFit] | None = None
    held_out, late = (
        held_out_prediction(inputs, models, options.servo_rate_dps, scaling, options.fit_gyro_bias)
        if len(flights) == 1
        else ({}, None)
    )
    peak = float(np.max(mach_numbers(inputs.recording)))
    # The constant model first: the θ-dependent one starts from its fit.
    for model in sorted(models, key=lambda m: m != "constant"):
        joint = identify_flights(
            flights,
            model,
            constant=constant,
            scaling=scaling,
            gyro_bias=options.fit_gyro_bias,
            intervals=options.intervals,
        )
        if model == "constant":
            constant = joint
        result = joint[0]
        metrics: dict[str, Any] = {
            **result.resimulate(),
            "v_ref_mps": inputs.v_ref_mps,
            "rho_ref_kgm3": inputs.rho_ref_kgm3,
            "density": inputs.density,
            **c_coefficients(result.params, inputs.v_ref_mps, inputs.rho_ref_kgm3),
            "loglike": result.loglike,
            "converged": result.converged,
            "turbulence_sd_deg": result.turbulence_sd_deg,
            "turbulence_tau_s": result.turbulence_tau_s,
            "std_errors": result.std_errors,
            "intervals": result.intervals,
            "flights": len(flights),
            "fitted_with": [f.recording.name for f in flights[1:]],
            "adequacy": flight_adequacy(result, context.recording.fin_range()),
            "fitted_s": [float(inputs.recording.time_s[0]), float(inputs.recording.time_s[-1])],
            "supersonic_excluded_s": cut[0].supersonic_excluded_s,
            "descent_excluded_s": cut[0].descent_excluded_s,
            "torque_exponent": result.scaling.torque_exponent,
            "damping_exponent": result.scaling.damping_exponent,
            "scaling_measured": result.scaling_measured,
            "eq_4_8_test": result.eq_4_8_test,
            "at_tunnel_airspeed": _at_tunnel(result),
        }
        _judge_held_out(metrics["adequacy"], held_out.get(model), result, late)
        _add_reason(
            metrics["adequacy"],
            f"it fits samples up to Mach {peak:.2f}: the roll model is subsonic "
            f"(eq. 4-8; above Mach {MACH_LIMIT:g} it is not)",
            1 if peak > MACH_LIMIT else 0,
        )
        if result.gyro_noise_pct is not None:
            metrics["gyro_noise_pct"] = result.gyro_noise_pct
            metrics["gyro_floor_dps"] = result.gyro_floor_dps
            if result.gyro_bias_dps is not None:
                metrics["gyro_bias_dps"] = result.gyro_bias_dps
        settings = {
            "interval_s": inputs.dt_s,
            "equations": f"flight Kalman smoother ({result.scaling.label()} scaling)",
            "frame": "flight",
            "v_ref_mps": inputs.v_ref_mps,
            "torque_exponent": result.scaling.torque_exponent,
            "damping_exponent": result.scaling.damping_exponent,
            "servo_rate_dps": options.servo_rate_dps,
            "rate0_dps": float(result.rate_dps[0]),  # the re-simulation's start
            "rig": dataclasses.asdict(inputs.rig),  # the fin the fit saw (the report's too)
        }
        fits[model] = ModelFit(
            "flight",
            model,
            result.params,
            result.disturbance(),
            metrics,
            settings,
            u_d_sd_deg=result.u_d_sd_deg,
            sample_posterior=result.posterior_draws,
        )
    return [fits[model] for model in models]
