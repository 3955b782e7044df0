"""Named virtual-tunnel truths the benchmarks check methods against.

The paper's rocket and schedule, and truths that differ from it in the gain,
the sign of the asymmetry, the shape of a(θ), the schedule, the turbulence's
distribution and correlation time, and the sensors: a method tuned to the
paper's truth alone is a defect.  Each entry makes the :class:`TunnelSpec` of
one seed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp

from identification.instruments.reference import Effects
from identification.instruments.tunnel import TunnelSpec
from identification.recordings.recording import Recording

__all__ = [
    "MISMATCH_TRUTHS",
    "SHAPES",
    "SHAPE_TRUTHS",
    "STICK",
    "TRUTHS",
    "shape_command",
    "spec_of",
    "stick_log",
]

#: name -> (description, tunnel settings other than the seed)
TRUTHS: dict[str, tuple[str, dict[str, object]]] = {
    "paper": ("the paper's rocket (eq. 49) and Table 1 schedule", {}),
    "paper-constant": (
        "the paper's constant-damping rocket (eq. 29, a = 1.314)",
        {"model": "constant"},
    ),
    "negative": (
        "α = 0.9, θ̄ = -3.3° (β = -3), τ = 0.3 s",
        {"alpha": 0.9, "beta": -3.0, "correlation_time": 0.3},
    ),
    "rising": (
        "a(θ) rising with |θ + θ̄| (ᾱ = +0.02, β̄ = 1.0), α = 0.5, β = 1.5",
        {"alpha": 0.5, "beta": 1.5, "alpha_bar": 0.02, "beta_bar": 1.0},
    ),
    "staircase-laplace": (
        "random staircase of 12 steps, Laplace turbulence, τ = 1.0 s, SD 7°",
        {
            "schedule": "staircase",
            "steps": 12,
            "turbulence": "laplace",
            "correlation_time": 1.0,
            "turbulence_sd": 7.0,
        },
    ),
    "gyro": (
        "rate gyro (2 % noise, eq. 52) and measured fin, no encoder; Student-t turbulence",
        {"no_encoder": True, "gyro_noise": 2.0, "measured_fin": True, "turbulence": "student-t"},
    ),
    # Outside the model (identification.instruments.reference): the paper's rocket and
    # schedule with one effect at a physically modest level, or all four together.
    "servo-lag": (
        "outside the model: a 50-ms servo lag and 0.5° of backlash",
        {"effects": Effects(servo_lag_s=0.05, backlash_deg=0.5)},
    ),
    "quadratic": (
        "outside the model: quadratic damping, 15 % more at 30 °/s",
        {"effects": Effects(quadratic_damping=0.15)},
    ),
    "quadratic-1.5x": (
        "outside the model: quadratic damping, 22.5 % more at 30 °/s (1.5x the quadratic truth)",
        {"effects": Effects(quadratic_damping=0.225)},
    ),
    "quadratic-strong": (
        "outside the model: quadratic damping, 50 % more at 30 °/s",
        {"effects": Effects(quadratic_damping=0.5)},
    ),
    "latency": (
        "outside the model: 30 ms of sensor latency",
        {"effects": Effects(latency_s=0.03)},
    ),
    "gusty": (
        "outside the model: turbulence whose intensity wanders (0.5-1.8x over ~20 s)",
        {"effects": Effects(gust_sd=0.35, gust_time_s=20.0)},
    ),
    "mismatch-all": (
        "outside the model: servo lag and backlash, quadratic damping, latency and gusts",
        {
            "effects": Effects(
                servo_lag_s=0.05,
                backlash_deg=0.5,
                quadratic_damping=0.15,
                latency_s=0.03,
                gust_sd=0.35,
            )
        },
    ),
}
#: The truths outside the model class.
MISMATCH_TRUTHS = ("servo-lag", "quadratic", "latency", "gusty", "mismatch-all")


def spec_of(truth: str, seed: int) -> TunnelSpec:
    """The tunnel run of ``truth`` with turbulence seed ``seed``."""
    _, settings = TRUTHS[truth]
    make: Callable[..., TunnelSpec] = TunnelSpec
    return make(seed=seed, **settings)


#: Rockets tried on the input shapes a user's rig makes (tunnel command-line settings):
#: the paper's, one with θ̄ < 0 and a shorter turbulence, one with constant damping.
SHAPE_TRUTHS: dict[str, str] = {
    "paper": "",
    "negative": "--alpha 0.9 --beta -3.0 --correlation-time 0.3",
    "constant": "--model constant --alpha 1.5 --beta 2 --beta-bar 4",
}
#: (shape, record length in s) -> its schedule: ramps, doublets and PRBS, not the
#: paper's long dwells, in 15-s and 60-s records.
SHAPES: dict[tuple[str, int], str] = {
    ("ramps", 15): "--schedule ramps --steps 3 --dwell-min 2 --dwell-max 3 --lead 1 --ramp 1",
    (
        "doublets",
        15,
    ): "--schedule doublets --steps 4 --pulse 1 --dwell-min 1 --dwell-max 2 --lead 1",
    ("prbs", 15): "--schedule prbs --duration 14 --pulse 0.5 --lead 1",
    ("ramps", 60): "--schedule ramps --steps 12 --dwell-min 2 --dwell-max 4 --lead 2 --ramp 1",
    (
        "doublets",
        60,
    ): "--schedule doublets --steps 12 --pulse 1 --dwell-min 1 --dwell-max 3 --lead 2",
    ("prbs", 60): "--schedule prbs --duration 58 --pulse 0.5 --lead 2",
}


def shape_command(truth: str, shape: tuple[str, int], seed: int) -> str:
    """The ``rocketroll tunnel`` settings of ``truth`` on ``shape`` at 100 Hz with a 1 %
    gyro, turbulence seed ``seed``."""
    return f"--seed {seed} --log-dt 0.01 --gyro-noise 1 {SHAPE_TRUTHS[truth]} {SHAPES[shape]}"


#: The rocket behind :func:`stick_log`: an aileron convention (α < 0), θ̄ 0.5°, a 2.4 1/s.
STICK = {"alpha": -2.9, "theta_bar_deg": 0.5, "a_per_s": 2.4}


def stick_log(
    seed: int, latency_s: float = 0.0, turbulence_deg: float = 0.7, duration_s: float = 20.0
) -> Recording:
    """A pilot's log made outside the toolkit: 25 Hz, the aileron a stick moved by hand
    (raised-cosine moves of 0.4-0.9 s between banks of 4-10° either way, dwells of 1-2 s;
    continuous, not the tunnel's command held per sample behind a servo), the roll
    ``v' = -a·v + a·α·(δ + θ̄ + u_d)`` (:data:`STICK`) integrated by scipy's ``solve_ivp``
    with ``u_d`` an Ornstein-Uhlenbeck process (1 s, SD ``turbulence_deg``) held over 2-ms
    steps, the gyro read ``latency_s`` late with 0.3 °/s of white noise, the aileron
    logged on time."""
    rng = np.random.default_rng(seed)
    alpha, theta_bar, a = STICK["alpha"], STICK["theta_bar_deg"], STICK["a_per_s"]
    moves: list[tuple[float, float, float, float]] = []
    t, level = 1.0, 0.0
    while t < duration_s:
        size = rng.uniform(4.0, 10.0)
        new = size * (rng.choice([-1.0, 1.0]) if level == 0.0 else -np.sign(level))
        move = rng.uniform(0.4, 0.9)
        moves.append((t, move, level, new))
        t, level = t + move + rng.uniform(1.0, 2.0), new

    def aileron(times: np.ndarray) -> np.ndarray:
        out = np.zeros_like(times)
        for start, move, before, after in moves:
            s = np.clip((times - start) / move, 0.0, 1.0)
            shaped = before + (after - before) * 0.5 * (1.0 - np.cos(np.pi * s))
            out = np.where(times >= start, shaped, out)
        return out

    h, tau = 0.002, 1.0
    fine = np.arange(0.0, duration_s + 1.0, h)
    phi = np.exp(-h / tau)
    shocks = turbulence_deg * np.sqrt(1.0 - phi**2) * rng.standard_normal(fine.size)
    ud = np.empty(fine.size)
    ud[0] = turbulence_deg * rng.standard_normal()
    for k in range(1, fine.size):
        ud[k] = phi * ud[k - 1] + shocks[k]

    stick = aileron(fine)

    def roll(time: float, v: np.ndarray) -> list[float]:
        k = min(int(time / h), fine.size - 2)
        between = (time - fine[k]) / h
        fin = stick[k] + between * (stick[k + 1] - stick[k])
        return [-a * v[0] + a * alpha * (fin + theta_bar + ud[k])]

    solved = solve_ivp(
        roll, (0.0, duration_s + 0.5), [alpha * (theta_bar + ud[0])], max_step=h,
        dense_output=True, rtol=1e-8, atol=1e-8,
    )  # fmt: skip
    times = np.arange(0.0, duration_s + 1e-9, 0.04)
    rate = solved.sol(np.maximum(times - latency_s, 0.0))[0] + rng.normal(0.0, 0.3, times.size)
    return Recording(
        name=f"stick-seed{seed}",
        source="synthetic",
        time_s=times,
        fin_deg=aileron(times),
        roll_rate_dps=rate,
        metadata={
            "truth.model": "constant",
            "truth.alpha": str(alpha),
            "truth.theta_bar_deg": str(theta_bar),
            "truth.beta_bar_per_s": str(a),
            "truth.sensor_latency_s": str(latency_s),
        },
    )
