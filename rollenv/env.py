"""``RocketRoll-v0`` and ``RocketRollRate-v0``: roll control of a sounding rocket in turbulence."""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec
from numpy.typing import NDArray

from disturbances.bank import TraceBank
from rollenv.bank import load_bank, make_config, settings_config
from rollenv.config import RollConfig, observation_bounds
from rollenv.core import RollBatch
from rollenv.history import EpisodeHistory, HistoryRecorder
from rollenv.layout import State

__all__ = ["RESET_OPTIONS", "RocketRollEnv", "check_action", "make_spaces"]

#: Keys ``reset(options=...)`` accepts.
RESET_OPTIONS = (
    "trace",
    "start",
    "rate_dps",
    "angle_deg",
    "fin_deg",
    "setpoint",
    "setpoints",
    "scales",
)

# The state's columns as plain ints for the per-step info (an IntEnum member costs about
# 0.1 µs a lookup; the env steps in a few µs).
_RATE, _ANGLE, _FIN, _COMMAND = (
    int(c) for c in (State.RATE, State.ANGLE, State.FIN, State.COMMAND)
)

#: Seconds of history a rendered frame shows.
RENDER_HISTORY_S = 10.0

ObsType = NDArray[np.float32]
ActType = NDArray[np.float32]


class EpisodeLengthSpec:
    """``spec.max_episode_steps`` that tells the truth: the environment's own length.

    The environment truncates itself (``episode_s / dt_s`` steps), so it is
    registered without a ``TimeLimit``; its spec reports that length all the
    same, for tools that read it (``gym.make(...).spec.max_episode_steps``).
    """

    config: RollConfig
    _spec: EnvSpec | None = None

    @property
    def spec(self) -> EnvSpec | None:
        spec = self._spec
        if spec is None or spec.max_episode_steps == self.config.max_episode_steps:
            return spec
        return dataclasses.replace(spec, max_episode_steps=self.config.max_episode_steps)

    @spec.setter
    def spec(self, value: EnvSpec | None) -> None:
        self._spec = value


