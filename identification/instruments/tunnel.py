"""Virtual wind tunnel: re-creates the paper's experiment with known ground truth.

The paper's raw data (its Fig. 2) is not public.  This module simulates the
same experiment -- the 5-kg rocket on its encoder shaft in the turbulent
vertical tunnel, a fin-command schedule logged every 0.1 s -- through the one
roll model of :mod:`identification.model`, and writes a recording whose
metadata carries the ground truth.  Every later step is validated against it:
simulate known parameters, identify them, check they come back.

Ingredients
-----------
* Roll model eq. 49 with the paper's α = 0.6590, β = 2.8856 (eq. 17) and
  ᾱ = -0.0289, β̄ = 2.4075 (eq. 48); or the constant-damping model eq. 29 with
  a = 1.314 1/s (eq. 46).
* Servo eq. 23 (150 °/s) with the ±40° fin range.
* Fin schedule: Table 1 of the paper, a random staircase, or what real rigs
  run: ramps between the staircase's levels, doublets, a pseudo-random binary
  sequence, a chirp.
* Turbulence as an equivalent fin angle ``u_d``, piecewise constant over each
  0.1 s log interval (paper §2.7.1), from a stationary process with a chosen
  marginal (Gaussian, Laplace or Student-t) and correlation time: a Gaussian
  AR(1) with lag-one correlation ``exp(-Δt/τ)`` mapped through the target
  distribution's quantile function (a Gaussian copula), so the marginal is
  exact and the correlation close to ``exp(-lag/τ)``.
* Sensors: the HEDS-5702 encoder, 256 cycles per revolution (§2.1) read in
  4x quadrature, i.e. 1024 counts (0.35°) per revolution -- with 256 counts
  (1.41°) the quantisation alone would give a roll-angle error of about
  0.35° MAE, above the paper's re-simulation error of 0.13-0.18°; optional
  rate gyro with the multiplicative noise of eq. 52; optional measured fin.
* Optionally a flight computer's rate loop on the fins (``--loop-gain``): the command is
  the schedule (then an excitation on top) plus the gain times minus the gyro's rate read
  ``--loop-delay`` earlier, saturated at the fins' ``--stops``; flown one logging interval
  at a time by the reference integrator (:mod:`identification.instruments.reference`),
  never by the model it is to check, and stated in ``loop.*`` metadata.

Calibration of the default turbulence
-------------------------------------
The paper reports the *identified* ``u_d,θ``: 90 % interval [-13.38, 14.28]°
(§3.2), a largest value of about 32° (§3.3), no significant departure from
normality (§3.4).  The identification cannot return the turbulence exactly:
the roll rate is differentiated from a 10 Hz encoder and smoothed (§3.2), which
attenuates fast fluctuations.  The defaults are therefore calibrated so that
the paper's own pipeline (:func:`identification.methods.pipeline.identify`, default
options) run on tunnel data returns the paper's numbers:

* Gaussian, mean 0° (a mean is indistinguishable from the asymmetry θ̄);
* correlation time τ = 0.5 s: over 12 seeds, shorter or longer τ were tried
  (0.3, 0.5, 0.7, 1.0 s); longer τ widens the scatter of the steady-state
  slopes (α error up to 3.5 % at 1 s against 2.4 % at 0.5 s), shorter τ is
  attenuated more by the smoothing;
* SD 9.8°: the identified ``u_d,θ`` 90 % interval then averages
  [-13.7, 13.5]° over seeds 0-19 (seed 0: [-12.5, 13.6]°), against the
  paper's [-13.38, 14.28]°.  The true interval is about ±16°.

With these, the mean absolute roll rate of the Table 1 run is 16.1-17.1 °/s
over seeds 0-19 (paper: 16.4 °/s).  ``benchmarks/ground_truth.py`` measures
the recovery.
"""

from __future__ import annotations

import functools
import math
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy import signal, stats

from identification import paper
from identification.instruments.reference import (
    Effects,
    GyroReader,
    LoopRun,
    RateLoop,
    fly_loop,
    gust_factor,
    gust_stream,
    simulate_reference,
)
from identification.model import (
    MODEL_NAMES,
    PAPER_CONSTANT,
    PAPER_THETA,
    RollParams,
    Servo,
    simulate,
)
from identification.recordings.recording import Recording, StatedRig, metadata_items
from rocketroll_common.errors import SettingError
from rocketroll_common.settings import check, parse, setting, to_argv

FloatArray = NDArray[np.float64]

__all__ = [
    "PAPER_TABLE1",
    "FinSchedule",
    "SmoothSchedule",
    "TunnelSpec",
    "Turbulence",
    "fin_schedule",
    "loop_items",
    "run_tunnel",
    "synthetic_recording",
    "truth_items",
]

Distribution = Literal["gaussian", "laplace", "student-t"]
DISTRIBUTIONS: tuple[str, ...] = ("gaussian", "laplace", "student-t")

#: Paper Table 1: (start time s, fin angle °) of each step; 0° before 68.1 s, end 573.0 s.
PAPER_TABLE1 = paper.TABLE1
PAPER_END_S = paper.TABLE1_END_S
#: Smallest difference between consecutive staircase levels, °.
MIN_STEP_DEG = 5.0


