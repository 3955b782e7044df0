"""Memory for a memoryless policy: the last observations and actions beside the current one.

A flight computer's observation (encoder error, gyro rate, fin angle) does not
say where the rocket is within an encoder count, nor what the turbulence has
been doing; the PID's integral and the observer's state carry that.  An MLP
policy gets the same chance from a window of its own past:
``[o_t, o_{t-1}, ..., o_{t-k}, a_{t-1}, ..., a_{t-k}]`` (zeros before the
episode's start).  :class:`History` keeps that window for a batch of
environments; :class:`agents.vecenv.VecHistory` wraps an SB3 ``VecEnv`` with it for
training,
and :class:`agents.learned.LearnedController` keeps one of its own when acting, so the
policy sees the same vector in training and in the evaluation.  :class:`ErrorIntegral`
is the PID's own memory made of the same history: a leaky sum of the observed error.
:class:`PolicyLayout` records which of these (and the observer's estimate, a residual or an
incremental action) a trained policy reads and sends.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from rollenv.layout import Obs

__all__ = ["ErrorIntegral", "FlightClock", "History", "PolicyLayout", "history_space"]

Float32Array = NDArray[np.float32]


def history_space(observation: spaces.Box, action: spaces.Box, k: int) -> spaces.Box:
    """The observation space of ``k`` steps of history beside the current observation."""
    low = np.concatenate([np.tile(observation.low, k + 1), np.tile(action.low, k)])
    high = np.concatenate([np.tile(observation.high, k + 1), np.tile(action.high, k)])
    return spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


class History:
    """The last ``k`` observations and actions of ``n`` environments.

    >>> h = History(n=1, obs_dim=2, act_dim=1, k=2)
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
        Steps of past observations and actions beside the observation (:class:`History`).
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
