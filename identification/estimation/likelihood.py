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
(:func:`covariance`) and their standard errors (:func:`standard_errors`), profile-
likelihood intervals where the Hessian says nothing (:func:`profile_interval`), and
posterior draws of the states (:func:`posterior_states`).  What every fit of the
roll model gives back is a :class:`StateSpaceFit`.

The tunnel's ``ml`` method (:mod:`identification.methods.ml`: the turbulence an
AR state, a fast kernel of its own) and the ``flight`` method
(:mod:`identification.methods.flightfit`: the turbulence a field flown through,
its system changing with the airspeed) are two such models; each keeps only its
parameter map, its system, its starts and its searches.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np
from scipy import optimize, stats

from identification.estimation.statespace import LinearGaussian, Smoothed, simulation_smoother
from identification.model import Disturbance, RollParams
from rocketroll_common.arrays import FloatArray, readonly_array

__all__ = [
    "OUTSIDE",
    "PROFILE_ENDS",
    "Likelihood",
    "ParameterMap",
    "ProfileInterval",
    "StateSpaceFit",
    "covariance",
    "hessian_holds",
    "hessian_interval",
    "maximise",
    "negloglike",
    "negloglike_at",
    "numerical_hessian",
    "posterior_states",
    "profile_interval",
    "profile_step",
    "select_order",
    "standard_errors",
    "standing_interval",
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
    """−log-likelihood and its forward-difference gradient (:func:`_fd_value_and_gradient`)."""
    return _fd_value_and_gradient(functools.partial(negloglike, model), x)


def _fd_value_and_gradient(
    f: Callable[[FloatArray], float], x: FloatArray
) -> tuple[float, FloatArray]:
    """``f`` and its forward-difference gradient, the ``k + 1`` evaluations spread over
    threads (what scipy's ``approx_grad`` does, one after another)."""
    steps = _FD_STEP * np.maximum(1.0, np.abs(x))
    points = [x] + [x + step * unit for step, unit in zip(steps, np.eye(x.size), strict=True)]
    values = np.fromiter(_threads().map(f, points), float, len(points))
    return float(values[0]), (values[1:] - values[0]) / steps


def maximise(model: Likelihood, starts: Sequence[dict[str, Any]]) -> optimize.OptimizeResult:
    """L-BFGS-B from each start (natural parameters, clipped into the map's bounds); the
    result of least −log-likelihood (the first of equals).

    The gradient is forward differences: on threads where the map is unbounded, scipy's
    where it has bounds (which steps back from a bound)."""
    best: optimize.OptimizeResult | None = None
    objective = functools.partial(negloglike, model)
    for start in starts:
        result = _minimise(objective, model.parameters.vector(start), model.parameters.bounds)
        if best is None or result.fun < best.fun:
            best = result
    if best is None:
        raise ValueError("maximise needs at least one start")
    return best


def _minimise(
    f: Callable[[FloatArray], float],
    x0: FloatArray,
    bounds: Sequence[tuple[float | None, float | None]] | None,
) -> optimize.OptimizeResult:
    """L-BFGS-B on ``f`` from ``x0`` (clipped into ``bounds``): the gradient on threads
    (:func:`_fd_value_and_gradient`) where unbounded, scipy's where bounded."""
    if bounds is None:
        objective: Callable[[FloatArray], Any] = functools.partial(_fd_value_and_gradient, f)
        return optimize.minimize(
            objective, x0, jac=True, method="L-BFGS-B", options={"maxiter": MAX_ITERATIONS}
        )
    low = [-np.inf if lo is None else lo for lo, _ in bounds]
    high = [np.inf if hi is None else hi for _, hi in bounds]
    return optimize.minimize(
        f,
        np.clip(x0, low, high),
        method="L-BFGS-B",
        bounds=list(bounds),
        options={"maxiter": MAX_ITERATIONS},
    )


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


#: How each end of a :class:`ProfileInterval` is set.
PROFILE_ENDS = {
    "likelihood": "the profile likelihood falls to the level there: the data determine this side",
    "range": "the parameter's range (or the model's edge) ends first, within the level: "
    "the data do not exclude the range's end",
    "open": "the profile likelihood never falls to the level within the search: "
    "the data do not bound this side",
}


@dataclass(frozen=True)
class ProfileInterval:
    """A profile-likelihood interval: the values of one parameter the data do not reject
    at ``level`` (twice the log-likelihood within the χ²₁ quantile of the best, every other
    parameter re-fitted at each value).

    ``low_end`` / ``high_end`` say how each end is set (:data:`PROFILE_ENDS`);
    ``low``/``high`` are the range's end there, or, where open, the farthest value tried.
    ``gain`` is the most the log-likelihood rose along the profile above the fit's (a
    positive ``gain`` beyond a few hundredths: the fit was not at the maximum).
    ``evaluations``: the likelihood evaluations spent."""

    estimate: float
    low: float
    high: float
    low_end: str
    high_end: str
    level: float
    gain: float
    evaluations: int

    @property
    def determined(self) -> bool:
        """Both ends set by the likelihood: the data bound the parameter on both sides."""
        return self.low_end == "likelihood" and self.high_end == "likelihood"

    def joined(self, others: Sequence[ProfileInterval]) -> ProfileInterval:
        """This interval widened to hold ``others`` (the profiles from the likelihood's
        other optima, each at the same level from the best): the values no basin's profile
        rejects lie between the lowest low and the highest high.  The estimate stays this
        one's; each end is labelled as the profile that set it."""
        every = [self, *others]
        low = min(every, key=lambda p: p.low)
        high = max(every, key=lambda p: p.high)
        return dataclasses.replace(
            self,
            low=low.low,
            high=high.high,
            low_end=low.low_end,
            high_end=high.high_end,
            gain=max(p.gain for p in every),
            evaluations=sum(p.evaluations for p in every),
        )

    def as_dict(self, to_natural: Callable[[float], float] | None = None) -> dict[str, Any]:
        """The interval as the JSON reports it (``method: profile``), its values mapped by
        ``to_natural`` (increasing: the coordinate profiled was, say, a log)."""
        convert = to_natural or float
        return {
            "method": "profile",
            "estimate": convert(self.estimate),
            "low": convert(self.low),
            "high": convert(self.high),
            "low_end": self.low_end,
            "high_end": self.high_end,
            "level": self.level,
            "determined": self.determined,
        }


def hessian_interval(
    estimate: float, se: float, level: float = 0.95, *, log: bool = False
) -> dict[str, Any]:
    """The Hessian's interval ``estimate ± z·se`` in :meth:`ProfileInterval.as_dict`'s form
    (``method: hessian``); ``log``: ``estimate`` and ``se`` are a positive parameter's log
    and its SE, the interval ``exp(estimate ± z·se)``."""
    z = float(stats.norm.ppf(0.5 + 0.5 * level))
    convert = math.exp if log else float
    return {
        "method": "hessian",
        "estimate": convert(estimate),
        "low": convert(estimate - z * se),
        "high": convert(estimate + z * se),
        "low_end": "likelihood",
        "high_end": "likelihood",
        "level": level,
        "determined": True,
    }


#: How precisely a profile interval's end is found, in ``step``\ s (standard errors).
_PROFILE_XTOL = 0.01


def hessian_holds(
    interval: dict[str, Any], limits: tuple[float, float], *, signed: bool = False
) -> bool:
    """Whether the Hessian's interval can stand for the likelihood's: it stays within the
    parameter's ``limits``, and, for a ``signed`` parameter (a gain, whose sign is the
    finding), it does not reach zero.  Where it cannot, the quadratic that the Hessian reads
    has left the region the data describe: the profile likelihood says instead."""
    low, high = interval["low"], interval["high"]
    inside = limits[0] <= low and high <= limits[1]
    return bool(inside and not (signed and low <= 0.0 <= high))


def standing_interval(
    estimate: float,
    se: float,
    limits: tuple[float, float],
    *,
    signed: bool = False,
    log: bool = False,
) -> dict[str, Any] | None:
    """The Hessian's 95 % interval (:func:`hessian_interval`) where it can stand for the
    likelihood's (:func:`hessian_holds`, ``limits`` on the coordinate's scale: a log's where
    ``log``); None where it cannot, or ``se`` is not a positive number: the profile
    likelihood's (:func:`profile_interval`, from :func:`profile_step`) is the interval then."""
    if not (math.isfinite(se) and se > 0):
        return None
    wald = hessian_interval(estimate, se, log=log)
    natural = (math.exp(limits[0]), math.exp(limits[1])) if log else limits
    return wald if hessian_holds(wald, natural, signed=signed) else None


def profile_step(estimate: float, se: float) -> float:
    """Where a profile starts its search (:func:`profile_interval`'s ``step``): the standard
    error where the Hessian gives one, else a tenth of the estimate (at least 0.01)."""
    return se if math.isfinite(se) and se > 0 else 0.1 * max(abs(estimate), 0.1)


def profile_interval(
    f: Callable[[FloatArray], float],
    point: FloatArray,
    index: int,
    *,
    step: float,
    limits: tuple[float, float] = (-math.inf, math.inf),
    level: float = 0.95,
    bounds: Sequence[tuple[float | None, float | None]] | None = None,
    max_doublings: int = 8,
    reference: float | None = None,
) -> ProfileInterval:
    """The profile-likelihood interval of coordinate ``index`` of a fit at ``point``.

    ``f`` is the −log-likelihood over the whole vector (:data:`OUTSIDE` where no model);
    at each trial value of the coordinate every other one is re-fitted (L-BFGS-B from the
    nearest profile point, under ``bounds``).  Each side is searched outwards from where a
    quadratic profile of standard error ``step`` would cross the level, the stride growing
    up to ``max_doublings`` times and stopping at ``limits`` (the parameter's physical
    range); the crossing is then found by Brent's method, to 1 % of ``step``.  Unlike the
    Hessian's ``±1.96·SE``, this needs no positive definite curvature at the optimum and is
    not symmetric: it says where the data stop telling the parameter, on each side.

    ``reference``: the least ``f`` the fit knows of, where ``point`` is another optimum (a
    second basin of a likelihood with several): the level is then measured from it, and the
    interval is that basin's share of the values the data do not reject
    (:meth:`ProfileInterval.joined` joins the basins')."""
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be positive and finite, got {step!r}")
    x_hat = np.asarray(point, dtype=float)
    centre = float(x_hat[index])
    crit = 0.5 * float(stats.chi2.ppf(level, 1))
    nuisance = None if bounds is None else [b for i, b in enumerate(bounds) if i != index]
    best = f(x_hat) if reference is None else float(reference)
    lowest = [best]
    count = [1]

    def profile(c: float, warm: FloatArray) -> tuple[float, FloatArray]:
        def held(rest: FloatArray) -> float:
            return f(np.insert(rest, index, c))

        rest = np.delete(warm, index)
        if rest.size == 0:
            value, x = held(rest), np.array([c])
            count[0] += 1
        else:
            result = _minimise(held, rest, nuisance)
            value, x = float(result.fun), np.insert(result.x, index, c)
            count[0] += int(result.nfev) * (rest.size + 1)
        lowest.append(value)
        return value, x

    def side(sign: float) -> tuple[float, str]:
        inside, warm = centre, x_hat
        edge = limits[1] if sign > 0 else limits[0]
        size = math.sqrt(2.0 * crit) * step  # where a quadratic profile crosses the level
        for _ in range(max_doublings + 1):
            c = centre + sign * size
            at_edge = sign * (c - edge) >= 0.0
            c = edge if at_edge else c
            value, x = profile(c, warm)
            if value - best > crit:
                try:
                    found = optimize.brentq(
                        lambda v, start=warm: profile(v, start)[0] - best - crit,
                        inside,
                        c,
                        xtol=_PROFILE_XTOL * step,
                        maxiter=40,
                    )
                except ValueError:  # re-fitted at the inside point, the level is met there
                    found = inside
                # Where the far point is no model, the crossing may be the model's edge (a
                # jump), not the likelihood's fall: the level must be met there.
                met = value < OUTSIDE or abs(profile(found, warm)[0] - best - crit) < 0.1 * crit
                return float(found), "likelihood" if met else "range"
            inside, warm = c, x
            if at_edge:
                return c, "range"
            size *= 1.5 if size < 4.0 * step else 2.0  # near the level: small strides
        return inside, "open"

    low, low_end = side(-1.0)
    high, high_end = side(1.0)
    return ProfileInterval(
        estimate=centre,
        low=low,
        high=high,
        low_end=low_end,
        high_end=high_end,
        level=level,
        gain=max(0.0, best - min(lowest)),
        evaluations=count[0],
    )


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