@dataclass(frozen=True)
class Turbulence:
    """Stationary disturbance process ``u_d`` (equivalent fin angle).

    Attributes
    ----------
    distribution : {"gaussian", "laplace", "student-t"}
        Marginal distribution.
    sd_deg : float
        Standard deviation of the marginal, °.
    mean_deg : float
        Mean, °.
    correlation_time_s : float
        τ: lag-one correlation over a hold interval Δt is ``exp(-Δt/τ)``;
        0 gives independent values.
    dof : float
        Degrees of freedom of the Student-t marginal (> 2).
    """

    distribution: Distribution = "gaussian"
    sd_deg: float = 9.8
    mean_deg: float = 0.0
    correlation_time_s: float = 0.5
    dof: float = 4.0

    def __post_init__(self) -> None:
        if self.distribution not in DISTRIBUTIONS:
            raise ValueError(
                f"distribution must be one of {', '.join(DISTRIBUTIONS)}, not {self.distribution!r}"
            )
        if not (np.isfinite(self.sd_deg) and self.sd_deg >= 0):
            raise ValueError(f"sd_deg must be >= 0, got {self.sd_deg!r}")
        if not np.isfinite(self.mean_deg):
            raise ValueError(f"mean_deg must be finite, got {self.mean_deg!r}")
        if not (np.isfinite(self.correlation_time_s) and self.correlation_time_s >= 0):
            raise ValueError(f"correlation_time_s must be >= 0, got {self.correlation_time_s!r}")
        if self.distribution == "student-t" and not (np.isfinite(self.dof) and self.dof > 2):
            raise ValueError(f"dof must be > 2 for a finite variance, got {self.dof!r}")

    def sample(self, n: int, dt_s: float, rng: np.random.Generator) -> FloatArray:
        """Draw ``n`` consecutive hold values spaced ``dt_s`` apart.

        Parameters
        ----------
        n : int
            Number of values.
        dt_s : float
            Hold interval, s.
        rng : numpy.random.Generator
            Source of randomness.

        Returns
        -------
        ndarray, shape (n,)
            ``u_d`` in °, stationary from the first value.
        """
        rho = float(np.exp(-dt_s / self.correlation_time_s)) if self.correlation_time_s > 0 else 0.0
        eps = rng.standard_normal(n)
        # AR(1) with unit variance, started in its stationary distribution.
        z = signal.lfilter([np.sqrt(1.0 - rho * rho)], [1.0, -rho], eps[1:], zi=[rho * eps[0]])[0]
        z = np.concatenate([eps[:1], z])
        return self.mean_deg + self.sd_deg * self._standardised(z)

    def _standardised(self, z: FloatArray) -> FloatArray:
        """Map standard normal ``z`` to the unit-variance target marginal."""
        if self.distribution == "gaussian":
            return z
        tail = stats.norm.logsf(np.abs(z))  # log P(Z > |z|), accurate far out
        if self.distribution == "laplace":
            # Laplace(b = 1/√2): quantile of p = Φ(-|z|) is b·(log 2 + log p) on that side.
            return -np.sign(z) * (np.log(2.0) + tail) / np.sqrt(2.0)
        scale = np.sqrt((self.dof - 2.0) / self.dof)
        return np.asarray(np.sign(z) * stats.t.isf(np.exp(tail), self.dof) * scale, dtype=float)


@dataclass(frozen=True)
class FinSchedule:
    """Fin-command schedule: a level held from each change time to the next.

    Attributes
    ----------
    change_times_s : tuple of float
        Times at which the command changes, s, strictly increasing.
    levels_deg : tuple of float
        The command from each change time on, °.
    end_s : float
        End of the run, s.
    initial_deg : float
        Command before the first change, °.
    """

    change_times_s: tuple[float, ...]
    levels_deg: tuple[float, ...]
    end_s: float
    initial_deg: float = 0.0

    def __post_init__(self) -> None:
        times = np.asarray(self.change_times_s, dtype=float)
        if len(self.change_times_s) != len(self.levels_deg):
            raise ValueError("change_times_s and levels_deg must have the same length")
        if times.size and (np.any(np.diff(times) <= 0) or times[0] <= 0):
            raise ValueError("change_times_s must be positive and strictly increasing")
        if times.size and self.end_s <= times[-1]:
            raise ValueError("end_s must come after the last change time")

    @classmethod
    def paper(cls) -> FinSchedule:
        """Table 1 of the paper: 0° until 68.1 s, eight steps, end at 573.0 s."""
        times, levels = zip(*PAPER_TABLE1, strict=True)
        return cls(tuple(times), tuple(levels), PAPER_END_S)

    @classmethod
    def staircase(
        cls,
        rng: np.random.Generator,
        steps: int,
        range_deg: float = 40.0,
        dwell_s: tuple[float, float] = (20.0, 60.0),
        lead_s: float = 20.0,
        min_step_deg: float = MIN_STEP_DEG,
        grid_s: float = 0.1,
    ) -> FinSchedule:
        """Random staircase: ``steps`` levels uniform in ±``range_deg``.

        Consecutive levels differ by at least ``min_step_deg``; each dwell is
        uniform in ``dwell_s``; times are rounded to ``grid_s``.  The command
        is 0° for the first ``lead_s`` seconds.
        """
        if steps < 1:
            raise ValueError(f"steps must be >= 1, got {steps}")
        lo, hi = dwell_s
        if not (0 < lo <= hi):
            raise ValueError(f"dwell_s must satisfy 0 < min <= max, got {dwell_s}")
        if range_deg <= min_step_deg / 2:
            raise ValueError(f"range_deg must exceed min_step_deg/2, got {range_deg}")
        levels: list[float] = []
        previous = 0.0
        while len(levels) < steps:
            level = round(float(rng.uniform(-range_deg, range_deg)), 2)
            if abs(level - previous) >= min_step_deg:
                levels.append(level)
                previous = level
        dwells = np.round(rng.uniform(lo, hi, size=steps) / grid_s) * grid_s
        edges = np.round((lead_s + np.concatenate([[0.0], np.cumsum(dwells)])) / grid_s) * grid_s
        times = tuple(round(float(t), 6) for t in edges[:-1])
        return cls.starting(times, tuple(levels), round(float(edges[-1]), 6))

    @classmethod
    def starting(
        cls, times: tuple[float, ...], levels: tuple[float, ...], end_s: float
    ) -> FinSchedule:
        """The schedule of these changes; one at time 0 (no lead) is the initial level."""
        if times and times[0] <= 0.0:
            return cls(times[1:], levels[1:], end_s, initial_deg=levels[0])
        return cls(times, levels, end_s)

    def command(self, time_s: FloatArray) -> FloatArray:
        """The commanded level at each time, °."""
        levels = np.concatenate([[self.initial_deg], np.asarray(self.levels_deg, dtype=float)])
        # side="right" plus a tolerance: a change at T applies from t = T on.
        index = np.searchsorted(np.asarray(self.change_times_s) - 1e-9, time_s, side="right")
        return levels[index]

    @classmethod
    def doublets(
        cls,
        rng: np.random.Generator,
        count: int,
        range_deg: float,
        pulse_s: float,
        dwell_s: tuple[float, float],
        lead_s: float,
        grid_s: float,
    ) -> FinSchedule:
        """``count`` doublets: ``+A`` for ``pulse_s``, ``-A`` for ``pulse_s``, back to 0°,
        ``A`` uniform in [``range_deg``/2, ``range_deg``] with a random sign, each followed
        by a dwell at 0° uniform in ``dwell_s``; every time a whole number of ``grid_s``
        log steps (the pulse at least one), so both halves last alike."""
        k, pulse = round(lead_s / grid_s), _whole_steps(pulse_s, grid_s)
        times: list[int] = []
        levels: list[float] = []
        for _ in range(count):
            amplitude = float(rng.uniform(range_deg / 2, range_deg)) * float(rng.choice([-1, 1]))
            times += [k, k + pulse, k + 2 * pulse]
            levels += [round(amplitude, 2), round(-amplitude, 2), 0.0]
            k += 2 * pulse + _whole_steps(float(rng.uniform(*dwell_s)), grid_s)
        return cls.starting(_seconds(times, grid_s), tuple(levels), _seconds([k], grid_s)[0])

    @classmethod
    def prbs(
        cls,
        rng: np.random.Generator,
        duration_s: float,
        range_deg: float,
        bit_s: float,
        lead_s: float,
        grid_s: float,
    ) -> FinSchedule:
        """A pseudo-random binary sequence: ``±range_deg``, a fair coin every ``bit_s`` (a
        whole number of ``grid_s`` log steps) for ``duration_s`` after the lead (white up
        to about 1/(2·``bit_s``) Hz)."""
        lead, bit = round(lead_s / grid_s), _whole_steps(bit_s, grid_s)
        bits = max(1, round(duration_s / (bit * grid_s)))
        signs = rng.choice([-1.0, 1.0], size=bits)
        times = _seconds([lead + j * bit for j in range(bits)], grid_s)
        end = _seconds([lead + bits * bit], grid_s)[0]
        return cls.starting(times, tuple(range_deg * signs), end)


