"""Maximum-likelihood identification with the turbulence as a state (``method="ml"``).

The paper's model (eq. 36/49) over one sample interval ``Δt``, with the fin
angle ``θ(t)`` known (step 5: the servo of eq. 23 on the command, or the
measured fin) and ``u_d`` held, is affine in the rate, the angle and ``u_d``
(:func:`identification.model.piece_coefficients`, composed over the fine
grid's substeps)::

    v[k+1] = E[k]·v[k] + G[k]·u_d[k] + f[k]
    φ[k+1] = φ[k] + A[k]·v[k] + B[k]·u_d[k] + g[k]

The turbulence is a zero-mean autoregressive process of order ``p`` on the
sample grid, ``u_d[k+1] = Σ a_i·u_d[k+1-i] + η[k]`` (its mean cannot be told
from the asymmetry θ̄: θ̄ carries it, as in the paper).  With the state
``[v, φ, u_d[k], ..., u_d[k-p+1]]`` this is a linear Gaussian state-space
model (written in :mod:`identification.methods.rollspace`) whose measurements are the
recording's columns: the encoder angle with its quantisation (variance
``q²/12``, ``q`` read off the data), the rate gyro with the multiplicative
noise of eq. 52 (its level estimated), or both.  Real sensors are noisier
than the paper's: an angle that scatters more than its grid explains (a
potentiometer, an attitude estimate, a log converted from radians) gets a
white-noise SD of its own, and a gyro whose readings scatter at rest (a MEMS
gyro's additive noise) an additive floor, kept where it raises the likelihood
by an effect size (:data:`_FLOOR_GAIN`).  Read as exact, either noise would be
carried by the turbulence, and the fit runs away.

The parameters -- α, θ̄, the damping (``a``, or ᾱ and β̄), the AR
coefficients, the innovation SD and the gyro's noise level -- maximise the
Kalman filter's likelihood (the estimation core,
:mod:`identification.estimation.likelihood`: L-BFGS-B); their standard errors come
from the Hessian of the log-likelihood.  The order
``p`` is the one of smallest AIC up to :data:`MAX_ORDER`.  The smoother gives
``E[u_d | data]`` and its pointwise SD; :meth:`MLFit.posterior_draws` draws whole
traces from ``p(u_d | data)`` with the simulation smoother -- turbulence with
the right amplitude and spectrum that is consistent with the recording.

No step structure is needed: ramps, doublets, random inputs and dwell steps
alike, from the angle, the rate or both.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import optimize, stats

from identification.compiled import UNSCALED
from identification.estimation.likelihood import (
    OUTSIDE,
    StateSpaceFit,
    covariance,
    maximise,
    numerical_hessian,
    posterior_states,
    profile_interval,
    profile_step,
    select_order,
    standard_errors,
    standing_interval,
)
from identification.estimation.statespace import (
    LinearGaussian,
    Smoothed,
    filtered_means,
    smooth,
    standardized_innovations,
)
from identification.methods import Context, ModelFit, resimulation_metrics
from identification.methods.pipeline import (
    IdentifyOptions,
    Measurements,
    delayed_fin,
    latency_stated,
    measurements,
    model_inputs,
    with_latency,
)
from identification.methods.rollspace import (
    MIN_DAMPING,
    RollData,
    RollLikelihood,
    RollParameterMap,
    RollParts,
    count_params,
    negloglike_natural,
    pacf_from_ar,
    parameter_map,
    prepare,
    roll_loglike,
    roll_parts,
    roll_system,
    stationary_cov,
)
from identification.methods.steps import IdentificationError
from identification.methods.terms import latency_term
from identification.model import (
    QUADRATIC_RATE_DPS,
    TERM_LEVEL,
    RollParams,
    check_model,
    quadratic_growth,
)
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray, readonly_array

if TYPE_CHECKING:
    from identification.methods.diagnosis import LoopAlone

__all__ = [
    "MAX_ORDER",
    "DelaySearch",
    "LatencySearch",
    "MLFit",
    "QuadraticSearch",
    "context_latency",
    "delay_search",
    "latency_search",
    "maximum_likelihood",
    "ml_method",
    "posterior_given",
    "quadratic_fit",
    "quadratic_search",
    "rate_damped",
]

#: Highest AR order of the turbulence tried.
MAX_ORDER = 3


def _start(data: RollData, inputs: Measurements, model: str, order: int) -> dict[str, Any]:
    """A starting point from the data alone: α and θ̄ from a line through rate
    against fin angle, a = 1 1/s, u_d of the residual's size, lag-one correlation 0.5."""
    fin = np.asarray(inputs.theta_fine[:: data.per], dtype=float)
    rate = np.asarray(inputs.velocity_dps, dtype=float)
    slope, intercept = np.polyfit(fin, rate, 1)
    if abs(slope) < 1e-3:
        slope = 1e-3 if slope >= 0 else -1e-3
    residual = rate / slope - fin - intercept / slope
    return _starting_point(data, order, slope, intercept / slope, 1.0, residual)


def _starting_point(
    data: RollData, order: int, alpha: float, theta_bar: float, damping: float, residual: FloatArray
) -> dict[str, Any]:
    """Natural parameters to start from: the rocket given (constant damping), ``u_d``
    of the residual's size (at least 0.5°) with lag-one correlation 0.5, the gyro's
    noise 2 % and the angle's as its second differences show it."""
    sd_u = max(float(np.std(residual)), 0.5)
    ar = np.zeros(order)
    ar[0] = 0.5
    return {
        "alpha": float(alpha),
        "theta_bar": float(theta_bar),
        "alpha_bar": 0.0,
        "beta_bar": float(damping),
        "ar": ar,
        "innovation_sd": sd_u * math.sqrt(1.0 - 0.25),
        "gyro": 0.02,
        "angle_sd": data.angle_noise,
    }


def _equation_error_start(data: RollData, inputs: Measurements) -> dict[str, Any] | None:
    """A second starting point, from the one-step regression of the smoothed rate on
    itself and the fin (``v[k+1] = e·v[k] + c·θ[k] + d``: the model's sample map with
    ``u_d`` in the residual), for any input; None where it gives no damped rocket.

    :func:`_start`'s line through rate against fin reads the steady state, which a
    chirp or a fast PRBS never reaches: its slope then says a tiny gain and a huge
    asymmetry, from where the optimiser finds a rocket the fin barely moves.
    """
    fin = np.asarray(inputs.theta_fine[:: data.per], dtype=float)
    rate = np.asarray(inputs.velocity_dps, dtype=float)
    design = np.column_stack([rate[:-1], fin[:-1], np.ones(rate.size - 1)])
    (e, c, d), *_ = np.linalg.lstsq(design, rate[1:], rcond=None)
    if not (0.0 < e < 1.0 and abs(c) > 1e-9):
        return None
    dt = float(np.median(np.diff(data.time_s)))
    residual = (rate[1:] - design @ np.array([e, c, d])) / c
    damping = max(-math.log(e) / dt, 2.0 * MIN_DAMPING)
    return _starting_point(data, 1, c / (1.0 - e), d / c, damping, residual)


