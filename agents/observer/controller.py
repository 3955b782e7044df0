"""The observer controller: LQR state feedback on the estimate, scheduled in flight, and its
design from a train split."""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from agents.base import Design, FlightView
from agents.nominal import NominalModel
from agents.observer.estimator import OFFSET_POLE, RollObserver, TurbulenceModel
from disturbances.bank import TraceBank
from identification.model import RollParams
from rocketroll_common.arrays import FloatArray
from rollenv.config import RollConfig
from rollenv.flight import tunnel_frame
from rollenv.layout import Obs

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
#: The weights in flight (scheduled), chosen on 20 train flights of each task as in the
#: tunnel: angle move 3 / 0.3 / 0.03 / 0.01 / 0.003 / 0.001 / 0.0003 gave 1.45° / 1.20 /
#: 1.09 / 1.06 / 1.05 / 1.047 / 1.049 at 3.5 / 6.6 / 11 / 13 / 16 / 18 / 20 °/s of fin travel
#: (the PID 1.24° at 21 °/s).  Before the filter read the summed gyro as the noisy angle it
#: is (:attr:`~agents.observer.estimator.RollObserver.summed`) it took it for an exact one,
#: and a light move weight let the gyro's noise chatter the fins: 0.005 / 1 / 3 gave 2.72°
#: / 1.56 / 1.43 at 142 / 29 / 13 °/s.  Rate move 0.003 / 0.1 / 1 / 3 gave 3.70 / 3.72 /
#: 3.82 / 3.93 °/s: the tunnel's weight stays.
FLIGHT_WEIGHTS: dict[str, dict[str, float]] = {
    "angle": {"rate": 0.01, "move": 0.001},
    "rate": {"rate": 1.0, "move": 0.003},
}


