"""Memory for a memoryless policy: the last observations and actions beside the current one.

A flight computer's observation (encoder error, gyro rate, fin angle) does not
say where the rocket is within an encoder count, nor what the turbulence has
been doing; the PID's integral and the observer's state carry that.  An MLP
policy gets the same chance from a window of its own past:
``[o_t, o_{t-1}, ..., o_{t-k}, a_{t-1}, ..., a_{t-k}]`` (zeros before the
episode's start).  :class:`ObservationWindow` keeps that window for a batch of
environments.  :class:`ErrorIntegral` is the PID's own memory made of the same
history: a leaky sum of the observed error; :class:`FlightClock` the flight's phase.
:class:`PolicyLayout` records which of these (and the observer's estimate, a residual or an
incremental action) a trained policy reads and sends, and :class:`PolicyObservation` builds
them, in one order, for training (:class:`agents.vecenv.VecPolicyObservation` over an SB3
``VecEnv``) and for acting (:class:`agents.learned.LearnedController`): one stack, so the
policy sees the same vector in both, and a new observation feature is written once.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from rollenv.layout import OBSERVATION_NAMES, Obs

__all__ = [
    "ErrorIntegral",
    "FlightClock",
    "ObservationWindow",
    "PolicyLayout",
    "PolicyObservation",
    "history_space",
    "incremental_commands",
    "observation_names",
]

Float32Array = NDArray[np.float32]


def history_space(observation: spaces.Box, action: spaces.Box, k: int) -> spaces.Box:
    """The observation space of ``k`` steps of history beside the current observation."""
    low = np.concatenate([np.tile(observation.low, k + 1), np.tile(action.low, k)])
    high = np.concatenate([np.tile(observation.high, k + 1), np.tile(action.high, k)])
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


class ObservationWindow:
    """The last ``k`` observations and actions of ``n`` environments.

    >>> h = ObservationWindow(n=1, obs_dim=2, act_dim=1, k=2)
    >>> h.augment(np.array([[1.0, 2.0]])).tolist()
    [[1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]
    >>> h.push(np.array([[1.0, 2.0]]), np.array([[0.5]]))
    >>> h.augment(np.array([[3.0, 4.0]])).tolist()
    [[3.0, 4.0, 1.0, 2.0, 0.0, 0.0, 0.5, 0.0]]
    """

    def __init__(self, n: int, obs_dim: int, act_dim: int, k: int) -> None:
        if k < 1:
            raise ValueError(f"history must be >= 1 step, got {k}")
        self.k = k
        self._obs = np.zeros((n, k, obs_dim), dtype=np.float32)
        self._act = np.zeros((n, k, act_dim), dtype=np.float32)

    def clear(self, rows: Any = slice(None)) -> None:
        """Forget the history of ``rows`` (all by default): a new episode."""
        self._obs[rows] = 0.0
        self._act[rows] = 0.0

    def push(self, obs: NDArray[Any], actions: NDArray[Any]) -> None:
        """Record the observation each env acted on and the action it took."""
        self._obs[:, 1:] = self._obs[:, :-1]
        self._act[:, 1:] = self._act[:, :-1]
        self._obs[:, 0] = obs
        self._act[:, 0] = np.asarray(actions).reshape(self._act.shape[0], -1)

    def augment(self, obs: NDArray[Any], rows: Any = slice(None)) -> Float32Array:
        """``obs`` (of ``rows``) with its history: ``[o_t, past obs..., past actions...]``."""
        obs = np.asarray(obs, dtype=np.float32)
        past_obs = self._obs[rows].reshape(obs.shape[0], -1)
        past_act = self._act[rows].reshape(obs.shape[0], -1)
        return np.concatenate([obs, past_obs, past_act], axis=1)


class FlightClock:
    """The flight's phase for a policy: the rocket's gain and damping multipliers at each
    environment's control step, read from the nominal flight by the steps since launch.

    A flight computer knows the time since launch; the scheduled PID and observer read the
    nominal flight's schedule by it (:mod:`rollenv.flight`), and a policy given this clock
    reads the same two numbers (``V/V_ref`` and ``ρV/(ρ_ref·V_ref)``, eq. 4-8).

    >>> clock = FlightClock(np.array([[1.0, 1.0], [2.0, 1.9], [3.0, 2.7]]), n=2)
    >>> clock.values().tolist()
    [[1.0, 1.0], [1.0, 1.0]]
    >>> clock.advance(); clock.clear(1); clock.values().tolist()
    [[2.0, 1.899999976158142], [1.0, 1.0]]
    """

    SIZE = 2
    NAMES = ("flight_gain", "flight_damping")

    def __init__(self, scales: NDArray[Any], n: int = 1) -> None:
        table = np.asarray(scales, dtype=np.float32)
        if table.ndim != 2 or table.shape[1] != self.SIZE or table.shape[0] < 1:
            raise ValueError(f"scales must have shape (steps, 2), not {table.shape}")
        self._table = table
        self._step = np.zeros(n, dtype=np.intp)

    def clear(self, rows: Any = slice(None)) -> None:
        """Back to launch for ``rows`` (all by default): a new episode."""
        self._step[rows] = 0

    def advance(self) -> None:
        """One control step later, for every environment."""
        self._step += 1

    def values(self, rows: Any = slice(None)) -> Float32Array:
        """The multipliers of ``rows``' coming control step (held after the last), (n, 2)."""
        index = np.minimum(self._step[rows], self._table.shape[0] - 1)
        return np.asarray(self._table[index], dtype=np.float32).reshape(-1, self.SIZE)


class ErrorIntegral:
    """A leaky integral of the observed tracking error, for a policy: the memory a PID's
    integral term carries, made of the observation history alone (no model of the rocket).

    ``I_t = exp(-dt/τ)·I_{t-1} + dt·clip(e_t, -c, c)``, ``e_t`` the observation's
    tracking error (``Obs.ERROR``: ° on the angle task, °/s on the rate task), zero before
    the episode.  A memoryless policy (or one with a short window) sees only whole encoder
    counts and the trim it needs is the episode's own; the integral says how long the
    error has sat on one side.  The clip ``c`` keeps a slew's large errors from winding
    it up (conditional integration, as a PID's anti-windup).

    Parameters
    ----------
    dt_s : float
        The control step, s.
    time_s : float
        The leak's time constant τ, s (``math.inf``: no leak).
    clip : float or None
        The largest error magnitude integrated (None: no clip).
    n : int
        Environments.

    >>> integral = ErrorIntegral(dt_s=0.5, time_s=math.inf, clip=2.0, n=2)
    >>> integral.add(np.array([[1.0, 0, 0, 0], [5.0, 0, 0, 0]])).ravel().tolist()
    [0.5, 1.0]
    >>> integral.clear(1)
    >>> integral.add(np.array([[1.0, 0, 0, 0], [-1.0, 0, 0, 0]])).ravel().tolist()
    [1.0, -0.5]
    """

    SIZE = 1
    NAMES = ("error_integral",)

    def __init__(self, dt_s: float, time_s: float, clip: float | None = None, n: int = 1) -> None:
        if not dt_s > 0 or not time_s > 0:
            raise ValueError(f"dt_s and time_s must be > 0, got {dt_s} and {time_s}")
        if clip is not None and not clip > 0:
            raise ValueError(f"clip must be > 0 or None, got {clip}")
        self.dt = float(dt_s)
        self.decay = math.exp(-self.dt / float(time_s))
        self.clip = None if clip is None else float(clip)
        self._value = np.zeros(n, dtype=np.float64)

    def clear(self, rows: Any = slice(None)) -> None:
        """Zero the integral of ``rows`` (all by default): a new episode."""
        self._value[rows] = 0.0

    def add(self, obs: NDArray[Any], rows: slice = slice(None)) -> Float32Array:
        """Integrate the observations ``obs`` of ``rows`` (one row each) and return the
        integrals, float32 of shape ``(rows, 1)``."""
        error = np.asarray(obs, dtype=np.float64).reshape(-1, obs.shape[-1])[:, Obs.ERROR]
        if self.clip is not None:
            error = np.clip(error, -self.clip, self.clip)
        self._value[rows] = self.decay * self._value[rows] + self.dt * error
        return self._value[rows].astype(np.float32).reshape(-1, self.SIZE)


@dataclass(frozen=True)
class PolicyLayout:
    """What a trained policy reads and sends beyond the env's observation and action.

    Training writes it into ``settings.json``'s ``hyperparameters`` (:meth:`record`, from
    :attr:`agents.train.Hyperparameters.layout`); :class:`agents.learned.LearnedController`
    reads it back (:meth:`from_settings`) to rebuild the policy's observation and command.

    Attributes
    ----------
    history : int
        Steps of past observations and actions beside the observation (:class:`ObservationWindow`).
    observer : bool
        The observer's estimate in the observation (implied by ``residual``).
    residual : float
        0, or the scale of the action as a residual on the observer controller's command
        (the observer's estimate is then in the observation: ``observer`` is set).
    incremental : float
        0, or the scale of the action as a change of the last fin command.
    flight_clock : bool
        The flight's phase in the observation (:class:`FlightClock`).
    integral : float
        0, or the time constant (s) of the observed error's leaky integral
        (:class:`ErrorIntegral`) in the observation.
    integral_clip : float or None
        The largest error magnitude that integral integrates (None: no clip).
    """

    history: int = 0
    observer: bool = False
    residual: float = 0.0
    incremental: float = 0.0
    flight_clock: bool = False
    integral: float = 0.0
    integral_clip: float | None = None

    def __post_init__(self) -> None:
        if self.residual and not self.observer:  # a residual acts on the observer's command
            object.__setattr__(self, "observer", True)

    def record(self) -> dict[str, Any]:
        """The keys ``settings.json`` records, those set only."""
        return {
            **({"history": self.history} if self.history else {}),
            **({"observer": True} if self.observer else {}),
            **({"residual": self.residual} if self.residual else {}),
            **({"incremental": self.incremental} if self.incremental else {}),
            **({"flight_clock": True} if self.flight_clock else {}),
            **({"integral": self.integral} if self.integral else {}),
            **({"integral_clip": self.integral_clip} if self.integral_clip is not None else {}),
        }

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any]) -> PolicyLayout:
        """The layout a run's ``settings.json`` records (absent keys: not used)."""
        hyper = settings.get("hyperparameters") or {}
        residual = float(hyper.get("residual") or 0.0)
        clip = hyper.get("integral_clip")
        return cls(
            history=int(hyper.get("history") or 0),
            observer=bool(hyper.get("observer", False)),
            residual=residual,
            incremental=float(hyper.get("incremental") or 0.0),
            flight_clock=bool(hyper.get("flight_clock", False)),
            integral=float(hyper.get("integral") or 0.0),
            integral_clip=None if clip is None else float(clip),
        )


