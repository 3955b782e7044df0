"""The one closed form (:func:`identification.model.piece_coefficients`), compiled by numba.

The environment's kernel (:mod:`rollenv.core`) and the maximum-likelihood
identification (:mod:`identification.methods.ml`) both call :data:`piece`, so the
physics they integrate is the source in :mod:`identification.model`, not a
copy.  For numba the array helpers ``select`` and ``phi_functions`` become
scalar branches (only the branch that is used is computed).
"""

from __future__ import annotations

from typing import Any

import numba
import numba.extending
import numpy as np

from identification import model
from identification.model import RollParams
from rocketroll_common.arrays import FloatArray

__all__ = [
    "UNSCALED",
    "interval_maps",
    "interval_maps_kernel",
    "linkage",
    "linkage_path",
    "piece",
]


@numba.extending.overload(model.select)
def _select_scalar(condition: Any, if_true: Any, if_false: Any) -> Any:
    """Scalar ``select`` for numba: a branch, not a 0-d array per call."""

    def impl(condition: Any, if_true: Any, if_false: Any) -> Any:
        return if_true if condition else if_false

    return impl


_phi_taylor = numba.njit(cache=True, nogil=True)(model.phi_taylor)
_phi_direct = numba.njit(cache=True, nogil=True)(model.phi_direct)


@numba.extending.overload(model.phi_functions)
def _phi_functions_scalar(z: Any) -> Any:
    """Scalar ``phi_functions`` for numba: only the branch that is used is computed."""

    def impl(z: Any) -> Any:
        if abs(z) < model.PHI_TAYLOR_BELOW:
            return _phi_taylor(z)
        return _phi_direct(z)

    return impl


#: ``piece(alpha, theta_bar, beta_bar, alpha_bar, theta0, theta1, u_d, h) -> (E, c, A, B)``
#: for scalars, compiled (see :func:`identification.model.piece_coefficients`).
piece = numba.njit(cache=True, nogil=True)(model.piece_coefficients)
#: ``linkage(servo, drive, theta, command, max_move, decay, ramp, half) -> (servo, drive,
#: fin)``, compiled (see :func:`identification.model.linkage_step`).
linkage = numba.njit(cache=True, nogil=True)(model.linkage_step)


@numba.njit(cache=True, nogil=True)
def _linkage_path(
    command: FloatArray, start: float, max_move: float, decay: float, ramp: float, half: float
) -> FloatArray:
    out = np.empty(command.size + 1)
    servo = drive = theta = start
    out[0] = start
    for k in range(command.size):
        servo, drive, theta = linkage(servo, drive, theta, command[k], max_move, decay, ramp, half)
        out[k + 1] = theta
    return out


def linkage_path(
    command_deg: FloatArray,
    theta0_deg: float,
    dt_s: float,
    servo: model.Servo,
    link: model.Linkage,
) -> FloatArray:
    """:func:`identification.model.servo_path` through a :class:`~identification.model.Linkage`:
    the fin at the boundaries of consecutive steps of ``dt_s`` with held commands (shape
    ``(n + 1,)``), servo, drive and fin starting together at ``theta0_deg``."""
    cmd = np.clip(np.asarray(command_deg, dtype=np.float64), -servo.range_deg, servo.range_deg)
    decay, ramp, half = link.coefficients(dt_s)
    return np.asarray(
        _linkage_path(cmd, float(theta0_deg), servo.rate_limit_dps * dt_s, decay, ramp, half)
    )


@numba.njit(cache=True, nogil=True)
def _substep(
    alpha: float,
    theta_bar: float,
    beta_bar: float,
    alpha_bar: float,
    t0: float,
    t1: float,
    u: float,
    h: float,
    rate_limit: float,
) -> tuple[float, float, float, float]:
    """One substep's ``(E, c, A, B)``: the fin linear from ``t0`` to ``t1`` over ``h``, or,
    with ``rate_limit > 0`` (a servo), moving at that rate until it reaches ``t1`` and then
    holding (the two pieces composed, as :func:`identification.model.roll_coefficients`)."""
    if rate_limit <= 0.0:
        return piece(alpha, theta_bar, beta_bar, alpha_bar, t0, t1, u, h)
    ramp = min(abs(t1 - t0) / rate_limit, h)
    e1, c1, a1, b1 = piece(alpha, theta_bar, beta_bar, alpha_bar, t0, t1, u, ramp)
    e2, c2, a2, b2 = piece(alpha, theta_bar, beta_bar, alpha_bar, t1, t1, u, h - ramp)
    return e2 * e1, e2 * c1 + c2, a1 + a2 * e1, b1 + a2 * c1 + b2