class RocketRollEnv(EpisodeLengthSpec, gym.Env[ObsType, ActType]):
    """Roll control of a 5-kg sounding rocket in a turbulent vertical wind tunnel.

    ## Description

    The rocket of the paper "Minimal modelling approach to describe turbulent
    rocket roll dynamics in a vertical wind tunnel" hangs on a shaft in the
    tunnel's vertical flow, free to roll.  Four fins, moved together by one
    servo, are its only control.  The flow is turbulent: the disturbance
    ``u_d(t)``, an equivalent fin angle identified from recordings, pushes the
    roll rate around by several °/s.  The agent commands the fin angle to hold
    the roll angle at a setpoint (``RocketRoll-v0``, ``task="angle"``) or to
    track a roll-rate setpoint (``RocketRollRate-v0``, ``task="rate"``).

    Everything that moves the rocket comes from data: each episode replays a
    window of an identified ``u_d`` trace from the disturbance database,
    with the rocket parameters (α, θ̄, a or a(θ)) identified together with
    that trace, so a replay is consistent with its identification.

    ## Action Space

    ``Box(-1, 1, (1,), float32)``: the fin command, scaled by the fin range.

    | Num | Action      | Min | Max | Unit                                  |
    |-----|-------------|-----|-----|---------------------------------------|
    | 0   | fin command | -1  | 1   | fraction of ``fin_range_deg`` (40°)   |

    Actions outside [-1, 1] are clipped to it; NaN or infinite actions raise
    ``ValueError``.  The command is held for the control step; the servo
    follows it at no more than 150 °/s (eq. 23).

    ## Observation Space

    ``Box(low, high, (4,), float32)``, what a flight computer would have:

    | Num | Observation      | Min  | Max | Unit                                   |
    |-----|------------------|------|-----|----------------------------------------|
    | 0   | tracking error   | -180 | 180 | ° (angle: setpoint - measured angle, wrapped) |
    |     |                  | -500 | 500 | °/s (rate: setpoint - measured rate)   |
    | 1   | roll rate        | -250 | 250 | °/s, rate gyro, clipped to full scale  |
    | 2   | fin angle        | -40  | 40  | °, the servo's actual fin angle        |
    | 3   | last fin command | -40  | 40  | °                                      |

    With ``sensors=True`` (default) the angle is read by an encoder of
    ``encoder_counts`` (256) counts per revolution, floor-quantised to
    1.40625°, and the rate by a gyro with the multiplicative noise of eq. 52,
    ``(1 + η/100·ε)·v`` with ε ~ N(0, 1) and η = ``gyro_noise_pct`` (2).
    The true state is never in the observation; it is in ``info``.

    ## Transition Dynamics

    The θ-dependent roll model of the paper (eq. 36 with eq. 48-49)::

        dv/dt = -a(θ)·(v - α·(θ + θ̄ + u_d)),   a(θ) = ᾱ·|θ + θ̄| + β̄,   dφ/dt = v

    (``model="constant"``: a constant ``a``, eq. 29).  Each 0.1-s control
    step is ten 0.01-s substeps (the paper's δt).  On each substep the fin
    moves toward the held command by at most 1.5° (150 °/s) within ±40°, the
    fin is linear within the substep, ``u_d`` is held on its own 0.1-s grid,
    and rate and angle are advanced by the exact exponential update of
    :func:`identification.model.piece_coefficients` -- the computation of the
    identification's re-simulation, so replaying a recording's commands
    reproduces it to rounding.

    ## Rewards

    Per step, a Python float::

        r = -[(e/E)² + w_v·(v/V)² + w_f·(Δθ/(150 °/s·Δt))²]

    with ``e`` the true tracking error (° wrapped to ±180, or °/s), ``E`` =
    ``error_scale`` (10° or 5 °/s), ``v`` the roll rate and ``V`` =
    ``rate_scale_dps`` (10 °/s) -- this term only for the angle task, weight
    ``w_v = rate_weight`` (0.1) -- and ``Δθ`` the fin travel over the step,
    normalised by the most the servo can travel, weight ``w_f =
    fin_weight`` (0.1).  A perfect, still controller earns 0.  Evaluation
    metrics (RMS error, fin travel, time at the limits) are computed by the
    agents' evaluation protocol, not from the reward.

    ## Starting State

    A window of ``episode_s`` (60 s) is drawn uniformly over all (trace,
    offset) pairs of the chosen split (``split="train"``; ``"test"`` for
    evaluation).  The fin starts at 0°, the rate at the steady rate
    ``α·(θ̄ + u_d[0])`` for that fin angle, the angle uniform in
    ±``initial_angle_deg`` (0).  The setpoint (``setpoint="steps"``) is 0
    for the first ``setpoint_period_s`` (10 s) and then steps every period to
    a value uniform in ±``setpoint_range`` (90° or 10 °/s);
    ``setpoint="zero"`` holds 0.

    ``reset(options=...)`` fixes any of these for replays and evaluation:
    ``trace`` (index in the bank or uid), ``start`` (sample of the trace),
    ``rate_dps``, ``angle_deg``, ``fin_deg``, ``setpoint`` (held constant) or
    ``setpoints`` (the schedule: one value per period, ``episode_s /
    setpoint_period_s`` of them, rounded up), and ``scales``: a rocket that
    changes during the episode (an airspeed that varies), as multipliers of
    its gain α and its damping a(θ) (:class:`rollenv.layout.Scale`), one pair
    for the whole episode (shape ``(2,)``) or one per control step (shape
    ``(episode_s / dt_s, 2)``); all ones is the identified rocket.
    :meth:`replay_options` gives the options that recreate the current
    episode's draw (with its ``scales`` when it had any).

    ## Episode End

    * Termination: never -- the rocket is on its shaft; no physical limit of
      the rig can be crossed.  (The gyro saturates at ±250 °/s.)
    * Truncation: after ``episode_s / dt_s`` steps (600).  The environment
      truncates itself, so ``gym.make(..., max_episode_steps=N)`` can only
      shorten episodes; ``env.spec.max_episode_steps`` reports the length all
      the same.  Stepping past the end raises ``RuntimeError``.

    ## Arguments

    ``gym.make("RocketRoll-v0", **options)`` (``import rollenv`` first, or
    ``gym.make("rollenv:RocketRoll-v0")``), with any field of
    :class:`rollenv.config.RollConfig` as a keyword:

    * ``task`` "angle" | "rate"; ``split`` "train" | "test";
      ``method`` "paper" (default) | "output-error" | any registered
      identification method: whose parameters and ``u_d`` traces replay;
      ``disturbance`` "replay" | "surrogate" | "none";
      ``disturbance_scale`` (1.0); ``model`` "theta" | "constant";
      ``domain_randomization`` (False: α, θ̄, β̄, ᾱ drawn each reset uniformly
      over the range found among the bank's traces);
    * timing: ``dt_s`` (0.1), ``substep_s`` (0.01), ``episode_s`` (60; a
      flight's: to apogee);
    * sensors: ``sensors`` (True), ``angle_sensor`` "encoder" | "gyro",
      ``encoder_counts`` (256), ``gyro_noise_pct`` (2), ``gyro_range_dps``
      (250);
    * flight (below): ``flight`` (None: the tunnel), ``flight_turbulence``
      "tunnel" | "dryden", ``gust_severity``;
    * setpoints: ``setpoint`` "steps" | "zero", ``setpoint_period_s``,
      ``setpoint_range``, ``initial_angle_deg``;
    * reward: ``error_scale``, ``rate_scale_dps``, ``rate_weight``,
      ``fin_weight``;
    * ``db``: a database file (default: ``$ROCKETROLL_DB`` or the default
      database, built on first use); ``bank``: a
      :class:`disturbances.bank.TraceBank` to use instead;
    * ``render_mode``: "rgb_array" | "human" (a window; without a display
      it warns once and draws nothing).

    An unknown option is a ``ValueError`` naming it.  A database with no
    trace as long as an episode is a ``ValueError`` at construction.

    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import rollenv
    >>> from disturbances.bank import TraceBank
    >>> bank = TraceBank.from_arrays([np.zeros(600)], dt_s=0.1)  # or omit: the database
    >>> env = gym.make("RocketRoll-v0", bank=bank)
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, obs.dtype
    ((4,), dtype('float32'))
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> type(reward), terminated, truncated
    (<class 'float'>, False, False)

    ## Flight: ``RocketRollFlight-v0`` and ``RocketRollFlightRate-v0``

    The same rocket, off the tunnel's shaft and flying: ``flight="default"``
    (or a rocket YAML, or a recorded ``V(t)`` CSV; :mod:`rollenv.flight`), with
    ``angle_sensor="gyro"`` and ``setpoint="zero"``: hold the roll angle (or
    stop the roll) from launch to apogee.

    * **Episode**: from the moment the airspeed reaches the tunnel's 50 km/h
      (the rocket has left its rail, not rolling: rate 0) to apogee, in whole
      control steps -- 212 steps (21.2 s) of the default ascent, whose
      airspeed peaks at 603 km/h (Mach 0.50) at burnout and whose apogee is
      2010 m (:func:`rocketroll_physics.ascent.simulate_ascent`).  Truncation at
      apogee; no termination.
    * **Transition**: the dynamics above with the rocket's coefficients
      scaled every control step by the airspeed ``V`` and density ``ρ`` at
      the step's midpoint, from eq. 4-8 (``c ∝ ρV``, ``b ∝ ρV²``)::

          α(t) = α·V/V_ref,    a(θ, t) = a(θ)·ρV/(ρ_ref·V_ref),    θ̄ unchanged

      with ``V_ref`` = 50 km/h and ``ρ_ref`` the ISA's sea level (the tunnel
      where the model was identified); ᾱ and β̄ scale together, like ``a``.
      Assumed: constant ``C_P``, ``C_δ`` and inertia (subsonic; the paper's
      §4 warns of change past Mach 0.8), and an asymmetry θ̄ that does not
      depend on airspeed.  The factors are held at 0.001 or above as ``V → 0``
      at apogee.  At 600 km/h the gain and the damping are 12× the tunnel's:
      a fin that rolls the rocket at 26 °/s in the tunnel rolls it at over
      300 °/s in flight.
    * **Sensors**: no encoder; the rate gyro (eq. 52's noise, ±250 °/s) and
      the flight computer's angle, its readings summed over each control
      step from the true angle at launch (``φ̂ += Δt·v̂``), so it drifts.
    * **Turbulence** (``flight_turbulence``): ``"tunnel"`` (default) flies the
      database's traces: time compressed by ``V/V_ref`` (Taylor's frozen
      turbulence) and the flow angle scaled by ``V_ref/V`` (the tunnel's gust
      velocities; :mod:`rocketroll_physics.flown`), so the replay keeps the
      database's identified data and its train/test split.  ``"dryden"``:
      the Dryden roll gust of MIL-F-8785C (``gust_severity`` light, moderate
      or severe; :mod:`rocketroll_physics.dryden`), ``u_d = p_g/α(t)``.  Tunnel
      turbulence is the default because it is this project's measured data
      (and stronger than the free atmosphere's: a cautious default); Dryden is
      the standard model to check a controller against.
    * **Info** adds ``airspeed_mps``, ``altitude_m``, ``dynamic_pressure_pa``
      and ``mach`` at the observation's time.

    ## Version History

    * v0: initial version (the flight variants added without changing the
      tunnel's: their episodes, observations and rewards are the same).
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 (Gymnasium's convention; copied per instance)
        "render_modes": ["human", "rgb_array"],
        "render_fps": 10,
    }

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        bank: TraceBank | None = None,
        db: str | os.PathLike[str] | None = None,
        **settings: Any,
    ) -> None:
        self.config = settings_config(
            lambda given: make_config(type(self).__name__, given), settings, db
        )
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, "
                f"not {render_mode!r}"
            )
        self.render_mode = render_mode
        # in flight a given tunnel bank becomes its flights (load_bank's are already)
        self.bank = load_bank(self.config, db) if bank is None else self.config.flights(bank)
        self._batch = RollBatch(self.config, self.bank, 1)
        self._index = self._batch.all
        self._action = np.zeros(1)
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.config.dt_s}
        self.action_space, self.observation_space = make_spaces(self.config)
        self._started = False
        self._max_steps = self.config.max_episode_steps
        self._episode: dict[str, Any] = {}
        schedule = self.config.flight_schedule
        self._flight_columns = tuple(schedule.at_steps.items()) if schedule is not None else ()
        self._initial: dict[str, float] = {}
        self._history = HistoryRecorder(self.config.max_episode_steps + 1)
        self._renderer: Any = None

    # ------------------------------------------------------------------- gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[ObsType, dict[str, Any]]:
        super().reset(seed=seed)
        fixed = reset_arguments(options, self.bank, self.config.setpoint_segments)
        self._batch.reset(self._index, self.np_random, **fixed)
        self._initial = {  # the initial state given, and a drawn angle (for replay_options)
            key: float(fixed[key]) for key in ("rate_dps", "angle_deg", "fin_deg") if key in fixed
        }
        if self.config.initial_angle_deg > 0 and "angle_deg" not in fixed:
            self._initial["angle_deg"] = float(self._batch.state[0, _ANGLE])
        self._episode = self._episode_info()
        self._started = True
        self._history.clear()
        if self.render_mode is not None:
            self._history.record(self._batch, 0)
        if self.render_mode == "human":
            self.render()
        return self._batch.obs[0].copy(), self._info()

    def step(self, action: ActType) -> tuple[ObsType, SupportsFloat, bool, bool, dict[str, Any]]:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self._batch.step_count[0] >= self._max_steps:
            raise RuntimeError(
                f"the episode ended (truncated after {self._max_steps} steps); call reset()"
            )
        self._action[0] = _one_action(action)
        self._batch.step(self._action, self.np_random, self._index)
        if self.render_mode is not None:
            self._history.record(self._batch, 0, float(self._batch.reward[0]))
        if self.render_mode == "human":
            self.render()
        truncated = bool(self._batch.step_count[0] >= self._max_steps)
        return (
            self._batch.obs[0].copy(),
            float(self._batch.reward[0]),
            False,
            truncated,
            self._info(),
        )

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            gym.logger.warn(
                "render() was called without a render_mode; pass render_mode='rgb_array' or "
                "'human' to gym.make"
            )
            return None
        from rollenv.render import Renderer

        if self._renderer is None:
            title = self.spec.id if self.spec is not None else type(self).__name__
            self._renderer = Renderer(self.render_mode, self.metadata["render_fps"], title=title)
        recent = self.history().tail(round(RENDER_HISTORY_S / self.config.dt_s) + 1)
        if self.render_mode == "rgb_array":
            frame: NDArray[np.uint8] = self._renderer.frame(recent)
            return frame
        self._renderer.show(recent)
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ---------------------------------------------------------------- extras
    def replay_options(self) -> dict[str, Any]:
        """Reset options that recreate this episode: its trace window, setpoints, the
        rocket's ``scales`` if it had any, and its initial state where it was given or
        drawn (a random initial angle).

        ``env.reset(seed=s, options=env.replay_options())`` then replays the
        same disturbance and setpoint schedule (the gyro noise follows ``s``, and
        so does a domain-randomised rocket, which is drawn again); the
        evaluation protocol stores episodes this way.
        """
        if not self._started:
            raise RuntimeError("call reset() before replay_options()")
        b = self._batch
        trace = b.bank.traces[int(b.trace[0])]
        options: dict[str, Any] = {
            "trace": trace.uid,
            "start": int(b.start[0]),
            "setpoints": b.setpoints[0].tolist(),
        }
        options.update(self._initial)
        if b.scale_stride[0]:
            options["scales"] = b.episode_scales(0).tolist()
        return options

    def history(self) -> EpisodeHistory:
        """The episode so far, one row per control step (recorded when rendering)."""
        if not self._started or len(self._history) == 0:
            raise RuntimeError(
                "no history: call reset() first, with a render_mode (only rendering records it)"
            )
        info = self.bank.traces[int(self._batch.trace[0])]
        label = f"{info.uid} ({info.split}, {self.config.disturbance})"
        if self._flight_columns:  # where the rocket is on its flight now
            now = dict(self._flight_columns)
            k = int(self._batch.step_count[0])
            label = (
                f"V {now['airspeed_mps'][k] * 3.6:.0f} km/h, h {now['altitude_m'][k]:.0f} m, "
                f"q {now['dynamic_pressure_pa'][k] / 1e3:.1f} kPa · {label}"
            )
        return self._history.history(self.config.task, self.config.fin_range_deg, label)

    @property
    def core(self) -> RollBatch:
        """The batch of one underneath: true state and future ``u_d``, for privileged
        controllers (the oracle bound) and tests.  Writing to it breaks the episode."""
        return self._batch

    # ------------------------------------------------------------------ helpers
    def _info(self) -> dict[str, Any]:
        b = self._batch
        state = b.state[0].tolist()
        step = int(b.step_count[0])
        return {
            "roll_deg": state[_ANGLE],
            "roll_rate_dps": state[_RATE],
            "fin_deg": state[_FIN],
            "fin_cmd_deg": state[_COMMAND],
            "u_d_deg": float(b.u_now[0]),
            "setpoint": b.setpoint_of(0),
            "tracking_error": float(b.error[0]),
            "time_s": round(step * self.config.dt_s, 9),
            **self._episode,
            **{name: float(column[step]) for name, column in self._flight_columns},
        }

    def _episode_info(self) -> dict[str, Any]:
        b = self._batch
        trace = b.bank.traces[int(b.trace[0])]
        return {"trace": trace.uid, "start_s": float(b.start[0]) * trace.dt_s}


def make_spaces(config: RollConfig) -> tuple[spaces.Space[ActType], spaces.Space[ObsType]]:
    """The action and observation space (float32 ``Box``es) of one env with ``config``."""
    high, low = observation_bounds(config)
    action = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
    observation = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
    return cast(spaces.Space[ActType], action), cast(spaces.Space[ObsType], observation)


def _one_action(action: Any) -> float:
    """:func:`check_action` for one env, without array work on the common path."""
    if isinstance(action, np.ndarray) and action.size == 1:
        value = float(action.flat[0])
        if not math.isfinite(value):
            raise ValueError(f"action must be finite, got {value!r}")
        return min(max(value, -1.0), 1.0)
    return float(check_action(action, 1)[0])


def check_action(action: Any, n: int) -> NDArray[np.float64]:
    """Actions as ``n`` finite numbers clipped to [-1, 1]; a clear ``ValueError`` otherwise."""
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"action must be numbers, got {action!r}") from exc
    if a.size != n:
        shape = "(1,)" if n == 1 else f"({n}, 1) or ({n},)"
        raise ValueError(f"action must have shape {shape}, got shape {a.shape}")
    a = a.reshape(n)
    if not np.all(np.isfinite(a)):
        bad = a[~np.isfinite(a)][0]
        raise ValueError(f"action must be finite, got {bad!r}")
    return np.clip(a, -1.0, 1.0)


def reset_arguments(
    options: dict[str, Any] | None, bank: TraceBank, segments: int
) -> dict[str, Any]:
    """``reset(options=...)`` checked and turned into :meth:`RollBatch.reset` keywords
    (``segments``: the length a ``setpoints`` schedule must have)."""
    if not options:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"options must be a dict, got {type(options).__name__}")
    unknown = sorted(set(options) - set(RESET_OPTIONS))
    if unknown:
        raise ValueError(
            f"unknown reset option(s) {', '.join(map(repr, unknown))}; known: "
            f"{', '.join(RESET_OPTIONS)}"
        )
    fixed: dict[str, Any] = {}
    trace = options.get("trace")
    if trace is not None:
        if isinstance(trace, str):
            uids = [t.uid for t in bank.traces]
            if trace not in uids:
                raise ValueError(f"reset option trace={trace!r} is not in {bank.description}")
            fixed["trace"] = uids.index(trace)
        elif isinstance(trace, int | np.integer) and not isinstance(trace, bool):
            if not 0 <= int(trace) < len(bank):
                raise ValueError(f"reset option trace={trace} is out of range 0..{len(bank) - 1}")
            fixed["trace"] = int(trace)
        else:
            raise ValueError(f"reset option trace must be an index or a uid, got {trace!r}")
    start = options.get("start")
    if start is not None:
        if not isinstance(start, int | np.integer) or isinstance(start, bool) or start < 0:
            raise ValueError(f"reset option start must be a sample index >= 0, got {start!r}")
        if "trace" not in fixed:
            raise ValueError("reset option start needs a trace")
        fixed["start"] = int(start)
    schedule = options.get("setpoints")
    if schedule is not None:
        if "setpoint" in options and options["setpoint"] is not None:
            raise ValueError("reset options setpoint and setpoints exclude each other")
        try:
            values = np.asarray(schedule, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"reset option setpoints must be numbers, got {schedule!r}") from exc
        if values.shape != (segments,):
            raise ValueError(
                f"reset option setpoints must hold {segments} values (one per setpoint "
                f"period), got shape {values.shape}"
            )
        if not np.all(np.isfinite(values)):
            raise ValueError("reset option setpoints must be finite")
        fixed["setpoints"] = values
    scales = options.get("scales")
    if scales is not None:
        try:
            values = np.asarray(scales, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"reset option scales must be numbers, got {scales!r}") from exc
        if not np.all(np.isfinite(values)) or np.any(values <= 0):
            raise ValueError("reset option scales must be finite and positive")
        fixed["scales"] = values
    for name in ("rate_dps", "angle_deg", "fin_deg", "setpoint"):
        value = options.get(name)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
            raise ValueError(f"reset option {name} must be a number, got {value!r}")
        if not math.isfinite(float(value)):
            raise ValueError(f"reset option {name} must be finite, got {value!r}")
        fixed[name] = float(value)
    return fixed