def incremental_commands(
    last: NDArray[Any], actions: NDArray[Any], scale: float
) -> NDArray[np.float32]:
    """``clip(last + scale·actions, -1, 1)`` as float32 of ``actions``' shape: the fin
    commands of incremental actions (``last`` the last commands, fractions of the range)."""
    actions = np.asarray(actions, dtype=np.float64)
    moved = np.asarray(last, dtype=np.float64).reshape(-1, 1) + scale * actions.reshape(
        len(actions), -1
    )
    return np.clip(moved, -1.0, 1.0).astype(np.float32).reshape(actions.shape)


def observation_names(layout: PolicyLayout | None = None) -> list[str]:
    """The names of the observation a policy of ``layout`` reads: the env's, the observer's
    estimate, the flight's phase, the error's integral, then the history (``name@t-k``, and
    ``action@t-k``); None: the env's observation alone.

    Examples
    --------
    >>> observation_names(PolicyLayout(history=1))[4:]
    ['tracking_error@t-1', 'roll_rate_dps@t-1', 'fin_deg@t-1', 'fin_cmd_deg@t-1', 'action@t-1']
    >>> len(observation_names(PolicyLayout(history=2, observer=True)))  # (4 + 3) x 3 + 2
    23
    """
    layout = layout or PolicyLayout()
    now = [*OBSERVATION_NAMES]
    now += list(PolicyObservation.OBSERVER_NAMES) if layout.observer else []
    now += list(FlightClock.NAMES) if layout.flight_clock else []
    now += list(ErrorIntegral.NAMES) if layout.integral else []
    past = [f"{name}@t-{k}" for k in range(1, layout.history + 1) for name in now]
    return now + past + [f"action@t-{k}" for k in range(1, layout.history + 1)]


