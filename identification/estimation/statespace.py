"""Linear Gaussian state-space models: Kalman filter, likelihood, smoother, simulation smoother.

The model (the notation of Durbin & Koopman, *Time Series Analysis by State
Space Methods*, and of ``statsmodels.tsa.statespace``)::

    y[k]   = Z · s[k] + ε[k],            ε[k] ~ N(0, diag(H[k]))
    s[k+1] = T[k] · s[k] + c[k] + η[k],  η[k] ~ N(0, Q[k])
    s[0]   ~ N(a0, P0)

with a time-varying transition ``T[k]`` and intercept ``c[k]`` (the roll
model's closed form depends on the fin history, :mod:`identification.methods.ml`), a
state covariance ``Q`` that is constant (the tunnel) or changes per step (a
flight, whose airspeed scales the turbulence's effect: :mod:`identification.methods.flightfit`),
a selection ``Z`` of state components, diagonal measurement variances that may
change per sample, and missing observations as NaN.  Observations are
processed one component at a time (the univariate treatment of Koopman &
Durbin 2000), which with a diagonal ``H`` is the same filter as the
multivariate one.

The kernels are compiled by numba: the likelihood of a 5 700-sample record with
a four-dimensional state takes well under a millisecond, so maximum likelihood
can afford a few hundred evaluations.  ``tests/identification/test_statespace.py``
checks the likelihood, the smoothed states and covariances and the simulation
smoother against ``statsmodels`` to 1e-8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from rocketroll_common.arrays import FloatArray

IntArray = NDArray[np.intp]

__all__ = [
    "LinearGaussian",
    "Smoothed",
    "filtered_means",
    "loglike",
    "predict",
    "simulation_smoother",
    "smooth",
    "standardized_innovations",
    "update",
]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True, eq=False)
class LinearGaussian:
    """A linear Gaussian state-space model and its data.

    Attributes
    ----------
    y : ndarray, shape (n, d)
        Observations; NaN where a component is missing.
    observed : ndarray of int, shape (d,)
        The state component each observation column measures (``Z`` is a selection).
    obs_var : ndarray, shape (n, d)
        Measurement variance of each observation, ``H[k]`` (diagonal).
    transition : ndarray, shape (n, m, m)
        ``T[k]``, from sample ``k`` to ``k + 1`` (the last one is not used).
    intercept : ndarray, shape (n, m)
        ``c[k]``.
    state_cov : ndarray, shape (m, m) or (n, m, m)
        ``Q``, the covariance of the state disturbance: one for every step, or
        ``Q[k]`` from sample ``k`` to ``k + 1`` (the last one is not used).
    initial_mean, initial_cov : ndarray, shapes (m,) and (m, m)
        ``a0`` and ``P0``.
    """

    y: FloatArray
    observed: IntArray
    obs_var: FloatArray
    transition: FloatArray
    intercept: FloatArray
    state_cov: FloatArray
    initial_mean: FloatArray
    initial_cov: FloatArray

    def __post_init__(self) -> None:
        n, d = self.y.shape
        m = self.initial_mean.size
        shapes = {
            "observed": (self.observed.shape, (d,)),
            "obs_var": (self.obs_var.shape, (n, d)),
            "transition": (self.transition.shape, (n, m, m)),
            "intercept": (self.intercept.shape, (n, m)),
            "state_cov": (self.state_cov.shape, (n, m, m) if self.state_cov.ndim == 3 else (m, m)),
            "initial_cov": (self.initial_cov.shape, (m, m)),
        }
        for name, (got, want) in shapes.items():
            if got != want:
                raise ValueError(f"LinearGaussian.{name}: shape {got}, expected {want}")

    @property
    def n_states(self) -> int:
        return int(self.initial_mean.size)

    def _args(
        self,
    ) -> tuple[
        FloatArray, IntArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray
    ]:
        """The arrays in the kernels' order, contiguous and of their dtypes (``Q`` always
        three-dimensional: one step's, or every step's)."""
        state_cov = self.state_cov if self.state_cov.ndim == 3 else self.state_cov[None]
        return (
            np.ascontiguousarray(self.y, dtype=float),
            np.ascontiguousarray(self.observed, dtype=np.intp),
            np.ascontiguousarray(self.obs_var, dtype=float),
            np.ascontiguousarray(self.transition, dtype=float),
            np.ascontiguousarray(self.intercept, dtype=float),
            np.ascontiguousarray(state_cov, dtype=float),
            np.ascontiguousarray(self.initial_mean, dtype=float),
            np.ascontiguousarray(self.initial_cov, dtype=float),
        )


@numba.njit(cache=True, nogil=True)
def update(
    a: FloatArray,
    p: FloatArray,
    y: FloatArray,
    observed: IntArray,
    obs_var: FloatArray,
    gains: FloatArray,
) -> float:
    """Measurement update of one sample in place, one component at a time.

    ``y``, ``obs_var``: this sample's observations (NaN: missing) and their
    variances; ``gains`` (d, m) receives the Kalman gains.  Returns the
    sample's log-likelihood, ``-inf`` if a prediction variance is not positive.
    """
    m = a.size
    ll = 0.0
    for j in range(y.size):
        value = y[j]
        if math.isnan(value):
            continue
        i = observed[j]
        f = p[i, i] + obs_var[j]
        if not f > 0.0:
            return -np.inf
        innovation = value - a[i]
        ll -= 0.5 * (_LOG_2PI + math.log(f) + innovation * innovation / f)
        for r in range(m):
            gains[j, r] = p[r, i] / f
        for r in range(m):
            a[r] += gains[j, r] * innovation
            for s in range(m):
                p[r, s] -= gains[j, r] * gains[j, s] * f
    return ll


@numba.njit(cache=True, nogil=True)
def predict(
    a: FloatArray,
    p: FloatArray,
    t: FloatArray,
    c: FloatArray,
    q: FloatArray,
    work: FloatArray,
) -> None:
    """Time update in place: ``a <- T a + c``, ``P <- T P T' + Q``.

    ``work``: an (m + 1, m) scratch array, so a step allocates nothing.
    """
    m = a.size
    for r in range(m):
        acc = c[r]
        for s in range(m):
            acc += t[r, s] * a[s]
        work[m, r] = acc
        for s in range(m):
            acc = 0.0
            for k in range(m):
                acc += t[r, k] * p[k, s]
            work[r, s] = acc
    a[:] = work[m]
    for r in range(m):
        for s in range(r, m):
            acc = q[r, s]
            for k in range(m):
                acc += work[r, k] * t[s, k]
            p[r, s] = acc
            p[s, r] = acc


@numba.njit(cache=True, nogil=True)
def _filter(
    y: FloatArray,
    observed: IntArray,
    obs_var: FloatArray,
    transition: FloatArray,
    intercept: FloatArray,
    state_cov: FloatArray,
    a0: FloatArray,
    p0: FloatArray,
    keep: bool,
) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Univariate Kalman filter.  Returns the log-likelihood and, with ``keep``,
    the predicted and filtered means and covariances and the gains."""
    n, d = y.shape
    m = a0.size
    size = n if keep else 1
    a_pred = np.empty((size, m))
    p_pred = np.empty((size, m, m))
    a_filt = np.empty((size, m))
    p_filt = np.empty((size, m, m))
    gains = np.zeros((size, d, m))
    a = a0.copy()
    p = p0.copy()
    work = np.empty((m + 1, m))
    ll = 0.0
    for k in range(n):
        if keep:
            a_pred[k] = a
            p_pred[k] = p
        ll += update(a, p, y[k], observed, obs_var[k], gains[k if keep else 0])
        if not ll > -np.inf:
            return -np.inf, a_pred, p_pred, a_filt, p_filt, gains
        if keep:
            a_filt[k] = a
            p_filt[k] = p
        if k + 1 < n:
            q = state_cov[min(k, state_cov.shape[0] - 1)]
            predict(a, p, transition[k], intercept[k], q, work)
    return ll, a_pred, p_pred, a_filt, p_filt, gains


