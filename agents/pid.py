"""A discrete PID roll controller with gains placed on the identified roll model.

Re-tuning for another database (``rocketroll tune pid --db FILE``,
:mod:`agents.tune`) takes the nominal rocket of that database's train split,
sweeps the closed-loop bandwidth ω over train-split episodes of the
evaluation protocol and prints the gains of the best ω; pass it back with
``rocketroll eval --policy pid:OMEGA``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agents.base import Design, FlightView
from agents.nominal import NominalModel
from rollenv.config import RollConfig
from rollenv.layout import Obs

__all__ = [
    "DEFAULT_BANDWIDTH",
    "FLIGHT_BANDWIDTH",
    "PIDController",
    "PIDGains",
    "check_omega",
    "make_pid",
    "make_tunnel_pid",
]

#: Closed-loop bandwidth ω (rad/s) per task, chosen by :func:`agents.tune.tune_bandwidth`
#: on the default database's train split (docs: results/evaluation.md, the PID's gains).
DEFAULT_BANDWIDTH = {"angle": 2.5, "rate": 8.0}
#: The same for the scheduled PID in flight (``rocketroll tune pid --env-id
#: RocketRollFlight-v0`` and ``RocketRollFlightRate-v0``, 20 train episodes: 1.19° at ω = 6,
#: against 2.90° at the tunnel's 2.5; 4.54 °/s at ω = 3.5, flat from 3 to 4, against holding
#: the trim's 4.86).  The flying rocket is faster: a(t) grows to 12× the tunnel's, so
#: along most of the flight the rocket is faster than these designs and the rate feedback
#: is held at 0 (:meth:`PIDGains.place`).
FLIGHT_BANDWIDTH = {"angle": 6.0, "rate": 3.5}


@dataclass(frozen=True)
class PIDGains:
    """Gains of :class:`PIDController` and how they were obtained.

    The fin command (°) is ``θ_c = -θ̄ + k_ff·r + k_p·e + k_i·∫e dt - k_d·v``
    with ``e`` the tracking error, ``r`` the setpoint and ``v`` the
    (filtered) measured roll rate.

    Attributes
    ----------
    kp, ki, kd : float
        Proportional (°/° or °/(°/s)), integral (per s) and derivative (s,
        angle task only) gains.
    k_ff : float
        Setpoint feedforward (rate task: ``1/α``, the fin angle that holds a
        roll rate in steady state, eq. 16; angle task: 0).
    trim_deg : float
        Feedforward of the asymmetry, ``-θ̄``.
    tf_s : float
        Time constant of the first-order filter on the measured rate (0:
        none, the default).  With this gyro (2 % noise, eq. 52) a filter does
        not help: on 30 train episodes 0.02-0.2 s left the angle task's RMS
        error unchanged and made the rate task's worse (1.52 → 1.64-5.9 °/s,
        the lag); it is there for a noisier gyro.
    tt_s : float
        Anti-windup tracking time constant (back-calculation).
    omega, zeta : float
        The design: closed-loop poles of ``(s + ω)(s² + 2ζωs + ω²)`` (angle)
        or ``s² + 2ζωs + ω²`` (rate).
    model : NominalModel
        The rocket the gains were placed on.
    """

    kp: float
    ki: float
    kd: float
    k_ff: float
    trim_deg: float
    tf_s: float
    tt_s: float
    omega: float
    zeta: float
    model: NominalModel

    @classmethod
    def place(
        cls,
        model: NominalModel,
        task: str,
        omega: float | None = None,
        zeta: float = 1.0,
        tf_s: float = 0.0,
        *,
        own_damping: bool = True,
    ) -> PIDGains:
        """Gains that put the closed-loop poles of the linearised rocket at ``-ω``.

        ``own_damping`` (default): where the rocket is faster than the design its rate
        gain is held at 0 (below); False places it as the algebra gives, of α's opposite
        sign there --
        for a planner's tail on the exact rocket (:mod:`agents.oracle`), which has no
        sample-and-hold, delay or noise for it to amplify.

        Notes
        -----
        About trim the roll model (eq. 36, 49) is linear with ``a = β̄``::

            dv/dt = -a·v + a·α·(θ + θ̄ + u_d),   dφ/dt = v.

        **Angle task.**  With ``θ = -θ̄ + k_p·e + k_i·∫e - k_d·v`` and
        ``e = r - φ`` (``r`` constant), the closed loop from ``r`` and
        ``u_d`` to ``φ`` has the characteristic polynomial::

            s³ + a(1 + α·k_d)·s² + a·α·k_p·s + a·α·k_i.

        Matching ``(s + ω)(s² + 2ζωs + ω²) = s³ + (1+2ζ)ω·s² + (1+2ζ)ω²·s + ω³``
        gives::

            k_d = ((1 + 2ζ)·ω/a - 1)/α,   k_p = (1 + 2ζ)·ω²/(a·α),   k_i = ω³/(a·α).

        The derivative acts on the measured rate (the gyro), so setpoint
        steps cause no derivative kick and nothing is differentiated
        numerically.  ``u_d`` enters where θ does, so the integral removes
        any constant part of it and any error in θ̄.

        **Rate task.**  With ``θ = -θ̄ + r/α + k_p·e + k_i·∫e``, ``e = r - v``::

            s² + a(1 + α·k_p)·s + a·α·k_i = s² + 2ζω·s + ω²
            ⇒ k_p = (2ζω/a - 1)/α,   k_i = ω²/(a·α).

        The feedforward ``r/α`` makes a setpoint step need no integral
        action in the nominal case.

        **A rocket faster than the design.**  Where ``a > 2ζω`` (rate) or
        ``a > (1 + 2ζ)ω`` (angle) -- in flight, where ``a`` grows to 12× the
        tunnel's -- the placed rate gain (``k_p`` of the rate loop, ``k_d``
        of the angle loop) would be of α's opposite sign: positive feedback of the
        measured rate, slowing the rocket to the design, which amplifies the
        turbulence and the gyro's noise through the 0.1-s sample-and-hold.
        That gain is held at 0 there: the rocket keeps its own damping and
        the other gains keep their placed values (on the flight rate task,
        20 train episodes at the tuned ω: 4.54 °/s against 5.48 placed
        unclamped at its own best ω and the trim's 4.86).

        **A negative gain.**  With an aileron convention where a positive fin rolls
        the rocket negative, α < 0 (θ̄ and ``u_d``, in fin degrees, change sign with
        it).  The loops above see α only through ``α·k``: every gain, the
        feedforward and the trim change sign with α, and the controller is the
        mirror image of the one for ``|α|`` -- the rate gain held at 0 by the sign of
        ``a·α·k``, the damping it adds, not by the gain's own.  The anti-windup
        tracking time is ``|T_t|``.

        ζ = 1 (default) makes the angle loop a triple pole: no overshoot in
        the linear range.  ω is limited by what the model leaves out: the
        0.1-s sample-and-hold (a delay of about 0.05 s), the servo's 150 °/s
        and the encoder's 1.4° quantisation, which the proportional and
        integral gains amplify; :func:`agents.tune.tune_bandwidth` picks it on train
        episodes.  The anti-windup tracking time is Åström's
        ``T_t = sqrt(T_i·T_d)`` (``T_i = k_p/k_i``, ``T_d = k_d/k_p``; ``T_i``
        without a derivative).

        References
        ----------
        K. J. Åström and R. M. Murray, *Feedback Systems*, 2nd ed., ch. 11
        (PID design by pole placement, integrator windup).
        """
        if task not in ("angle", "rate"):
            raise ValueError(f"task must be 'angle' or 'rate', got {task!r}")
        w = DEFAULT_BANDWIDTH[task] if omega is None else float(omega)
        if not math.isfinite(w) or w <= 0:
            raise ValueError(f"omega must be a positive number (rad/s), got {omega!r}")
        if not math.isfinite(zeta) or zeta <= 0:
            raise ValueError(f"zeta must be positive, got {zeta!r}")
        if not math.isfinite(tf_s) or tf_s < 0:
            raise ValueError(f"tf_s must be >= 0 (s), got {tf_s!r}")
        a, alpha = model.a_per_s, model.alpha
        if task == "angle":
            added = (1 + 2 * zeta) * w / a - 1  # the damping the rate feedback adds, per a
            kd = added / alpha if added > 0 or not own_damping else 0.0
            kp = (1 + 2 * zeta) * w * w / (a * alpha)
            ki = w**3 / (a * alpha)
            k_ff = 0.0
            ti = kp / ki
            tt = math.sqrt(ti * max(kd / kp, 0.0)) or ti
        else:
            kd = 0.0
            added = 2 * zeta * w / a - 1
            kp = added / alpha if added > 0 or not own_damping else 0.0
            ki = w * w / (a * alpha)
            k_ff = 1.0 / alpha
            tt = abs(kp / ki) or 1.0 / w
        return cls(kp, ki, kd, k_ff, -model.theta_bar_deg, tf_s, tt, w, zeta, model)


class PIDController:
    """Discrete PID on the sensors only (encoder error, gyro rate, fin angle).

    Per control step ``Δt``: the measured rate is low-pass filtered
    (backward Euler, time constant ``tf_s``), the command of
    :class:`PIDGains` is computed and clipped to the fin range, and the
    integral is advanced by ``Δt·e`` plus the back-calculation term
    ``Δt/T_t·(θ - θ_c)/k_i``, where ``θ`` is the fin angle the servo
    actually reached -- so both the range limit and the servo's rate limit
    stop the integral from winding up.

    The encoder floors the angle to its resolution ``q``: the true error lies
    in ``(e_meas - q, e_meas]``; the angle loop uses the middle,
    ``e_meas - q/2``, so it holds the rocket centred on the setpoint.
    """

    name = "PID"

    def __init__(
        self,
        gains: PIDGains,
        config: RollConfig,
        schedule: Sequence[PIDGains] | None = None,
    ) -> None:
        self.gains = gains
        self.config = config
        self.schedule = tuple(schedule) if schedule is not None else None
        self._dt = config.dt_s
        self._range = config.fin_range_deg
        self._angle = config.task == "angle"
        half_count = 0.5 * config.encoder_resolution_deg if config.sensors else 0.0
        self._offset = half_count if self._angle else 0.0
        self._beta = self._dt / (gains.tf_s + self._dt)
        self._aw = self._back_calculation(gains)
        self._aw_of = [self._back_calculation(g) for g in self.schedule or ()]
        self.reset()

    def _back_calculation(self, gains: PIDGains) -> float:
        """The anti-windup factor ``min(Δt/T_t, 1)/k_i`` of ``gains``: a tracking time
        shorter than the control step (a rate loop placed near the open-loop pole, where
        ``k_p`` nears 0) would overcorrect the integral each step and diverge; at most one
        step resets it fully.  Of ``k_i``'s sign, which is α's."""
        return min(self._dt / gains.tt_s, 1.0) / gains.ki if gains.ki else 0.0

    @classmethod
    def for_env(
        cls,
        config: RollConfig,
        model: NominalModel,
        omega: float | None = None,
        zeta: float = 1.0,
        tf_s: float = 0.0,
    ) -> PIDController:
        """Gains placed on ``model`` (:meth:`PIDGains.place`) for ``config``'s task."""
        return cls(PIDGains.place(model, config.task, omega, zeta, tf_s), config)

    @classmethod
    def scheduled(
        cls,
        config: RollConfig,
        model: NominalModel,
        omega: float | None = None,
        zeta: float = 1.0,
        tf_s: float = 0.0,
    ) -> PIDController:
        """Gains scheduled on the flight's dynamic pressure: at each control step the gains
        placed on ``model`` carried to that step's airspeed and density (``a·damping``,
        ``α·gain``, the env's own multipliers, :mod:`rollenv.flight`), so the closed-loop
        poles stay at ``-ω`` from 50 km/h to 600 km/h -- except where the flying rocket is
        faster than the design, whose rate gain is then held at 0 (:meth:`PIDGains.place`).

        The controller counts its control steps from ``reset``: a flight computer with a
        launch detector reading the nominal flight's schedule by time since launch.
        Below the tunnel's airspeed (the last seconds before apogee) the schedule holds the
        gains of ``V_ref`` at that altitude's density.  ``omega`` defaults to
        :data:`FLIGHT_BANDWIDTH`.  In the tunnel (no
        ``config.flight``) these are :meth:`for_env`'s fixed gains.
        """
        flight = config.flight_schedule
        if flight is None:
            return cls(PIDGains.place(model, config.task, omega, zeta, tf_s), config)
        if omega is None:
            omega = FLIGHT_BANDWIDTH[config.task]
        fixed = PIDGains.place(model, config.task, omega, zeta, tf_s)
        steps = flight.scales[: config.max_episode_steps]
        # Below the tunnel's airspeed (near apogee) the schedule freezes at V_ref: placed on
        # a vanishing a·α the gains would grow without bound where the fins have no
        # authority left; the density ratio rho/rho_ref = damping/gain is kept.
        held = np.maximum(steps[:, 0], 1.0)
        schedule = [
            PIDGains.place(
                dataclasses.replace(
                    model,
                    a_per_s=model.a_per_s * damping * speed / gain,
                    alpha=model.alpha * speed,
                ),
                config.task,
                omega,
                zeta,
                tf_s,
            )
            for (gain, damping), speed in zip(steps, held, strict=True)
        ]
        return cls(fixed, config, schedule)

    def reset(self, env: FlightView | None = None) -> None:
        """Zero the integral and the clock; the rate filter restarts from the next
        measurement."""
        self._integral = 0.0
        self._rate = math.nan
        self._command = math.nan
        self._step = 0

    def act(self, obs: NDArray[np.float32], env: FlightView | None = None) -> NDArray[np.float32]:
        """The fin command for observation ``(error, rate, fin, last command)``."""
        g, aw = self.gains, self._aw
        if self.schedule is not None:  # this control step's gains
            k = min(self._step, len(self.schedule) - 1)
            g, aw = self.schedule[k], self._aw_of[k]
        self._step += 1
        error = float(obs[Obs.ERROR]) - self._offset
        rate = float(obs[Obs.RATE])
        fin = float(obs[Obs.FIN])
        if math.isnan(self._rate):
            self._rate = rate
        else:
            self._rate += self._beta * (rate - self._rate)
            self._integral += aw * (fin - self._command)  # back-calculation
        if self._angle:
            raw = g.trim_deg + g.kp * error + g.ki * self._integral - g.kd * self._rate
        else:
            setpoint = float(obs[Obs.ERROR]) + rate  # e = r - v_meas
            error = setpoint - self._rate
            raw = g.trim_deg + g.k_ff * setpoint + g.kp * error + g.ki * self._integral
        command = min(max(raw, -self._range), self._range)
        self._integral += self._dt * error
        self._command = raw
        return np.array([command / self._range], dtype=np.float32)


def check_omega(policy: str, arg: str | None, env_id: str = "") -> float | None:
    """``OMEGA`` of ``--policy pid:OMEGA`` (or ``pid-tunnel:OMEGA``), a bandwidth in rad/s
    (None: the task's default); ``ValueError`` naming the value if it is not a positive
    number.  The registry's check, before any design."""
    if not arg:
        return None
    try:
        omega = float(arg)
    except ValueError:
        raise ValueError(f"--policy {policy}:OMEGA needs a number, got {policy}:{arg}") from None
    if not (math.isfinite(omega) and omega > 0):
        raise ValueError(
            f"--policy {policy}:OMEGA must be a positive bandwidth (rad/s), got {policy}:{arg}"
        )
    return omega


def _omega(design: Design, policy: str) -> float | None:
    return check_omega(policy, design.arg)


def make_pid(design: Design) -> PIDController:
    """``--policy pid[:OMEGA]``: gains placed on the train split's nominal rocket; in
    flight scheduled on the dynamic pressure (:meth:`PIDController.scheduled`)."""
    omega = _omega(design, "pid")
    model = NominalModel.from_bank(design.train_bank)
    pid = PIDController.scheduled(design.config, model, omega)
    if design.arg:
        pid.name = f"PID ω={omega:g}"
    return pid


def make_tunnel_pid(design: Design) -> PIDController:
    """``--policy pid-tunnel[:OMEGA]``: the tunnel's fixed gains, in flight too (the
    controller tuned in the tunnel and flown unchanged: the flight table's cautionary row)."""
    omega = _omega(design, "pid-tunnel")
    pid = PIDController.for_env(design.config, NominalModel.from_bank(design.train_bank), omega)
    pid.name = "PID, tunnel gains" + (f" ω={omega:g}" if design.arg else "")
    return pid
