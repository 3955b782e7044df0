"""Maximum likelihood on a linear Gaussian state-space model, written once for every model.

statsmodels' ``MLEModel`` in miniature.  A model is

* a **parameter map** (:class:`ParameterMap`): the names of the vector the optimiser moves,
  its map to the natural parameters (``natural``) and back (``vector``), and its
  bounds (None: unbounded);
* its **log-likelihood** at natural parameters (:class:`Likelihood`'s
  ``loglike``): the Kalman filter's on the system it builds for them
  (:func:`identification.estimation.statespace.loglike`), or a faster kernel of
  its own; ``-inf`` where the parameters are no model (an unstable rocket).

On those this module fits it once for all: the negative log-likelihood the
optimiser reads (:func:`negloglike`, :data:`OUTSIDE` where it is not finite),
L-BFGS-B from each start (:func:`maximise`), the Hessian
(:func:`numerical_hessian`), the covariance of the estimates
(:func:`covariance`) and their standard errors (:func:`standard_errors`), and
posterior draws of the states (:func:`posterior_states`).  What every fit of the
roll model gives back is a :class:`StateSpaceFit`.

The tunnel's ``ml`` method (:mod:`identification.methods.ml`: the turbulence an
AR state, a fast kernel of its own) and the ``flight`` method
(:mod:`identification.methods.flightfit`: the turbulence a field flown through,
its system changing with the airspeed) are two such models; each keeps only its
parameter map, its system, its starts and its searches.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np
from scipy import optimize

from identification.estimation.statespace import LinearGaussian, Smoothed, simulation_smoother
from identification.model import Disturbance, RollParams
from rocketroll_common.arrays import FloatArray, readonly_array

__all__ = [
    "OUTSIDE",
    "Likelihood",
    "ParameterMap",
    "StateSpaceFit",
    "covariance",
    "maximise",
    "negloglike",
    "negloglike_at",
    "numerical_hessian",
    "posterior_states",
    "select_order",
    "standard_errors",
]

#: Negative log-likelihood where the parameters are outside the model (unstable, not finite).
OUTSIDE = 1e12
#: Forward-difference step of the gradient, relative to ``max(1, |x|)`` (√ machine epsilon).
_FD_STEP = math.sqrt(np.finfo(float).eps)
#: Step scale of the Hessian's central differences (statsmodels' ``EPS**(1/4)``).
_HESS_STEP = float(np.finfo(float).eps) ** 0.25
#: L-BFGS-B's iteration limit.
MAX_ITERATIONS = 500


class ParameterMap(Protocol):
    """The unconstrained vector the optimiser moves and its map to natural parameters."""

    @property
    def names(self) -> tuple[str, ...]: ...

    @property
    def bounds(self) -> list[tuple[float | None, float | None]] | None:
        """L-BFGS-B's bounds, one per name; None where the vector is unbounded."""
        ...

    def natural(self, x: FloatArray) -> dict[str, Any]: ...

    def vector(self, nat: dict[str, Any]) -> FloatArray: ...


class Likelihood(Protocol):
    """A model with its data: its parameter map and its log-likelihood at natural parameters."""

    @property
    def parameters(self) -> ParameterMap: ...

    def loglike(self, nat: dict[str, Any]) -> float:
        """The log-likelihood at ``nat``; ``-inf`` where ``nat`` is no model."""
        ...


def negloglike_at(loglike: Callable[[dict[str, Any]], float], nat: dict[str, Any]) -> float:
    """Minus ``loglike`` (a model's log-likelihood) at natural parameters ``nat``;
    :data:`OUTSIDE` where it is not finite."""
    value = -loglike(nat)
    return value if math.isfinite(value) else OUTSIDE


def negloglike(model: Likelihood, x: FloatArray) -> float:
    """Minus the model's log-likelihood at the optimiser's vector ``x``."""
    return negloglike_at(model.loglike, model.parameters.natural(x))


