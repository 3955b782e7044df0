"""``RocketRollVectorEnv``: many RocketRoll environments stepped as one numpy batch."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from disturbances.bank import TraceBank
from rollenv.bank import load_bank, make_config
from rollenv.core import RollBatch
from rollenv.env import check_action, make_spaces, reset_arguments

__all__ = ["INFO_KEYS", "RocketRollVectorEnv"]

#: Arrays in every step's and reset's ``info`` (true state; see RocketRollEnv).
INFO_KEYS = ("roll_deg", "roll_rate_dps", "fin_deg", "u_d_deg", "setpoint", "tracking_error")


class RocketRollVectorEnv(VectorEnv[NDArray[np.float32], NDArray[np.float32], NDArray[Any]]):
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
    render_mode : None
        Vector rendering is not provided; render a single environment.
    parallel : bool
        Spread the batch over numba's threads (``NUMBA_NUM_THREADS``, default
        all cores).  Off by default: it pays only when nothing else runs on
        those cores; oversubscribed (e.g. next to torch's threads while
        training) it can be many times slower.  ``benchmarks/env_speed.py``
        measures both.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 (Gymnasium's convention; copied per instance)
        "render_modes": [],
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
        if render_mode is not None:
            raise ValueError(
                "RocketRollVectorEnv does not render; make a single RocketRoll-v0 with "
                "render_mode='rgb_array'"
            )
        env_id = "RocketRollRate-v0" if settings.get("task") == "rate" else "RocketRoll-v0"
        self.config = make_config(env_id, settings)
        self.num_envs = int(num_envs)
        self.render_mode = None
        self.bank = load_bank(self.config, db) if bank is None else bank
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

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Reset every env (``options`` as for the single env apply to all)."""
        if isinstance(seed, list):
            raise ValueError("RocketRollVectorEnv takes one int seed for the batch, not a list")
        super().reset(seed=seed)
        fixed = reset_arguments(options, self.bank, self.config.setpoint_segments)
        self._batch.reset(self._batch.all, self.np_random, **fixed)
        self._prev_done[:] = False
        self._started = True
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
        return b.obs.copy(), reward, terminated, truncated, self._info()

    def _info(self) -> dict[str, Any]:
        b = self._batch
        values = {
            "roll_deg": b.state[:, 1].copy(),
            "roll_rate_dps": b.state[:, 0].copy(),
            "fin_deg": b.state[:, 2].copy(),
            "u_d_deg": b.u_now.copy(),
            "setpoint": b.setpoint_now(),
            "tracking_error": b.error.copy(),
        }
        info: dict[str, Any] = {}
        for key, value in values.items():
            info[key] = value
            info[f"_{key}"] = self._mask
        return info