#: Closed-loop starts: the loop's gain times the rocket's, α·K (a stabilising loop's is
#: positive, and of order one), and the damping, 1/s.
_LOOP_STARTS = ((0.5, 1.0), (1.5, 1.0), (1.5, 3.0), (4.0, 3.0))


def _closed_loop_starts(data: RollData, inputs: Measurements) -> list[dict[str, Any]]:
    """Starting points for a log flown under a rate loop (the fin follows the measured rate:
    :func:`~identification.methods.diagnosis.feedback`), none otherwise.

    There the line through rate against fin reads the loop, not the rocket: its slope is
    ``−1/K`` (the wrong sign), and from it the optimiser stops where the fin does nothing
    (α ≈ 0), a local optimum.  A loop that stabilises the rocket has ``α·K > 0`` of order
    one: α is started at a few such products over the loop's gain ``K`` read off the log,
    θ̄ from the mean rate and fin (``v̄ = α·(θ̄ + fin̄)``)."""
    from identification.methods.diagnosis import feedback, logged_fin, looped

    rec = inputs.recording
    fin = np.asarray(inputs.theta_fine[:: data.per], dtype=float)
    rate = np.asarray(
        rec.roll_rate_dps if rec.roll_rate_dps is not None else inputs.velocity_dps, dtype=float
    )[: fin.size]
    dt = float(np.median(np.diff(data.time_s)))
    command = logged_fin(rec)[: fin.size]
    free = np.abs(command) < 0.995 * float(np.max(np.abs(command)))  # off the stops
    loop = feedback(command, rate, dt, free)
    gain = loop["gain"]
    if not (looped(loop) and math.isfinite(gain) and abs(gain) > 1e-6):
        return []
    starts = []
    for product, damping in _LOOP_STARTS:
        alpha = product / gain
        theta_bar = float(np.mean(rate)) / alpha - float(np.mean(fin))
        residual = rate / alpha - fin - theta_bar
        starts.append(_starting_point(data, 1, alpha, theta_bar, damping, residual))
    return starts


@dataclass(frozen=True, eq=False, kw_only=True)
class MLFit(StateSpaceFit):
    """Result of :func:`maximum_likelihood` for one damping model: a
    :class:`~identification.estimation.likelihood.StateSpaceFit` (the rocket, its
    log-likelihood, ``u_d`` and draws of it) with the tunnel model's own figures.

    Attributes
    ----------
    ar : ndarray
        The turbulence's AR coefficients (order = size).
    innovation_sd_deg, sd_deg : float
        SD of the AR innovation and of ``u_d`` itself, °.
    gyro_noise : float
        Estimated gyro noise level (eq. 52, fraction), 0 without a gyro.
    gyro_floor_dps : float
        Estimated additive white noise SD of the gyro, °/s (0 where eq. 52 alone
        describes it).
    angle_noise_deg : float
        Estimated white noise SD of the angle beyond its grid's quantisation, ° (0
        for an encoder).
    aic : float
        ``2k - 2·loglike``.
    n_params : int
        ``k``.
    std_errors : dict
        Standard error of each natural parameter (NaN where the Hessian is
        not positive definite there).
    correlations : dict
        Correlation of each pair of the rocket's estimates, ``"alpha~theta_bar"``
        (empty where the Hessian is not positive definite).
    orders : dict
        AIC of each AR order tried.
    intervals : dict
        A 95 % interval of each of the rocket's parameters (:func:`rocket_intervals`): the
        Hessian's where it is positive definite, the profile likelihood's where it is not
        (or for all, asked so), each saying whether the data determine it.
    loop_alone : dict
        Where a rate loop alone moves the fin and answers within the log's sample
        (:func:`~identification.methods.diagnosis.loop_alone`): the loop
        (:func:`loop_bound`); empty otherwise.
    latency : dict
        The sensors' latency searched where none is stated (:func:`latency_search`'s
        figures: the estimate, s, its likelihood-ratio statistic and p, whether it is
        admitted, in which case the fit is on the fin delayed by it); empty where stated.
    nfev : int
        Likelihood evaluations (all orders).
    u_d_deg, u_d_sd_deg : ndarray, shape (n - 1,)
        Posterior mean and SD of ``u_d`` over each sample interval; the SD of a fit holds
        the parameters' own uncertainty too (delta method over the observed information),
        which on a short record is most of it (:func:`posterior_given`'s, under given
        parameters, is the smoother's alone).  The posterior draws
        (:meth:`posterior_draws`) are conditional on the fitted parameters.
    """

    ar: FloatArray
    innovation_sd_deg: float
    sd_deg: float
    gyro_noise: float
    gyro_floor_dps: float
    angle_noise_deg: float
    aic: float
    n_params: int
    correlations: dict[str, float]
    orders: dict[int, float]
    nfev: int
    intervals: dict[str, dict[str, Any]] = field(default_factory=dict)
    latency: dict[str, Any] = field(default_factory=dict)
    loop_alone: dict[str, Any] = field(default_factory=dict)
    _state_space: LinearGaussian = field(repr=False)
    _smoothed: Smoothed = field(repr=False)

    @property
    def initial_state(self) -> tuple[float, float]:
        """Posterior mean roll rate (°/s) and angle (°) at the first sample."""
        first = self._smoothed.mean[0]
        return float(first[0]), float(first[1])

    def posterior_draws(self, size: int, seed: int = 0) -> FloatArray:
        """``size`` draws of the whole ``u_d`` trace from its posterior given the recording.

        Durbin–Koopman simulation smoothing
        (:func:`~identification.estimation.likelihood.posterior_states`): each draw is a
        realisation of the fitted turbulence process consistent with the data.  Returns
        shape ``(size, n - 1)``, ° per sample interval.
        """
        draws = posterior_states(self._state_space, self._smoothed, size, seed)
        return np.asarray(draws[:, :-1, 2], dtype=float)