@functools.cache
def _threads() -> ThreadPoolExecutor:
    """Workers for the likelihood evaluations of a difference (the kernels release the GIL)."""
    return ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1)))


def _value_and_gradient(model: Likelihood, x: FloatArray) -> tuple[float, FloatArray]:
    """−log-likelihood and its forward-difference gradient, the ``k + 1`` evaluations
    spread over threads (what scipy's ``approx_grad`` does, one after another)."""
    steps = _FD_STEP * np.maximum(1.0, np.abs(x))
    points = [x] + [x + step * unit for step, unit in zip(steps, np.eye(x.size), strict=True)]
    values = np.fromiter(
        _threads().map(lambda point: negloglike(model, point), points), float, len(points)
    )
    return float(values[0]), (values[1:] - values[0]) / steps


def maximise(model: Likelihood, starts: Sequence[dict[str, Any]]) -> optimize.OptimizeResult:
    """L-BFGS-B from each start (natural parameters, clipped into the map's bounds); the
    result of least −log-likelihood (the first of equals).

    The gradient is forward differences: on threads where the map is unbounded, scipy's
    where it has bounds (which steps back from a bound)."""
    bounds = model.parameters.bounds
    objective: Callable[[FloatArray], Any]
    if bounds is None:
        objective, jac = functools.partial(_value_and_gradient, model), True
    else:
        objective, jac = functools.partial(negloglike, model), None
        low = [-np.inf if lo is None else lo for lo, _ in bounds]
        high = [np.inf if hi is None else hi for _, hi in bounds]
    best: optimize.OptimizeResult | None = None
    for start in starts:
        x0 = model.parameters.vector(start)
        result = optimize.minimize(
            objective,
            x0 if bounds is None else np.clip(x0, low, high),
            jac=jac,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": MAX_ITERATIONS},
        )
        if best is None or result.fun < best.fun:
            best = result
    if best is None:
        raise ValueError("maximise needs at least one start")
    return best


def numerical_hessian(f: Callable[[FloatArray], float], x: FloatArray) -> FloatArray:
    """statsmodels' ``approx_hess3`` (Ridout's four-point central differences, its steps,
    its arithmetic: the same numbers), with the ``2k(k + 1)`` evaluations of ``f``
    spread over threads."""
    n = x.size
    h = _HESS_STEP * np.maximum(np.abs(x), 0.1)
    ee = np.diag(h)
    pairs = [(i, j) for i in range(n) for j in range(i, n)]
    points = [
        point
        for i, j in pairs
        for point in (
            x + ee[i, :] + ee[j, :],
            x + ee[i, :] - ee[j, :],
            x - ee[i, :] + ee[j, :],
            x - ee[i, :] - ee[j, :],
        )
    ]
    values = np.fromiter(_threads().map(f, points), float, len(points)).reshape(-1, 4)
    hess = np.outer(h, h)
    for (i, j), (pp, pm, mp, mm) in zip(pairs, values, strict=True):
        hess[i, j] = (pp - pm - (mp - mm)) / (4.0 * hess[i, j])
        hess[j, i] = hess[i, j]
    return hess


def covariance(hess: FloatArray) -> FloatArray | None:
    """The estimates' covariance, the inverse of the −log-likelihood's Hessian; None where it
    is singular."""
    try:
        return np.asarray(np.linalg.inv(hess), dtype=float)
    except np.linalg.LinAlgError:
        return None


