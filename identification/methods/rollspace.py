"""The roll model as a linear Gaussian state-space model, the turbulence an AR state: what
the ``ml`` method (:mod:`identification.methods.ml`) fits.

The paper's model (eq. 36/49) over one sample interval ``Δt``, with the fin
angle ``θ(t)`` known and ``u_d`` held, is affine in the rate, the angle and
``u_d`` (:func:`identification.model.piece_coefficients`, composed over the
fine grid's substeps)::

    v[k+1] = E[k]·v[k] + G[k]·u_d[k] + f[k]
    φ[k+1] = φ[k] + A[k]·v[k] + B[k]·u_d[k] + g[k]

With the turbulence a zero-mean AR process of order ``p`` on the sample grid
and the state ``[v, φ, u_d[k], ..., u_d[k-p+1]]``, this module writes the
model once: the recording's measurements and their noise (:func:`prepare`), the
optimiser's parameters (:class:`RollParameterMap`), the system for given parameters
(:func:`roll_parts`, :func:`roll_transition`, :func:`roll_system`) and its
log-likelihood by a sparse compiled Kalman filter (:func:`roll_loglike`), which
the estimation core (:mod:`identification.estimation.likelihood`) maximises
through :class:`RollLikelihood`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from scipy import linalg

from identification.compiled import UNSCALED, interval_maps_kernel
from identification.estimation.likelihood import negloglike_at
from identification.estimation.statespace import LinearGaussian, update
from identification.methods.pipeline import Measurements
from identification.recordings.recording import quantum_of
from rocketroll_common.arrays import FloatArray

__all__ = [
    "MIN_DAMPING",
    "RollData",
    "RollLikelihood",
    "RollParameterMap",
    "RollParts",
    "ar_from_pacf",
    "count_params",
    "loglike",
    "negloglike_natural",
    "pacf_from_ar",
    "parameter_map",
    "pivot",
    "prepare",
    "roll_loglike",
    "roll_parts",
    "roll_system",
    "roll_transition",
    "stationary_cov",
]


#: Smallest damping the optimiser may visit, 1/s.
MIN_DAMPING = 0.01


#: Variance floor of a measurement, (° or °/s)², so an ideal sensor stays regular.
_VAR_FLOOR = 1e-8


@dataclass(frozen=True)
class RollData:
    """What the likelihood needs from a recording, prepared once."""

    name: str
    time_s: FloatArray
    theta_fine: FloatArray
    per: int
    h: float
    y: FloatArray  # (n, d): columns in the order of ``observed``
    observed: np.ndarray  # state index of each column: 0 rate, 1 angle
    angle_var: float  # encoder quantisation variance, or NaN without an encoder
    has_gyro: bool
    angle_noise: float  # the angle's noise SD beyond its grid read off the data, ° (0: none)
    theta_min: float
    theta_max: float
    #: Per substep: the gain's and the damping's multipliers (empty: none), as in flight.
    gain_scale: FloatArray = field(default_factory=lambda: UNSCALED)
    damping_scale: FloatArray = field(default_factory=lambda: UNSCALED)

    @property
    def n(self) -> int:
        return int(self.y.shape[0])


#: The angle's sample-to-sample noise, as a multiple of its grid's ``q/√12``, beyond
#: which it is not an encoder's quantisation alone and its SD is a parameter.
_BEYOND_GRID = 2.0


def _noise_beyond_grid(angle: FloatArray, grid_var: float) -> float:
    """The angle's white-noise SD as its second differences show it (``SD(Δ²φ)/√6``),
    where that is more than :data:`_BEYOND_GRID` times what the grid explains; else 0.

    An encoder's reading scatters by its quantisation only (``q²/12``); an analogue
    angle (a potentiometer, an attitude estimate, a converted log) has noise of its
    own, which read as exact would make the turbulence carry it.
    """
    sd = float(np.std(np.diff(angle, 2))) / math.sqrt(6.0)
    return sd if sd > _BEYOND_GRID * math.sqrt(grid_var) else 0.0


def prepare(inputs: Measurements) -> RollData:
    rec = inputs.recording
    # A validated recording has at least 50 samples and a fin that moves.
    theta = np.asarray(inputs.theta_fine, dtype=float)
    columns, observed = [], []
    angle_var = math.nan
    angle_noise = 0.0
    if rec.roll_rate_dps is not None:
        columns.append(np.asarray(rec.roll_rate_dps, dtype=float))
        observed.append(0)
    if rec.roll_deg is not None:
        roll = np.asarray(rec.roll_deg, dtype=float)
        q = quantum_of(roll)
        angle_var = max(q * q / 12.0, _VAR_FLOOR)
        angle_noise = _noise_beyond_grid(roll, angle_var)
        columns.append(roll)
        observed.append(1)
    return RollData(
        name=rec.name,
        time_s=np.asarray(rec.time_s, dtype=float),
        theta_fine=theta,
        per=int(inputs.grid.per_sample),
        h=float(inputs.grid.step_s),
        y=np.column_stack(columns),
        observed=np.asarray(observed, dtype=np.intp),
        angle_var=angle_var,
        has_gyro=rec.roll_rate_dps is not None,
        angle_noise=angle_noise,
        theta_min=float(theta.min()),
        theta_max=float(theta.max()),
    )


# ----------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class RollParameterMap:
    """Names of the unconstrained vector the optimiser moves, for one model and order.

    The θ-dependent damping is moved as its value ``a_mid`` at the typical
    deflection ``|θ + θ̄| = pivot`` and its change ``slope = ᾱ·pivot`` across
    it: ᾱ and β̄ themselves are nearly collinear, which slows the optimiser.
    """

    model: str
    order: int
    gyro: bool
    pivot: float = 1.0
    angle: bool = False  # the angle's noise beyond its grid is a parameter
    floor: bool = False  # the gyro's additive noise is a parameter

    @property
    def names(self) -> tuple[str, ...]:
        damping = ("a",) if self.model == "constant" else ("a_mid", "slope")
        ar = tuple(f"ar{i + 1}" for i in range(self.order))
        return (
            "alpha",
            "theta_bar",
            *damping,
            *ar,
            "sd",
            *(("gyro",) if self.gyro else ()),
            *(("angle",) if self.angle else ()),
            *(("floor",) if self.floor else ()),
        )

    @property
    def bounds(self) -> None:
        """None: the vector is unbounded (the transforms below keep it in the model)."""
        return None

    def natural(self, x: FloatArray) -> dict[str, Any]:
        """Parameters from the optimiser's vector: AR coefficients stationary by
        construction (partial autocorrelations through tanh), SDs positive (log), both
        held in a box (:data:`_PACF_BOX`, :data:`_LOG_SD_BOX`) where they stay regular."""
        values = dict(zip(self.names, x.tolist(), strict=True))
        pacf = np.tanh(np.clip([values[f"ar{i + 1}"] for i in range(self.order)], *_PACF_BOX))
        out: dict[str, Any] = {
            "alpha": values["alpha"],
            "theta_bar": values["theta_bar"],
            "ar": ar_from_pacf(pacf),
            "innovation_sd": _level(values["sd"]),
            "gyro": _level(values["gyro"]) if self.gyro else 0.0,
            "angle_sd": _level(values["angle"]) if self.angle else 0.0,
            "gyro_floor": _level(values["floor"]) if self.floor else 0.0,
        }
        if self.model == "constant":
            out["alpha_bar"], out["beta_bar"] = 0.0, values["a"]
        else:
            out["alpha_bar"] = values["slope"] / self.pivot
            out["beta_bar"] = values["a_mid"] - values["slope"]
        return out

    def vector(self, nat: dict[str, Any]) -> FloatArray:
        """The optimiser's vector for natural parameters (inverse of :meth:`natural`)."""
        pacf = pacf_from_ar(np.asarray(nat["ar"], dtype=float))
        slope = nat["alpha_bar"] * self.pivot
        values = {
            "alpha": nat["alpha"],
            "theta_bar": nat["theta_bar"],
            "a": nat["beta_bar"],
            "a_mid": nat["beta_bar"] + slope,
            "slope": slope,
            "sd": math.log(nat["innovation_sd"]),
            "gyro": math.log(max(nat["gyro"], 1e-6)),
            "angle": math.log(max(nat.get("angle_sd", 0.0), 1e-6)),
            "floor": math.log(max(nat.get("gyro_floor", 0.0), 1e-6)),
            **{
                f"ar{i + 1}": float(np.arctanh(np.clip(r, -0.999, 0.999)))
                for i, r in enumerate(pacf)
            },
        }
        return np.array([values[name] for name in self.names], dtype=float)


