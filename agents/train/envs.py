"""The training and evaluation environments of a run: the batched core behind SB3's
``VecEnv`` (``VecNormalize(VecMonitor(...))``), and the names of the policy's observation."""

from __future__ import annotations

import os
from typing import Any

from agents.memory import PolicyLayout, PolicyObservation, observation_names
from agents.train.hyperparams import Hyperparameters
from rocketroll_common.errors import UsageError


def make_env(
    hp: Hyperparameters,
    n_envs: int,
    seed: int,
    *,
    split: str,
    db: str | os.PathLike[str] | None = None,
    training: bool = True,
) -> tuple[Any, Any, Any]:
    """The vector env stack of a run: ``VecNormalize(VecMonitor(RollVecEnv))``, with
    :class:`~agents.vecenv.VecPolicyObservation` over the adapter where the entry's layout
    reads or sends more than the env's observation and action (``observer``,
    ``residual``, ``flight_clock``, ``integral``, ``history``, ``incremental``).

    The monitor is inside, so it records the raw returns whatever
    ``VecNormalize`` does to rewards.  ``training=False`` (evaluation):
    frozen statistics (synced from training by the caller), raw rewards, and
    every recording of the split (a ``recording`` option chooses what is
    trained on, not the held-out set).

    Returns
    -------
    adapter : RollVecEnv
        The adapter at the bottom (for seeding).
    env : VecEnv
        The top of the stack.
    normalize : VecNormalize or None
        The normalisation wrapper, None when ``hp.normalize`` is None.
    """
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.vecenv import RollVecEnv, VecPolicyObservation

    for forbidden in ("split", "task"):
        if forbidden in hp.env_kwargs:
            raise UsageError(f"{hp.source}, {hp.env_id}: env_kwargs may not set {forbidden!r}")
    options = dict(hp.env_kwargs)
    if not training:  # the held-out check replays the whole test split
        options.pop("recording", None)
    try:
        adapter = RollVecEnv(n_envs, hp.env_id, db=db, seed=seed, split=split, **options)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{hp.source}, {hp.env_id}: env_kwargs: {exc}") from exc
    env: Any = adapter
    if hp.layout.record():
        env = VecPolicyObservation(env, _policy_observation(hp, adapter, n_envs, split, db))
    env = VecMonitor(env)
    normalize = None
    if hp.normalize is not None:
        norm = dict(hp.normalize)
        norm.setdefault("gamma", float(hp.algo_kwargs.get("gamma", 0.99)))
        if not training:
            norm.update(training=False, norm_reward=False)
        normalize = VecNormalize(env, **norm)
        env = normalize
    return adapter, env, normalize


def _policy_observation(
    hp: Hyperparameters,
    adapter: Any,
    n_envs: int,
    split: str,
    db: str | os.PathLike[str] | None,
) -> PolicyObservation:
    """The observation and command of the entry's layout for the adapter's ``n_envs``."""
    config = adapter.config
    features = None
    if hp.layout.observer:
        from agents.base import design_bank
        from agents.observer import ObserverFeatures

        train_bank = adapter.bank
        if split != "train" or config.flight_schedule is not None or config.recording is not None:
            # the observer is designed on the train split (the replayed recording's part
            # there, where it has one), as --policy designs it when the policy is
            # evaluated; in flight on its tunnel traces
            train_bank = design_bank(config, db)
        features = ObserverFeatures.from_bank(config, train_bank, n_envs, hp.layout.residual)
    scales = None
    if hp.layout.flight_clock:
        if config.flight_schedule is None:
            raise UsageError(f"{hp.source}, {hp.env_id}: flight_clock needs a flight")
        scales = config.flight_schedule.scales[: config.max_episode_steps]
    return PolicyObservation(
        hp.layout,
        n_envs,
        dt_s=config.dt_s,
        fin_range_deg=config.fin_range_deg,
        features=features,
        scales=scales,
    )


# ----------------------------------------------------------------------------- outputs
def normalization_record(venv: Any, layout: PolicyLayout | None = None) -> dict[str, Any]:
    """The observation normalisation of a ``VecNormalize`` (or None) as plain JSON data, for
    a policy of ``layout``."""
    names = observation_names(layout)
    if venv is None or not venv.norm_obs:
        return {"norm_obs": False, "observation_names": names}
    rms = venv.obs_rms
    return {
        "norm_obs": True,
        "observation_names": names,
        "mean": [float(x) for x in rms.mean],
        "var": [float(x) for x in rms.var],
        "count": float(rms.count),
        "clip_obs": float(venv.clip_obs),
        "epsilon": float(venv.epsilon),
        "formula": "clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs) as float32",
    }
