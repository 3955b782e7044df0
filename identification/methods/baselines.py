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
velocity processing and fin-angle model as the pipeline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

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
from identification.model import RollParams, damping, simulate
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray

__all__ = ["OutputErrorFit", "output_error", "output_error_method"]

#: Most refits over a shorter velocity smoothing (:func:`output_error_method`).
MAX_RESMOOTHING = 3

#: Smallest damping the optimiser may visit, 1/s (keeps the simulation stable).
MIN_DAMPING = 0.01


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
        Model simulations used by the optimiser (without the Jacobian's).
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
        measured rate against the fin angle (all samples after the first
        deflection), ``a = 1 1/s``, ``ᾱ = 0`` -- nothing from the paper's
        method or the ground truth.

    Returns
    -------
    OutputErrorFit
    """
    return _output_error(model_inputs(recording, model, options), model, x0)


def _output_error(inputs: Measurements, model: str, x0: RollParams | None) -> OutputErrorFit:
    inputs.require_steps()
    segments, grid, theta_fine = inputs.segments, inputs.grid, inputs.theta_fine
    velocity = inputs.velocity_dps

    first = int(segments.start_index[0])
    start_fine = first * grid.per_sample
    theta = theta_fine[start_fine:]
    target = velocity[first:]
    n_intervals = theta.size - 1
    dt, per = grid.step_s, grid.per_sample
    t0 = float(grid.time_s[start_fine])

    def params_of(x: FloatArray) -> RollParams:
        if model == "constant":
            return RollParams(float(x[0]), float(x[1]), float(x[2]))
        return RollParams(float(x[0]), float(x[1]), float(x[3]), float(x[2]))

    def residual(x: FloatArray) -> FloatArray:
        params = params_of(x)
        if float(np.min(damping(params, theta))) < MIN_DAMPING:
            # Outside the stable region: a large, finite cost steers the optimiser back.
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

    if x0 is None:
        fin_samples = np.asarray(theta[::per])
        slope, intercept = np.polyfit(fin_samples, target, 1)
        start = RollParams(float(slope), float(intercept / slope), 1.0)
    else:
        start = x0
    if model == "constant":
        x_start = [start.alpha, start.theta_bar_deg, start.beta_bar_per_s]
        lower = [-np.inf, -np.inf, MIN_DAMPING]
        upper = [np.inf, np.inf, np.inf]
    else:
        x_start = [
            start.alpha,
            start.theta_bar_deg,
            start.alpha_bar_per_deg_s,
            start.beta_bar_per_s,
        ]
        lower = [-np.inf, -np.inf, -np.inf, MIN_DAMPING]
        upper = [np.inf, np.inf, np.inf, np.inf]
    result = least_squares(
        residual, np.asarray(x_start), bounds=(lower, upper), x_scale="jac", method="trf"
    )
    names = (
        ("alpha", "theta_bar", "a_per_s")
        if model == "constant"
        else ("alpha", "theta_bar", "alpha_bar", "beta_bar_per_s")
    )
    se, corr = _sandwich(np.asarray(result.jac), np.asarray(result.fun), names)
    return OutputErrorFit(
        model=model,
        params=params_of(result.x),
        rate_rmse_dps=float(np.sqrt(np.mean(result.fun**2))),
        nfev=int(result.nfev),
        success=bool(result.success),
        message=str(result.message),
        std_errors=se,
        correlations=corr,
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
    from identification.methods.statistics import decorrelation_stride, newey_west_meat

    n, k = jac.shape
    try:
        bread = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        return standard_errors(None, names)
    lags = min(4 * decorrelation_stride(residuals, math.exp(-1.0)), n // 4)
    meat = newey_west_meat(jac * residuals[:, None], max(lags, 1))
    return standard_errors(bread @ meat @ bread * n / (n - k), names)


def output_error_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """The output-error peer as an identification method (``method="output-error"``).

    Its ``u_d`` is recovered by the paper's step 8 under its own parameters
    and re-simulated the same way (:func:`identification.methods.pipeline.recover_disturbance`),
    so the traces and metrics of both methods compare like for like.  Where the
    velocity smoothing is not short against the fitted rocket's time constant
    (:func:`identification.methods.pipeline.smoothing_for`: a rocket several times faster than
    the paper's) the rate is smoothed again over a shorter window and the fit starts
    again from the previous one, until the window is short against the time constant
    fitted through it (at most :data:`MAX_RESMOOTHING` times).  Metrics: the
    re-simulation errors, the output error's RMS, the optimiser's work, and the
    shorter window where one was used.
    """
    inputs = context.measurements
    options = context.options
    fits = []
    for model in models:
        found = _output_error(inputs, model, None)
        used, window = inputs, math.inf  # the window used, where shorter than the options'
        for _ in range(MAX_RESMOOTHING):
            shorter = smoothing_for(found.params, used, options)
            if shorter is None or shorter >= window:
                break
            window, used = shorter, context.smoothed_over(shorter)
            found = _output_error(used, model, found.params)
        dist, resim = recover_disturbance(used, found.params, model, options)
        metrics = {
            "n_steps": inputs.segments.n_steps,
            "sources": {
                "fin_steps": inputs.segments.fin_source,
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
        }
        fits.append(
            ModelFit("output-error", model, found.params, dist, metrics, trace_settings(dist))
        )
    return fits
