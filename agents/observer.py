"""Observer-based roll control: the turbulence estimated on the fly and cancelled.

The paper treats the turbulence as an equivalent fin angle ``u_d`` (eq. 36:
``θ + θ̄ + u_d`` drives the roll), which makes it a *matched* disturbance:
whatever of it can be predicted, the fins can cancel.  This module does that
with the identification's own state-space model (:mod:`identification.ml`),
run forward in real time:

* :class:`Turbulence` -- the autoregressive model of ``u_d`` on the control
  grid, fitted to the train split's traces (pooled least squares, order by
  AIC as in :mod:`identification.ml`), and a slow random-walk *offset* that
  carries what is constant in an episode: the rocket's own θ̄ against the
  nominal one, and any other steady mismatch.
* :class:`RollObserver` -- a Kalman filter on ``[v, ψ, u_d[k], ...,
  u_d[k-p+1], b]``: roll rate, angle relative to the setpoint, the AR lags
  and the offset.  Its time update is the ML model's
  (:func:`identification.ml.interval_maps` over the fin path the servo takes
  to the command, :func:`identification.ml.roll_transition`,
  :func:`identification.statespace.predict`), its measurement update the
  ML's for the gyro (:func:`identification.statespace.update`, the
  multiplicative noise of eq. 52 as ``g²·(v̂² + P_vv)``); the encoder as a
  quantised measurement: the prior of the angle truncated to the count read
  (:meth:`RollObserver._encoder`).  A setpoint step shows as a reading the
  prior puts no mass on; the angle's variance is then widened so the reading
  re-anchors it (the step is unknown, the rest of the state is not).
* :class:`ObserverController` -- LQR state feedback on the observer's
  estimate (:func:`scipy.linalg.solve_discrete_are`), designed on the same
  model linearised at trim with the fin as a state, so the cost weighs the
  fin's move per step.  The gain on the turbulence states is the
  disturbance-observer feedforward (about ``-1`` on ``û_d``: cancellation);
  the offset state gives the integral action of an LQI without an integrator
  that can wind up.

Deployable: it reads the observation and its own configuration only.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg
from statsmodels.tsa.arima_process import ArmaProcess

from agents.base import Design, FlightView
from agents.nominal import NominalModel
from disturbances.bank import TraceBank
from identification.ml import MAX_ORDER, interval_maps, roll_transition, stationary_cov
from identification.model import RollParams
from identification.statespace import predict, update
from rocketroll_common.arrays import FloatArray
from rollenv.core import RollConfig, wrap_deg
from rollenv.layout import Obs

__all__ = [
    "DEFAULT_WEIGHTS",
    "FLIGHT_WEIGHTS",
    "ObserverController",
    "ObserverFeatures",
    "RollObserver",
    "Turbulence",
    "make_observer",
]

#: Variance floor of a measurement (an ideal sensor stays regular), as in the ML.
_VAR_FLOOR = 1e-8
#: Variance added to the angle when a setpoint step is detected, °²: the reading decides.
_DIFFUSE = 1e6
#: Pole the LQR design gives the (constant) offset state.
_OFFSET_POLE = 0.9999
#: A reading on which the prior puts less probability than this is a setpoint step.
_JUMP_MASS = 1e-9


@dataclass(frozen=True)
class Turbulence:
    """``u_d = w + b``: an AR(p) process ``w`` on the control grid and a slow offset ``b``.

    Attributes
    ----------
    ar : ndarray
        AR coefficients ``a_1..a_p`` of ``w[k+1] = Σ a_i·w[k+1-i] + η``.
    innovation_sd : float
        SD of ``η``, °.
    offset_sd : float
        Prior SD of ``b`` at reset, °: how far a rocket's θ̄ (plus its trace's
        mean ``u_d``) lies from the nominal one.
    drift_sd : float
        SD of ``b``'s random-walk step per control step, °.
    dt_s : float
        The grid, s.
    source : str
        What it was fitted to.
    """

    ar: FloatArray
    innovation_sd: float
    offset_sd: float
    drift_sd: float
    dt_s: float
    source: str = "given"

    def __post_init__(self) -> None:
        ar = np.asarray(self.ar, dtype=float)
        if ar.ndim != 1 or ar.size < 1 or not np.all(np.isfinite(ar)):
            raise ValueError(f"Turbulence.ar must be one or more finite numbers, got {self.ar!r}")
        if not ArmaProcess(ar=np.r_[1.0, -ar]).isstationary:
            raise ValueError(f"Turbulence.ar {ar.tolist()} is not stationary")
        for name in ("innovation_sd", "offset_sd", "drift_sd", "dt_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"Turbulence.{name} must be a number >= 0, got {value!r}")
        object.__setattr__(self, "ar", ar)

    @property
    def order(self) -> int:
        return int(self.ar.size)

    def flown(self, gains: FloatArray) -> tuple[FloatArray, FloatArray]:
        """This (tunnel) turbulence flown along a flight, as an AR(1) per control step.

        ``gains`` are the flight's ``V/V_ref`` per control step (:mod:`rollenv.flight`).
        The flight env flies the tunnel's traces time-compressed by ``V/V_ref`` and
        scaled by ``V_ref/max(V, V_ref)`` (:mod:`disturbances.flight`), so from one
        control step to the next the turbulence is as correlated as this model is at a
        lag of ``dt·V/V_ref`` (its autocorrelation, interpolated), and its SD is this
        model's times the scale.  Returns the per-step coefficient of ``w[k+1]`` on
        ``w[k]`` (the scale's change included) and the innovation's SD, each of shape
        (steps,).
        """
        gains = np.asarray(gains, dtype=float)
        sd = math.sqrt(float(stationary_cov(self.ar, self.innovation_sd)[0, 0]))
        lags = int(np.ceil(np.max(gains))) + 2
        acf = ArmaProcess(ar=np.r_[1.0, -self.ar]).acf(lags + 1)
        phi = np.interp(gains, np.arange(lags + 1), acf, right=0.0)
        scale = 1.0 / np.maximum(gains, 1.0)
        after = np.append(scale[1:], scale[-1])
        coefficient = phi * after / scale
        innovation = after * sd * np.sqrt(np.maximum(1.0 - phi**2, 0.0))
        return coefficient, innovation

    @classmethod
    def from_bank(
        cls,
        bank: TraceBank,
        dt_s: float,
        nominal: NominalModel,
        *,
        max_order: int = MAX_ORDER,
        drift_sd: float = 0.01,
    ) -> Turbulence:
        """Fit to the traces of ``bank`` (the *train* split) on the ``dt_s`` grid.

        Each trace is averaged over blocks of ``dt_s`` (the env holds ``u_d``
        per sample; a control step sees the block's mean), its mean removed,
        and the AR coefficients of orders 1..``max_order`` are fitted by
        pooled least squares; the order of smallest AIC is kept.  The offset's
        prior SD is the spread of the traces' rockets' θ̄ about ``nominal``'s
        and of the traces' means, together.
        """
        if len(bank) == 0:
            raise ValueError(f"{bank.description} has no traces to fit the turbulence to")
        series = []
        offsets = []
        for trace, params in zip(bank.traces, bank.params, strict=True):
            per = dt_s / trace.dt_s
            if abs(per - round(per)) > 1e-9 * per or round(per) < 1:
                raise ValueError(
                    f"trace {trace.uid}: Δt {trace.dt_s:g} s does not divide the control step "
                    f"{dt_s:g} s"
                )
            u = np.asarray(trace.u_d_deg, dtype=float)
            k = round(per)
            u = u[: u.size // k * k].reshape(-1, k).mean(axis=1)
            offsets.append(params.theta_bar_deg + u.mean() - nominal.theta_bar_deg)
            series.append(u - u.mean())
        best: tuple[float, FloatArray, float] | None = None
        for p in range(1, max_order + 1):
            rows = [
                np.column_stack([s[p - 1 - i : s.size - 1 - i] for i in range(p)]) for s in series
            ]
            x = np.vstack(rows)
            y = np.concatenate([s[p:] for s in series])
            coef, *_ = np.linalg.lstsq(x, y, rcond=None)
            var = float(np.mean((y - x @ coef) ** 2))
            aic = y.size * math.log(var) + 2 * (p + 1)
            if best is None or aic < best[0]:
                best = (aic, coef, var)
        assert best is not None
        _, coef, var = best
        return cls(
            ar=coef,
            innovation_sd=math.sqrt(var),
            offset_sd=float(np.sqrt(np.mean(np.square(offsets)))),
            drift_sd=drift_sd,
            dt_s=dt_s,
            source=f"AR({coef.size}) fitted to {bank.description}",
        )


class RollObserver:
    """Kalman filter on ``[v, ψ, u_d[k], ..., u_d[k-p+1], b]`` from the flight sensors.

    ``v`` roll rate (°/s); ``ψ`` roll angle minus the setpoint (°, angle task;
    in the rate task the angle is not measured and ``ψ`` is not used);
    ``u_d[k]`` the AR part of the turbulence acting over the coming control
    step (after :meth:`update` its estimate is the AR prediction), then its
    lags; ``b`` the offset.  :attr:`u_d` is ``û_d[k] + b̂``, the estimate of
    what the coming step will meet; :attr:`u_d_last` the smoothed-by-one
    estimate of what the last step met.

    Parameters
    ----------
    rocket : RollParams
        The nominal rocket (eq. 49).
    turbulence : Turbulence
        The turbulence model on the control grid.
    config : RollConfig
        The environment's settings: control step, servo, sensors, task.
    scales : ndarray, shape (steps, 2), optional
        In flight: the rocket's gain and damping multipliers at each control step
        (:attr:`rollenv.flight.FlightSchedule.scales`, eq. 4-8); the filter's model at
        step ``k`` is ``rocket`` carried there (:meth:`rocket_at`), and its turbulence
        ``turbulence`` flown there (:meth:`Turbulence.flown`: an AR(1) per step).  The
        step is counted from :meth:`reset`, as the scheduled PID counts it.
    """

    def __init__(
        self,
        rocket: RollParams,
        turbulence: Turbulence,
        config: RollConfig,
        scales: FloatArray | None = None,
    ) -> None:
        if abs(turbulence.dt_s - config.dt_s) > 1e-9:
            raise ValueError(
                f"the turbulence model's grid ({turbulence.dt_s:g} s) is not the control "
                f"step ({config.dt_s:g} s)"
            )
        self.rocket = rocket
        self.turbulence = turbulence
        self._scaled = None if scales is None else [rocket.scaled(g, d) for g, d in scales]
        self.per = round(config.dt_s / config.substep_s)
        self.h = config.substep_s
        self.max_move = config.rate_limit_dps * config.substep_s
        self.fin_range = config.fin_range_deg
        self.angle_task = config.task == "angle"
        self.count = config.encoder_resolution_deg if config.sensors else 0.0
        self.gyro_var = (config.gyro_noise_pct / 100.0) ** 2 if config.sensors else 0.0
        # At least two lags, so the last step's u_d is a state (an AR(1) gets a zero a_2).
        self.ar = np.pad(turbulence.ar, (0, max(0, 2 - turbulence.order)))
        self._flown: tuple[FloatArray, FloatArray] | None = None
        if scales is not None:  # in flight: an AR(1) per step, two lags kept
            self._flown = turbulence.flown(np.asarray(scales)[:, 0])
            self.ar = np.array([self._flown[0][0], 0.0])
        p = self.ar.size
        self.m = 3 + p
        self.bias = self.m - 1
        self.state_cov = np.zeros((self.m, self.m))
        self.state_cov[2, 2] = turbulence.innovation_sd**2
        innovation = turbulence.innovation_sd if self._flown is None else self._flown[1][0]
        self.state_cov[self.bias, self.bias] = turbulence.drift_sd**2
        self._prior_cov = np.zeros((self.m, self.m))
        self._prior_cov[0, 0] = 1e4
        self._prior_cov[1, 1] = _DIFFUSE
        self._prior_cov[2 : 2 + p, 2 : 2 + p] = stationary_cov(self.ar, innovation)
        self._prior_cov[self.bias, self.bias] = turbulence.offset_sd**2
        self._gyro = np.array([0], dtype=np.intp)
        self._y = np.zeros(1)
        self._var = np.zeros(1)
        self._gains = np.zeros((1, self.m))
        self._work = np.zeros((self.m + 1, self.m))
        self._fin = np.zeros(self.per + 1)
        self.reset()

    def reset(self) -> None:
        """Back to the prior: nothing measured yet."""
        self.mean = np.zeros(self.m)
        self.cov = self._prior_cov.copy()
        self.steps = 0
        self.setpoint_steps = 0

    # ---------------------------------------------------------------- filter
    def fin_path(self, fin_deg: float, command_deg: float) -> FloatArray:
        """The fin angle at each substep boundary of one control step (the env's servo)."""
        command = min(max(command_deg, -self.fin_range), self.fin_range)
        reach = self.max_move * np.arange(self.per + 1)
        np.clip(command - fin_deg, -reach, reach, out=self._fin)
        self._fin += fin_deg
        return self._fin

    def rocket_at(self, step: int) -> RollParams:
        """The filter's rocket at control step ``step`` (the nominal one in the tunnel)."""
        if self._scaled is None:
            return self.rocket
        return self._scaled[min(max(step, 0), len(self._scaled) - 1)]

    def ar_at(self, step: int) -> tuple[FloatArray, float]:
        """The turbulence's AR coefficients and innovation SD over control step ``step``."""
        if self._flown is None:
            return self.ar, self.turbulence.innovation_sd
        k = min(max(step, 0), self._flown[0].size - 1)
        return np.array([self._flown[0][k], 0.0]), float(self._flown[1][k])

    def step_model(
        self,
        fin_deg: float,
        command_deg: float,
        rocket: RollParams | None = None,
        ar: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """``T``, ``c`` of one control step that starts with the fin at ``fin_deg``
        (under ``rocket`` and turbulence ``ar``; default: the nominal ones)."""
        model = self.rocket if rocket is None else rocket
        maps = interval_maps(model, self.fin_path(fin_deg, command_deg), self.per, self.h)
        t_roll, c_roll = roll_transition(maps, self.ar if ar is None else ar)
        t = np.zeros((self.m, self.m))
        c = np.zeros(self.m)
        t[:-1, :-1] = t_roll[0]
        c[:-1] = c_roll[0]
        t[:, self.bias] = t[:, 2]  # b acts where u_d does ...
        t[2:, self.bias] = 0.0  # ... but is no part of the AR recursion
        t[self.bias, self.bias] = 1.0
        return t, c

    def predict(self, fin_deg: float, command_deg: float) -> None:
        """Time update over the control step just taken (fin at its start, the command)."""
        step = self.steps - 1
        ar, innovation = self.ar_at(step)
        t, c = self.step_model(fin_deg, command_deg, self.rocket_at(step), ar)
        self.state_cov[2, 2] = innovation**2
        predict(self.mean, self.cov, t, c, self.state_cov, self._work)

    def update(self, obs: NDArray[np.float32]) -> None:
        """Measurement update with one observation (the env's ``Obs`` layout): the gyro,
        then (angle task) the encoder."""
        self._y[0] = float(obs[Obs.RATE])
        self._var[0] = self.gyro_var * (self.mean[0] ** 2 + self.cov[0, 0]) + _VAR_FLOOR
        update(self.mean, self.cov, self._y, self._gyro, self._var, self._gains)
        if self.angle_task:
            self._encoder(-float(obs[Obs.ERROR]))
        self.steps += 1

    def _encoder(self, reading: float) -> None:
        """The encoder's update: ``reading = φ_q - setpoint`` with ``φ_q`` the angle
        floored to a count, so ``ψ`` lies in ``[reading, reading + q)``.

        The prior of ``ψ`` is truncated to that interval and its mean and
        variance matched (the assumed-density update for a quantised
        measurement; the rest of the state follows through its regression on
        ``ψ``).  Unlike the white-noise model ``q²/12`` this knows that a
        reading that does not change pins the angle to one count, and that a
        count edge crossed is sharp.  A reading the prior puts (almost) no
        mass on is a setpoint step: ``ψ`` is re-anchored on the count, the
        rest of the state kept.
        """
        q = self.count
        m, var = self.mean[1], self.cov[1, 1]
        lo = m + float(wrap_deg(reading - m))
        if q <= 0.0:  # no quantisation: an (almost) exact reading
            self._update_angle(lo, 0.0)
            return
        sd = math.sqrt(var)
        a, b = (lo - m) / sd, (lo + q - m) / sd
        mass = _normal_cdf(b) - _normal_cdf(a)
        if mass < _JUMP_MASS:
            if self.steps > 0:
                self.setpoint_steps += 1
            self.cov[1, 1] += _DIFFUSE
            sd = math.sqrt(self.cov[1, 1])
            a, b = (lo - m) / sd, (lo + q - m) / sd
            mass = _normal_cdf(b) - _normal_cdf(a)
        pa, pb = _normal_pdf(a), _normal_pdf(b)
        shift = (pa - pb) / mass
        mean_t = m + sd * shift
        var_t = sd * sd * max(1.0 + (a * pa - b * pb) / mass - shift * shift, 1e-6 / 12.0)
        self._update_angle(mean_t, var_t)

    def _update_angle(self, mean: float, var: float) -> None:
        """Set ``ψ``'s mean and variance, the rest of the state by its regression on ``ψ``."""
        p11 = self.cov[1, 1]
        gain = self.cov[:, 1] / p11
        self.mean += gain * (mean - self.mean[1])
        self.cov -= np.outer(gain, gain) * (p11 - max(var, _VAR_FLOOR))
        self.cov = 0.5 * (self.cov + self.cov.T)
        self.mean[1] = wrap_deg(self.mean[1])

    @property
    def u_d(self) -> float:
        """Estimate of ``u_d`` over the coming control step, ° (AR prediction plus offset)."""
        return float(self.mean[2] + self.mean[self.bias])

    @property
    def u_d_last(self) -> float:
        """Estimate of ``u_d`` over the control step just taken, ° (filtered: given the
        rate it left behind)."""
        return float(self.mean[3] + self.mean[self.bias])


def _normal_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2.0))


def _normal_pdf(x: float) -> float:
    return math.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)


# ----------------------------------------------------------------------------- control
#: LQR weights per task: the cost per step is ``ψ² + rate·v² + move·Δθ²`` (angle task)
#: or ``rate·(v - r)² + move·Δθ²`` (rate task).  Chosen on 20 train-split episodes of the
#: default replay (``setpoint=zero`` for the angle task) as the least RMS error whose fin
#: travel stays within the PID's on the same episodes: angle move 0.01 / 0.006 / 0.004
#: gave 0.56° / 0.51° / 0.48° at 40 / 45 / 49 °/s (PID 0.94° at 49 °/s), a rate weight
#: of 0.1 or 0.001 changed < 0.03°; rate task move 0.03 / 0.01 / 0.003 / 0.001 gave
#: settled 1.24 / 1.12 / 1.07 / 1.07 °/s at 43 / 55 / 69 / 78 °/s (PID 1.44 at 75).
DEFAULT_WEIGHTS: dict[str, dict[str, float]] = {
    "angle": {"rate": 0.01, "move": 0.005},
    "rate": {"rate": 1.0, "move": 0.003},
}
#: The weights in flight (scheduled), chosen on 20 train flights of each task: angle move
#: 0.005 / 0.2 / 1 / 3 / 10 / 30 / 100 gave 2.72° / 2.21 / 1.56 / 1.43 / 1.61 / 1.83 / 2.14
#: at 142 / 89 / 29 / 13 / 5.5 / 3.5 / 2.1 °/s of fin travel (at 0.005 the fins chatter at
#: the servo's rate limit: the rocket answers a fin 12x more strongly at top speed); rate
#: move 0.003 / 0.1 / 1 / 3 gave 3.70 / 3.72 / 3.82 / 3.93 °/s: the tunnel's weight stays.
FLIGHT_WEIGHTS: dict[str, dict[str, float]] = {
    "angle": {"rate": 0.01, "move": 3.0},
    "rate": {"rate": 1.0, "move": 0.003},
}


class ObserverController:
    """Disturbance-observer feedforward with LQR state feedback (module docstring)."""

    name = "observer"

    def __init__(
        self,
        config: RollConfig,
        rocket: NominalModel,
        turbulence: Turbulence,
        weights: dict[str, float] | None = None,
        *,
        scheduled: bool = False,
    ) -> None:
        self.config = config
        self.rocket = rocket
        self.turbulence = turbulence
        flight = config.flight_schedule if scheduled else None
        scales = None if flight is None else flight.scales[: config.max_episode_steps]
        self.observer = RollObserver(rocket.params, turbulence, config, scales)
        self.weights = {**DEFAULT_WEIGHTS[config.task], **(weights or {})}
        self._range = config.fin_range_deg
        self._angle = config.task == "angle"
        self.gain = self._design()
        #: In flight, scheduled: the LQR gain of each control step, designed on the
        #: nominal rocket carried to that step's airspeed and density -- held at the
        #: tunnel's airspeed below it (near apogee), as the scheduled PID's gains are.
        self.schedule: list[FloatArray] | None = None
        #: ... and each step's rocket and Riccati matrix (the MPC plans on them).
        self.rockets: list[RollParams] = []
        self.riccati_schedule: list[FloatArray] = []
        if scales is not None:
            held = np.maximum(scales[:, 0], 1.0)
            self.rockets = [
                rocket.params.scaled(speed, damping * speed / gain)
                for (gain, damping), speed in zip(scales, held, strict=True)
            ]
            self.schedule = []
            for k, scaled in enumerate(self.rockets):
                self.schedule.append(self._design(scaled, k))
                self.riccati_schedule.append(self.riccati)
            self._design()  # the nominal design's Riccati matrix stays the attribute
        self.reset()

    def design_model(
        self, rocket: RollParams | None = None, step: int | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The design's linear model and cost: ``A, B, Q, R, S`` of ``x⁺ = A x + B u`` and
        the stage cost ``x'Qx + u'Ru + 2x'Su`` (on ``rocket``, default the nominal one,
        and the turbulence of control ``step``, default the tunnel's).

        ``x = [v, ψ, u_d lags, b, θ + θ̄]`` (``ψ`` left out on the rate task)
        and ``u`` the command plus ``θ̄``.  The model is the observer's at trim
        with the fin as a state (the fin at the step's start), so the cost can
        weigh the move ``Δθ``.  The servo moves the fin at its rate limit and
        then holds it: the step's response is not linear in the move, and the
        design takes its secant over a typical move (one SD of the
        turbulence's innovation: what a cancelling fin moves per step), shared
        between the fin at the start and the command so a fin at rest keeps
        the exact gain.
        """
        obs = self.observer
        trim = -self.rocket.theta_bar_deg
        if step is None:
            ar, innovation = obs.ar, self.turbulence.innovation_sd
        else:
            ar, innovation = obs.ar_at(step)
        t_rest, c_rest = obs.step_model(trim, trim, rocket, ar)
        move = max(innovation, 0.1)
        _, c_moved = obs.step_model(trim, trim + move, rocket, ar)
        m = obs.m
        n = m + 1
        a = np.zeros((n, n))
        a[:m, :m] = t_rest
        # The offset is constant, uncontrollable and so not stabilisable: designed as a
        # very slow AR(1) instead, its gain is that of a persistent disturbance.
        a[obs.bias, obs.bias] = _OFFSET_POLE
        b = np.zeros((n, 1))
        for row in (0, 1):  # rate, angle: command share by the secant, the rest on the fin
            to_command = (c_moved[row] - c_rest[row]) / move
            b[row, 0] = to_command
            a[row, m] = t_rest[row, 2] - to_command
        b[m, 0] = 1.0
        q = np.zeros((n, n))
        w = self.weights
        if self._angle:
            q[1, 1] = 1.0
        q[0, 0] = w["rate"]
        # the move Δθ = command - fin state: cost move·(u - x_fin)², a cross term
        r = np.array([[w["move"]]])
        s = np.zeros((n, 1))
        s[m, 0] = -w["move"]
        q[m, m] += w["move"]
        if not self._angle:  # ψ is not used in the rate task: leave it out of the design
            keep = self.design_states
            a, b, q, s = a[np.ix_(keep, keep)], b[keep], q[np.ix_(keep, keep)], s[keep]
        return a, b, q, r, s

    @property
    def design_states(self) -> list[int]:
        """Indices of the design's states in ``[v, ψ, u_d lags, b, θ + θ̄]``."""
        n = self.observer.m + 1
        return [i for i in range(n) if self._angle or i != 1]

    def _design(self, rocket: RollParams | None = None, step: int | None = None) -> FloatArray:
        """LQR gain on ``[v, ψ, u_d lags, b, θ + θ̄]`` with the command as the input
        (:meth:`design_model` on ``rocket`` at ``step``; zero on ``ψ`` in the rate task)."""
        a, b, q, r, s = self.design_model(rocket, step)
        x = linalg.solve_discrete_are(a, b, q, r, s=s)
        self.riccati = x
        k = np.linalg.solve(r + b.T @ x @ b, b.T @ x @ a + s.T)
        gain = -k[0]
        if not self._angle:
            gain = np.insert(gain, 1, 0.0)
        return np.asarray(gain)

    def design_state(self, obs: NDArray[np.float32]) -> tuple[FloatArray, float]:
        """The filter's update with ``obs``, then the design's state (full layout) and the
        shift ``θ̄ - offset`` from design input to fin command (``command = u - shift``)."""
        ob = self.observer
        if self._last is not None:
            ob.predict(*self._last)
        ob.update(obs)
        return self.state_of(obs)

    def state_of(self, obs: NDArray[np.float32]) -> tuple[FloatArray, float]:
        """The design's state and shift (:meth:`design_state`) of the filter as it stands,
        after its update with ``obs``."""
        ob = self.observer
        fin = float(obs[Obs.FIN])
        x = ob.mean.copy()
        theta_bar = self.rocket.theta_bar_deg
        if self._angle:
            offset = 0.0
        else:
            setpoint = float(obs[Obs.ERROR]) + float(obs[Obs.RATE])
            x[0] -= setpoint
            offset = setpoint / ob.rocket_at(ob.steps - 1).alpha
        shift = theta_bar - offset
        return np.append(x, fin + shift), shift

    def command(self, state: FloatArray, shift: float, fin: float) -> float:
        """The fin command of the design's state (LQR), clipped to the fin's range."""
        command = float(self.gain @ state) - shift
        return min(max(command, -self._range), self._range)

    def reset(self, env: FlightView | None = None) -> None:
        """A new episode: the observer back to its prior."""
        self.observer.reset()
        self._last: tuple[float, float] | None = None

    @property
    def schedule_step(self) -> int:
        """In flight: the control step the filter has reached (the schedule's last after
        its end)."""
        assert self.schedule is not None
        return min(max(self.observer.steps - 1, 0), len(self.schedule) - 1)

    def follow_schedule(self) -> None:
        """In flight: the gain of the control step the filter has reached."""
        if self.schedule is not None:
            self.gain = self.schedule[self.schedule_step]

    def act(self, obs: NDArray[np.float32], env: FlightView | None = None) -> NDArray[np.float32]:
        """The fin command for observation ``obs``."""
        state, shift = self.design_state(obs)
        self.follow_schedule()
        fin = float(obs[Obs.FIN])
        command = self.command(state, shift, fin)
        self._last = (fin, command)
        return np.array([command / self._range], dtype=np.float32)


class ObserverFeatures:
    """The observer's estimate as extra observation values for a learned policy, and
    (``residual > 0``) the observer controller's command as the base its action adds to.

    One :class:`RollObserver` per environment, designed on the train split as
    the observer controller is; per step the filter takes the observation (and
    the step the last command made) and yields ``[v̂, ψ̂, û_d]`` (``ψ̂`` is 0 on
    the rate task, where no encoder anchors it).  Used by
    :class:`agents.vecenv.VecObserver` in training and by the learned
    controller when acting, the same code in both.

    With ``residual`` the filters are those of one :class:`ObserverController`
    per environment, and the action a policy chooses is a *residual* (Silver
    et al. 2018, "Residual policy learning"; Johannink et al. 2019): the fin
    command applied is the observer controller's plus ``residual`` × the
    action (both as fractions of the fin's range), clipped to the range
    (:meth:`record` returns it).  A policy whose action is 0 is the observer
    controller, so learning starts from it instead of from nothing.

    In flight (a config with a flight schedule) the filters and the controllers are
    scheduled as :func:`make_observer`'s, designed on the *tunnel's* train traces
    (:meth:`from_bank` takes those) with :data:`FLIGHT_WEIGHTS`; the per-step design
    is made once and shared by the environments.
    """

    SIZE = 3

    def __init__(
        self,
        config: RollConfig,
        rocket: NominalModel,
        turbulence: Turbulence,
        n: int,
        residual: float = 0.0,
    ):
        if not (math.isfinite(residual) and 0.0 <= residual <= 1.0):
            raise ValueError(f"residual must be a number in [0, 1], got {residual!r}")
        self._range = config.fin_range_deg
        self._angle = config.task == "angle"
        self.residual = float(residual)
        self.controllers: list[ObserverController] = []
        # One design (in flight: one per control step), copied: each env its own filter.
        first = ObserverController(config, rocket, turbulence, **scheduling(config))
        if residual:
            self.controllers = [first] + [_clone(first) for _ in range(n - 1)]
            self.filters = [c.observer for c in self.controllers]
        else:
            self.filters = [first.observer] + [copy.deepcopy(first.observer) for _ in range(n - 1)]
        self._last: list[tuple[float, float] | None] = [None] * n
        #: The observer controller's command per env for the coming step, fraction of the range.
        self.base = np.zeros(n)

    @classmethod
    def from_bank(
        cls, config: RollConfig, train_bank: TraceBank, n: int, residual: float = 0.0
    ) -> ObserverFeatures:
        """Designed on ``train_bank`` (the *train* split; in flight, its tunnel traces:
        :func:`agents.base.design_bank`), for ``n`` environments."""
        return cls(config, *designed_on(train_bank, config), n, residual)

    def clear(self, i: int | None = None) -> None:
        """A new episode for env ``i`` (all by default)."""
        for k in range(len(self.filters)) if i is None else (i,):
            self.filters[k].reset()
            self._last[k] = None

    def one(self, i: int, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        """Env ``i``'s filter takes ``obs``; its features (and, residual, the base command)."""
        f = self.filters[i]
        last = self._last[i]
        if last is not None:
            f.predict(*last)
        f.update(obs)
        if self.controllers:
            controller = self.controllers[i]
            state, shift = controller.state_of(obs)
            controller.follow_schedule()
            fin = float(obs[Obs.FIN])
            self.base[i] = controller.command(state, shift, fin) / self._range
        psi = float(f.mean[1]) if self._angle else 0.0
        return np.array([f.mean[0], psi, f.u_d], dtype=np.float32)

    def record(self, obs: NDArray[np.float32], actions: NDArray[np.float32]) -> NDArray[np.float32]:
        """The step each env is about to take, from the policy's ``actions``: the fin it
        starts from and the command applied, which is returned (the actions themselves,
        clipped to [-1, 1], or with ``residual`` the base command plus the residual)."""
        actions = np.clip(np.asarray(actions, dtype=np.float64).reshape(len(self.filters)), -1, 1)
        if self.controllers:
            actions = np.clip(self.base + self.residual * actions, -1.0, 1.0)
        for i in range(len(self.filters)):
            self._last[i] = (float(obs[i, Obs.FIN]), float(actions[i]) * self._range)
        return actions.astype(np.float32).reshape(-1, 1)


def _clone(controller: ObserverController) -> ObserverController:
    """Another controller of the same design (gains shared, read only) with its own filter."""
    twin = copy.copy(controller)
    twin.observer = copy.deepcopy(controller.observer)
    twin.reset()
    return twin


def designed_on(bank: TraceBank, config: RollConfig) -> tuple[NominalModel, Turbulence]:
    """The nominal rocket and the turbulence model a design fits to ``bank``'s traces."""
    nominal = NominalModel.from_bank(bank)
    return nominal, Turbulence.from_bank(bank, config.dt_s, nominal)


def scheduling(config: RollConfig) -> dict[str, Any]:
    """An observer-based controller's ``weights`` and ``scheduled`` for ``config``: in
    flight, scheduled with :data:`FLIGHT_WEIGHTS`; in the tunnel, the defaults."""
    if config.flight_schedule is None:
        return {"weights": None, "scheduled": False}
    return {"weights": FLIGHT_WEIGHTS[config.task], "scheduled": True}


def make_observer(design: Design) -> ObserverController:
    """``--policy observer``: designed on the train split's nominal rocket and turbulence.

    In flight it is scheduled: its filter's rocket and its LQR gain follow the flight's
    airspeed and density step by step, and its turbulence model (fitted, as in the tunnel,
    to the train split's tunnel traces) is flown by the env's law: each step's AR(1)
    coefficient and amplitude follow the airspeed (:meth:`Turbulence.flown`)."""
    design.no_argument("observer")
    nominal, turbulence = designed_on(design.design_bank, design.config)
    return ObserverController(
        config=design.config, rocket=nominal, turbulence=turbulence, **scheduling(design.config)
    )