@dataclass(frozen=True)
class _Information:
    """The observed information at the optimum, over every free parameter: the rocket's
    in natural units, then the turbulence's and the sensors' in the optimiser's.

    ``trial`` maps such a vector to natural parameters; ``cov`` is the inverted
    Hessian of the negative log-likelihood (None where it is not invertible)."""

    rocket: tuple[str, ...]
    point: FloatArray
    cov: FloatArray | None
    trial: Callable[[FloatArray], dict[str, Any]]


def _rocket(model: str) -> tuple[str, ...]:
    """The rocket's natural parameters of ``model``, in the order they are reported."""
    if model == "constant":
        return ("alpha", "theta_bar", "beta_bar")
    return ("alpha", "theta_bar", "alpha_bar", "beta_bar")


#: The name each model reports its ``beta_bar`` under: the constant damping ``a``, or eq.
#: 48's β̄.
_SHOWN = {"constant": {"beta_bar": "a_per_s"}, "theta": {"beta_bar": "beta_bar_per_s"}}


def _information(data: RollData, model: str, nat: dict[str, Any]) -> _Information:
    """The Hessian of the log-likelihood over all free parameters, inverted."""
    pmap = parameter_map(data, model, int(np.size(nat["ar"])), nat)
    rocket = _rocket(model)
    x0 = pmap.vector(nat)
    k = len(rocket)

    def trial(values: FloatArray) -> dict[str, Any]:
        # Rocket parameters in natural units, the turbulence's in the optimiser's.
        out = pmap.natural(np.concatenate([x0[:k], values[k:]]))
        out.update(zip(rocket, values[:k].tolist(), strict=True))
        return out

    point = np.concatenate([[nat[name] for name in rocket], x0[k:]])
    hess = numerical_hessian(lambda values: negloglike_natural(data, trial(values)), point)
    return _Information(rocket, point, covariance(hess), trial)


def _rocket_estimates(info: _Information, model: str) -> tuple[dict[str, float], dict[str, float]]:
    """Standard errors and correlations of the rocket's parameters
    (:func:`~identification.estimation.likelihood.standard_errors`; ``a_per_s`` names the constant
    damping, ``beta_bar_per_s`` eq. 48's)."""
    rename = _SHOWN[model]
    return standard_errors(info.cov, [rename.get(n, n) for n in info.rocket])


#: The physical range of each rocket parameter its profile interval stops at: an
#: asymmetry within a right angle of the fins' zero, a positive damping.
_RANGES = {
    "alpha": (-math.inf, math.inf),
    "theta_bar": (-90.0, 90.0),
    "alpha_bar": (-math.inf, math.inf),
    "beta_bar": (0.0, math.inf),
}


def rocket_intervals(
    data: RollData,
    model: str,
    nat: dict[str, Any],
    std_errors: dict[str, float],
    mode: str,
    rivals: Sequence[dict[str, Any]] = (),
) -> dict[str, dict[str, Any]]:
    """A 95 % interval for each of the rocket's parameters, by its reported name: the
    Hessian's ``±1.96·SE`` (``method: hessian``) where ``mode`` is ``auto``, the SE is finite
    and the interval holds (:func:`~identification.estimation.likelihood.standing_interval`:
    within the range, α's sign told), else the profile likelihood's
    (:func:`~identification.estimation.likelihood.profile_interval`, ``method: profile``;
    each end says whether the data, the parameter's range or nothing set it).

    The profile is taken in the optimiser's coordinates (the θ model's damping as its
    mid-range value and slope, where the re-fits converge), the parameter made one of them
    by a linear change of basis.

    ``rivals``: the likelihood's other optima the data do not reject
    (:meth:`_Search.rivals`).  With any, no interval is the Hessian's (the likelihood is not
    one hill): each parameter's profile is traced from every optimum, its level measured
    from the best, and the profiles joined (:meth:`ProfileInterval.joined`); ``optima``
    lists each optimum's value of the parameter."""
    pmap = parameter_map(data, model, int(np.size(nat["ar"])), nat)
    x_hat = pmap.vector(nat)
    others = [pmap.vector(r) for r in rivals]
    # The level is the best's where there are several optima (else the profile's own start).
    reference = min(negloglike_natural(data, r) for r in (nat, *rivals)) if rivals else None
    names = pmap.names
    rocket = _rocket(model)
    rename = _SHOWN[model]
    out: dict[str, dict[str, Any]] = {}
    for name in rocket:
        shown = rename.get(name, name)
        estimate = float(nat[name])
        se = std_errors.get(shown, math.nan)
        wald = standing_interval(estimate, se, _RANGES[name], signed=name == "alpha")
        if mode == "auto" and wald is not None and not rivals:
            out[shown] = wald
            continue
        basis, index = _basis(names, name, pmap.pivot)

        def objective(y: FloatArray, m: FloatArray = basis) -> float:
            return negloglike_natural(data, pmap.natural(m @ y))

        found, *around = (
            profile_interval(
                objective,
                np.asarray(np.linalg.solve(basis, x), dtype=np.float64),
                index,
                step=profile_step(estimate, se),
                limits=_RANGES[name],
                reference=reference,
            )
            for x in (x_hat, *others)
        )
        found = found.joined(around)
        out[shown] = found.as_dict()
        if rivals:
            out[shown]["optima"] = [estimate, *(float(r[name]) for r in rivals)]
        if found.gain > _PROFILE_GAIN:
            out[shown]["higher_likelihood_found"] = found.gain
    return out


def _basis(names: Sequence[str], name: str, pivot: float) -> tuple[FloatArray, int]:
    """``(M, i)``: the optimiser's vector is ``M·y`` with ``y[i]`` the natural parameter
    ``name`` (:class:`~identification.methods.rollspace.RollParameterMap`: ``ᾱ = slope/pivot``,
    ``β̄ = a_mid − slope``)."""
    basis = np.eye(len(names))
    if name in names:  # alpha, theta_bar
        return basis, names.index(name)
    if name == "beta_bar" and "a" in names:
        return basis, names.index("a")
    mid, slope = names.index("a_mid"), names.index("slope")
    if name == "alpha_bar":
        basis[slope, slope] = pivot
        return basis, slope
    basis[mid, slope] = 1.0  # a_mid = β̄ + slope
    return basis, mid


#: Log-likelihood gain along a profile from which the fit is said not to be at the maximum.
_PROFILE_GAIN = 0.05

#: Step of the band's differences, in standard errors of each parameter.
_BAND_STEP_SE = 0.1


def _smoothed_u(data: RollData, nat: dict[str, Any]) -> FloatArray | None:
    """The posterior mean ``u_d`` under ``nat`` (None: no stable model there)."""
    parts = roll_parts(data, nat)
    if parts is None:
        return None
    roll_loglike(data, parts)
    return np.asarray(smooth(roll_system(data, parts)).mean[:-1, 2], dtype=float)