#: Box of a partial autocorrelation's ``atanh``: ``|pacf| ≤ tanh(7) = 1 - 1.7e-6``.  A
#: turbulence the data cannot tell from a constant walks towards the unit root, where
#: ``tanh`` rounds to 1 and its stationary covariance is singular; the box stops it.
_PACF_BOX = (-7.0, 7.0)


#: Box of a noise level's natural log (SDs from 2e-9 to 2e4, ° or °/s, or a fraction):
#: a level the data do not need walks towards 0, where its variance underflows.
_LOG_SD_BOX = (-20.0, 10.0)


def _level(log_sd: float) -> float:
    """A noise level from its log, held in :data:`_LOG_SD_BOX`."""
    return math.exp(min(max(log_sd, _LOG_SD_BOX[0]), _LOG_SD_BOX[1]))


def ar_from_pacf(pacf: FloatArray) -> FloatArray:
    """AR coefficients from partial autocorrelations (Durbin–Levinson; |pacf| < 1: stationary)."""
    phi = np.zeros(0)
    for k, r in enumerate(np.asarray(pacf, dtype=float)):
        phi = np.append(phi - r * phi[::-1], r) if k else np.array([r])
    return phi


def pacf_from_ar(ar: FloatArray) -> FloatArray:
    """Partial autocorrelations of a stationary AR polynomial (inverse Durbin–Levinson)."""
    phi = np.asarray(ar, dtype=float).copy()
    out = np.empty(phi.size)
    for k in range(phi.size - 1, -1, -1):
        r = phi[k]
        out[k] = r
        if k:
            phi = (phi[:k] + r * phi[:k][::-1]) / (1.0 - r * r)
    return out