class PolicyObservation:
    """What a trained policy reads and sends for ``n`` environments, built from its
    :class:`PolicyLayout`: the one implementation training and acting share.

    Beside each environment's observation (``Obs``), in this order: the observer's
    estimate (``features``, an :class:`agents.observer.ObserverFeatures`), the flight's
    phase (:class:`FlightClock`, from the nominal flight's ``scales``), the observed error's
    leaky integral (:class:`ErrorIntegral`), then the history of those and of the actions
    (:class:`ObservationWindow`).  The policy's action becomes the fin command the environment gets:
    the observer controller's plus a residual (``features``), or a change of the last
    command (``incremental``), or the action itself.

    Per step: :meth:`observe` the environments' observations (after :meth:`clear` at an
    episode's start), then :meth:`command` the policy's actions; an episode that ends has
    its last observation seen through :meth:`terminal` before its row is cleared.

    Parameters
    ----------
    layout : PolicyLayout
        What the policy reads and sends.
    n : int
        Environments.
    dt_s, fin_range_deg : float
        The control step (s) and the fin's range (°).
    features : ObserverFeatures, optional
        The observer's estimate, designed on the train split (required by an ``observer``
        layout).
    scales : ndarray, shape (steps, 2), optional
        The nominal flight's gain and damping multipliers per control step (required by a
        ``flight_clock`` layout).
    """

    #: The names of the observer's estimate in the observation.
    OBSERVER_NAMES = ("v_hat_dps", "psi_hat_deg", "u_d_hat_deg")
    #: The bounds the observation space gives each part beyond the env's: (low, high).
    OBSERVER_BOUND = 1e6
    CLOCK_BOUND = 1e3
    INTEGRAL_BOUND = 1e6

    def __init__(
        self,
        layout: PolicyLayout,
        n: int,
        *,
        dt_s: float,
        fin_range_deg: float,
        features: Any = None,
        scales: NDArray[Any] | None = None,
    ) -> None:
        if layout.observer and features is None:
            raise ValueError("this layout reads the observer's estimate: give its features")
        if layout.flight_clock and scales is None:
            raise ValueError("this layout reads the flight's phase: give the flight's scales")
        self.layout = layout
        self.n = n
        self.fin_range = float(fin_range_deg)
        self.features = features if layout.observer else None
        self.clock = FlightClock(scales, n) if scales is not None and layout.flight_clock else None
        self.integral = (
            ErrorIntegral(dt_s, layout.integral, layout.integral_clip, n)
            if layout.integral
            else None
        )
        #: Values per observation before the history.
        self.width = len(observation_names(dataclasses.replace(layout, history=0)))
        self.history = (
            ObservationWindow(n, self.width, 1, layout.history) if layout.history else None
        )
        self._raw: Float32Array | None = None
        self._now: Float32Array | None = None

    @property
    def size(self) -> int:
        """Values per policy observation (with the history)."""
        return len(observation_names(self.layout))

    def space(self, observation: spaces.Box, action: spaces.Box) -> spaces.Box:
        """The policy's observation space over the env's ``observation`` and ``action``."""
        low, high = [observation.low], [observation.high]
        for present, size, bound, positive in (
            (self.features is not None, len(self.OBSERVER_NAMES), self.OBSERVER_BOUND, False),
            (self.clock is not None, FlightClock.SIZE, self.CLOCK_BOUND, True),
            (self.integral is not None, ErrorIntegral.SIZE, self.INTEGRAL_BOUND, False),
        ):
            if present:
                big = np.full(size, np.float32(bound))
                low.append(np.zeros(size, np.float32) if positive else -big)
                high.append(big)
        now = spaces.Box(
            np.concatenate(low).astype(np.float32),
            np.concatenate(high).astype(np.float32),
            dtype=np.float32,
        )
        return history_space(now, action, self.layout.history) if self.history else now

    def clear(self, rows: Any = slice(None)) -> None:
        """A new episode for ``rows`` (all by default)."""
        if self.features is not None:
            self.features.clear(None if rows == slice(None) else rows)
        for part in (self.clock, self.integral, self.history):
            if part is not None:
                part.clear(rows)

    def _present(self, raw: Float32Array, rows: Any = slice(None)) -> Float32Array:
        """``raw`` (float32, one row per environment of ``rows``) with the values beside it."""
        parts = [raw]
        if self.features is not None:
            first = 0 if rows == slice(None) else rows.start
            parts.append(np.stack([self.features.one(first + i, o) for i, o in enumerate(raw)]))
        if self.clock is not None:
            parts.append(self.clock.values(rows))
        if self.integral is not None:
            parts.append(self.integral.add(raw, rows))
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)

    def observe(self, obs: Any) -> Float32Array:
        """The policy's observation of the environments' observations ``obs`` (n, 4)."""
        self._raw = np.asarray(obs, dtype=np.float32)
        self._now = self._present(self._raw)
        return self._now if self.history is None else self.history.augment(self._now)

    def terminal(self, i: int, obs: NDArray[Any]) -> Float32Array:
        """The policy's observation of environment ``i``'s last of an episode (for value
        bootstrapping), before :meth:`clear` of its row."""
        row = slice(i, i + 1)
        now = self._present(np.asarray(obs, dtype=np.float32).reshape(1, -1), row)
        return (now if self.history is None else self.history.augment(now, row))[0]

    def command(self, actions: NDArray[Any]) -> NDArray[np.float32]:
        """The fin commands (fractions of the range) the policy's ``actions`` send, from
        the observations last observed; the actions go into the history."""
        if self._raw is None or self._now is None:
            raise RuntimeError("observe the environments before commanding them")
        if self.history is not None:
            self.history.push(self._now, np.clip(np.asarray(actions, dtype=np.float32), -1, 1))
        out = actions
        if self.features is not None:
            out = self.features.record(self._raw, actions)
        if self.layout.incremental:
            last = np.asarray(self._raw, dtype=np.float64)[:, Obs.COMMAND] / self.fin_range
            out = incremental_commands(last, out, self.layout.incremental)
        if self.clock is not None:
            self.clock.advance()
        return out