def _parameter_variance(data: RollData, info: _Information, u: FloatArray) -> FloatArray:
    """The variance the parameters' own uncertainty adds to the posterior mean ``u_d``:
    ``J·C·Jᵀ`` per interval (delta method), ``J`` forward differences of the smoothed
    mean over each free parameter (steps of :data:`_BAND_STEP_SE` of its standard
    error), ``C`` the parameters' covariance.  Zero where there is no finite covariance
    (a singular information matrix); a parameter whose variance is not positive adds
    nothing."""
    if info.cov is None or not np.all(np.isfinite(info.cov)):
        return np.zeros_like(u)
    sd = np.sqrt(np.clip(np.diag(info.cov), 0.0, None))
    jac = np.zeros((u.size, info.point.size))
    for i, step_se in enumerate(sd):
        if not step_se > 0:
            continue
        step = _BAND_STEP_SE * step_se
        moved = info.point.copy()
        moved[i] += step
        shifted = _smoothed_u(data, info.trial(moved))
        if shifted is None:
            continue
        jac[:, i] = (shifted - u) / step
    return np.clip(np.einsum("ti,ij,tj->t", jac, info.cov, jac), 0.0, None)


def _maximise(
    data: RollData, pmap: RollParameterMap, start: dict[str, Any]
) -> optimize.OptimizeResult:
    """The estimation core's fit of the roll model of ``data`` from one start."""
    return maximise(RollLikelihood(data, pmap), [start])


@dataclass
class _Search:
    """Fits of one recording across models and AR orders, shared (the constant
    model's AR(1) fit starts the θ model)."""

    data: RollData
    inputs: Measurements
    nfev: int = 0
    found: dict[tuple[str, int], tuple[float, dict[str, Any], bool, str]] = field(
        default_factory=dict
    )
    #: Every optimum of the first fit's starts, (−log-likelihood, natural parameters).
    optima: list[tuple[float, dict[str, Any]]] = field(default_factory=list)

    def order(self, model: str, order: int) -> tuple[float, dict[str, Any], bool, str]:
        """(−log-likelihood, natural parameters, converged, message) of one model and order."""
        key = (model, order)
        if key not in self.found:
            if order > 1:
                warm = dict(self.order(model, order - 1)[1])
                warm["ar"] = np.append(warm["ar"], 0.0)
                self.found[key] = self._run(model, order, warm)
            elif model == "theta":  # ᾱ = 0: the nested model
                self.found[key] = self._run(model, order, dict(self.order("constant", 1)[1]))
            else:
                self.found[key] = self._first()
        return self.found[key]

    @functools.cached_property
    def loop_alone(self) -> LoopAlone | None:
        """The rate loop that alone moves the fin within the log's sample, if one does
        (:func:`~identification.methods.diagnosis.loop_alone`)."""
        from identification.methods.diagnosis import loop_alone

        rec = self.inputs.recording
        rate = rec.roll_rate_dps if rec.roll_rate_dps is not None else self.inputs.velocity_dps
        dt = float(np.median(np.diff(self.data.time_s)))
        return loop_alone(rec, np.asarray(rate, dtype=float), dt, rec.fin_range(None))

    def _run(
        self, model: str, order: int, warm: dict[str, Any]
    ) -> tuple[float, dict[str, Any], bool, str]:
        pmap = parameter_map(self.data, model, order, warm)
        result = _maximise(self.data, pmap, warm)
        # Each call of the objective is one value and one forward difference per parameter.
        self.nfev += int(result.nfev) * (result.x.size + 1)
        return (
            float(result.fun),
            pmap.natural(result.x),
            bool(result.success),
            str(result.message),
        )

    def _first(self) -> tuple[float, dict[str, Any], bool, str]:
        """The constant model's AR(1) fit from the data alone, which also settles the
        gyro's noise for every fit after it: eq. 52's multiplicative noise, or that with
        an additive floor (a MEMS gyro's white noise, there when the rocket is still)
        where the floor raises the likelihood by at least :data:`_FLOOR_GAIN` per reading.

        Where the first start's optimum disagrees with the one-step regression
        (:func:`_equation_error_start`), each is fitted from that second start too, and
        its optimum kept where it is better by :data:`_START_GAIN`; likewise from the
        closed loop's starts where the fin follows the rate (:func:`_closed_loop_starts`).
        """
        start = _start(self.data, self.inputs, "constant", 1)
        second = _equation_error_start(self.data, self.inputs)
        looped = _closed_loop_starts(self.data, self.inputs)
        floors = [0.0, _quiet_noise(self.data)] if self.data.has_gyro else [0.0]
        best, tried = [], []
        for floor in floors:
            found = self._run("constant", 1, dict(start, gyro_floor=floor))
            optima = [(found[0], found[1])]
            if second is not None and _disagree(self.data, found[1], second):
                other = self._run("constant", 1, dict(second, gyro_floor=floor))
                optima.append((other[0], other[1]))
                if other[0] < found[0] - _START_GAIN:
                    found = other
            best.append(found)
            tried.append(optima)
        pick = 1 if len(best) > 1 and best[0][0] - best[1][0] >= _FLOOR_GAIN * self.data.n else 0
        chosen = best[pick]
        self.optima = list(tried[pick])
        for third in looped:  # with the gyro's noise the first fits chose
            other = self._run(
                "constant", 1, dict(third, gyro_floor=chosen[1].get("gyro_floor", 0.0))
            )
            self.optima.append((other[0], other[1]))
            if other[0] < chosen[0] - _START_GAIN:
                chosen = other
        return chosen

    def rivals(
        self, model: str, order: int, fun: float, nat: dict[str, Any]
    ) -> list[tuple[float, dict[str, Any]]]:
        """The other optima of ``model`` at ``order`` the data do not reject beside the
        fit ``(fun, nat)``: each optimum of the first fit's starts that tells another rocket
        (:func:`_disagree`) and lies within twice :data:`_RIVAL_LEVEL` of the first fit's
        best, re-fitted at this model and order from there, kept where it still tells
        another rocket and its −log-likelihood is within :data:`_RIVAL_LEVEL` of ``fun`` (or
        below it).  A closed loop's likelihood has such a second basin: the fin doing
        nothing (α ≈ 0) and the turbulence doing all, near the rocket's."""
        first = self.order("constant", 1)
        kept: list[tuple[float, dict[str, Any]]] = []
        seen = [first[1]]
        for value, other in sorted(self.optima, key=lambda o: o[0]):
            if value > first[0] + 2.0 * _RIVAL_LEVEL:
                continue
            if any(not _disagree(self.data, known, other) for known in seen):
                continue
            seen.append(other)
            if (model, order) == ("constant", 1):
                refit = (value, other)
            else:
                warm = dict(other, ar=np.append(other["ar"], np.zeros(order - 1)))
                found = self._run(model, order, warm)
                refit = (found[0], found[1])
            if refit[0] <= fun + _RIVAL_LEVEL and _disagree(self.data, nat, refit[1]):
                kept.append(refit)
        return kept