@numba.njit(cache=True, nogil=True)
def _smoother_gains(
    transition: FloatArray, p_pred: FloatArray, p_filt: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """RTS gains ``J[k] = P[k|k] T[k]' P[k+1|k]^-1`` and the smoothed covariances."""
    n, m, _ = p_filt.shape
    gains = np.zeros((n, m, m))
    p_smooth = np.empty((n, m, m))
    p_smooth[n - 1] = p_filt[n - 1]
    for k in range(n - 2, -1, -1):
        cross = p_filt[k] @ transition[k].T
        # J = cross · P_pred^-1, i.e. P_pred · J' = cross' (P_pred symmetric).
        j = np.linalg.solve(p_pred[k + 1], cross.T).T
        gains[k] = j
        ps = p_filt[k] + j @ (p_smooth[k + 1] - p_pred[k + 1]) @ j.T
        p_smooth[k] = 0.5 * (ps + ps.T)
    return gains, p_smooth


@numba.njit(cache=True, nogil=True)
def _smoothed_means(
    y: FloatArray,
    observed: IntArray,
    transition: FloatArray,
    intercept: FloatArray,
    a0: FloatArray,
    gains: FloatArray,
    rts: FloatArray,
) -> FloatArray:
    """Smoothed state means for observations ``y`` given the filter's and smoother's gains.

    The gains of a linear Gaussian model do not depend on the data, so the
    simulation smoother runs only this for each of its draws."""
    n, d = y.shape
    m = a0.size
    a_pred = np.empty((n, m))
    a_filt = np.empty((n, m))
    a = a0.copy()
    for k in range(n):
        a_pred[k] = a
        for j in range(d):
            value = y[k, j]
            if math.isnan(value):
                continue
            innovation = value - a[observed[j]]
            for r in range(m):
                a[r] += gains[k, j, r] * innovation
        a_filt[k] = a
        if k + 1 < n:
            a = transition[k] @ a + intercept[k]
    out = np.empty((n, m))
    out[n - 1] = a_filt[n - 1]
    for k in range(n - 2, -1, -1):
        out[k] = a_filt[k] + rts[k] @ (out[k + 1] - a_pred[k + 1])
    return out


def filtered_means(model: LinearGaussian) -> tuple[FloatArray, FloatArray]:
    """The predicted and the filtered state means, each ``(n, m)``: the state at each
    reading given those before it, and given it too."""
    args = model._args()
    ll, predicted, _, filtered, _, _ = _filter(*args, True)
    if not ll > -np.inf:
        raise ValueError("the filter met a reading of zero likelihood: no filtered means")
    return predicted, filtered


def loglike(model: LinearGaussian) -> float:
    """Log-likelihood of the observations (prediction-error decomposition)."""
    y, observed, obs_var, transition, intercept, state_cov, a0, p0 = model._args()
    ll = _filter(y, observed, obs_var, transition, intercept, state_cov, a0, p0, False)[0]
    return float(ll)


@dataclass(frozen=True, eq=False)
class Smoothed:
    """The smoother's output.

    Attributes
    ----------
    loglike : float
        Log-likelihood of the observations.
    mean : ndarray, shape (n, m)
        ``E[s[k] | y]``.
    cov : ndarray, shape (n, m, m)
        ``Var[s[k] | y]``.
    filter_gains, smoother_gains : ndarray
        The Kalman gains (one per observation component) and the RTS gains,
        reused by :func:`simulation_smoother`.
    """

    loglike: float
    mean: FloatArray
    cov: FloatArray
    filter_gains: FloatArray
    smoother_gains: FloatArray


def smooth(model: LinearGaussian) -> Smoothed:
    """Kalman filter and Rauch–Tung–Striebel smoother."""
    y, observed, obs_var, transition, intercept, state_cov, a0, p0 = model._args()
    ll, _, p_pred, _, p_filt, gains = _filter(
        y, observed, obs_var, transition, intercept, state_cov, a0, p0, True
    )
    if not np.isfinite(ll):
        raise ValueError("the model's prediction variance is not positive")
    rts, p_smooth = _smoother_gains(transition, p_pred, p_filt)
    mean = _smoothed_means(y, observed, transition, intercept, a0, gains, rts)
    return Smoothed(float(ll), mean, p_smooth, gains, rts)


def standardized_innovations(model: LinearGaussian, channel: int = 0) -> FloatArray:
    """The one-step prediction errors of observation ``channel`` (the first one the filter
    reads at each step, before any other of that step), each divided by its predicted SD;
    missing readings left out.  White and of unit variance where the model is right."""
    y, observed, obs_var, transition, intercept, state_cov, a0, p0 = model._args()
    ll, a_pred, p_pred, _, _, _ = _filter(
        y, observed, obs_var, transition, intercept, state_cov, a0, p0, True
    )
    if not np.isfinite(ll):
        raise ValueError("the model's prediction variance is not positive")
    o = int(observed[channel])
    error = y[:, channel] - a_pred[:, o]
    variance = p_pred[:, o, o] + obs_var[:, channel]
    ok = np.isfinite(error) & (variance > 0)
    return np.asarray(error[ok] / np.sqrt(variance[ok]), dtype=float)


@numba.njit(cache=True, nogil=True)
def _simulate(
    observed: IntArray,
    obs_var: FloatArray,
    missing: NDArray[np.bool_],
    transition: FloatArray,
    intercept: FloatArray,
    state_chol: FloatArray,
    initial: FloatArray,
    eps: FloatArray,
    eta: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """States and observations from given standard-normal draws (``eps``, ``eta``)."""
    n, d = obs_var.shape
    m = initial.size
    states = np.empty((n, m))
    ys = np.empty((n, d))
    s = initial.copy()
    for k in range(n):
        states[k] = s
        for j in range(d):
            if missing[k, j]:
                ys[k, j] = np.nan
            else:
                ys[k, j] = s[observed[j]] + math.sqrt(obs_var[k, j]) * eps[k, j]
        if k + 1 < n:
            chol = state_chol[min(k, state_chol.shape[0] - 1)]
            s = transition[k] @ s + intercept[k] + chol @ eta[k]
    return states, ys


def simulation_smoother(
    model: LinearGaussian,
    smoothed: Smoothed,
    rng: np.random.Generator | None = None,
    size: int = 1,
    *,
    draws: tuple[FloatArray, FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """Draws of the states from their posterior given the data (Durbin & Koopman 2002).

    Each draw simulates states and observations ``(s+, y+)`` from the model,
    smooths ``y+`` with the same gains, and returns
    ``E[s | y] + s+ - E[s+ | y+]``: an exact draw from ``p(s | y)``.

    Parameters
    ----------
    model : LinearGaussian
        The model (with the data).
    smoothed : Smoothed
        :func:`smooth` of it.
    rng : numpy.random.Generator, optional
        Source of the draws.
    size : int
        Number of draws.
    draws : tuple of ndarray, optional
        ``(eps, eta, initial)`` per draw, standard-normal measurement shocks
        (size, n, d), state shocks (size, n, m) and initial states (size, m)
        themselves, instead of ``rng`` (for tests that compare with another
        implementation).

    Returns
    -------
    ndarray, shape (size, n, m)
    """
    y, observed, obs_var, transition, intercept, state_cov, a0, p0 = model._args()
    n, d = y.shape
    m = a0.size
    missing = np.isnan(y)
    state_chol = _cholesky(state_cov)  # one per step, or one for all
    if draws is None:
        generator = np.random.default_rng() if rng is None else rng
        eps = generator.standard_normal((size, n, d))
        eta = generator.standard_normal((size, n, m))
        initial = a0 + generator.standard_normal((size, m)) @ _cholesky(p0).T
    else:
        eps, eta, initial = (np.asarray(x, dtype=float) for x in draws)
        size = initial.shape[0]
    out = np.empty((size, n, m))
    for i in range(size):
        states, ys = _simulate(
            observed,
            obs_var,
            missing,
            transition,
            intercept,
            state_chol,
            initial[i],
            eps[i],
            eta[i],
        )
        again = _smoothed_means(
            ys, observed, transition, intercept, a0, smoothed.filter_gains, smoothed.smoother_gains
        )
        out[i] = smoothed.mean + states - again
    return out


def _cholesky(cov: FloatArray) -> FloatArray:
    """A square root ``L`` with ``L·L' = cov`` that tolerates zero rows (singular ``Q``);
    of each matrix of a stack (..., m, m)."""
    values, vectors = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    root = vectors * np.sqrt(np.clip(values, 0.0, None))[..., None, :]
    return np.ascontiguousarray(root, dtype=float)
