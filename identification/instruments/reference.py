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
it when an effect is on, and fly their rate loop on it (:func:`fly_loop`);
``benchmarks/closed_loop.py`` flies it in closed loop.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields, replace

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
    "GyroReader",
    "LoopRun",
    "RateLoop",
    "ReferenceRun",
    "advance",
    "fine_steps",
    "fly_loop",
    "gust_factor",
    "gust_stream",
    "loop_start",
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
    gain: ArrayLike | None = None,
    damping: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """One command held over ``len(u_d_deg)`` fine steps of ``h_s`` (one ``u_d`` each):
    ``state`` (:data:`STATE_COLUMNS`) advanced in place; the rate and angle at every fine
    step edge (the first is the start) -- the closed-loop truth of the benchmarks steps the
    rocket this way.  ``gain`` and ``damping`` multiply ``α`` and ``a(θ)`` per fine step (the
    rocket in flight; default ones, the rocket as ``params`` states it)."""
    u = np.ascontiguousarray(u_d_deg, dtype=np.float64)
    command = np.full(u.size, float(command_deg))
    scale = [
        np.ones(u.size)
        if x is None
        else np.ascontiguousarray(np.broadcast_to(np.asarray(x, dtype=np.float64), (u.size,)))
        for x in (gain, damping)
    ]
    _, rate, angle = _integrate(
        command, u, 1, h_s, rocket_tuple(params, effects), scale[0], scale[1], rate_limit_dps,
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


#: A rate gyro as a loop reads it: ``read(rate, k, own)``, the reading of the roll rate
#: ``rate`` (°/s) at logging sample ``k`` -- ``own`` False for the reading the log holds,
#: True for the controller's own reading at another instant (with its own noise).
GyroReader = Callable[[float, int, bool], float]


@dataclass(frozen=True)
class RateLoop:
    """A flight computer's proportional roll-rate loop on the fins, run at the logging
    rate: the command ``clip(e + gain·(0 − rate read delay_s before), ±stops_deg)``, held
    until the next sample (``e`` the excitation); the fins' stops are the servo's range."""

    gain: float
    delay_s: float
    stops_deg: float


@dataclass(frozen=True)
class LoopRun:
    """A closed-loop run at the logging times: the saturated command, the fin, the roll
    rate and angle as the sensors see them, the gyro's readings (None without a gyro), and
    the loop's delay as flown (a whole number of the integrator's steps)."""

    command: FloatArray
    fin: FloatArray
    rate: FloatArray
    angle: FloatArray
    gyro: FloatArray | None
    delay_s: float


def _reading(fine: FloatArray, position: float) -> float:
    """The value of ``fine`` (one per fine step edge) at a fractional ``position``, from the
    edges on either side (only the one below where it falls on an edge)."""
    i = int(position)
    fraction = position - i
    if fraction == 0.0:
        return float(fine[i])
    return float(fine[i] + fraction * (fine[i + 1] - fine[i]))


def loop_start(
    params: RollParams, excitation_deg: float, u_mean_deg: float, gain: float, stops: float
) -> float:
    """The fin at which the loop holds the rocket steady for a held excitation and mean
    turbulence: the root of ``θ = clip(e - K·v(θ), ±stops)``, ``v(θ)`` the steady rate
    (one root where ``α·K`` > 0, the loop damping the roll; one of them where it drives it)."""

    def excess(theta: float) -> float:
        rate = float(params.steady_rate(theta, u_mean_deg))
        return theta - min(max(excitation_deg - gain * rate, -stops), stops)

    lo, hi = -stops, stops  # excess(lo) <= 0 <= excess(hi): a root lies between
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if excess(mid) > 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def fly_loop(
    params: RollParams,
    effects: Effects,
    loop: RateLoop,
    excitation_deg: FloatArray,
    u_d_deg: FloatArray,
    dt_s: float,
    *,
    rate_limit_dps: float,
    u_start_deg: float,
    gyro: GyroReader | None,
    gain: ArrayLike | None = None,
    damping: ArrayLike | None = None,
) -> LoopRun:
    """Fly the rocket under the rate ``loop``, one logging interval of ``dt_s`` at a time
    through the reference integrator (:func:`advance`: RK4 on its fine grid, the servo's
    rate limit and the stops as its range, the effects' lag and backlash).

    At each logging time ``t_k`` (``k`` = 0 .. n, ``excitation_deg`` holding ``e_k``) the
    controller reads the gyro as it read the rocket ``loop.delay_s`` earlier -- on the fine
    grid, the delay rounded to a whole number of fine steps, the effects' sensor latency on
    top as for the logged gyro -- and commands ``clip(e_k + K·(0 - reading), ±stops)``, held
    until ``t_{k+1}`` through ``u_d_deg[k]``.  A reading the log holds (a delay of whole
    logging intervals) is that logged reading, noise and all; a reading at another instant
    is ``gyro``'s own (``gyro`` None: the true rate, noise-free).  ``gain`` and ``damping``
    (shape ``(n·per,)``, per fine step: :func:`fine_steps`) scale ``α`` and ``a(θ)`` as in
    flight; default ones.  Before the run the rocket was steady under the loop at the first
    fine step's gain, through ``u_start_deg`` (:func:`loop_start`)."""
    n = excitation_deg.size - 1
    per, h = fine_steps(dt_s)
    scales = [
        None if x is None else np.broadcast_to(np.asarray(x, dtype=np.float64), (n * per,))
        for x in (gain, damping)
    ]
    delay_steps = round(loop.delay_s / h)
    logged, between = divmod(delay_steps, per)  # between == 0: a reading the log holds
    lag = effects.latency_s / h  # the sensors' latency, in fine steps
    # The steady start with the rocket's quadratic damping, the effects' where they add it.
    steady = replace(
        params, quadratic_damping=effects.quadratic_damping or params.quadratic_damping
    )
    if scales[0] is not None and n > 0:  # in flight: the rocket at the first fine step
        steady = steady.scaled(float(scales[0][0]), 1.0)
    stops = loop.stops_deg
    fin0 = loop_start(steady, float(excitation_deg[0]), u_start_deg, loop.gain, stops)
    rate0 = float(steady.steady_rate(fin0, u_start_deg))
    state = np.array([fin0, fin0, fin0, rate0, 0.0])
    rate_fine = np.empty(n * per + 1)
    angle_fine = np.empty(n * per + 1)
    rate_fine[0], angle_fine[0] = rate0, 0.0
    fin, seen, reads, command = (np.empty(n + 1) for _ in range(4))
    fin[0] = fin0

    def read(rate: float, k: int, own: bool) -> float:
        return rate if gyro is None else gyro(rate, k, own)

    for k in range(n + 1):
        seen[k] = _reading(rate_fine, max(float(per * k) - lag, 0.0))
        reads[k] = read(seen[k], k, False)
        if between == 0 and k >= logged:
            reading = reads[k - logged]
        else:
            position = max(float(per * k - delay_steps) - lag, 0.0)
            reading = read(_reading(rate_fine, position), k, True)
        law = excitation_deg[k] + loop.gain * (0.0 - reading)
        command[k] = min(max(law, -stops), stops)
        if k == n:  # the last command is logged, never flown
            break
        span = slice(k * per, (k + 1) * per)
        rate, angle = advance(
            state, params, effects, command[k], np.full(per, u_d_deg[k]), h,
            rate_limit_dps=rate_limit_dps, fin_range_deg=stops,
            gain=None if scales[0] is None else scales[0][span],
            damping=None if scales[1] is None else scales[1][span],
        )  # fmt: skip
        rate_fine[span.start : span.stop + 1] = rate
        angle_fine[span.start : span.stop + 1] = angle
        fin[k + 1] = state[2]
    angle_seen = np.array([_reading(angle_fine, max(float(per * k) - lag, 0.0))
                           for k in range(n + 1)])  # fmt: skip
    return LoopRun(
        command, fin, seen, angle_seen, None if gyro is None else reads, round(delay_steps * h, 9)
    )