def _disagree(data: RollData, found: dict[str, Any], other: dict[str, Any]) -> bool:
    """Whether a fit and another estimate tell different rockets: gains more than 25 %
    apart (or of opposite sign), or asymmetries more than a quarter of the fin's span."""
    span = max(data.theta_max - data.theta_min, 1e-6)
    return bool(
        abs(found["alpha"] - other["alpha"]) > 0.25 * abs(other["alpha"])
        or abs(found["theta_bar"] - other["theta_bar"]) > 0.25 * span
    )


#: Log-likelihood by which the second start's optimum must beat the first's to be kept
#: (the same optimum reached from two starts differs in its last digits).
_START_GAIN = 1.0
#: How far below the best another optimum's log-likelihood may lie and still be a basin
#: the data do not reject: the 95 % profile level, half χ²₁'s quantile.
_RIVAL_LEVEL = 0.5 * float(stats.chi2.ppf(0.95, 1))
#: Log-likelihood gain per reading from which the gyro's additive floor is kept: an
#: effect size, not AIC's 1 in total, which on a long record of eq. 52's gyro adopts a
#: floor that only soaks up the model's small misfit (the virtual tunnel's gyros,
#: multiplicative only: 0.0002-0.0024 nats per reading; with 0.5 °/s of white noise
#: added: 0.04-0.12; the public aircraft roll rig's gyro: 0.14).
_FLOOR_GAIN = 0.01


def _quiet_noise(data: RollData) -> float:
    """A first guess of the gyro's additive noise SD: ``SD(Δ²y)/√6`` over the fifth of
    the readings nearest zero rate, °/s."""
    rate = data.y[:, int(np.flatnonzero(data.observed == 0)[0])]
    second = np.diff(rate, 2) / math.sqrt(6.0)
    quiet = np.abs(rate[1:-1]) <= np.percentile(np.abs(rate[1:-1]), 20.0)
    return max(float(np.std(second[quiet])), 1e-3)


def _fit(search: _Search, model: str, max_order: int = MAX_ORDER, intervals: str = "auto") -> MLFit:
    """The model's fit at the AR order of least AIC (orders tried upwards until AIC rises)."""
    check_model(model)
    data = search.data

    def aic(order: int) -> tuple[float, tuple[float, dict[str, Any], bool, str]]:
        found = search.order(model, order)
        return 2.0 * count_params(data, model, order, found[1]) + 2.0 * found[0], found

    best, orders, (fun, nat, converged, message) = select_order(
        aic, range(1, max_order + 1), stop_when_worse=True
    )
    parts = roll_parts(data, nat)
    if parts is None or not fun < OUTSIDE:
        raise IdentificationError(
            f"{data.name}: maximum likelihood found no stable model ({message})"
        )
    rivals = search.rivals(model, best, fun, nat)
    better = min(rivals, key=lambda r: r[0], default=None)
    if better is not None and better[0] < fun - _START_GAIN:  # a rival basin is the best
        rivals = [r for r in rivals if r is not better] + [(fun, nat)]
        fun, nat = better
        parts = roll_parts(data, nat)
        if parts is None:
            raise IdentificationError(f"{data.name}: maximum likelihood found no stable model")
    info = _information(data, model, nat)
    std_errors, correlations = _rocket_estimates(info, model)
    alone = search.loop_alone  # once per recording, for every model fitted
    if alone is None:
        found = rocket_intervals(
            data, model, nat, std_errors, intervals, rivals=[r[1] for r in rivals]
        )
        bound: dict[str, Any] = {}
    else:  # the Hessian's precision is no precision where the rocket is not determined
        found, bound = loop_bound(model, nat, alone), alone.as_dict()
        std_errors = {name: math.nan for name in std_errors}
    fitted = _result(
        data,
        model,
        nat,
        parts,
        intervals=found,
        loglike=-fun,
        aic=float(orders[best]),
        n_params=count_params(data, model, best, nat),
        std_errors=std_errors,
        correlations=correlations,
        orders=orders,
        converged=converged,
        nfev=search.nfev,
        information=info,
    )
    return dataclasses.replace(fitted, loop_alone=bound) if bound else fitted


def loop_bound(model: str, nat: dict[str, Any], alone: LoopAlone) -> dict[str, dict[str, Any]]:
    """What a log flown under a rate loop alone, answering within the log's sample
    (:class:`~identification.methods.diagnosis.LoopAlone`), tells of the rocket: none of
    its parameters is determined (``method: loop``), each interval the values the closed
    loop leaves open -- α those for which the damping ``a = p/(1 + α·K)`` of a closed loop
    damping at ``p`` is positive, the damping and asymmetry their physical range.  Not
    even ``p`` is given: with the turbulence the only input, the rate's two time constants
    (the loop's and the turbulence's correlation) can trade places.

    Returns the intervals by reported name."""
    gain = alone.gain
    edge = -1.0 / gain  # where a = p/(1 + α·K) runs off to infinity
    ranges = {**_RANGES, "alpha": (edge, math.inf) if gain > 0 else (-math.inf, edge)}
    intervals = {}
    for name in _rocket(model):
        low, high = ranges[name]
        intervals[_SHOWN[model].get(name, name)] = {
            "method": "loop",
            "estimate": float(nat[name]),
            "low": float(low),
            "high": float(high),
            "low_end": "range" if math.isfinite(low) else "open",
            "high_end": "range" if math.isfinite(high) else "open",
            "level": _LEVEL,
            "determined": False,
        }
    return intervals


#: The level of :func:`loop_bound`'s interval (the rocket_intervals' own).
_LEVEL = 0.95