def standard_errors(
    cov: FloatArray | None, names: Sequence[str]
) -> tuple[dict[str, float], dict[str, float]]:
    """Standard errors and correlations of estimates ``names`` from their covariance
    (the first ``len(names)`` rows and columns of ``cov``): each SE (NaN where its variance
    is not positive, or ``cov`` is None) and each pair's correlation, ``"a~b"`` (empty
    unless every variance is positive)."""
    k = len(names)
    if cov is None:
        return {name: float("nan") for name in names}, {}
    block = np.asarray(cov, dtype=float)[:k, :k]
    var = np.diag(block)
    ok = np.isfinite(var) & (var > 0)
    sd = np.sqrt(np.where(ok, var, np.nan))
    se = {name: float(v) for name, v in zip(names, sd, strict=True)}
    if not np.all(ok):
        return se, {}
    corr = block / np.outer(sd, sd)
    return se, {
        f"{names[i]}~{names[j]}": float(corr[i, j]) for i in range(k) for j in range(i + 1, k)
    }


_Fit = TypeVar("_Fit")


def select_order(
    fit: Callable[[int], tuple[float, _Fit]],
    orders: Sequence[int],
    *,
    stop_when_worse: bool = False,
) -> tuple[int, dict[int, float], _Fit]:
    """The model order of least AIC: the one AR-order selection of the turbulence's fits.

    Each of ``orders`` is tried in turn, ``fit(order)`` giving its AIC and its fit; the
    first of equal AICs is kept.  ``stop_when_worse``: stop at the first order past the
    best whose AIC does not improve on it (for costly fits of nested models).  Returns the
    best order, the AIC of each order tried and the best order's fit.

    >>> select_order(lambda p: ((p - 2) ** 2, f"AR({p})"), range(1, 6), stop_when_worse=True)
    (2, {1: 1, 2: 0, 3: 1}, 'AR(2)')
    """
    aics: dict[int, float] = {}
    fits: dict[int, _Fit] = {}
    best: int | None = None
    for order in orders:
        aics[order], fits[order] = fit(order)
        if best is None or aics[order] < aics[best]:
            best = order
        elif stop_when_worse and order > best:
            break
    if best is None:
        raise ValueError("select_order needs at least one order")
    return best, aics, fits[best]


def posterior_states(
    system: LinearGaussian, smoothed: Smoothed, size: int, seed: int = 0
) -> FloatArray:
    """``size`` draws of the whole state path from its posterior given the data (the
    simulation smoother, seeded), shape ``(size, n, m)``."""
    if size < 1:
        raise ValueError(f"size must be at least 1, got {size}")
    return simulation_smoother(system, smoothed, np.random.default_rng(seed), size)


@dataclass(frozen=True, eq=False, kw_only=True)
class StateSpaceFit:
    """What every maximum-likelihood fit of the roll model gives: the rocket, the
    turbulence ``u_d`` the smoother recovers with its pointwise SD, and draws of it.

    Attributes
    ----------
    model : str
        ``constant`` or ``theta``.
    params : RollParams
        The estimate.
    loglike : float
        The log-likelihood at the estimate.
    std_errors : dict
        Standard errors of the rocket's estimates (by name).
    converged : bool
        The optimiser's verdict.
    time_s : ndarray, shape (n,)
        Sample times.
    interval_s : float
        The interval ``u_d`` is held over, s.
    u_d_deg, u_d_sd_deg : ndarray, shape (n - 1,)
        Posterior mean and SD of ``u_d`` over each sample interval, °.
    """

    model: str
    params: RollParams
    loglike: float
    std_errors: dict[str, float]
    converged: bool
    time_s: FloatArray
    interval_s: float
    u_d_deg: FloatArray
    u_d_sd_deg: FloatArray

    def disturbance(self) -> Disturbance:
        """The posterior mean ``u_d`` as a step-8 style disturbance (held per interval)."""
        return Disturbance(
            model=self.model,
            params=self.params,
            interval_s=self.interval_s,
            start_s=readonly_array(self.time_s[:-1]),
            u_d_deg=readonly_array(self.u_d_deg),
        )

    def posterior_draws(self, size: int, seed: int = 0) -> FloatArray:
        """``size`` draws of the whole ``u_d`` trace from its posterior given the recording,
        shape ``(size, n - 1)``, ° per sample interval: each a turbulence the rocket may
        have met that is consistent with the data."""
        raise NotImplementedError