def _whole_steps(seconds: float, grid_s: float) -> int:
    """The whole number of log steps nearest ``seconds``, at least one."""
    return max(1, round(seconds / grid_s))


def _seconds(steps: Sequence[int], grid_s: float) -> tuple[float, ...]:
    """Times in s of whole log steps (rounded to µs, as the staircase's)."""
    return tuple(round(k * grid_s, 6) for k in steps)


@dataclass(frozen=True)
class SmoothSchedule:
    """A fin command that moves continuously: linear between breakpoints (ramps), or a
    sine sweep (chirp); logged, like any command, as its value at each log time.

    Attributes
    ----------
    times_s, values_deg : tuple of float
        Breakpoints of a piecewise-linear command (held after the last one).
    end_s : float
        End of the run, s.
    chirp : tuple of float or None
        ``(amplitude °, f0 Hz, f1 Hz, start s, duration T s, stop s)``: a linear sweep
        ``A·sin(2π(f0·τ + (f1 - f0)·τ²/(2T)))``, τ = t - start, from τ = 0 to its last
        zero crossing ``stop`` ≤ T, 0 outside it.
    """

    times_s: tuple[float, ...]
    values_deg: tuple[float, ...]
    end_s: float
    chirp: tuple[float, float, float, float, float, float] | None = None

    @classmethod
    def ramps(
        cls,
        rng: np.random.Generator,
        steps: int,
        range_deg: float,
        ramp_s: float,
        dwell_s: tuple[float, float],
        lead_s: float,
    ) -> SmoothSchedule:
        """The staircase's levels (:meth:`FinSchedule.staircase`), each reached by a linear
        ramp of ``ramp_s`` and held for a dwell uniform in ``dwell_s``: as a rig that
        slews its fins at a set rate commands them."""
        stairs = FinSchedule.staircase(rng, steps, range_deg, dwell_s, lead_s, grid_s=1e-6)
        previous = stairs.initial_deg  # the first level, without a lead
        times, values = [0.0], [previous]
        for start, level in zip(stairs.change_times_s, stairs.levels_deg, strict=True):
            times += [start, start + ramp_s]
            values += [previous, level]
            previous = level
        return cls(tuple(times), tuple(values), stairs.end_s + ramp_s)

    @classmethod
    def sweep(
        cls, range_deg: float, f0_hz: float, f1_hz: float, duration_s: float, lead_s: float
    ) -> SmoothSchedule:
        """A chirp of amplitude ``range_deg`` from ``f0_hz`` to ``f1_hz`` over ``duration_s``
        after ``lead_s`` at 0°, then 0° for 5 s."""
        # The sweep stops at its last zero crossing within duration_s: no step at its end.
        rate = (f1_hz - f0_hz) / (2.0 * duration_s)
        half_cycles = math.floor(2.0 * (f0_hz * duration_s + rate * duration_s**2))
        target = half_cycles / 2.0
        if abs(rate) < 1e-15:
            stop = target / f0_hz
        else:
            stop = (-f0_hz + math.sqrt(f0_hz**2 + 4.0 * rate * target)) / (2.0 * rate)
        chirp = (range_deg, f0_hz, f1_hz, lead_s, duration_s, min(stop, duration_s))
        return cls((0.0,), (0.0,), lead_s + duration_s + 5.0, chirp)

    def command(self, time_s: FloatArray) -> FloatArray:
        """The command at each time, °."""
        t = np.asarray(time_s, dtype=float)
        out = np.interp(t, self.times_s, self.values_deg)
        if self.chirp is not None:
            amplitude, f0, f1, start, duration, stop = self.chirp
            tau = t - start
            inside = (tau >= 0) & (tau <= stop)
            phase = f0 * tau + (f1 - f0) * tau**2 / (2.0 * duration)
            out = np.where(inside, amplitude * np.sin(2.0 * np.pi * phase), out)
        return np.asarray(out)