def _result(
    data: RollData,
    model: str,
    nat: dict[str, Any],
    parts: RollParts,
    *,
    loglike: float,
    aic: float,
    n_params: int,
    std_errors: dict[str, float],
    orders: dict[int, float],
    converged: bool,
    nfev: int,
    information: _Information | None = None,
    correlations: dict[str, float] | None = None,
    intervals: dict[str, dict[str, Any]] | None = None,
) -> MLFit:
    """An :class:`MLFit` for parameters ``nat``: smoother, posterior ``u_d``; its band
    widened by the parameters' uncertainty where their ``information`` is given."""
    roll_loglike(data, parts)  # the gyro's variances, as the likelihood had them
    ss = roll_system(data, parts)
    smoothed = smooth(ss)
    u_mean = np.asarray(smoothed.mean[:-1, 2], dtype=float)
    u_var = np.clip(smoothed.cov[:-1, 2, 2], 0.0, None)
    if information is not None:
        u_var = u_var + _parameter_variance(data, information, u_mean)
    u_cov = stationary_cov(nat["ar"], nat["innovation_sd"])
    return MLFit(
        model=model,
        params=RollParams(nat["alpha"], nat["theta_bar"], nat["beta_bar"], nat["alpha_bar"]),
        ar=np.asarray(nat["ar"], dtype=float),
        innovation_sd_deg=float(nat["innovation_sd"]),
        sd_deg=float(math.sqrt(u_cov[0, 0])),
        gyro_noise=float(nat["gyro"]),
        gyro_floor_dps=float(nat.get("gyro_floor", 0.0)),
        angle_noise_deg=float(nat.get("angle_sd", 0.0)),
        loglike=float(loglike),
        aic=aic,
        n_params=n_params,
        std_errors=std_errors,
        correlations=correlations or {},
        orders=orders,
        converged=converged,
        nfev=nfev,
        intervals=intervals or {},
        u_d_deg=readonly_array(u_mean),
        u_d_sd_deg=readonly_array(np.sqrt(u_var)),
        time_s=readonly_array(data.time_s),
        interval_s=float(data.time_s[1] - data.time_s[0]),
        _state_space=ss,
        _smoothed=smoothed,
    )


def posterior_given(
    recording: Recording,
    params: RollParams,
    ar: Sequence[float],
    sd_deg: float,
    *,
    gyro_noise: float = 0.0,
    options: IdentifyOptions | None = None,
) -> MLFit:
    """The posterior of ``u_d`` under given parameters and turbulence statistics (no fit).

    With the tunnel's true parameters and its turbulence (AR(1),
    ``exp(-Δt/τ)``, its SD) this is the best any estimate of ``u_d`` from the
    recording can do: the bound :mod:`benchmarks.ground_truth` holds the
    methods to.

    Parameters
    ----------
    recording : Recording
        The data.
    params : RollParams
        The rocket.
    ar : sequence of float
        AR coefficients of the turbulence on the sample grid (stationary).
    sd_deg : float
        SD of ``u_d`` itself, °.
    gyro_noise : float
        The gyro's noise level (eq. 52, a fraction), if the recording has a gyro.
    options : IdentifyOptions, optional
        Fine grid and servo settings.
    """
    coefficients = np.asarray(ar, dtype=float)
    if coefficients.ndim != 1 or coefficients.size < 1:
        raise ValueError("ar must be a sequence of at least one coefficient")
    if np.any(np.abs(pacf_from_ar(coefficients)) >= 1.0):
        raise ValueError(f"ar {coefficients.tolist()} is not stationary")
    if not sd_deg > 0.0:
        raise ValueError(f"sd_deg must be positive, got {sd_deg!r}")
    opts = IdentifyOptions() if options is None else options
    data = prepare(measurements(recording, opts))
    unit = math.sqrt(stationary_cov(coefficients, 1.0)[0, 0])
    nat = {
        "alpha": params.alpha,
        "theta_bar": params.theta_bar_deg,
        "alpha_bar": params.alpha_bar_per_deg_s,
        "beta_bar": params.beta_bar_per_s,
        "ar": coefficients,
        "innovation_sd": sd_deg / unit,
        "gyro": gyro_noise,
    }
    parts = roll_parts(data, nat)
    if parts is None:
        raise IdentificationError(f"{recording.name}: the damping a(θ) is not positive")
    model = "constant" if params.is_constant_damping else "theta"
    ll = -negloglike_natural(data, nat)
    return _result(
        data,
        model,
        nat,
        parts,
        loglike=ll,
        aic=math.nan,
        n_params=0,
        std_errors={},
        orders={},
        converged=True,
        nfev=1,
    )


def maximum_likelihood(
    recording: Recording,
    model: str = "theta",
    *,
    options: IdentifyOptions | None = None,
    max_order: int = MAX_ORDER,
) -> MLFit:
    """Fit eq. 29 (``model="constant"``) or eq. 49 (``"theta"``) by maximum likelihood.

    Parameters
    ----------
    recording : Recording
        Any recording with a fin input and the roll angle, the roll rate or both.
    model : str
        ``constant`` or ``theta``.
    options : IdentifyOptions, optional
        Fine grid and servo settings (shared with the paper's pipeline).
    max_order : int
        Highest AR order of the turbulence tried (AIC picks).

    Returns
    -------
    MLFit
    """
    inputs = model_inputs(recording, model, options)
    mode = (options or IdentifyOptions()).intervals
    found = latency_search(inputs, options)
    return dataclasses.replace(_fit(found.search, model, max_order, mode), latency=found.term)


@dataclass(frozen=True)
class DelaySearch:
    """:func:`delay_search`'s answer: the fin's delay (in fine-grid steps) that describes the
    roll best, and the log-likelihoods it was judged by."""

    delay_steps: int
    step_s: float
    loglike_undelayed: float
    loglike_delayed: float
    screened: dict[int, float]

    @property
    def statistic(self) -> float:
        """The likelihood-ratio statistic of the delay against none (0 at none)."""
        return max(2.0 * (self.loglike_delayed - self.loglike_undelayed), 0.0)


@dataclass(frozen=True)
class LatencySearch:
    """:func:`latency_search`'s answer: the fits to make every model on (on the fin
    delayed by the latency where it is admitted) and the term's figures (empty where the
    latency is stated)."""

    search: _Search
    term: dict[str, Any]

    @property
    def admitted_s(self) -> float | None:
        """The latency admitted, s; None where none is (or it is stated)."""
        return float(self.term["estimate_s"]) if self.term.get("admitted") else None


