"""The observer's estimator: the turbulence model fitted to the train split and the Kalman
filter that runs the identification's state-space model forward in real time (the
package's docstring)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from statsmodels.tsa.arima_process import ArmaProcess

from agents.nominal import NominalModel
from disturbances.bank import TraceBank
from identification.compiled import interval_maps
from identification.estimation.likelihood import select_order
from identification.estimation.statespace import predict, update
from identification.methods.ml import MAX_ORDER
from identification.methods.rollspace import roll_transition, stationary_cov
from identification.model import Rig, RollParams, linkage_step
from rocketroll_common.arrays import FloatArray
from rollenv.config import RollConfig
from rollenv.core import wrap_deg
from rollenv.layout import Obs

#: Variance floor of a measurement (an ideal sensor stays regular), as in the ML.
_VAR_FLOOR = 1e-8
#: Variance added to the angle when a setpoint step is detected, °²: the reading decides.
_DIFFUSE = 1e6
#: Pole the LQR design gives the (constant) offset state.
OFFSET_POLE = 0.9999
#: A reading on which the prior puts less probability than this is a setpoint step.
_JUMP_MASS = 1e-9


@dataclass(frozen=True)
class TurbulenceModel:
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
            raise ValueError(
                f"TurbulenceModel.ar must be one or more finite numbers, got {self.ar!r}"
            )
        if not ArmaProcess(ar=np.r_[1.0, -ar]).isstationary:
            raise ValueError(f"TurbulenceModel.ar {ar.tolist()} is not stationary")
        for name in ("innovation_sd", "offset_sd", "drift_sd", "dt_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"TurbulenceModel.{name} must be a number >= 0, got {value!r}")
        object.__setattr__(self, "ar", ar)

    @property
    def order(self) -> int:
        return int(self.ar.size)

    def flown(self, gains: FloatArray) -> tuple[FloatArray, FloatArray]:
        """This (tunnel) turbulence flown along a flight, as an AR(1) per control step.

        ``gains`` are the flight's ``V/V_ref`` per control step (:mod:`rollenv.flight`).
        The flight env flies the tunnel's traces time-compressed by ``V/V_ref`` and
        scaled by ``V_ref/max(V, V_ref)`` (:mod:`rocketroll_physics.flown`), so from one
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
    ) -> TurbulenceModel:
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

        def pooled(p: int) -> tuple[float, tuple[FloatArray, float]]:
            rows = [
                np.column_stack([s[p - 1 - i : s.size - 1 - i] for i in range(p)]) for s in series
            ]
            x = np.vstack(rows)
            y = np.concatenate([s[p:] for s in series])
            coef, *_ = np.linalg.lstsq(x, y, rcond=None)
            var = float(np.mean((y - x @ coef) ** 2))
            return y.size * math.log(var) + 2 * (p + 1), (coef, var)

        _, _, (coef, var) = select_order(pooled, range(1, max_order + 1))
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
    turbulence : TurbulenceModel
        The turbulence model on the control grid.
    config : RollConfig
        The environment's settings: control step, servo, sensors, task.
    scales : ndarray, shape (steps, 2), optional
        In flight: the rocket's gain and damping multipliers at each control step
        (:attr:`rollenv.flight.FlightSchedule.scales`, eq. 4-8); the filter's model at
        step ``k`` is ``rocket`` carried there (:meth:`rocket_at`), and its turbulence
        ``turbulence`` flown there (:meth:`TurbulenceModel.flown`: an AR(1) per step).  The
        step is counted from :meth:`reset`, as the scheduled PID counts it.
    airspeed_ratio : ndarray, shape (steps,), optional
        With ``scales``: the flight's ``V/V_ref`` per step, which the turbulence is flown
        by (:attr:`rollenv.flight.FlightSchedule.airspeed_ratio`; default the gain of
        ``scales``, which it is for the tunnel's rocket by eq. 4-8).
    rig : Rig, optional
        The servo's linkage and the sensors' latency the filter expects (default: the
        model's ideal rig).  With a linkage the filter runs the servo and the fin's
        drive forward from its own commands (:func:`~identification.model.linkage_step`,
        the environment's), the fin starting each step where the observation reports
        it.  With a latency the filter's state is the rocket's when the sensors read it,
        ``latency_s`` (rounded to a substep) ago: each time update is over the control
        step that far back, the fin path taken from the commands' history, and
        :meth:`present` carries the estimate to now over the fin path since.
    """

    def __init__(
        self,
        rocket: RollParams,
        turbulence: TurbulenceModel,
        config: RollConfig,
        scales: FloatArray | None = None,
        airspeed_ratio: FloatArray | None = None,
        rig: Rig | None = None,
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
        #: Whether the angle is the flight computer's sum of the gyro's readings: exact at
        #: launch, its error then a random walk of the gyro's noise (:attr:`walk`).
        self.summed = config.angle_sensor == "gyro"
        # At least two lags, so the last step's u_d is a state (an AR(1) gets a zero a_2).
        self.ar = np.pad(turbulence.ar, (0, max(0, 2 - turbulence.order)))
        self._flown: tuple[FloatArray, FloatArray] | None = None
        if scales is not None:  # in flight: an AR(1) per step, two lags kept
            speeds = np.asarray(scales)[:, 0] if airspeed_ratio is None else airspeed_ratio
            self._flown = turbulence.flown(np.asarray(speeds))
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
        self.rig = Rig() if rig is None else rig
        #: Whether a linkage lies between servo and fin; its ``(decay, ramp, half)`` per substep.
        self.linked = not self.rig.linkage.direct
        self._link = self.rig.linkage.coefficients(self.h)
        #: The sensors' latency, substeps.
        self.delay = round(self.rig.latency_s / self.h)
        self.reset()

    def reset(self) -> None:
        """Back to the prior: nothing measured yet."""
        self.mean = np.zeros(self.m)
        self.cov = self._prior_cov.copy()
        self.steps = 0
        self.setpoint_steps = 0
        #: The variance of the summed gyro's error so far, °² (0 at launch; flight only).
        self.walk = 0.0
        #: With a linkage: the servo and the fin's drive now (None: at rest on the first fin).
        self._servo: tuple[float, float] | None = None
        #: With a latency: the fin at the last ``per + delay + 1`` substep boundaries, to now.
        self._fins: FloatArray | None = None

    # ---------------------------------------------------------------- filter
    def fin_path(
        self,
        fin_deg: float,
        command_deg: float,
        servo_deg: float | None = None,
        drive_deg: float | None = None,
        *,
        play: bool = True,
    ) -> FloatArray:
        """The fin angle at each substep boundary of one control step (the env's servo;
        with a linkage, its servo and drive starting at ``servo_deg`` and ``drive_deg``,
        default at rest on the fin, the play left out with ``play=False``)."""
        if self.linked:
            return self._linked(fin_deg, command_deg, servo_deg, drive_deg, play)[0]
        command = min(max(command_deg, -self.fin_range), self.fin_range)
        reach = self.max_move * np.arange(self.per + 1)
        np.clip(command - fin_deg, -reach, reach, out=self._fin)
        self._fin += fin_deg
        return self._fin

    def _linked(
        self,
        fin: float,
        command: float,
        servo: float | None = None,
        drive: float | None = None,
        play: bool = True,
    ) -> tuple[FloatArray, float, float]:
        """The fin path of one control step through the linkage towards ``command``
        (within the fin's range), and the servo and drive at its end."""
        decay, ramp, half = self._link
        command = min(max(command, -self.fin_range), self.fin_range)
        servo = fin if servo is None else servo
        drive = fin if drive is None else drive
        half = half if play else 0.0
        self._fin[0] = fin
        for k in range(self.per):
            servo, drive, fin = linkage_step(
                servo, drive, fin, command, self.max_move, decay, ramp, half
            )
            self._fin[k + 1] = fin
        return self._fin, servo, drive

    def drive_after(self, servo_deg: float, drive_deg: float, command_deg: float) -> float:
        """The fin's drive after one control step from ``servo_deg`` and ``drive_deg``
        towards ``command_deg`` (the linkage's lag alone)."""
        return self._linked(drive_deg, command_deg, servo_deg, drive_deg, play=False)[2]

    def servo(self, fin_deg: float) -> float:
        """Where the servo is now (the fin ``fin_deg`` itself without a linkage)."""
        return fin_deg if self._servo is None else self._servo[0]

    def drive(self, fin_deg: float) -> float:
        """Where the fin's drive is now (the fin ``fin_deg`` itself without a linkage)."""
        return fin_deg if self._servo is None else self._servo[1]

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
        return self.path_model(self.fin_path(fin_deg, command_deg), rocket, ar)

    def path_model(
        self, path: FloatArray, rocket: RollParams | None = None, ar: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """``T``, ``c`` of one control step over the fin ``path`` (:meth:`step_model`)."""
        model = self.rocket if rocket is None else rocket
        maps = interval_maps(model, path, self.per, self.h)
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
        if self.linked or self.delay:
            t, c = self.path_model(self._advance(fin_deg, command_deg), self.rocket_at(step), ar)
        else:
            t, c = self.step_model(fin_deg, command_deg, self.rocket_at(step), ar)
        self.state_cov[2, 2] = innovation**2
        predict(self.mean, self.cov, t, c, self.state_cov, self._work)

    def _advance(self, fin_deg: float, command_deg: float) -> FloatArray:
        """With a linkage or a latency: the fin path of the step just taken (the linkage
        run on from where it stood), and the path the time update is over (that step's,
        or, with a latency, the step ``delay`` substeps earlier)."""
        if self.linked:
            path, servo, drive = self._linked(fin_deg, command_deg, *(self._servo or (None, None)))
            self._servo = (servo, drive)
        else:
            path = self.fin_path(fin_deg, command_deg)
        if not self.delay:
            return path
        if self._fins is None:  # at rest on the first fin before the episode
            self._fins = np.full(self.per + self.delay + 1, fin_deg)
        self._fins = np.concatenate([self._fins[self.per : -1], [fin_deg], path[1:]])
        return self._fins[: self.per + 1]

    def present(self, fin_deg: float) -> FloatArray:
        """The state's estimate now: the filter's mean, and with a latency carried to now.

        The filter's steps lag the control steps by ``delay`` substeps, so its ``u_d``
        states are those of ``round(delay / per)`` control steps back: they are carried
        that many steps ahead by the AR model's mean, and the rate and angle over the last
        ``delay`` substeps' fin path with ``u_d`` held at the control step just taken's
        (``fin_deg``, the fin now, is the path before the first step)."""
        mean = self.mean.copy()
        if not self.delay:
            return mean
        p = self.ar.size
        lags = mean[2 : 2 + p]
        last = self.steps - 2  # the control step just taken (its update counted)
        ar = self.ar_at(last)[0]
        for _ in range(round(self.delay / self.per)):
            lags = np.concatenate([[ar @ lags], lags[:-1]])
        mean[2 : 2 + p] = lags
        path = np.full(self.delay + 1, fin_deg) if self._fins is None else self._fins[self.per :]
        e, g, f, a, b, c = interval_maps(self.rocket_at(last), path, self.delay, self.h)[0]
        u = lags[1] + mean[self.bias]  # the control step just taken's
        mean[0], mean[1] = e * mean[0] + g * u + f, mean[1] + a * mean[0] + b * u + c
        mean[1] = wrap_deg(mean[1])
        return mean

    def update(self, obs: NDArray[np.float32]) -> None:
        """Measurement update with one observation (the env's ``Obs`` layout): the gyro,
        then (angle task) the encoder, or in flight the summed gyro."""
        noise = self.gyro_var * (self.mean[0] ** 2 + self.cov[0, 0])  # the gyro's, °²/s²
        if self.summed:  # the step's reading of the gyro, summed: its noise in the angle
            self.walk += (self.per * self.h) ** 2 * noise
        self._y[0] = float(obs[Obs.RATE])
        self._var[0] = noise + _VAR_FLOOR
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
        if self.summed:  # the summed gyro: the angle plus the walk of its noise so far
            noise = max(self.walk, _VAR_FLOOR)
            if math.erfc(abs(lo - m) / math.sqrt(2.0 * (var + noise))) < _JUMP_MASS:
                if self.steps > 0:  # a reading the prior cannot have made: a setpoint step
                    self.setpoint_steps += 1
                self.cov[1, 1] += _DIFFUSE
                var = self.cov[1, 1]
            gain = var / (var + noise)
            self._update_angle(m + gain * (lo - m), var * noise / (var + noise))
            return
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
