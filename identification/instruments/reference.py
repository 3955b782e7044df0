"""A rocket outside the roll model: the reference integrator of its physics.

The roll model (eq. 36/49 with the servo of eq. 23; :mod:`identification.model`)
is what every identification fits and every environment replays.  A real rocket
is never exactly that model.  :class:`Effects` names what it may add, each off at
zero and bounded to a physical range:

* **servo lag** -- the fin follows the rate-limited servo through a first-order
  lag ``τ·dθ/dt = θ_servo − θ``;
* **backlash** -- play between servo and fin: the fin stays put until the servo
  has moved half the play from it (a dead band of that width);
* **sensor latency** -- the roll sensors (encoder and gyro) read the rocket as it
  was this long ago;
* **quadratic damping** -- a damping that grows with the roll rate:
  ``a(θ)·(1 + q·|v|/30 °/s)``, so ``q`` is the fraction added at 30 °/s;
* **gusty turbulence** -- the turbulence's intensity wanders: ``u_d`` times
  ``exp(σ·x − σ²/2)`` with ``x`` a unit Ornstein-Uhlenbeck process of
  correlation time ``T`` (``σ`` 0.35 keeps it between about 0.5× and 1.8×).

:func:`simulate_reference` integrates the rocket with these effects by the
classical fourth-order Runge-Kutta method on a fixed fine step (1 ms by
default), the fin moving linearly over each step: a second implementation of
the roll dynamics, written apart from the exact kernel of
:mod:`identification.model` so that a bug in one is not a bug in both (with
every effect off the two agree to within 1e-3 °/s on the paper's run;
``tests/identification/test_reference.py``).  The virtual tunnel
(:mod:`identification.instruments.tunnel`) and the flight recorder
(:mod:`identification.instruments.flightlog`, the gain and damping per step) write their truth with
it when an effect is on; ``benchmarks/closed_loop.py`` flies it in closed loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.model import QUADRATIC_RATE_DPS, RIG_LIMITS, RollParams
from rocketroll_common.arrays import FloatArray
from rocketroll_common.settings import check, setting

__all__ = [
    "QUADRATIC_RATE_DPS",
    "STATE_COLUMNS",
    "Effects",
    "ReferenceRun",
    "advance",
    "fine_steps",
    "gust_factor",
    "gust_stream",
    "simulate_reference",
]

#: The reference integrator's default step, s.
FINE_STEP_S = 0.001


@dataclass(frozen=True)
class Effects:
    """What a rocket adds to the roll model; every field 0 is the model itself.

    Each field is a ``rocketroll tunnel`` flag
    (:class:`identification.instruments.tunnel.TunnelSpec` holds one), bounded to a physical range.
    """

    servo_lag_s: float = setting(
        0.0,
        "outside the model: a first-order lag of the fin behind the rate-limited servo",
        ge=0.0,
        le=RIG_LIMITS["lag_s"],
        unit="s",
        flag="--servo-lag",
        metavar="S",
    )
    backlash_deg: float = setting(
        0.0, "outside the model: play between servo and fin", ge=0.0,
        le=RIG_LIMITS["backlash_deg"], unit="°",
        flag="--backlash", metavar="DEG",
    )  # fmt: skip
    latency_s: float = setting(
        0.0, "outside the model: delay of the roll sensors", ge=0.0,
        le=RIG_LIMITS["latency_s"], unit="s",
        flag="--sensor-latency", metavar="S",
    )  # fmt: skip
    quadratic_damping: float = setting(
        0.0,
        "outside the model: damping added at 30 °/s, as a fraction of a(θ) (a damping "
        "growing with the roll rate)",
        ge=0.0,
        le=2.0,
        metavar="Q",
    )
    gust_sd: float = setting(
        0.0,
        "outside the model: SD of the turbulence's log intensity, which wanders (0.35: "
        "between about 0.5x and 1.8x)",
        ge=0.0,
        le=1.5,
        metavar="SD",
    )
    gust_time_s: float = setting(
        20.0,
        "correlation time of the wandering intensity (--gust-sd)",
        ge=0.1,
        le=600.0,
        unit="s",
        flag="--gust-time",
        metavar="S",
    )

    def __post_init__(self) -> None:
        check(self)

    @property
    def any(self) -> bool:
        """Whether any effect is on (the gust's time alone is not an effect)."""
        return any(getattr(self, f.name) for f in fields(self) if f.name != "gust_time_s")

    def metadata(self, section: str) -> list[tuple[str, object]]:
        """A recording's metadata of a truth with these effects: each as ``truth.*`` and a
        line ``SECTION.effects`` saying which are on."""
        return [
            ("truth.servo_lag_s", self.servo_lag_s),
            ("truth.backlash_deg", self.backlash_deg),
            ("truth.sensor_latency_s", self.latency_s),
            ("truth.quadratic_damping", self.quadratic_damping),
            ("truth.gust_sd", self.gust_sd),
            ("truth.gust_time_s", self.gust_time_s),
            (f"{section}.effects", f"outside the model: {self.describe()}"),
        ]

    def describe(self) -> str:
        """The effects that are on, e.g. ``servo lag 0.05 s, latency 0.03 s``; ``none``."""
        words = {
            "servo_lag_s": ("servo lag", "s"),
            "backlash_deg": ("backlash", "°"),
            "latency_s": ("latency", "s"),
            "quadratic_damping": ("quadratic damping", "× a(θ) at 30 °/s"),
            "gust_sd": ("gust intensity SD", f"(log, over {self.gust_time_s:g} s)"),
        }
        said = [
            f"{w} {getattr(self, k):g} {unit}" for k, (w, unit) in words.items() if getattr(self, k)
        ]
        return ", ".join(said) or "none"


@dataclass(frozen=True)
class ReferenceRun:
    """What :func:`simulate_reference` gives at the logging times (``n + 1`` of them).

    ``fin_deg`` is the fin itself (after lag and backlash), ``rate_dps`` and
    ``angle_deg`` the roll as the sensors read it (delayed by the latency);
    ``true_rate_dps`` and ``true_angle_deg`` the roll at that time.
    """

    time_s: FloatArray
    fin_deg: FloatArray
    rate_dps: FloatArray
    angle_deg: FloatArray
    true_rate_dps: FloatArray
    true_angle_deg: FloatArray


def gust_factor(n: int, dt_s: float, effects: Effects, rng: np.random.Generator) -> FloatArray:
    """The turbulence's wandering intensity at ``n`` samples ``dt_s`` apart: ``exp(σ·x −
    σ²/2)`` with ``x`` a unit Ornstein-Uhlenbeck process of correlation time
    ``effects.gust_time_s`` (mean 1); ones where ``effects.gust_sd`` is 0."""
    if effects.gust_sd == 0.0:
        return np.ones(n)
    rho = math.exp(-dt_s / effects.gust_time_s)
    noise = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = noise[0]
    scale = math.sqrt(1.0 - rho * rho)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + scale * noise[k]
    sigma = effects.gust_sd
    return np.asarray(np.exp(sigma * x - 0.5 * sigma * sigma))


def gust_stream(seed: int) -> np.random.Generator:
    """The wandering intensity's generator for a virtual run of ``seed``: the seed's fourth
    child, so the three streams the tunnel and the flight recorder draw their schedule,
    turbulence and sensors from (its first three) stay what they are without it."""
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])