#: A virtual rocket's truth settings: default, help (``{at}`` the operating point, the
#: paper's values by name) and bounds.
_ROCKET_SETTINGS: dict[str, tuple[float | None, str, dict[str, Any]]] = {
    "alpha": (
        PAPER_THETA.alpha,
        "steady-state gain α{at} (eq. 17: {alpha})",
        {"ge": -10.0, "le": 10.0, "unit": "(°/s)/°"},
    ),
    "beta": (
        PAPER_THETA.beta_dps,
        "steady-state offset β{at} (eq. 17: {beta_dps}); θ̄ = β/α",
        {"ge": -100.0, "le": 100.0, "unit": "°/s"},
    ),
    "alpha_bar": (
        None,
        "ᾱ{at} (eq. 48: {alpha_bar_per_deg_s}; 0 for --model constant)",
        {"ge": -1.0, "le": 1.0, "unit": "1/(s·°)"},
    ),
    "beta_bar": (
        None,
        "β̄{at} (eq. 48: {beta_bar_per_s}), or the constant a (eq. 46: {a_per_s})",
        {"gt": 0.0, "le": 100.0, "unit": "1/s"},
    ),
}


#: The rate loop's settings: default, help (its words filled in by :func:`loop_setting`) and
#: bounds; the tunnel's and the flight recorder's are these.
_LOOP_SETTINGS: dict[str, tuple[float, str, dict[str, Any]]] = {
    "loop_gain": (
        0.0,
        "a proportional roll-rate loop on the fins{whose}, run at the logging rate: fin "
        "command = {excitation} + this × (0 - {rate} read --loop-delay earlier), saturated at "
        "--stops (0: open loop, the {excitation} alone; the sign of --alpha damps the roll, the "
        "other drives it)",
        {"ge": -10.0, "le": 10.0, "unit": "°/(°/s)"},
    ),
    "loop_delay": (
        0.02,
        "the loop's delay (sensor and computation): it reads {reads} from this long before "
        "each command, to the integrator's step (1 ms)",
        {"ge": 0.0, "le": 0.5, "unit": "s"},
    ),
    "stops": (
        Servo().range_deg,
        "the fins' mechanical stops: the command saturates at ±this (the logged command is "
        "the saturated one)",
        {"ge": 2.0, "le": Servo().range_deg, "unit": "°"},
    ),
}


def loop_setting(name: str, **words: str) -> Any:
    """The setting of a virtual instrument's rate loop ``name`` (``loop_gain``,
    ``loop_delay``, ``stops``), its help in the instrument's ``words`` (``whose``,
    ``excitation``, ``rate``; ``reads``)."""
    default, text, bounds = _LOOP_SETTINGS[name]
    return setting(default, text.format(**words), **bounds)


class LoopFlown:
    """What a virtual instrument that may fly a rate loop (its settings from
    :func:`loop_setting`) derives from them: whether it does, the loop, the servo whose
    range is the stops, and the check that an excitation of ``none`` has a loop."""

    loop_gain: float
    loop_delay: float
    stops: float
    servo_rate: float
    schedule: str

    @property
    def closed_loop(self) -> bool:
        """Whether a rate loop flies the fins (``loop_gain`` not 0)."""
        return self.loop_gain != 0.0

    def rate_loop(self) -> RateLoop:
        """The rate loop flown (its gain 0 in open loop)."""
        return RateLoop(float(self.loop_gain), float(self.loop_delay), float(self.stops))

    def servo(self) -> Servo:
        """The servo flown: its rate limit, the fins' stops its range."""
        return Servo(rate_limit_dps=self.servo_rate, range_deg=float(self.stops))

    def check_loop(self) -> None:
        """Refuse (``SettingError``) the excitation ``none`` without a loop."""
        if self.schedule == "none" and not self.closed_loop:
            raise SettingError(
                "schedule",
                "none leaves the fins at 0° without a loop: give --loop-gain, or a schedule",
            )


def rocket_setting(name: str, at: str = "") -> Any:
    """The setting (help, default, bounds) of a virtual rocket's truth ``name``
    (``alpha``, ``beta``, ``alpha_bar``, ``beta_bar``), given ``at`` an operating point
    (``" at --v-ref"`` for a flight); the tunnel's and the flight recorder's are these."""
    if name not in _ROCKET_SETTINGS:
        raise ValueError(f"no rocket setting {name!r}")
    default, text, bounds = _ROCKET_SETTINGS[name]
    return setting(default, text.format(at=at, **paper.PARAMETERS), **bounds)


def rocket_params(
    model: str, alpha: float, beta: float, alpha_bar: float | None, beta_bar: float | None
) -> RollParams:
    """A virtual rocket's truth from its settings: ``ᾱ``/``β̄`` default (None) to the
    paper's for ``model`` -- ᾱ = -0.0289, β̄ = 2.4075 (eq. 48) or ᾱ = 0, a = 1.314 (eq. 46)."""
    base = PAPER_THETA if model == "theta" else PAPER_CONSTANT
    return RollParams.from_steady_state(
        alpha=alpha,
        beta=beta,
        beta_bar=base.beta_bar_per_s if beta_bar is None else beta_bar,
        alpha_bar=base.alpha_bar_per_deg_s if alpha_bar is None else alpha_bar,
    )