@numba.njit(cache=True, nogil=True)
def interval_maps_kernel(
    alpha: float,
    theta_bar: float,
    beta_bar: float,
    alpha_bar: float,
    theta_fine: FloatArray,
    per: int,
    h: float,
    gain: FloatArray,
    damping: FloatArray,
    rate_limit: float,
) -> FloatArray:
    """Per sample interval ``[E, G, f, A, B, g]`` of the affine update (module docstring).

    ``gain`` and ``damping`` (one per substep, or empty: 1) multiply ``α`` and the
    damping (``β̄`` and ``ᾱ``) substep by substep -- the rocket at a changing airspeed;
    ``rate_limit > 0``: the fin is a servo's, its ramp may end inside a substep.  An
    interval with the fin at rest and the rocket constant is one exact piece; any other
    is the composition of its substeps.
    """
    n = (theta_fine.size - 1) // per
    out = np.empty((n, 6))
    scaled = gain.size > 0
    for k in range(n):
        lo = k * per
        th = theta_fine[lo]
        rest = not scaled
        for j in range(1, per + 1):
            if not rest:
                break
            if theta_fine[lo + j] != th:
                rest = False
        if rest:
            e, c0, a, b0 = piece(alpha, theta_bar, beta_bar, alpha_bar, th, th, 0.0, per * h)
            _, c1, _, b1 = piece(alpha, theta_bar, beta_bar, alpha_bar, th, th, 1.0, per * h)
            out[k, 0] = e
            out[k, 1] = c1 - c0
            out[k, 2] = c0
            out[k, 3] = a
            out[k, 4] = b1 - b0
            out[k, 5] = b0
            continue
        e_v, g_v, f_v, a_p, b_p, g_p = 1.0, 0.0, 0.0, 0.0, 0.0, 0.0
        for j in range(per):
            t0 = theta_fine[lo + j]
            t1 = theta_fine[lo + j + 1]
            g = gain[lo + j] if scaled else 1.0
            d = damping[lo + j] if scaled else 1.0
            args = (alpha * g, theta_bar, beta_bar * d, alpha_bar * d, t0, t1)
            e, c0, a, b0 = _substep(*args, 0.0, h, rate_limit)
            _, c1, _, b1 = _substep(*args, 1.0, h, rate_limit)
            # φ gains a·v + b with v the rate at the substep's start.
            a_p += a * e_v
            b_p += a * g_v + (b1 - b0)
            g_p += a * f_v + b0
            e_v, g_v, f_v = e * e_v, e * g_v + (c1 - c0), e * f_v + c0
        out[k] = (e_v, g_v, f_v, a_p, b_p, g_p)
    return out


#: No per-substep scales: the rocket the parameters say, throughout.
UNSCALED = np.empty(0)


def interval_maps(
    params: RollParams,
    theta_fine: FloatArray,
    per: int,
    h: float,
    *,
    gain: FloatArray | None = None,
    damping: FloatArray | None = None,
    rate_limit_dps: float | None = None,
) -> FloatArray:
    """``[E, G, f, A, B, g]`` of each sample interval of ``per`` substeps of ``h`` s
    (module docstring) for the fin path ``theta_fine`` (one value per substep
    boundary, ``n·per + 1`` of them) under the rocket ``params``; ``gain`` and
    ``damping`` (one per substep) scale it along a flight, ``rate_limit_dps`` makes the
    fin a servo's (its ramp may end inside a substep)."""
    theta = np.ascontiguousarray(theta_fine, dtype=float)
    if per < 1 or (theta.size - 1) % per:
        raise ValueError(
            f"theta_fine needs n·{per} + 1 values (a whole number of intervals), got {theta.size}"
        )
    steps = theta.size - 1
    if (gain is None) != (damping is None):
        raise ValueError("give gain and damping together")
    scales = [
        UNSCALED if x is None else np.ascontiguousarray(x, dtype=float) for x in (gain, damping)
    ]
    if gain is not None and any(x.shape != (steps,) for x in scales):
        raise ValueError(f"gain and damping need one value per substep ({steps})")
    return np.asarray(
        interval_maps_kernel(
            params.alpha,
            params.theta_bar_deg,
            params.beta_bar_per_s,
            params.alpha_bar_per_deg_s,
            theta,
            per,
            h,
            scales[0],
            scales[1],
            -1.0 if rate_limit_dps is None else float(rate_limit_dps),
        )
    )
