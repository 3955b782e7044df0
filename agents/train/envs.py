"""The training and evaluation environments of a run: the batched core behind SB3's
``VecEnv`` (``VecNormalize(VecMonitor(...))``), and the names of the policy's observation."""

from __future__ import annotations

import os
from typing import Any

from agents.memory import PolicyLayout
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
    """The vector env stack of a run: ``VecNormalize(VecMonitor(RollVecEnv))``, with, from
    the adapter up, ``VecIncremental``, ``VecObserver``, ``VecFlightClock``,
    ``VecErrorIntegral`` and ``VecHistory`` when the entry asks for ``incremental``,
    ``observer``, ``flight_clock``, ``integral`` and ``history``.

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

    from agents.vecenv import RollVecEnv

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
    if hp.layout.incremental:
        from agents.vecenv import VecIncremental

        env = VecIncremental(env, hp.layout.incremental, adapter.config.fin_range_deg)
    if hp.layout.observer:
        from agents.base import design_bank
        from agents.observer import ObserverFeatures
        from agents.vecenv import VecObserver

        train_bank = adapter.bank
        if (
            split != "train"
            or adapter.config.flight_schedule is not None
            or adapter.config.recording is not None
        ):
            # the observer is designed on the train split (the replayed recording's part
            # there, where it has one), as --policy designs it when the policy is
            # evaluated; in flight on its tunnel traces
            train_bank = design_bank(adapter.config, db)
        features = ObserverFeatures.from_bank(
            adapter.config, train_bank, n_envs, hp.layout.residual
        )
        env = VecObserver(env, features)
    if hp.layout.flight_clock:
        from agents.vecenv import VecFlightClock

        schedule = adapter.config.flight_schedule
        if schedule is None:
            raise UsageError(f"{hp.source}, {hp.env_id}: flight_clock needs a flight")
        env = VecFlightClock(env, schedule.scales[: adapter.config.max_episode_steps])
    if hp.layout.integral:
        from agents.memory import ErrorIntegral
        from agents.vecenv import VecErrorIntegral

        integral = ErrorIntegral(
            adapter.config.dt_s, hp.layout.integral, hp.layout.integral_clip, n_envs
        )
        env = VecErrorIntegral(env, integral)
    if hp.layout.history:
        from agents.vecenv import VecHistory

        env = VecHistory(env, hp.layout.history)
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


# ----------------------------------------------------------------------------- outputs
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
    from agents.memory import ErrorIntegral, FlightClock
    from rollenv.layout import OBSERVATION_NAMES

    layout = layout or PolicyLayout()
    now = [*OBSERVATION_NAMES]
    now += ["v_hat_dps", "psi_hat_deg", "u_d_hat_deg"] if layout.observer else []
    now += list(FlightClock.NAMES) if layout.flight_clock else []
    now += list(ErrorIntegral.NAMES) if layout.integral else []
    past = [f"{name}@t-{k}" for k in range(1, layout.history + 1) for name in now]
    return now + past + [f"action@t-{k}" for k in range(1, layout.history + 1)]


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