def check_rocket(
    model: str, alpha: float, beta: float, alpha_bar: float | None, beta_bar: float | None
) -> None:
    """Refuse a virtual rocket's settings that make no rocket (``SettingError`` naming the
    setting): ᾱ with the constant model, a vanishing gain, an asymmetry beyond ±45°, a
    damping that reaches zero within the fin range."""
    if model == "constant" and alpha_bar not in (None, 0.0):
        raise SettingError("alpha_bar", "must be 0 for the constant-damping model")
    if abs(alpha) < 1e-3:
        raise SettingError("alpha", f"must be at least 0.001 in size, got {alpha!r}")
    if abs(beta / alpha) > 45.0:
        raise SettingError("beta", f"gives an asymmetry θ̄ = β/α = {beta / alpha:.4g}° beyond ±45°")
    params = rocket_params(model, alpha, beta, alpha_bar, beta_bar)
    lowest = params.beta_bar_per_s + min(params.alpha_bar_per_deg_s, 0.0) * (
        Servo().range_deg + abs(params.theta_bar_deg)
    )
    if lowest <= 0.0:
        raise SettingError(
            "alpha_bar",
            f"makes the damping a(θ) = ᾱ·|θ + θ̄| + β̄ reach {lowest:.3g} 1/s within the "
            f"±{Servo().range_deg:g}° fin range; it must stay positive",
        )


def check_dwells(log_dt: float, dwell_min: float, dwell_max: float) -> None:
    """Refuse staircase dwells shorter than a logging interval or out of order."""
    if not log_dt <= dwell_min <= dwell_max:
        raise SettingError(
            "dwell_min",
            f"must be at least --log-dt ({log_dt:g} s) and at most --dwell-max "
            f"({dwell_max:g} s), got {dwell_min:g} s",
        )