def stationary_cov(ar: FloatArray, innovation_sd: float) -> FloatArray:
    """Covariance of ``[u_d[k], ..., u_d[k-p+1]]`` of the stationary AR process."""
    p = ar.size
    companion = np.zeros((p, p))
    companion[0] = ar
    companion[1:, :-1] = np.eye(p - 1)
    q = np.zeros((p, p))
    q[0, 0] = innovation_sd**2
    cov = linalg.solve_discrete_lyapunov(companion, q)
    return np.asarray(0.5 * (cov + cov.T), dtype=float)


@dataclass(frozen=True, eq=False)
class RollParts:
    """The roll model's state-space pieces under one set of parameters."""

    maps: FloatArray  # (n - 1, 6): [E, G, f, A, B, g] per interval
    ar: FloatArray
    innovation_var: float
    gyro_var: float  # g² of eq. 52
    floor_var: float  # the gyro's additive noise variance, (°/s)²
    obs_var: FloatArray  # the gyro's columns NaN until a filter pass fills them
    initial_mean: FloatArray
    initial_cov: FloatArray


def roll_parts(data: RollData, nat: dict[str, Any]) -> RollParts | None:
    """The model of ``data`` under natural parameters; None where the damping is not positive."""
    alpha, theta_bar = nat["alpha"], nat["theta_bar"]
    alpha_bar, beta_bar = nat["alpha_bar"], nat["beta_bar"]
    lowest = beta_bar + min(
        alpha_bar * abs(data.theta_min + theta_bar), alpha_bar * abs(data.theta_max + theta_bar)
    )
    if not (lowest >= MIN_DAMPING and alpha != 0.0):
        return None
    ar = np.asarray(nat["ar"], dtype=float)
    m = 2 + ar.size
    maps = interval_maps_kernel(
        alpha,
        theta_bar,
        beta_bar,
        alpha_bar,
        data.theta_fine,
        data.per,
        data.h,
        data.gain_scale,
        data.damping_scale,
        -1.0,
    )
    obs_var = np.empty(data.y.shape)
    for j, index in enumerate(data.observed.tolist()):
        if index == 1:
            obs_var[:, j] = data.angle_var + nat.get("angle_sd", 0.0) ** 2
        else:  # eq. 52: Var = g²·v², filled in by the filter (:func:`_sparse_loglike`)
            obs_var[:, j] = math.nan
    u_cov = stationary_cov(ar, nat["innovation_sd"])
    initial_mean = np.zeros(m)
    initial_cov = np.zeros((m, m))
    initial_cov[2:, 2:] = u_cov
    initial_mean[0] = alpha * (float(data.theta_fine[0]) + theta_bar)
    initial_cov[0, 0] = (alpha**2) * u_cov[0, 0] + 1.0
    angle_col = np.flatnonzero(data.observed == 1)
    if angle_col.size:
        # Where the angle starts is not a parameter: a wide prior, pinned by the first reading.
        initial_mean[1] = data.y[0, angle_col[0]]
        initial_cov[1, 1] = 1e4
    else:
        initial_cov[1, 1] = 1.0
    return RollParts(
        maps,
        ar,
        nat["innovation_sd"] ** 2,
        nat["gyro"] ** 2,
        nat.get("gyro_floor", 0.0) ** 2,
        obs_var,
        initial_mean,
        initial_cov,
    )


