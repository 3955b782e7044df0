"""``RocketRollVectorEnv``: many RocketRoll environments stepped as one numpy batch."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from disturbances.bank import TraceBank
from rollenv.bank import load_bank, make_config, settings_config
from rollenv.core import RollBatch
from rollenv.env import EpisodeLengthSpec, check_action, make_spaces, reset_arguments
from rollenv.history import HistoryRecorder
from rollenv.layout import State

__all__ = ["INFO_KEYS", "RocketRollVectorEnv"]

#: Arrays in every step's and reset's ``info`` (true state; see RocketRollEnv).
INFO_KEYS = (
    "roll_deg",
    "roll_rate_dps",
    "fin_deg",
    "fin_cmd_deg",
    "u_d_deg",
    "setpoint",
    "tracking_error",
)


class RocketRollVectorEnv(
    EpisodeLengthSpec, VectorEnv[NDArray[np.float32], NDArray[np.float32], NDArray[Any]]
):
    """``num_envs`` copies of :class:`rollenv.env.RocketRollEnv` in one batch.

    The same pure core (:class:`rollenv.core.RollBatch`) steps all of them in
    one compiled loop, spread over numba's threads for large batches; spaces,
    dynamics, rewards, options and reset options are those of the single
    environment.  Built by ``gym.make_vec("RocketRoll-v0", num_envs=N)``
    (the ``vector_entry_point``) or directly.

    Autoreset is ``NEXT_STEP``, as in Gymnasium's ``CartPoleVectorEnv``: the
    step after an env's episode ends resets it, ignores its action and
    returns its first observation with reward 0 and neither flag set.  All
    randomness comes from ``self.np_random``; with ``num_envs=1`` the
    rollout equals the single environment's step for step (given the same
    seed and ``reset()`` after each episode).

    ``info`` holds the true state of every env as arrays (``INFO_KEYS``,
    each with its ``_key`` mask, all True).

    Parameters
    ----------
    num_envs : int
        Batch size.
    bank, db, **settings
        As for :class:`rollenv.env.RocketRollEnv`.
    render_mode : None or "rgb_array"
        ``"rgb_array"``: :meth:`render` returns one frame per env (each env's
        history is recorded, which costs time; for a window use a single env).
    parallel : bool
        Spread the batch over numba's threads (``NUMBA_NUM_THREADS``, default
        all cores).  Off by default: it pays only when nothing else runs on
        those cores; oversubscribed (e.g. next to torch's threads while
        training) it can be many times slower.  ``benchmarks/env_speed.py``
        measures both.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 (Gymnasium's convention; copied per instance)
        "render_modes": ["rgb_array"],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        render_mode: str | None = None,
        *,
        bank: TraceBank | None = None,
        db: str | os.PathLike[str] | None = None,
        parallel: bool = False,
        **settings: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(
                f"RocketRollVectorEnv renders 'rgb_array' frames (one per env), not "
                f"{render_mode!r}; for a window make a single env with render_mode='human'"
            )
        self.config = settings_config(
            lambda given: make_config(type(self).__name__, given), settings, db
        )
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        # in flight a given tunnel bank becomes its flights (load_bank's are already)
        self.bank = load_bank(self.config, db) if bank is None else self.config.flights(bank)
        self._batch = RollBatch(self.config, self.bank, self.num_envs, parallel=parallel)
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.config.dt_s}
        self.single_action_space, self.single_observation_space = make_spaces(self.config)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._prev_done = np.zeros(self.num_envs, dtype=np.bool_)
        self._started = False
        mask = np.ones(self.num_envs, dtype=np.bool_)
        mask.flags.writeable = False
        self._mask = mask
        capacity = self.config.max_episode_steps + 1
        self._recorders = (
            [HistoryRecorder(capacity) for _ in range(self.num_envs)] if render_mode else []
        )
        self._renderer: Any = None

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Reset every env (``options`` as for the single env apply to all of them, for
        this episode only: the ``NEXT_STEP`` autoreset that follows an episode's end
        draws the next episode with no options, the database's rocket among them)."""
        if isinstance(seed, list):
            raise ValueError("RocketRollVectorEnv takes one int seed for the batch, not a list")
        super().reset(seed=seed)
        fixed = reset_arguments(options, self.bank, self.config.setpoint_segments)
        self._batch.reset(self._batch.all, self.np_random, **fixed)
        self._prev_done[:] = False
        self._started = True
        for i, recorder in enumerate(self._recorders):
            recorder.clear()
            recorder.record(self._batch, i)
        return self._batch.obs.copy(), self._info()

    def step(
        self, actions: NDArray[Any]
    ) -> tuple[
        NDArray[np.float32],
        NDArray[np.float64],
        NDArray[np.bool_],
        NDArray[np.bool_],
        dict[str, Any],
    ]:
        """Step all envs; those whose episode ended at the last step are reset instead."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        action = check_action(actions, self.num_envs)
        b = self._batch
        done = self._prev_done
        any_done = bool(done.any())
        if any_done:
            resetting = np.flatnonzero(done)
            b.reset(resetting, self.np_random)
            index = np.flatnonzero(~done)
        else:
            index = b.all
        b.step(action, self.np_random, index)
        reward = b.reward.copy()
        truncated = b.truncated
        if any_done:
            reward[done] = 0.0
            truncated[done] = False
        terminated = np.zeros(self.num_envs, dtype=np.bool_)
        self._prev_done = truncated.copy()
        for i, recorder in enumerate(self._recorders):
            if any_done and done[i]:
                recorder.clear()
            recorder.record(b, i, float(reward[i]))
        return b.obs.copy(), reward, terminated, truncated, self._info()

    def render(self) -> tuple[NDArray[np.uint8], ...] | None:
        """One RGB frame per env (``render_mode="rgb_array"``), as the single env draws it."""
        if self.render_mode is None:
            from gymnasium import logger as gym_logger

            gym_logger.warn(
                "render() was called without a render_mode; pass render_mode='rgb_array' to "
                "gym.make_vec"
            )
            return None
        if not self._started:
            raise RuntimeError("call reset() before render()")
        from rollenv.env import RENDER_HISTORY_S
        from rollenv.render import Renderer

        if self._renderer is None:
            self._renderer = Renderer("rgb_array", self.metadata["render_fps"])
        samples = round(RENDER_HISTORY_S / self.config.dt_s) + 1
        frames = []
        for i, recorder in enumerate(self._recorders):
            info = self.bank.traces[int(self._batch.trace[i])]
            label = f"env {i}: {info.uid} ({info.split}, {self.config.disturbance})"
            history = recorder.history(self.config.task, self.config.fin_range_deg, label)
            frames.append(self._renderer.frame(history.tail(samples)))
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        """Free the renderer's figure."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def _info(self) -> dict[str, Any]:
        b = self._batch
        values = {
            "roll_deg": b.state[:, State.ANGLE].copy(),
            "roll_rate_dps": b.state[:, State.RATE].copy(),
            "fin_deg": b.state[:, State.FIN].copy(),
            "fin_cmd_deg": b.state[:, State.COMMAND].copy(),
            "u_d_deg": b.u_now.copy(),
            "setpoint": b.setpoint_now(),
            "tracking_error": b.error.copy(),
        }
        schedule = self.config.flight_schedule
        if schedule is not None:
            for name, column in schedule.at_steps.items():
                values[name] = column[b.step_count]
        info: dict[str, Any] = {}
        for key, value in values.items():
            info[key] = value
            info[f"_{key}"] = self._mask
        return info