@dataclass(frozen=True)
class TunnelSpec(LoopFlown):
    """Everything that defines one virtual tunnel run; each field is a ``rocketroll tunnel`` flag.

    The defaults re-create the paper's experiment.  ``alpha_bar``/``beta_bar``
    default (``None``) to the paper's values for the chosen ``model``:
    ᾱ = -0.0289, β̄ = 2.4075 (θ-dependent, eq. 48) or ᾱ = 0, β̄ = a = 1.314
    (constant, eq. 46).  Every number is bounded to a physical range; a value
    outside it is a :class:`~rocketroll_common.errors.SettingError` naming the
    field (the flag, on the command line).
    """

    seed: int = setting(
        0, "random seed; the same seed gives a byte-identical file", ge=0, le=2**63 - 1, always=True
    )
    schedule: Literal["paper", "staircase", "ramps", "doublets", "prbs", "chirp", "none"] = setting(
        "paper",
        "fin-command schedule: the paper's Table 1; a random staircase; the staircase's "
        "levels reached by linear ramps (--ramp); doublets (--pulse); a pseudo-random "
        "binary sequence (--pulse bits for --duration); a chirp (--chirp-from to "
        "--chirp-to Hz over --duration); none (0° for --duration, only under "
        "--loop-gain). Under --loop-gain it is the excitation added to the loop's command",
    )
    steps: int = setting(10, "number of staircase or ramp levels, or of doublets", ge=1, le=200)
    fin_range: float = setting(
        40.0,
        "staircase and ramp levels are uniform in ±this; the amplitude of the other schedules",
        gt=MIN_STEP_DEG / 2,
        le=40.0,
        unit="°",
    )
    dwell_min: float = setting(
        20.0, "shortest dwell (staircase, ramps, after a doublet)", gt=0.0, le=3600.0, unit="s"
    )
    dwell_max: float = setting(
        60.0, "longest dwell (staircase, ramps, after a doublet)", gt=0.0, le=3600.0, unit="s"
    )
    lead: float = setting(
        20.0, "the command holds 0° this long before the schedule", ge=0.0, le=3600.0, unit="s"
    )
    ramp: float = setting(1.0, "time of each ramp (ramps)", gt=0.0, le=600.0, unit="s")
    pulse: float = setting(
        1.0, "a doublet's pulse, a PRBS bit (doublets, prbs)", gt=0.0, le=600.0, unit="s"
    )
    duration: float = setting(
        60.0, "length of the PRBS or the chirp", gt=0.0, le=86_400.0, unit="s"
    )
    chirp_from: float = setting(0.05, "the chirp's first frequency", gt=0.0, le=500.0, unit="Hz")
    chirp_to: float = setting(2.0, "the chirp's last frequency", gt=0.0, le=500.0, unit="Hz")
    model: str = setting(
        "theta", "damping model: theta (eq. 49) or constant (eq. 29)", choices=MODEL_NAMES
    )
    alpha: float = rocket_setting("alpha")
    beta: float = rocket_setting("beta")
    alpha_bar: float | None = rocket_setting("alpha_bar")
    beta_bar: float | None = rocket_setting("beta_bar")
    servo_rate: float = setting(
        Servo().rate_limit_dps,
        "servo rate limit (eq. 23: 60°/0.4 s = 150)",
        gt=0.0,
        le=10_000.0,
        unit="°/s",
    )
    loop_gain: float = loop_setting(
        "loop_gain", whose="", excitation="schedule", rate="the roll rate"
    )
    loop_delay: float = loop_setting(
        "loop_delay", reads="the gyro's rate (with its --gyro-noise, else noise-free)"
    )
    stops: float = loop_setting("stops")
    turbulence: Distribution = setting("gaussian", "marginal distribution of u_d")
    turbulence_sd: float = setting(
        Turbulence().sd_deg, "standard deviation of u_d", ge=0.0, le=45.0, unit="°"
    )
    turbulence_mean: float = setting(
        Turbulence().mean_deg, "mean of u_d", ge=-45.0, le=45.0, unit="°"
    )
    correlation_time: float = setting(
        Turbulence().correlation_time_s,
        "correlation time of u_d (0: independent per interval)",
        ge=0.0,
        le=600.0,
        unit="s",
    )
    dof: float = setting(
        Turbulence().dof, "degrees of freedom of the student-t marginal", gt=2.0, le=1000.0
    )
    effects: Effects = setting(default_factory=Effects, flatten=True)
    log_dt: float = setting(0.1, "logging interval (the paper: 0.1)", ge=0.001, le=1.0, unit="s")
    substeps: int = setting(10, "exact-update substeps per logging interval", ge=1, le=1000)
    encoder_counts: int = setting(
        1024,
        "encoder counts per revolution (HEDS-5702: 256 cycles read in 4x quadrature = 1024; "
        "0: ideal)",
        ge=0,
        le=2**24,
    )
    no_encoder: bool = setting(False, "omit the encoder angle (needs --gyro-noise)")
    gyro_noise: float | None = setting(
        None,
        "add a rate-gyro column with eq. 52 noise of this many percent",
        ge=0.0,
        le=100.0,
        unit="%",
    )
    measured_fin: bool = setting(False, "add the actual (measured) fin angle column fin_deg")
    state_rig: bool = setting(
        False,
        "the recording states its rig as a user who measured it would (format 1.2's rig.* "
        "lines: the truth's servo lag, backlash and sensor latency)",
    )
    name: str | None = setting(None, "recording name (default tunnel-<schedule>-seed<N>)")
    split: Literal["train", "test"] | None = setting(
        None,
        "evaluation split to record in the metadata (default: none; the disturbance database "
        "then splits by content hash)",
    )

    def __post_init__(self) -> None:
        check(self)
        check_rocket(self.model, self.alpha, self.beta, self.alpha_bar, self.beta_bar)
        if self.no_encoder and self.gyro_noise is None:
            raise SettingError("no_encoder", "needs a rate gyro (give --gyro-noise, e.g. 0)")
        self.check_loop()
        if self.schedule in ("doublets", "prbs") and self.pulse < self.log_dt:
            raise SettingError(
                "pulse", f"{self.pulse:g} s is shorter than the logging interval {self.log_dt:g} s"
            )
        nyquist = 0.5 / self.log_dt
        if self.schedule == "chirp" and max(self.chirp_from, self.chirp_to) > nyquist / 2:
            raise SettingError(
                "chirp_to" if self.chirp_to >= self.chirp_from else "chirp_from",
                f"above {nyquist / 2:g} Hz, half the Nyquist frequency of --log-dt "
                f"{self.log_dt:g} s: the logged command would not show the sweep",
            )
        check_dwells(self.log_dt, self.dwell_min, self.dwell_max)
        if self.schedule == "ramps" and self.ramp > self.dwell_min:
            raise SettingError(
                "ramp",
                f"{self.ramp:g} s is longer than --dwell-min {self.dwell_min:g} s: each level "
                "must be reached before the next ramp starts",
            )
        _check_schedule(self)  # the schedule the seed draws (cheap), before any simulation

    @functools.cached_property
    def schedule_drawn(self) -> FinSchedule | SmoothSchedule:
        """The fin-command schedule of this run, drawn from the seed's schedule stream."""
        return fin_schedule(self, _streams(self.seed)[0])

    def params(self) -> RollParams:
        """Ground-truth roll parameters of this run."""
        return rocket_params(self.model, self.alpha, self.beta, self.alpha_bar, self.beta_bar)

    def turbulence_model(self) -> Turbulence:
        """Turbulence process of this run."""
        return Turbulence(
            distribution=self.turbulence,
            sd_deg=self.turbulence_sd,
            mean_deg=self.turbulence_mean,
            correlation_time_s=self.correlation_time,
            dof=self.dof,
        )

    def default_name(self) -> str:
        """``tunnel-<schedule>-seed<N>`` unless a name was given."""
        return self.name or f"tunnel-{self.schedule}-seed{self.seed}"

    def to_args(self) -> list[str]:
        """The ``rocketroll tunnel`` arguments that reproduce this spec.

        Only fields that differ from their defaults appear, ``--seed`` always
        (:func:`rocketroll_common.settings.to_argv`).
        """
        return to_argv(self)

    def command(self) -> str:
        """The full shell command, e.g. ``rocketroll tunnel --seed 0``."""
        return shlex.join(["rocketroll", "tunnel", *self.to_args()])


def _streams(seed: int) -> tuple[np.random.Generator, ...]:
    """Independent generators for schedule, turbulence and sensors.

    Spawned from one seed, so switching a sensor on does not change the
    turbulence of the same seed.
    """
    children = np.random.SeedSequence(seed).spawn(3)
    return tuple(np.random.default_rng(child) for child in children)


def fin_schedule(spec: TunnelSpec, rng: np.random.Generator) -> FinSchedule | SmoothSchedule:
    """The fin-command schedule ``spec`` asks for, drawn from ``rng``."""
    dwell = (spec.dwell_min, spec.dwell_max)
    if spec.schedule == "paper":
        return FinSchedule.paper()
    if spec.schedule == "staircase":
        return FinSchedule.staircase(
            rng, spec.steps, spec.fin_range, dwell, spec.lead, grid_s=spec.log_dt
        )
    if spec.schedule == "ramps":
        return SmoothSchedule.ramps(rng, spec.steps, spec.fin_range, spec.ramp, dwell, spec.lead)
    if spec.schedule == "doublets":
        return FinSchedule.doublets(
            rng, spec.steps, spec.fin_range, spec.pulse, dwell, spec.lead, spec.log_dt
        )
    if spec.schedule == "prbs":
        return FinSchedule.prbs(
            rng, spec.duration, spec.fin_range, spec.pulse, spec.lead, spec.log_dt
        )
    if spec.schedule == "none":
        return FinSchedule((), (), spec.duration)
    return SmoothSchedule.sweep(
        spec.fin_range, spec.chirp_from, spec.chirp_to, spec.duration, spec.lead
    )