def latency_search(inputs: Measurements, options: IdentifyOptions | None) -> LatencySearch:
    """The sensors' latency where none is stated, as a term of the fit
    (:func:`~identification.methods.terms.latency_term`, on the constant model's AR(1)
    fit: screened by the filter at its parameters, fitted where the screen rises), searched
    by the likelihood with the turbulence modelled: in a rate error the turbulence's
    response hides a latency of a sample, which a slower rocket then absorbs.  A late gyro,
    or a fin logged ahead of the roll it drives (an aileron leading its roll by a sample),
    biases the gain and the damping otherwise."""
    search = _Search(prepare(inputs), inputs)
    recording = inputs.recording
    if latency_stated(recording, options):
        return LatencySearch(search, {})
    step = inputs.grid.step_s
    fun, nat = search.order("constant", 1)[:2]
    fitted: dict[int, _Search] = {}

    def refit(d: int) -> float:
        late = model_inputs(recording, "constant", with_latency(options, d * step))
        fitted[d] = _Search(prepare(late), late)
        return fitted[d].order("constant", 1)[0]

    found = latency_term(
        step,
        fun,
        lambda d: negloglike_natural(prepare(delayed_fin(inputs, d)), nat),
        refit,
    )
    if not found["admitted"]:
        return LatencySearch(search, found)
    chosen = fitted[found["steps"]]
    chosen.nfev += search.nfev + sum(f.nfev for d, f in fitted.items() if d != found["steps"])
    return LatencySearch(chosen, found)


def context_latency(context: Context) -> LatencySearch:
    """:func:`latency_search` on a context's measurements, made once for every method run
    on the recording that takes it (``ml``, ``output-error``)."""
    return context.shared(
        "sensor latency", lambda: latency_search(context.measurements, context.options)
    )


def delay_search(inputs: Measurements, model: str, max_latency_s: float) -> DelaySearch:
    """The fin's delay, in fine-grid steps up to ``max_latency_s``, that best describes the
    roll under ``model`` at the AR order of its undelayed fit: the sensors' latency as a
    term (:func:`~identification.methods.terms.latency_term`), each delay screened by
    the log-likelihood at the undelayed fit's parameters, re-fitted from there where the
    screen rises (the statistic is conservative: the screen may miss a better delay, never
    invent one)."""
    search = _Search(prepare(inputs), inputs)
    base = _fit(search, model)
    nat = search.order(model, base.ar.size)[1]
    step = inputs.grid.step_s
    screened = {0: base.loglike}

    def screen(d: int) -> float:
        screened[d] = -negloglike_natural(prepare(delayed_fin(inputs, d)), nat)
        return -screened[d]

    def refit(d: int) -> float:
        data = prepare(delayed_fin(inputs, d))
        result = _maximise(data, parameter_map(data, model, base.ar.size, nat), nat)
        return min(float(result.fun), -screened[d])

    term = latency_term(step, -base.loglike, screen, refit, max_latency_s=max_latency_s)
    delayed_loglike = base.loglike + 0.5 * term["statistic"]
    return DelaySearch(term["steps"], step, base.loglike, delayed_loglike, screened)


@dataclass(frozen=True)
class QuadraticSearch:
    """:func:`quadratic_search`'s answer: the damping's growth with the roll rate that
    describes the roll best, the log-likelihoods it was judged by (``profile``: each
    ``q`` tried), and its 95 % profile-likelihood interval (an end on the search's bound
    where the profile does not fall that far within it)."""

    coefficient: float
    loglike_linear: float
    loglike_quadratic: float
    profile: dict[float, float]
    interval: tuple[float, float]
    #: ``|v|`` per substep, the linear fit's filtered and predicted rate (:func:`rate_damped`).
    speed: FloatArray = field(default_factory=lambda: UNSCALED, repr=False)

    @property
    def statistic(self) -> float:
        """The likelihood-ratio statistic of the quadratic term against none (0 at none)."""
        return max(2.0 * (self.loglike_quadratic - self.loglike_linear), 0.0)

    @property
    def p(self) -> float:
        """The likelihood-ratio test's p-value (χ² with one degree of freedom: two-sided,
        ``q = 0`` inside the search's bounds)."""
        return float(stats.chi2.sf(self.statistic, 1))

    def summary(self, level: float = TERM_LEVEL) -> dict[str, Any]:
        """The search as a fit's metrics: the estimate, its interval, the test and whether
        the term is admitted at ``level``."""
        return {
            "estimate": self.coefficient,
            "interval": list(self.interval),
            "statistic": self.statistic,
            "p": self.p,
            "level": level,
            "admitted": self.p < level,
            "rate_dps": QUADRATIC_RATE_DPS,
        }


def rate_damped(data: RollData, speed: FloatArray, coefficient: float) -> RollData:
    """``data`` with the damping ``a(θ)·(1 + q·|v|/QUADRATIC_RATE_DPS)`` (``q`` the
    ``coefficient``, ``|v|`` the ``speed`` per substep) and the gain divided by the same:
    ``dv/dt = -a(θ)·(v - α·(θ + θ̄ + u_d)) - a(θ)·q·v·|v|/QUADRATIC_RATE_DPS``, with ``|v|``
    a path given in advance (:func:`quadratic_search`'s: the linear fit's filtered and
    predicted rate, its linearisation point)."""
    if coefficient == 0.0:
        return data
    scale = quadratic_growth(speed, coefficient)
    return dataclasses.replace(data, gain_scale=1.0 / scale, damping_scale=scale)


def quadratic_search(
    inputs: Measurements,
    model: str,
    bounds: tuple[float, float] = (-0.3, 1.0),
    *,
    search: _Search | None = None,
) -> QuadraticSearch:
    """The quadratic damping coefficient within ``bounds`` that best describes the roll
    (:func:`rate_damped`): its profile likelihood, every parameter refitted at each ``q``
    (the gain and the damping law absorb part of the term: a screen at the linear fit's
    parameters misses it), maximised by a bounded scalar search to 0.005.

    ``|v|`` along each interval is what the linear fit knew before that interval's
    reading, from its filtered rate at the interval's start to its prediction at the end:
    the smoothed rate would know the reading, and with it the turbulence the term is
    judged against (on the paper's in-model truth it found q ≈ -0.1 at LR 30-80).
    ``search`` is the linear fits' of ``inputs`` where the caller has them."""
    if search is None:
        search = _Search(prepare(inputs), inputs)
    data = search.data
    base = _fit(search, model)
    nat = search.order(model, base.ar.size)[1]
    predicted, filtered = filtered_means(base._state_space)
    share = (np.arange(data.per) + 0.5) / data.per
    speed = np.abs(filtered[:-1, :1] * (1.0 - share) + predicted[1:, :1] * share).ravel()
    mean_speed = float(np.mean(speed))
    # a damping that stays positive at the fastest roll: q > -QUADRATIC_RATE_DPS / |v|
    lowest = -0.9 * QUADRATIC_RATE_DPS / max(float(np.max(speed)), 1e-9)
    bounds = (max(bounds[0], lowest), bounds[1])
    profile: dict[float, float] = {0.0: base.loglike}

    def negloglike(c: float) -> float:
        if c not in profile:
            damped = rate_damped(data, speed, c)
            # the linear fit's parameters, its gain given back the rate's mean damping
            gain = float(quadratic_growth(mean_speed, c))
            warm = {**nat, "alpha": nat["alpha"] * gain}
            result = _maximise(damped, parameter_map(damped, model, base.ar.size, nat), warm)
            profile[c] = max(-float(result.fun), -negloglike_natural(damped, warm))
        return -profile[c]

    for end in bounds:  # the profile's ends, which the bounded search does not visit
        negloglike(end)
    optimize.minimize_scalar(negloglike, bounds=bounds, method="bounded", options={"xatol": 0.005})
    best = max(profile, key=lambda c: profile[c])
    floor = profile[best] - 0.5 * float(stats.chi2.ppf(0.95, 1))
    ends = []
    for end in bounds:
        if -negloglike(end) >= floor:
            ends.append(end)
        else:
            ends.append(
                optimize.brentq(lambda c: -negloglike(c) - floor, *sorted((best, end)), xtol=0.005)
            )
    return QuadraticSearch(
        float(best),
        base.loglike,
        profile[best],
        dict(sorted(profile.items())),
        (ends[0], ends[1]),
        readonly_array(speed),
    )


