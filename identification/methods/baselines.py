"""A peer estimator for comparison: output-error nonlinear least squares.

The paper contrasts its integral-based method with the usual approach to
roll identification, nonlinear optimisation of a simulated model's output
(§1, refs. 28-30).  :func:`output_error` is that approach on the same
recording and the same model (eq. 29 or eq. 49, simulated by
:func:`identification.model.simulate`): the parameters minimise the squared
difference between the simulated roll rate -- with the disturbance left out,
i.e. treated as output noise -- and the measured one, by
``scipy.optimize.least_squares`` (trust-region reflective, finite-difference
Jacobian).  Same data as steps 1-4 (after the first deflection), same
velocity processing and fin-angle model as the pipeline -- but no fin steps are
needed: the fit starts where the fin first moves (:func:`first_deflection`), so
ramps, sine sweeps, doublets and random inputs fit as the paper's schedule does,
at any sampling rate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from identification.methods import Context, ModelFit, resimulation_metrics, trace_settings
from identification.methods.pipeline import (
    IdentifyOptions,
    Measurements,
    model_inputs,
    recover_disturbance,
    smoothing_for,
)
from identification.methods.steps import IdentificationError
from identification.model import RollParams, damping, simulate
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray

__all__ = ["OutputErrorFit", "first_deflection", "output_error", "output_error_method"]

#: Most refits over a shorter velocity smoothing (:func:`output_error_method`).
MAX_RESMOOTHING = 3

#: Smallest damping the optimiser may visit, 1/s (keeps the simulation stable).
MIN_DAMPING = 0.01

#: Largest damping the optimiser may visit, as ``a·Δt`` over the sampling interval: a
#: rocket that settles by e^-20 within one sample follows the fin at once as far as the
#: samples show, the cost no longer changes beyond, and a rate that follows the fin with
#: no lag at all would draw the fit on until the model's exponentials underflow.
MAX_DAMPING_SAMPLE = 20.0

#: Typical damping (the median along the fin's path) at which a fit is refused, as
#: ``a·Δt``: the rate shows no lag behind the fin, and its damping, near
#: :data:`MAX_DAMPING_SAMPLE`, is the bound's, not the recording's.
NO_LAG_SAMPLE = 10.0

#: Change of the fin angle between two points of the fine grid above which the fin
#: counts as moving, ° (step 1's sample-to-sample tolerance).
FIN_STILL_DEG = 0.05

#: Fewest samples from the first deflection on that output error fits.
MIN_FIT_SAMPLES = 10

#: Relative margin by which the fit from the one-step regression's start must lower the
#: cost of the one from the line's to be kept (:func:`output_error`, an input without
#: held steps): both reach the same optimum on most recordings, to the optimiser's
#: tolerance.
SAME_COST = 1e-6


@dataclass(frozen=True, eq=False)
class OutputErrorFit:
    """Result of :func:`output_error`.

    Attributes
    ----------
    model : str
        ``constant`` (α, θ̄, a) or ``theta`` (α, θ̄, ᾱ, β̄).
    params : RollParams
        The estimate.
    rate_rmse_dps : float
        RMS of simulated minus measured roll rate at the optimum, °/s.
    nfev : int
        Model simulations used by the optimiser (without the Jacobian's), from the
        start kept (:func:`output_error`).
    success : bool
        ``scipy.optimize.least_squares`` converged.
    message : str
        Its message.
    std_errors, correlations : dict
        Each parameter's standard error and each pair's correlation, from the
        Jacobian at the optimum with a Newey-West covariance of the residuals
        (:func:`_sandwich`; the rate's error holds the turbulence's response, far from
        white).
    """

    model: str
    params: RollParams
    rate_rmse_dps: float
    nfev: int
    success: bool
    message: str
    std_errors: dict[str, float] = field(default_factory=dict)
    correlations: dict[str, float] = field(default_factory=dict)


def output_error(
    recording: Recording,
    model: str = "constant",
    *,
    options: IdentifyOptions | None = None,
    x0: RollParams | None = None,
) -> OutputErrorFit:
    """Fit eq. 29 (``model="constant"``) or eq. 49 (``"theta"``) by output error.

    Parameters
    ----------
    recording : Recording
        Any recording the pipeline accepts.
    model : str
        ``constant`` or ``theta``.
    options : IdentifyOptions, optional
        Velocity smoothing, fine grid and servo settings (shared with
        :func:`identification.methods.pipeline.identify`).
    x0 : RollParams, optional
        Starting point.  Default: α and β from a straight line through the
        measured rate against the fin angle (all samples from the first
        deflection on, :func:`first_deflection`), ``a = 1 1/s``, ``ᾱ = 0`` --
        nothing from the paper's method or the ground truth.  That line reads
        the steady state, which held fin steps reach (two or more, step 1) and
        a sweep or a quick random input never does: without them the fit also
        starts from the one-step regression of the rate on itself and the fin,
        and the lower cost is kept (the line's, unless the other's is lower by
        more than :data:`SAME_COST`).

    Raises
    ------
    IdentificationError
        Where the fin first moves fewer than :data:`MIN_FIT_SAMPLES` samples
        from the end, or the fitted rate follows the fin with no lag the
        samples show (:data:`NO_LAG_SAMPLE`).

    Returns
    -------
    OutputErrorFit
    """
    return _output_error(model_inputs(recording, model, options), model, x0)


def first_deflection(inputs: Measurements) -> int:
    """Index of the sample output error starts from: where the fin first moves.

    On a recording with fin steps that is the first step ``T_1`` (step 1), so output
    error fits the data the paper's steps 1-4 fit (§2.1: after the first deflection).
    On any other input it is the last sample before the fin angle the model is driven
    with (step 5, on the fine grid) first changes by more than :data:`FIN_STILL_DEG`:
    the same instant for a command, which the servo follows from the sample it changes
    at, and for a measured fin, which leaves its level after that sample.

    Not the first sample: before the first deflection a log may hold the rig starting
    up (the wind rising, the rocket released), which the model does not describe, and
    with the fin held it tells only the level ``α·θ̄`` plus the turbulence's mean --
    which the data after it tell as well.  A fin noisy beyond the tolerance moves from
    the first sample, and the fit starts there.
    """
    steps = inputs.steps_found
    if not isinstance(steps, IdentificationError) and steps.n_steps:
        return int(steps.start_index[0])
    theta = np.asarray(inputs.theta_fine, dtype=float)
    moving = np.flatnonzero(np.abs(np.diff(theta)) > FIN_STILL_DEG)
    return int(moving[0]) // inputs.grid.per_sample if moving.size else 0


def _output_error(inputs: Measurements, model: str, x0: RollParams | None) -> OutputErrorFit:
    grid, theta_fine = inputs.grid, inputs.theta_fine
    velocity = inputs.velocity_dps

    first = first_deflection(inputs)
    if velocity.size - first < MIN_FIT_SAMPLES:
        raise IdentificationError(
            f"{inputs.recording.name}: the fin first moves {velocity.size - first} sample(s) "
            f"from the end; output error needs at least {MIN_FIT_SAMPLES} from there"
        )
    start_fine = first * grid.per_sample
    theta = theta_fine[start_fine:]
    target = velocity[first:]
    n_intervals = theta.size - 1
    dt, per = grid.step_s, grid.per_sample
    dt_sample = dt * per
    t0 = float(grid.time_s[start_fine])

    def params_of(x: FloatArray) -> RollParams:
        if model == "constant":
            return RollParams(float(x[0]), float(x[1]), float(x[2]))
        return RollParams(float(x[0]), float(x[1]), float(x[3]), float(x[2]))

    def residual(x: FloatArray) -> FloatArray:
        params = params_of(x)
        along = damping(params, theta)
        if (
            float(np.min(along)) < MIN_DAMPING
            or float(np.max(along)) * dt_sample > MAX_DAMPING_SAMPLE
        ):
            # Outside the stable region, or a rocket faster than the samples show: a
            # large, finite cost steers the optimiser back.
            return np.full(target.size, 1e3)
        sim = simulate(
            params,
            dt,
            theta,
            np.zeros(n_intervals),
            rate0_dps=float(target[0]),
            servo=None,
            substeps=1,
            t0_s=t0,
        )
        return np.asarray(sim.rate_dps[::per] - target, dtype=float)

    if model == "constant":
        lower = [-np.inf, -np.inf, MIN_DAMPING]
    else:
        lower = [-np.inf, -np.inf, -np.inf, MIN_DAMPING]
    bounds = (lower, [np.inf] * len(lower))

    def vector(start: RollParams) -> FloatArray:
        if model == "constant":
            return np.asarray([start.alpha, start.theta_bar_deg, start.beta_bar_per_s])
        return np.asarray(
            [
                start.alpha,
                start.theta_bar_deg,
                start.alpha_bar_per_deg_s,
                start.beta_bar_per_s,
            ]
        )

    def solve(start: RollParams) -> Any:
        return least_squares(residual, vector(start), bounds=bounds, x_scale="jac", method="trf")

    fin_samples = np.asarray(theta[::per], dtype=float)
    steps = inputs.steps_found
    held = not isinstance(steps, IdentificationError) and steps.n_steps >= 2
    if x0 is not None:
        result = solve(x0)
    else:
        result = solve(_line_start(fin_samples, target))
        other = None if held else _regression_start(fin_samples, target, dt_sample)
        if other is not None:
            second = solve(other)
            if second.cost < result.cost * (1.0 - SAME_COST):
                result = second
    params = params_of(result.x)
    typical = float(np.median(damping(params, theta)))
    if typical * dt_sample > NO_LAG_SAMPLE:
        raise IdentificationError(
            f"{inputs.recording.name}: output error finds no lag of the roll rate behind the "
            f"fin (a = {typical:.3g} 1/s, a time constant under a tenth of the "
            f"{dt_sample:g}-s sampling): the recording does not show the roll's dynamics"
        )
    names = (
        ("alpha", "theta_bar", "a_per_s")
        if model == "constant"
        else ("alpha", "theta_bar", "alpha_bar", "beta_bar_per_s")
    )
    se, corr = _sandwich(np.asarray(result.jac), np.asarray(result.fun), names)
    return OutputErrorFit(
        model=model,
        params=params,
        rate_rmse_dps=float(np.sqrt(np.mean(result.fun**2))),
        nfev=int(result.nfev),
        success=bool(result.success),
        message=str(result.message),
        std_errors=se,
        correlations=corr,
    )


def _line_start(fin: FloatArray, rate: FloatArray) -> RollParams:
    """α and θ̄ from a straight line through the rate against the fin angle (the steady
    state, which held fin steps reach), ``a = 1 1/s``; a gain below 0.001 in size is held
    there, with its sign."""
    slope, intercept = np.polyfit(fin, rate, 1)
    if abs(slope) < 1e-3:
        slope = 1e-3 if slope >= 0 else -1e-3
    return RollParams(float(slope), float(intercept / slope), 1.0)


def _regression_start(fin: FloatArray, rate: FloatArray, dt_s: float) -> RollParams | None:
    """A rocket from the one-step regression ``v[k+1] = e·v[k] + c·θ[k] + d`` (the model's
    sample map with ``u_d`` in the residual: ``a = -ln(e)/Δt``, ``α = c/(1 - e)``,
    ``θ̄ = d/c``), which any input informs; None where it gives no damped rocket.

    The line of :func:`_line_start` reads the steady state, which a sweep or a quick random
    input never reaches: it then says a tiny gain and a huge asymmetry, a local optimum
    of the output error's cost the optimiser stays in (as for
    :func:`identification.methods.ml.maximum_likelihood`'s starts)."""
    design = np.column_stack([rate[:-1], fin[:-1], np.ones(rate.size - 1)])
    (e, c, d), *_ = np.linalg.lstsq(design, rate[1:], rcond=None)
    if not (0.0 < e < 1.0 and abs(c) > 1e-9):
        return None
    return RollParams(
        float(c / (1.0 - e)), float(d / c), max(-math.log(e) / dt_s, 2.0 * MIN_DAMPING)
    )


def _sandwich(
    jac: FloatArray, residuals: FloatArray, names: Sequence[str]
) -> tuple[dict[str, float], dict[str, float]]:
    """Standard errors and correlations of a least-squares fit whose residuals are
    correlated in time (the turbulence's response is in them): the Newey-West sandwich
    ``(JᵀJ)⁻¹ S (JᵀJ)⁻¹`` with ``S`` over Bartlett-weighted lags up to four times the
    residuals' correlation length (:func:`identification.methods.statistics.newey_west_meat`,
    statsmodels' ``S_hac_simple``), with its small-sample
    factor ``n / (n - k)``.  NaN / empty where ``JᵀJ`` is singular.

    Approximate: over 12 seeds each of three tunnel truths the errors of α were 1.10-1.35
    reported standard errors in SD (1.15-1.50 with lags up to twice the correlation
    length), where 1 is exact."""
    from identification.estimation.likelihood import standard_errors
    from identification.methods.statistics import newey_west_covariance, newey_west_lags

    n, k = jac.shape
    try:
        cov = newey_west_covariance(jac, residuals, newey_west_lags(residuals))
    except np.linalg.LinAlgError:
        return standard_errors(None, names)
    return standard_errors(cov * n / (n - k), names)


def output_error_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """The output-error peer as an identification method (``method="output-error"``).

    Its ``u_d`` is recovered by the paper's step 8 under its own parameters
    and re-simulated the same way (:func:`identification.methods.pipeline.recover_disturbance`),
    so the traces and metrics of both methods compare like for like.  Where the
    velocity smoothing is not short against the fitted rocket's time constant
    (:func:`identification.methods.pipeline.smoothing_for`: a rocket several times faster than
    the paper's) the rate is smoothed again over a shorter window and the fit starts
    again from the previous one, until the window is short against the time constant
    fitted through it (at most :data:`MAX_RESMOOTHING` times).  Where no sensors' latency
    is stated it fits the fin delayed by the one the likelihood admits
    (:func:`~identification.methods.ml.context_latency`, ``ml``'s search):
    in the rate error the turbulence's response hides a latency of a sample, and the fit
    takes it for a slower rocket (a 40-ms late gyro on a 25-Hz pilot's log: ``a`` 15 %
    low).  Metrics: the re-simulation errors, the output error's RMS, the optimiser's
    work, the shorter window where one was used and the latency's search
    (``sensor_latency``, as ``ml``'s); ``n_steps`` is the number of fin steps found (0
    where there are none: a sweep, doublets, a random input, which it fits all the same
    from the first deflection, :func:`first_deflection`), and, as for the ``ml`` method,
    the sources name no step column where no steps were found.
    """
    from identification.methods.ml import context_latency

    latency = context_latency(context)  # its own rate error cannot tell it: the likelihood's
    inputs = context.measured(None, latency.admitted_s)
    options = context.options
    steps = None if isinstance(inputs.steps_found, IdentificationError) else inputs.steps_found
    fits = []
    for model in models:
        found = _output_error(inputs, model, None)
        used, window = inputs, math.inf  # the window used, where shorter than the options'
        for _ in range(MAX_RESMOOTHING):
            shorter = smoothing_for(found.params, used, options)
            if shorter is None or shorter >= window:
                break
            window, used = shorter, context.measured(shorter, latency.admitted_s)
            found = _output_error(used, model, found.params)
        dist, resim = recover_disturbance(used, found.params, model, options)
        metrics = {
            "n_steps": 0 if steps is None else steps.n_steps,
            "sources": {
                **({} if steps is None else {"fin_steps": steps.fin_source}),
                "angle": inputs.angle_source,
                "velocity": used.velocity_source,
                "fin_angle": inputs.theta_source,
            },
            **resimulation_metrics(resim),
            "rate_rmse_dps": found.rate_rmse_dps,
            "nfev": found.nfev,
            "converged": found.success,
            "optimizer_message": found.message,
            "std_errors": found.std_errors,
            "correlations": found.correlations,
            **({"smoothing_window_s": window} if math.isfinite(window) else {}),
            **({"sensor_latency": latency.term} if latency.term else {}),
        }
        fits.append(
            ModelFit("output-error", model, found.params, dist, metrics, trace_settings(dist))
        )
    return fits