#: Most samples a tunnel run logs (each column 8 bytes a sample; 14 h at 100 Hz).
MAX_SAMPLES = 5_000_000

#: What sets each schedule's length, for the message that refuses one.
_LENGTH_SET_BY = {
    "paper": "the paper's Table 1",
    "staircase": "--lead, --steps and the dwells",
    "ramps": "--lead, --steps, the dwells and --ramp",
    "doublets": "--lead, --steps, --pulse and the dwells",
    "prbs": "--lead and --duration",
    "chirp": "--lead and --duration (and 5 s at 0° after it)",
    "none": "--duration",
}


def _check_schedule(spec: TunnelSpec) -> None:
    """Refuse (``SettingError``, before anything is simulated) a run a recording cannot
    hold -- its span, its number of samples -- or, in open loop, a command that never
    changes (under a loop the turbulence moves the fins)."""
    from identification.recordings.recording import DURATION_RANGE_S, MIN_SAMPLES

    flag = "duration" if spec.schedule in ("prbs", "chirp", "none") else "steps"
    if spec.schedule == "none":
        _check_samples(spec, spec.duration)
    if spec.schedule in ("prbs", "chirp"):  # known before the sequence is drawn
        _check_samples(spec, spec.lead + spec.duration + (5.0 if spec.schedule == "chirp" else 0))
    schedule = spec.schedule_drawn
    n = round(schedule.end_s / spec.log_dt)
    span = n * spec.log_dt
    shortest, longest = DURATION_RANGE_S
    if not shortest <= span <= longest or n + 1 < MIN_SAMPLES:
        raise SettingError(
            flag,
            f"the {spec.schedule} schedule runs {span:g} s in {n + 1} samples; a recording spans "
            f"{shortest:g} s to {longest / 3600:g} h in at least {MIN_SAMPLES} samples (set by "
            f"{_LENGTH_SET_BY[spec.schedule]}, and --log-dt)",
        )
    _check_samples(spec, span)
    if spec.closed_loop:
        return
    command = _saturated(schedule.command(spec.log_dt * np.arange(n + 1, dtype=float)), spec)
    if np.ptp(command) == 0.0:
        raise SettingError(
            flag,
            f"the {spec.schedule} schedule never moves the fins (at {command[0]:g}° "
            "throughout): give it more steps, a lead or a longer run",
        )


def _saturated(command: FloatArray, spec: TunnelSpec) -> FloatArray:
    """The command at the fins' stops, as the flight computer sends and logs it."""
    return np.asarray(np.clip(command, -spec.stops, spec.stops), dtype=float)


def _check_samples(spec: TunnelSpec, span_s: float) -> None:
    samples = span_s / spec.log_dt
    if samples > MAX_SAMPLES:
        raise SettingError(
            "log_dt",
            f"{span_s:g} s every {spec.log_dt:g} s is {samples:,.0f} samples, more than "
            f"{MAX_SAMPLES:,}: log less often or run shorter",
        )


def run_tunnel(spec: TunnelSpec) -> Recording:
    """Run the virtual wind tunnel.

    Parameters
    ----------
    spec : TunnelSpec
        The run; the same spec always gives the same recording.

    Returns
    -------
    Recording
        ``source = synthetic``, with ``fin_cmd_deg``, ``roll_deg`` (unless
        ``no_encoder``), the optional ``fin_deg`` and ``roll_rate_dps``, and the
        ground-truth ``ud_true_deg``; the metadata carries the truth and the
        exact command (and, under a loop, the controller: ``loop.*``).

    Examples
    --------
    >>> from identification.instruments.tunnel import TunnelSpec, run_tunnel
    >>> rec = run_tunnel(TunnelSpec(seed=1))
    >>> rec.source, rec.n_samples
    ('synthetic', 5731)
    """
    _, rng_turbulence, rng_sensor = _streams(spec.seed)
    schedule = spec.schedule_drawn  # from the schedule's stream, drawn once with the spec
    n = round(schedule.end_s / spec.log_dt)
    time = spec.log_dt * np.arange(n + 1, dtype=float)
    excitation = schedule.command(time)
    turbulence = spec.turbulence_model()
    u_d = turbulence.sample(n + 1, spec.log_dt, rng_turbulence)
    params = spec.params()
    servo = spec.servo()
    effects = spec.effects
    if effects.any:  # the turbulence's intensity wanders (a no-op unless --gust-sd)
        gust = gust_factor(n + 1, spec.log_dt, effects, gust_stream(spec.seed))
        u_d = turbulence.mean_deg + (u_d - turbulence.mean_deg) * gust
    gyro: FloatArray | None = None
    loop: list[tuple[str, object]] = []
    if spec.closed_loop:  # the fins under the rate loop: the reference integrator
        flown = _fly_loop(spec, excitation, u_d, params, rng_sensor)
        command, fin, rate, angle, gyro = (
            flown.command, flown.fin, flown.rate, flown.angle, flown.gyro
        )  # fmt: skip
        sensor = "roll_rate_dps" if spec.gyro_noise is not None else "the true roll rate"
        loop = loop_items(spec.rate_loop(), flown.delay_s, sensor, "tunnel.schedule")
    else:
        command = _saturated(excitation, spec)
        # The rocket starts at its steady roll rate for the initial fin angle.
        rate0 = float(params.steady_rate(command[0], turbulence.mean_deg))
        if effects.any:  # a rocket outside the model: the reference integrator
            ref = simulate_reference(
                params, spec.log_dt, command[:-1], u_d[:-1], effects,
                rate_limit_dps=servo.rate_limit_dps, fin_range_deg=servo.range_deg,
                rate0_dps=rate0,
            )  # fmt: skip
            fin, rate, angle = ref.fin_deg, ref.rate_dps, ref.angle_deg
        else:
            sim = simulate(
                params,
                spec.log_dt,
                command[:-1],
                u_d[:-1],
                rate0_dps=rate0,
                servo=servo,
                substeps=spec.substeps,
            )
            fin, rate, angle = sim.fin_deg, sim.rate_dps, sim.angle_deg

    columns: dict[str, FloatArray] = {"fin_cmd_deg": command}
    if spec.measured_fin:
        columns["fin_deg"] = fin
    if not spec.no_encoder:
        if spec.encoder_counts:
            resolution = 360.0 / spec.encoder_counts
            columns["roll_deg"] = np.floor(angle / resolution + 1e-9) * resolution
        else:
            columns["roll_deg"] = angle
    if spec.gyro_noise is not None:
        if gyro is None:
            eps = rng_sensor.standard_normal(rate.size)
            gyro = (1.0 + spec.gyro_noise / 100.0 * eps) * rate  # eq. 52
        columns["roll_rate_dps"] = gyro
    columns["ud_true_deg"] = u_d

    meta: list[tuple[str, object]] = [
        ("notes", "virtual wind tunnel (synthetic data with known ground truth)"),
        ("command", spec.command()),
        ("seed", spec.seed),
        ("tunnel.schedule", spec.schedule),
        ("tunnel.substeps", spec.substeps),
        *loop,
        *truth_items(spec.model, params),
        ("truth.servo_rate_dps", servo.rate_limit_dps),
        ("truth.fin_range_deg", servo.range_deg),
        ("truth.turbulence", turbulence.distribution),
        ("truth.turbulence_sd_deg", turbulence.sd_deg),
        ("truth.turbulence_mean_deg", turbulence.mean_deg),
        ("truth.turbulence_tau_s", turbulence.correlation_time_s),
    ]
    if turbulence.distribution == "student-t":
        meta.append(("truth.turbulence_dof", turbulence.dof))
    if effects.any:  # the truth outside the model
        meta += effects.metadata("tunnel")
    if not spec.no_encoder:
        meta.append(("sensor.encoder_counts", spec.encoder_counts))
    if spec.gyro_noise is not None:
        meta.append(("sensor.gyro_noise_pct", spec.gyro_noise))
    if spec.split is not None:
        meta.append(("split", spec.split))
    if spec.state_rig:
        stated = StatedRig(effects.servo_lag_s, effects.backlash_deg, effects.latency_s)
        meta += list(stated.metadata().items())
    return synthetic_recording(spec.default_name(), time, meta, columns)