def quadratic_fit(
    inputs: Measurements, model: str, found: QuadraticSearch, base: MLFit | None = None
) -> MLFit:
    """The fit with the quadratic damping ``found``: every parameter and the turbulence's
    AR order refitted with the damping ``a(θ)·(1 + q·|v|/QUADRATIC_RATE_DPS)`` along the
    search's ``|v|`` (:func:`rate_damped`), its posterior ``u_d`` that rocket's, its
    parameters carrying ``q`` (the environment replays it at each substep's own rate).
    At ``q = 0`` the linear fit ``base`` where given."""
    q = found.coefficient
    if q == 0.0 and base is not None:
        return base
    if np.size(found.speed) == 0:
        raise ValueError("the quadratic search carries no |v| path to refit along")
    damped = rate_damped(prepare(inputs), np.asarray(found.speed), q)
    fitted = _fit(_Search(damped, inputs), model)
    return dataclasses.replace(  # q is one parameter more, in every order's AIC too
        fitted,
        params=dataclasses.replace(fitted.params, quadratic_damping=q),
        n_params=fitted.n_params + 1,
        aic=fitted.aic + 2.0,
        orders={k: v + 2.0 for k, v in fitted.orders.items()},
    )


#: Lags of the innovations' autocorrelation and Ljung-Box test.
INNOVATION_LAGS = 10


def innovation_checks(found: MLFit) -> dict[str, Any]:
    """Whiteness and normality of the fit's one-step prediction errors of its first
    sensor (the gyro where there is one): the largest ``|ACF|`` over lags 1 to
    :data:`INNOVATION_LAGS` (an effect size: about ``2/√n`` for white noise), the Ljung-Box
    p-value at that lag (on a long record it rejects any small structure), skewness and
    excess kurtosis (0 and 0 for the normal the likelihood assumes)."""
    from scipy import stats
    from statsmodels.stats.diagnostic import acorr_ljungbox

    e = standardized_innovations(found._state_space, 0)
    centred = e - e.mean()
    denom = float(centred @ centred)
    acf = np.array(
        [float(centred[:-k] @ centred[k:]) / denom for k in range(1, INNOVATION_LAGS + 1)]
    )
    lb = acorr_ljungbox(e, lags=[INNOVATION_LAGS])
    sensor = "gyro" if int(found._state_space.observed[0]) == 0 else "angle"
    return {
        "sensor": sensor,
        "n": int(e.size),
        "max_acf": float(np.max(np.abs(acf))),
        "ljung_box_p": float(lb["lb_pvalue"].iloc[0]),
        "skewness": float(stats.skew(e)),
        "excess_kurtosis": float(stats.kurtosis(e)),
    }


def ml_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """Maximum likelihood as an identification method (``method="ml"``).

    Its trace is the posterior mean ``u_d``; metrics add the log-likelihood,
    AIC, AR order, standard errors and the turbulence's fitted statistics.
    The re-simulation (step 9) starts from the posterior mean initial state,
    the method's own estimate of it: the measured first velocity is a
    smoothed derivative whose error would stay in the angle for good.
    """
    searched = context_latency(context)
    search, latency = searched.search, searched.term
    inputs = search.inputs
    fits = []
    for model in models:
        found = _fit(search, model, intervals=context.options.intervals)
        beyond: dict[str, Any] = {}
        if context.options.fit_quadratic_damping:
            term = quadratic_search(inputs, model, search=search)
            beyond["quadratic_damping"] = term.summary()
            if term.p < TERM_LEVEL:
                found = quadratic_fit(inputs, model, term, found)
        dist = found.disturbance()
        resim = inputs.resimulate(dist, found.initial_state)
        metrics = {
            "sources": {
                "angle": inputs.angle_source,
                "velocity": inputs.velocity_source,
                "fin_angle": inputs.theta_source,
            },
            **resimulation_metrics(resim),
            "loglike": found.loglike,
            "aic": found.aic,
            "n_params": found.n_params,
            "ar_order": int(found.ar.size),
            "ar": found.ar.tolist(),
            "u_d_sd_deg": found.sd_deg,
            "innovation_sd_deg": found.innovation_sd_deg,
            "gyro_noise": found.gyro_noise,
            "gyro_floor_dps": found.gyro_floor_dps,
            "angle_noise_deg": found.angle_noise_deg,
            "std_errors": found.std_errors,
            "correlations": found.correlations,
            "intervals": found.intervals,
            **({"sensor_latency": latency} if latency else {}),
            **({"loop_alone": found.loop_alone} if found.loop_alone else {}),
            "aic_by_order": {str(k): v for k, v in found.orders.items()},
            "nfev": found.nfev,
            "converged": found.converged,
            "posterior_sd_mean_deg": float(np.mean(found.u_d_sd_deg)),
            "innovations": innovation_checks(found),
            **beyond,
        }
        settings = {"interval_s": found.interval_s, "estimate": "posterior mean (RTS smoother)"}
        fits.append(
            ModelFit(
                "ml",
                model,
                found.params,
                dist,
                metrics,
                settings,
                u_d_sd_deg=found.u_d_sd_deg,
                sample_posterior=found.posterior_draws,
            )
        )
    return fits