def roll_transition(maps: FloatArray, ar: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The transition ``T[k]`` and intercept ``c[k]`` of the state
    ``[v, φ, u_d[k], ..., u_d[k-p+1]]`` over each interval of ``maps``.

    ``maps`` (n, 6): ``[E, G, f, A, B, g]`` per interval (:func:`interval_maps`);
    ``ar``: the turbulence's AR coefficients.  Returns arrays of shapes
    (n, m, m) and (n, m), ``m = 2 + p``.  The one place the model's state-space
    form is written: the likelihood's sparse kernel (:func:`_predict_roll`) is
    checked against it, and the observer-based controller of
    :mod:`agents.observer` runs on it.
    """
    maps = np.atleast_2d(np.asarray(maps, dtype=float))
    n, p = maps.shape[0], ar.size
    m = 2 + p
    transition = np.zeros((n, m, m))
    transition[:, 0, 0] = maps[:, 0]
    transition[:, 0, 2] = maps[:, 1]
    transition[:, 1, 0] = maps[:, 3]
    transition[:, 1, 1] = 1.0
    transition[:, 1, 2] = maps[:, 4]
    transition[:, 2, 2:] = ar
    for i in range(1, p):
        transition[:, 2 + i, 1 + i] = 1.0
    intercept = np.zeros((n, m))
    intercept[:, 0] = maps[:, 2]
    intercept[:, 1] = maps[:, 5]
    return transition, intercept


def roll_system(data: RollData, parts: RollParts) -> LinearGaussian:
    """The model as a general :class:`LinearGaussian` (for the smoother)."""
    m = 2 + parts.ar.size
    # n samples, n - 1 intervals: the last transition is not used (an all-zero map).
    maps = np.vstack([parts.maps, np.zeros((1, parts.maps.shape[1]))])
    transition, intercept = roll_transition(maps, parts.ar)
    state_cov = np.zeros((m, m))
    state_cov[2, 2] = parts.innovation_var
    return LinearGaussian(
        y=data.y,
        observed=data.observed,
        obs_var=parts.obs_var,
        transition=transition,
        intercept=intercept,
        state_cov=state_cov,
        initial_mean=parts.initial_mean,
        initial_cov=parts.initial_cov,
    )


@numba.njit(cache=True, nogil=True)
def _predict_roll(
    a: FloatArray,
    p: FloatArray,
    step: FloatArray,
    ar: FloatArray,
    innovation_var: float,
    work: FloatArray,
) -> None:
    """The time update of :func:`identification.estimation.statespace.predict` for the roll model's
    sparse transition (``step`` = ``[E, G, f, A, B, g]``; AR companion below), in place.

    Row by row, ``T·P`` and then ``(T·P)·T'`` touch only the non-zero entries of ``T``:
    O(m·p) per row instead of O(m²)."""
    m = a.size
    e, g, f, aa, bb, gg = step[0], step[1], step[2], step[3], step[4], step[5]
    order = ar.size
    x0 = a[2]
    new2 = 0.0
    for j in range(order):
        new2 += ar[j] * a[2 + j]
    a1 = a[1] + aa * a[0] + bb * x0 + gg
    a0 = e * a[0] + g * x0 + f
    for i in range(m - 1, 2, -1):
        a[i] = a[i - 1]
    a[0], a[1], a[2] = a0, a1, new2
    tp = work  # rows of T·P
    for s in range(m):
        tp[0, s] = e * p[0, s] + g * p[2, s]
        tp[1, s] = aa * p[0, s] + p[1, s] + bb * p[2, s]
        acc = 0.0
        for j in range(order):
            acc += ar[j] * p[2 + j, s]
        tp[2, s] = acc
        for i in range(3, m):
            tp[i, s] = p[i - 1, s]
    for r in range(m):
        c0 = e * tp[r, 0] + g * tp[r, 2]
        c1 = aa * tp[r, 0] + tp[r, 1] + bb * tp[r, 2]
        acc = 0.0
        for j in range(order):
            acc += ar[j] * tp[r, 2 + j]
        p[r, 0] = c0
        p[r, 1] = c1
        p[r, 2] = acc
        for i in range(3, m):
            p[r, i] = tp[r, i - 1]
    p[2, 2] += innovation_var
    for r in range(m):  # symmetric by construction; keep it exactly so
        for s in range(r + 1, m):
            mean = 0.5 * (p[r, s] + p[s, r])
            p[r, s] = mean
            p[s, r] = mean


@numba.njit(cache=True, nogil=True)
def _sparse_loglike(
    maps: FloatArray,
    ar: FloatArray,
    innovation_var: float,
    gyro_var: float,
    floor_var: float,
    y: FloatArray,
    observed: np.ndarray,
    obs_var: FloatArray,
    a0: FloatArray,
    p0: FloatArray,
) -> float:
    """The Kalman filter's log-likelihood of :func:`roll_system`, with the roll model's
    sparse time update (what the optimiser calls).

    The gyro's noise is multiplicative (eq. 52: ``y = (1 + g·ε)·v``): its variance
    ``g²·v²`` is taken at the predicted rate, ``g²·E[v² | y before] = g²·(v̂² + P_vv)``,
    which makes the update the best linear one (the reading itself would put its
    own noise into its weight).  The variances used are written into ``obs_var``'s
    gyro columns, so the smoother runs on the filter's model."""
    n, d = y.shape
    m = a0.size
    gains = np.empty((d, m))
    work = np.empty((m, m))
    a = a0.copy()
    p = p0.copy()
    ll = 0.0
    for k in range(n):
        for j in range(d):
            if observed[j] == 0:  # the rate is updated first: a, p are the prediction
                obs_var[k, j] = gyro_var * (a[0] * a[0] + p[0, 0]) + floor_var + _VAR_FLOOR
        ll += update(a, p, y[k], observed, obs_var[k], gains)
        if not ll > -np.inf:
            return -np.inf
        if k + 1 < n:
            _predict_roll(a, p, maps[k], ar, innovation_var, work)
    return ll


def loglike(data: RollData, nat: dict[str, Any]) -> float:
    """The log-likelihood of ``data`` under natural parameters (``-inf``: no stable model)."""
    parts = roll_parts(data, nat)
    return -math.inf if parts is None else roll_loglike(data, parts)


def negloglike_natural(data: RollData, nat: dict[str, Any]) -> float:
    return negloglike_at(functools.partial(loglike, data), nat)


@dataclass(frozen=True)
class RollLikelihood:
    """The roll model of one recording, as the estimation core fits it (with the sparse
    kernel's log-likelihood)."""

    data: RollData
    parameters: RollParameterMap

    def loglike(self, nat: dict[str, Any]) -> float:
        return loglike(self.data, nat)


def roll_loglike(data: RollData, parts: RollParts) -> float:
    """The log-likelihood of ``data`` under ``parts`` (fills the gyro's variances)."""
    return float(
        _sparse_loglike(
            parts.maps,
            parts.ar,
            parts.innovation_var,
            parts.gyro_var,
            parts.floor_var,
            data.y,
            data.observed,
            parts.obs_var,
            parts.initial_mean,
            parts.initial_cov,
        )
    )


def pivot(data: RollData, theta_bar: float) -> float:
    """The typical deflection ``mean |θ + θ̄|`` of the recording, ° (at least 1°)."""
    return max(float(np.mean(np.abs(data.theta_fine + theta_bar))), 1.0)


def parameter_map(data: RollData, model: str, order: int, nat: dict[str, Any]) -> RollParameterMap:
    """The optimiser's parameters for ``data`` near ``nat``: the recording's sensors, and
    the gyro's noise chosen by the first fit (:meth:`_Search._first`), decide which
    noise levels are free."""
    return RollParameterMap(
        model,
        order,
        data.has_gyro,
        pivot(data, nat["theta_bar"]),
        angle=data.angle_noise > 0.0,
        floor=nat.get("gyro_floor", 0.0) > 0.0,
    )


def count_params(data: RollData, model: str, order: int, nat: dict[str, Any]) -> int:
    return len(parameter_map(data, model, order, nat).names)