def loop_items(
    loop: RateLoop, delay_s: float, sensor: str, excitation: str
) -> list[tuple[str, object]]:
    """A rate loop as the flight computer knows it, as a recording's ``loop.*`` metadata
    (free text to the recording format): its gain, its delay as flown, the fins' stops, the
    rate it reads (``sensor``) and its law, the excitation the metadata line ``excitation``
    names; the tunnel's and the flight recorder's."""
    return [
        ("loop.gain", float(loop.gain)),
        ("loop.delay_s", delay_s),
        ("loop.stops_deg", float(loop.stops_deg)),
        ("loop.rate_sensor", sensor),
        (
            "loop.law",
            "fin_cmd_deg(t) = clip(excitation(t) + gain * (0 - rate read at t - delay_s), "
            f"-stops_deg, stops_deg), held until the next sample; excitation: {excitation}",
        ),
    ]


def _fly_loop(
    spec: TunnelSpec,
    excitation: FloatArray,
    u_d: FloatArray,
    params: RollParams,
    rng_sensor: np.random.Generator,
) -> LoopRun:
    """Fly the tunnel's rocket under its rate loop (:func:`~identification.instruments.
    reference.fly_loop`), its gyro's eq. 52 noise drawn from the sensor stream: one value
    per logged reading, then one per reading of the controller's own; steady before the
    run for the mean turbulence."""
    gyro: GyroReader | None = None
    if spec.gyro_noise is not None:
        sd = spec.gyro_noise / 100.0
        eps_log = rng_sensor.standard_normal(excitation.size)
        eps_own = rng_sensor.standard_normal(excitation.size)

        def gyro(rate: float, k: int, own: bool) -> float:
            return (1.0 + sd * (eps_own if own else eps_log)[k]) * rate  # eq. 52

    return fly_loop(
        params, spec.effects, spec.rate_loop(), excitation, u_d, spec.log_dt,
        rate_limit_dps=spec.servo_rate, u_start_deg=spec.turbulence_mean, gyro=gyro,
    )  # fmt: skip


def truth_items(model: str, params: RollParams) -> list[tuple[str, object]]:
    """The rocket a virtual instrument flew, as a recording's ``truth.*`` metadata."""
    return [
        ("truth.model", model),
        ("truth.alpha", params.alpha),
        ("truth.beta_dps", params.beta_dps),
        ("truth.theta_bar_deg", params.theta_bar_deg),
        ("truth.alpha_bar_per_deg_s", params.alpha_bar_per_deg_s),
        ("truth.beta_bar_per_s", params.beta_bar_per_s),
    ]


def synthetic_recording(
    name: str, time: FloatArray, meta: list[tuple[str, object]], columns: dict[str, Any]
) -> Recording:
    """A virtual instrument's recording: its columns, its metadata (truth, sensors, the
    command that made it)."""
    return Recording(
        name=name, source="synthetic", time_s=time, metadata=metadata_items(meta), **columns
    )


def spec_from_command(command: str | Sequence[str]) -> TunnelSpec:
    """Parse a recorded ``rocketroll tunnel ...`` command back into a spec.

    The same code that writes the command (:meth:`TunnelSpec.to_args`) reads it.
    """
    argv = shlex.split(command) if isinstance(command, str) else list(command)
    if argv[:2] == ["rocketroll", "tunnel"]:
        argv = argv[2:]
    spec: TunnelSpec = parse(TunnelSpec, argv, prog="rocketroll tunnel")
    return spec