@numba.njit(cache=True, nogil=True)
def _accel(v: float, theta: float, u: float, p: tuple[float, ...]) -> float:
    alpha, theta_bar, beta_bar, alpha_bar, quadratic = p
    a = alpha_bar * abs(theta + theta_bar) + beta_bar
    return (
        -a * (v - alpha * (theta + theta_bar + u)) - a * quadratic * v * abs(v) / QUADRATIC_RATE_DPS
    )


@numba.njit(cache=True, nogil=True)
def _integrate(
    command: FloatArray,
    u_d: FloatArray,
    per: int,
    h: float,
    p: tuple[float, ...],
    gain: FloatArray,
    damping: FloatArray,
    rate_limit: float,
    fin_range: float,
    lag: float,
    backlash: float,
    state: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Fin, rate and angle at every fine step edge (``len(command)·per + 1``), from
    ``state`` (:data:`STATE_COLUMNS`), which is advanced to the end in place; ``gain`` and
    ``damping`` multiply ``α`` and ``a(θ)`` per fine step (the rocket in flight)."""
    n = command.size * per
    fin = np.empty(n + 1)
    rate = np.empty(n + 1)
    angle = np.empty(n + 1)
    servo, lagged, theta, v, phi = state[0], state[1], state[2], state[3], state[4]
    fin[0], rate[0], angle[0] = theta, v, phi
    follow = 1.0 - math.exp(-h / lag) if lag > 0.0 else 1.0
    half = 0.5 * backlash
    for j in range(n):
        k = j // per
        target = min(max(command[k], -fin_range), fin_range)
        servo += min(max(target - servo, -rate_limit * h), rate_limit * h)
        lagged += follow * (servo - lagged)
        new = lagged
        if backlash > 0.0:  # the fin moves only once its drive is half the play away
            if lagged > theta + half:
                new = lagged - half
            elif lagged < theta - half:
                new = lagged + half
            else:
                new = theta
        u = u_d[k]
        t0, t1 = theta, new
        tm = 0.5 * (t0 + t1)
        d = damping[j]
        q = (p[0] * gain[j], p[1], p[2] * d, p[3] * d, p[4])
        k1 = _accel(v, t0, u, q)
        k2 = _accel(v + 0.5 * h * k1, tm, u, q)
        k3 = _accel(v + 0.5 * h * k2, tm, u, q)
        k4 = _accel(v + h * k3, t1, u, q)
        dphi = h * (v + h * (k1 + k2 + k3) / 6.0)
        v += h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        phi += dphi
        theta = new
        fin[j + 1], rate[j + 1], angle[j + 1] = theta, v, phi
    state[0], state[1], state[2], state[3], state[4] = servo, lagged, theta, v, phi
    return fin, rate, angle


#: The reference integrator's state: the servo, the fin's drive (behind it by the lag), the
#: fin (behind its drive by the play), the roll rate and the roll angle.
STATE_COLUMNS = ("servo_deg", "drive_deg", "fin_deg", "rate_dps", "angle_deg")


def rocket_tuple(params: RollParams, effects: Effects) -> tuple[float, ...]:
    """The numbers :func:`_accel` reads: the rocket and its quadratic damping (the rocket's
    own, or the effects' for a truth whose parameters are the linear model's; not both)."""
    if params.quadratic_damping and effects.quadratic_damping:
        raise ValueError(
            "the quadratic damping is stated twice: the rocket's "
            f"{params.quadratic_damping:g} and the effects' {effects.quadratic_damping:g}"
        )
    return (
        params.alpha,
        params.theta_bar_deg,
        params.beta_bar_per_s,
        params.alpha_bar_per_deg_s,
        effects.quadratic_damping or params.quadratic_damping,
    )


def advance(
    state: FloatArray,
    params: RollParams,
    effects: Effects,
    command_deg: float,
    u_d_deg: ArrayLike,
    h_s: float,
    *,
    rate_limit_dps: float,
    fin_range_deg: float,
) -> tuple[FloatArray, FloatArray]:
    """One command held over ``len(u_d_deg)`` fine steps of ``h_s`` (one ``u_d`` each):
    ``state`` (:data:`STATE_COLUMNS`) advanced in place; the rate and angle at every fine
    step edge (the first is the start) -- the closed-loop truth of the benchmarks steps the
    rocket this way."""
    u = np.ascontiguousarray(u_d_deg, dtype=np.float64)
    command = np.full(u.size, float(command_deg))
    ones = np.ones(u.size)
    _, rate, angle = _integrate(
        command, u, 1, h_s, rocket_tuple(params, effects), ones, ones, rate_limit_dps,
        fin_range_deg, effects.servo_lag_s, effects.backlash_deg, state,
    )  # fmt: skip
    return rate, angle


def fine_steps(dt_s: float, fine_step_s: float = FINE_STEP_S) -> tuple[int, float]:
    """How :func:`simulate_reference` cuts a logging interval ``dt_s``: the number of
    Runge-Kutta steps (at most ``fine_step_s`` each) and their length."""
    per = max(1, math.ceil(dt_s / fine_step_s - 1e-9))
    return per, dt_s / per


def simulate_reference(
    params: RollParams,
    dt_s: float,
    command_deg: ArrayLike,
    u_d_deg: ArrayLike,
    effects: Effects,
    *,
    rate_limit_dps: float = 150.0,
    fin_range_deg: float = 40.0,
    rate0_dps: float | None = None,
    fine_step_s: float = FINE_STEP_S,
    gain: ArrayLike = 1.0,
    damping: ArrayLike = 1.0,
) -> ReferenceRun:
    """The rocket ``params`` with ``effects``, commanded ``command_deg`` (held over each of
    the ``n`` logging intervals of ``dt_s``) through ``u_d_deg`` (one per interval).

    Parameters
    ----------
    params : RollParams
        The rocket (eq. 36/49).
    dt_s : float
        The logging interval, s.
    command_deg, u_d_deg : array_like, shape (n,)
        The fin command and the turbulence (its gust factor already applied) per interval.
    effects : Effects
        What the rocket adds to the model (the gust is the caller's: :func:`gust_factor`).
    rate_limit_dps, fin_range_deg : float
        The servo's rate and range limits (eq. 23).
    rate0_dps : float, optional
        The roll rate at the start (default: steady for the first command).
    fine_step_s : float
        The Runge-Kutta step, at most this (a whole number of them per interval):
        :func:`fine_steps` gives it.
    gain, damping : float or array_like, shape (n·per,)
        Factors on ``α`` and on ``a(θ)``, one per fine step or for all (the rocket in
        flight: :func:`rocketroll_physics.scaling.roll_scales`; a gain below 0 is the flow
        over the fins reversed).

    Returns
    -------
    ReferenceRun
        At the ``n + 1`` logging times ``k·dt_s``.
    """
    command = np.ascontiguousarray(command_deg, dtype=np.float64)
    u = np.ascontiguousarray(u_d_deg, dtype=np.float64)
    if command.ndim != 1 or u.shape != command.shape or command.size < 1:
        raise ValueError("command_deg and u_d_deg must be 1-D, of one length >= 1")
    per, h = fine_steps(dt_s, fine_step_s)
    start = float(np.clip(command[0], -fin_range_deg, fin_range_deg))
    v0 = params.steady_rate(start, u[0]) if rate0_dps is None else rate0_dps
    state = np.array([start, start, start, float(v0), 0.0])
    fine = command.size * per
    scale = [np.ascontiguousarray(np.broadcast_to(np.asarray(x, dtype=np.float64), (fine,)))
             for x in (gain, damping)]  # fmt: skip
    fin, rate, angle = _integrate(
        command, u, per, h, rocket_tuple(params, effects), scale[0], scale[1], rate_limit_dps,
        fin_range_deg, effects.servo_lag_s, effects.backlash_deg, state,
    )  # fmt: skip
    log_t = dt_s * np.arange(command.size + 1, dtype=np.float64)
    # Where the sensors look, in fine steps (exact on the grid where there is no latency).
    seen = np.maximum(per * np.arange(command.size + 1) - effects.latency_s / h, 0.0)
    steps = np.arange(fin.size, dtype=np.float64)
    return ReferenceRun(
        time_s=log_t,
        fin_deg=fin[::per].copy(),
        rate_dps=np.interp(seen, steps, rate),
        angle_deg=np.interp(seen, steps, angle),
        true_rate_dps=rate[::per].copy(),
        true_angle_deg=angle[::per].copy(),
    )