class ObserverController:
    """Disturbance-observer feedforward with LQR state feedback (module docstring)."""

    name = "observer"

    def __init__(
        self,
        config: RollConfig,
        rocket: NominalModel,
        turbulence: TurbulenceModel,
        weights: dict[str, float] | None = None,
        *,
        scheduled: bool = False,
    ) -> None:
        self.config = config
        self.rocket = rocket
        self.turbulence = turbulence
        flight = config.flight_schedule if scheduled else None
        steps = config.max_episode_steps
        scales = None if flight is None else flight.scales[:steps]
        speeds = None if flight is None else flight.airspeed_ratio
        self.observer = RollObserver(
            rocket.params,
            turbulence,
            config,
            scales,
            None if speeds is None else speeds[:steps],
            rocket.rig,
        )
        #: Whether the design carries the fin's drive as a state (a servo lag).
        self._lagged = rocket.rig.lag_s > 0.0
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
        if scales is not None and speeds is not None and flight is not None:
            held = np.where(speeds[:steps] >= 1.0, scales[:, 0], flight.tunnel_gain)
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

        With a servo lag in the rocket's rig the fin's drive is one more state
        (``x = [..., θ_servo + θ̄, d + θ̄]``): the servo reaches the command and the
        drive follows it, each column the step's response to its state alone (the
        drive's exact, the command's by the secant, the servo's the rest of a fin at
        rest).  The play is left out of the design: the filter knows it, the states are
        read without it (:meth:`design_servo`) and the command is sent through it
        (:meth:`through_play`).
        """
        obs = self.observer
        trim = -self.rocket.theta_bar_deg
        if step is None:
            ar, innovation = obs.ar, self.turbulence.innovation_sd
        else:
            ar, innovation = obs.ar_at(step)
        t_rest, c_rest = obs.step_model(trim, trim, rocket, ar)
        move = max(innovation, 0.1)
        m = obs.m
        n = m + 1 + self._lagged
        a = np.zeros((n, n))
        a[:m, :m] = t_rest
        # The offset is constant, uncontrollable and so not stabilisable: designed as a
        # very slow AR(1) instead, its gain is that of a persistent disturbance.
        a[obs.bias, obs.bias] = OFFSET_POLE
        b = np.zeros((n, 1))
        _, c_moved = obs.path_model(obs.fin_path(trim, trim + move, play=False), rocket, ar)
        if self._lagged:  # the drive (the fin, without play) away from a servo at rest
            drive_path = obs.fin_path(trim + move, trim, trim, trim + move, play=False)
            _, c_drive = obs.path_model(drive_path, rocket, ar)
        for row in (0, 1):  # rate, angle: command share by the secant, the rest on the fin
            to_command = (c_moved[row] - c_rest[row]) / move
            b[row, 0] = to_command
            a[row, m] = t_rest[row, 2] - to_command
            if self._lagged:
                a[row, m + 1] = (c_drive[row] - c_rest[row]) / move
                a[row, m] -= a[row, m + 1]
        b[m, 0] = 1.0
        if self._lagged:  # the drive after the step: its own share, the command's, the servo's
            drive = obs.drive_after  # (servo, drive, command)
            a[m + 1, m + 1] = (drive(trim, trim + move, trim) - trim) / move
            b[m + 1, 0] = (drive(trim, trim, trim + move) - trim) / move
            a[m + 1, m] = 1.0 - a[m + 1, m + 1] - b[m + 1, 0]
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
        """Indices of the design's states in ``[v, ψ, u_d lags, b, θ + θ̄]`` (and the
        drive, with a lag)."""
        n = self.observer.m + 1 + self._lagged
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
        x = ob.present(fin)
        theta_bar = self.rocket.theta_bar_deg
        if self._angle:
            offset = 0.0
        else:
            setpoint = float(obs[Obs.ERROR]) + float(obs[Obs.RATE])
            x[0] -= setpoint
            offset = setpoint / ob.rocket_at(ob.steps - 1).alpha
        shift = theta_bar - offset
        if self._lagged:
            return np.append(x, [self.design_servo(fin) + shift, fin + shift]), shift
        return np.append(x, fin + shift), shift

    def design_servo(self, fin: float) -> float:
        """Where the servo stands as the design, which leaves the play out, reads it: moved
        by the play's offset (the drive's from the fin ``fin``), so that the drive is the
        fin; the fin itself without a lag."""
        ob = self.observer
        return ob.servo(fin) - (ob.drive(fin) - fin)

    def command(self, state: FloatArray, shift: float, fin: float) -> float:
        """The fin command of the design's state (LQR), clipped to the fin's range (``fin``:
        where the servo stands, :meth:`RollObserver.servo`)."""
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
        command = self.fin_command(state, shift, fin)
        self._last = (fin, command)
        return np.array([command / self._range], dtype=np.float32)

    def fin_command(self, state: FloatArray, shift: float, fin: float) -> float:
        """The servo's command, ° (the fin at ``fin``): the design's (:meth:`command`, from
        where the design reads the servo) through the play (:meth:`through_play`)."""
        return self.through_play(self.command(state, shift, self.design_servo(fin)), fin)

    def through_play(self, command: float, fin: float) -> float:
        """The servo command that puts the fin, now at ``fin``, at ``command`` through the
        rig's play: half the play beyond it in the direction the fin must move (the inverse
        of the play; ``command`` itself where the fin is to stay, or without play)."""
        half = 0.5 * self.rocket.rig.backlash_deg
        if not half:
            return command
        if command > fin:
            command += half
        elif command < fin:
            command -= half
        return min(max(command, -self._range), self._range)


def clone(controller: ObserverController) -> ObserverController:
    """Another controller of the same design (gains shared, read only) with its own filter."""
    twin = copy.copy(controller)
    twin.observer = copy.deepcopy(controller.observer)
    twin.reset()
    return twin


def designed_on(bank: TraceBank, config: RollConfig) -> tuple[NominalModel, TurbulenceModel]:
    """The nominal rocket (with the rig the environment flies: its settings over the traces'
    own, :meth:`RollConfig.rig_of`) and the turbulence model a design fits to ``bank``'s
    traces: in the tunnel's frame, where the model is flown from (a stored flight's own ``u_d``,
    recorded in flight, is taken there first: :func:`rollenv.flight.tunnel_frame`)."""
    nominal = NominalModel.from_bank(bank)
    nominal = dataclasses.replace(nominal, rig=config.rig_of(nominal.rig))
    schedule = config.flight_schedule
    if schedule is not None and any(t.flight_reference is not None for t in bank.traces):
        bank = tunnel_frame(bank, schedule)
    return nominal, TurbulenceModel.from_bank(bank, config.dt_s, nominal)


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
    coefficient and amplitude follow the airspeed (:meth:`TurbulenceModel.flown`)."""
    design.no_argument("observer")
    nominal, turbulence = designed_on(design.design_bank, design.config)
    return ObserverController(
        config=design.config, rocket=nominal, turbulence=turbulence, **scheduling(design.config)
    )
