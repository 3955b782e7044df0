"""``RollVecEnv``: a Stable-Baselines3 ``VecEnv`` directly over the RocketRoll batch core.

SB3 steps its environments through its own ``VecEnv`` API (``reset()``
returns observations only, ``step`` returns ``(obs, rewards, dones, infos)``
and resets finished environments in the same call).  ``DummyVecEnv`` over
``gym.make`` envs would step them one by one in Python; this adapter is the
SB3 analogue of :class:`rollenv.vector.RocketRollVectorEnv`: one
:class:`rollenv.core.RollBatch` advances all environments in one compiled
call, and all randomness comes from one ``np.random.Generator``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvWrapper,
)

from agents.memory import PolicyObservation
from disturbances.bank import TraceBank
from rollenv.bank import load_bank, settings_config, variant_config
from rollenv.core import RollBatch
from rollenv.env import check_action, make_spaces, reset_arguments

__all__ = [
    "ENV_ATTRIBUTES",
    "RollVecEnv",
    "StepReturn",
    "VecPolicyObservation",
]

#: What ``step`` and ``step_wait`` return: observations, rewards, dones, infos.
StepReturn = tuple[
    NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_], list[dict[str, Any]]
]

#: What ``get_attr`` answers (the same value for every environment of the batch).
ENV_ATTRIBUTES = ("render_mode", "config", "bank", "env_id", "spec", "metadata")


class RollVecEnv(VecEnv):
    """``num_envs`` RocketRoll environments as one Stable-Baselines3 ``VecEnv``.

    Spaces, dynamics, rewards, settings and reset options are those of
    :class:`rollenv.env.RocketRollEnv` (the core is shared); only the vector
    API is SB3's:

    * ``reset()`` returns the observations, shape ``(num_envs, len(Obs))`` float32,
      and fills ``self.reset_infos``.  Seeds set by :meth:`seed` and options
      set by ``set_options`` apply to that reset only, as in SB3's
      ``DummyVecEnv``.
    * ``step(actions)`` returns observations, rewards (float32, as
      ``DummyVecEnv``), ``dones`` (bool) and one info dict per env.  An env
      whose episode ends (truncation after ``max_episode_steps``; the
      rocket never terminates) is reset *in the same step*: ``dones[i]`` is
      True, ``infos[i]["terminal_observation"]`` is its last observation,
      ``infos[i]["TimeLimit.truncated"]`` is True (so PPO bootstraps the
      value), and ``obs[i]`` is the first observation of its new episode.
    * Every info holds ``"tracking_error"``: the true tracking error of that
      step (°, or °/s), as the single env's info, for evaluation; nothing
      else, to keep the per-step cost low.

    All randomness -- trace windows, setpoints, initial angles, gyro noise --
    comes from one ``np.random.Generator``, so the same seed gives the same
    rollout bit for bit.  With ``num_envs=1`` the rollout equals a
    ``RocketRollEnv`` reset with the same seed (and ``reset()`` at each
    truncation), step for step.

    Parameters
    ----------
    num_envs : int
        Batch size.
    env_id : str
        A registered variant (``"RocketRoll-v0"``: angle task,
        ``"RocketRollRate-v0"``: rate task, ...); its options, ``task`` among
        them, come with it (:func:`rollenv.bank.variant_config`).
    bank : TraceBank, optional
        Traces to replay instead of the database's.
    db : path, optional
        Database file (default: ``$ROCKETROLL_DB`` or the default database).
    seed : int, optional
        Seed of the generator until :meth:`seed` reseeds it.
    **settings
        Any field of :class:`rollenv.config.RollConfig` (``split``,
        ``episode_s``, ``setpoint``, ...), as for ``gym.make``.

    Notes
    -----
    The batch is stepped with the serial kernel: next to torch's threads,
    numba's parallel kernel oversubscribes the cores and is slower.

    Examples
    --------
    >>> import numpy as np
    >>> from disturbances.bank import TraceBank
    >>> bank = TraceBank.from_arrays([np.zeros(700)], dt_s=0.1)
    >>> venv = RollVecEnv(2, bank=bank, seed=0)
    >>> obs = venv.reset()
    >>> obs.shape, obs.dtype
    ((2, 4), dtype('float32'))
    >>> obs, rewards, dones, infos = venv.step(np.zeros((2, 1), np.float32))
    >>> rewards.dtype, dones.tolist(), sorted(infos[0])
    (dtype('float32'), [False, False], ['tracking_error'])
    """

    def __init__(
        self,
        num_envs: int = 1,
        env_id: str = "RocketRoll-v0",
        *,
        bank: TraceBank | None = None,
        db: str | os.PathLike[str] | None = None,
        seed: int | None = None,
        **settings: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs}")
        if "render_mode" in settings:
            raise ValueError("RollVecEnv does not render; render a single RocketRoll env")
        self.env_id = env_id
        self.config = settings_config(lambda given: variant_config(env_id, given), settings, db)
        # in flight a given tunnel bank becomes its flights (load_bank's are already)
        self.bank = load_bank(self.config, db) if bank is None else self.config.flights(bank)
        self._batch = RollBatch(self.config, self.bank, int(num_envs), parallel=False)
        self.render_mode: str | None = None
        self.spec = None
        self._rng = np.random.default_rng(seed)
        action_space, observation_space = make_spaces(self.config)
        super().__init__(int(num_envs), observation_space, action_space)
        self._actions: NDArray[np.float64] | None = None
        self._started = False
        self._uids = [t.uid for t in self.bank.traces]

    # ------------------------------------------------------------------ VecEnv
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the generator at the next :meth:`reset` (SB3's semantics).

        Returns ``[seed, seed + 1, ...]`` as SB3's ``VecEnv.seed`` does; the
        batch shares one generator, which the next ``reset()`` re-creates
        from ``seed`` (the first of them).  ``seed(None)`` leaves the
        generator as it is (returns ``None`` for every env).
        """
        if seed is None:
            self._seeds = [None] * self.num_envs
        else:
            self._seeds = [int(seed) + k for k in range(self.num_envs)]
        return list(self._seeds)

    def reset(self) -> NDArray[np.float32]:
        """Start new episodes in every env; the observations, shape ``(num_envs, len(Obs))``.

        Seeds from :meth:`seed` and options from ``set_options`` (the reset
        options of :class:`rollenv.env.RocketRollEnv`, :data:`rollenv.env.RESET_OPTIONS`)
        apply to this reset only.
        """
        first_seed = self._seeds[0]
        if first_seed is not None:
            self._rng = np.random.default_rng(first_seed)
        b = self._batch
        segments = self.config.setpoint_segments
        fixed = [reset_arguments(options, self.bank, segments) for options in self._options]
        if all(_same_arguments(f, fixed[0]) for f in fixed):
            b.reset(b.all, self._rng, **fixed[0])
        else:  # per-env options: one env after the other, in index order
            for k, f in enumerate(fixed):
                b.reset(b.all[k : k + 1], self._rng, **f)
        self._reset_seeds()
        self._reset_options()
        self._started = True
        self._actions = None
        for k in range(self.num_envs):
            self.reset_infos[k] = self._reset_info(k)
        return b.obs.copy()

    def step(self, actions: np.ndarray) -> StepReturn:
        """Step every env with ``actions``: :meth:`step_async` then :meth:`step_wait`."""
        self.step_async(actions)
        return self.step_wait()

    def step_async(self, actions: np.ndarray) -> None:
        """Hold ``actions`` (shape ``(num_envs, 1)`` or ``(num_envs,)``) for :meth:`step_wait`.

        Actions are clipped to [-1, 1]; NaN, infinite or wrongly shaped
        actions raise ``ValueError``.
        """
        if not self._started:
            raise RuntimeError("call reset() before step()")
        self._actions = check_action(actions, self.num_envs)

    def step_wait(self) -> StepReturn:
        """Step every env with the held actions; reset those whose episode ended."""
        if self._actions is None:
            raise RuntimeError("call step_async(actions) before step_wait()")
        b = self._batch
        b.step(self._actions, self._rng, b.all)
        self._actions = None
        obs = b.obs.copy()
        rewards = b.reward.astype(np.float32)
        dones = b.truncated
        infos: list[dict[str, Any]] = [{"tracking_error": e} for e in b.error.tolist()]
        if dones.any():
            ended = np.flatnonzero(dones)
            for i in ended.tolist():
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = True
            b.reset(ended, self._rng)
            obs[ended] = b.obs[ended]
            for i in ended.tolist():
                self.reset_infos[i] = self._reset_info(i)
        return obs, rewards, dones, infos

    def close(self) -> None:
        """Nothing to release (no subprocesses, no renderer)."""

    # -------------------------------------------------------------- attributes
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The value of ``attr_name`` for each env in ``indices``.

        The envs of the batch share one configuration, so each gets the same
        value; the attributes are :data:`ENV_ATTRIBUTES`.  Anything else
        raises ``AttributeError`` (SB3's ``has_attr`` relies on that).
        """
        if attr_name not in ENV_ATTRIBUTES:
            raise AttributeError(
                f"RollVecEnv's environments have no attribute {attr_name!r}; they share one "
                f"batch and answer only {', '.join(ENV_ATTRIBUTES)}"
            )
        value = getattr(self, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Not supported: the envs share one batch whose settings are fixed at construction."""
        self._indices(indices)
        raise AttributeError(
            f"cannot set {attr_name!r} on RollVecEnv's environments: they share one batch whose "
            "settings are fixed at construction; make a new RollVecEnv instead"
        )

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Not supported: there are no per-env objects whose methods could be called."""
        self._indices(indices)
        raise AttributeError(
            f"RollVecEnv cannot call {method_name!r} on its environments: they are rows of one "
            "batch, not gym.Env objects; use a single rollenv.env.RocketRollEnv for that"
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """False for each env: the batch holds no ``gym.Wrapper`` (e.g. no ``Monitor``)."""
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Not supported: the adapter does not render."""
        raise NotImplementedError(
            "RollVecEnv does not render; make a single RocketRoll env with render_mode='rgb_array'"
        )

    # ----------------------------------------------------------------- helpers
    @property
    def generator(self) -> np.random.Generator:
        """The generator every random draw of the batch comes from."""
        return self._rng

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        """``indices`` as a checked list (None: all envs)."""
        chosen = [int(i) for i in self._get_indices(indices)]
        for i in chosen:
            if not 0 <= i < self.num_envs:
                raise IndexError(f"env index {i} is out of range 0..{self.num_envs - 1}")
        return chosen

    def _reset_info(self, i: int) -> dict[str, Any]:
        """The reset info of env ``i``: its trace, window start and tracking error."""
        b = self._batch
        trace = int(b.trace[i])
        return {
            "tracking_error": float(b.error[i]),
            "trace": self._uids[trace],
            "start_s": float(b.start[i]) * self.bank.traces[trace].dt_s,
        }


def _same_arguments(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two checked reset-argument dicts are equal (values may be arrays)."""
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


class VecPolicyObservation(VecEnvWrapper):
    """An SB3 ``VecEnv`` that a trained policy of a :class:`~agents.memory.PolicyLayout`
    sees: its observations carry what the layout reads (the observer's estimate, the
    flight's phase, the error's integral, the history), and its actions become the fin
    commands the layout sends (a residual on the observer controller's, a change of the
    last one) -- all by one :class:`~agents.memory.PolicyObservation`, the acting
    controller's too.

    An env whose episode ends starts its new one afresh (no history, the observer, the
    clock and the integral reset); its ``terminal_observation`` is what the policy would
    have seen of it (for value bootstrapping).
    """

    def __init__(self, venv: VecEnv, stack: PolicyObservation) -> None:
        assert isinstance(venv.observation_space, spaces.Box)
        assert isinstance(venv.action_space, spaces.Box)
        space = stack.space(venv.observation_space, venv.action_space)
        super().__init__(venv, observation_space=space)
        self.stack = stack

    def reset(self) -> NDArray[np.float32]:
        obs = self.venv.reset()
        self.stack.clear()
        return self.stack.observe(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(self.stack.command(actions))

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = self.venv.step_wait()
        for i in np.flatnonzero(dones).tolist():
            terminal = infos[i].get("terminal_observation")
            if terminal is not None:
                infos[i]["terminal_observation"] = self.stack.terminal(i, terminal)
            self.stack.clear(i)
        return self.stack.observe(obs), rewards, dones, infos
