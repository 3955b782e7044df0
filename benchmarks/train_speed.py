"""Wall time and env-steps/s of PPO training on RocketRoll, against the adapter stepping alone.

In one run, with the hyperparameters of ``agents/hyperparams/ppo.yml`` for
``--env-id`` (``--timesteps`` and ``--envs`` overridable), this measures:

* **PPO training**: ``PPO.learn`` on ``VecNormalize(VecMonitor(RollVecEnv))``
  exactly as ``agents/train.py`` builds it (no evaluation, no checkpoints,
  no progress bar), split into rollout collection (env steps plus the
  policy's forward passes, timed by a callback) and the gradient updates;
* **the reference in the same run**: the adapter alone
  (:class:`agents.vecenv.RollVecEnv`, same ``num_envs``) stepping with random
  actions drawn beforehand, and the same through the wrappers PPO sees;
  timed in blocks before *and* after the training run (median over all
  blocks), so a busy spell of a shared machine shows as spread.

The ``share`` column is each row's time for PPO's number of env-steps as a
fraction of PPO's wall time: what the environment costs of a training run,
and so how much is PPO's own overhead (policy inference, GAE, updates).
Exit status 0 whatever the timings.

Run from the repository root::

    .venv/bin/python benchmarks/train_speed.py                      # the YAML budget (minutes)
    .venv/bin/python benchmarks/train_speed.py --timesteps 200000   # a quick measurement
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from agents.train import DEFAULT_HYPERPARAMS, load_hyperparameters, make_env, ppo_arguments
from agents.vecenv import RollVecEnv


class RolloutTimer(BaseCallback):
    """Accumulates the wall time PPO spends collecting rollouts."""

    def __init__(self) -> None:
        super().__init__()
        self.collect_s = 0.0
        self._t0 = 0.0

    def _on_rollout_start(self) -> None:
        self._t0 = time.perf_counter()

    def _on_rollout_end(self) -> None:
        self.collect_s += time.perf_counter() - self._t0

    def _on_step(self) -> bool:
        return True


def _stepper(venv: Any, steps: int, seed: int) -> Callable[[], float]:
    """A timed block of ``steps`` batched steps of ``venv`` with random actions."""
    venv.reset()
    actions = (
        np.random.default_rng(seed)
        .uniform(-1.0, 1.0, size=(steps, venv.num_envs, 1))
        .astype(np.float32)
    )

    def run() -> float:
        step = venv.step
        t0 = time.perf_counter()
        for a in actions:
            step(a)
        return time.perf_counter() - t0

    return run


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="RocketRoll-v0", help="environment id")
    parser.add_argument("--timesteps", type=int, help="env-steps to train (default: the YAML's)")
    parser.add_argument("--envs", type=int, help="environments (default: the YAML's)")
    parser.add_argument("--hyperparams", default=str(DEFAULT_HYPERPARAMS), help="YAML file")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch threads (1)")
    parser.add_argument("--ref-steps", type=int, default=5000, help="batched steps per ref block")
    parser.add_argument("--repeats", type=int, default=3, help="ref blocks before and after (3)")
    parser.add_argument("--seed", type=int, default=0)
    ns = parser.parse_args(argv)

    hp = load_hyperparameters(ns.hyperparams, ns.env_id)
    n_envs = ns.envs or hp.n_envs
    timesteps = ns.timesteps or hp.n_timesteps
    if timesteps is None:
        raise SystemExit(f"--timesteps is needed: {hp.source} has no n_timesteps for {ns.env_id}")
    torch.set_num_threads(ns.torch_threads)
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, torch {torch.__version__} "
        f"({ns.torch_threads} thread(s)), stable-baselines3 {stable_baselines3.__version__}, "
        f"{os.cpu_count()} CPU(s), {platform.machine()}"
    )
    print(f"{ns.env_id}: {timesteps:,} env-steps, {n_envs} envs, hyperparameters of {hp.source}\n")

    alone = _stepper(RollVecEnv(n_envs, ns.env_id, seed=ns.seed), ns.ref_steps, ns.seed)
    _, wrapped_env, _ = make_env(hp, n_envs, ns.seed, split="train")
    wrapped = _stepper(wrapped_env, ns.ref_steps, ns.seed)
    refs = {"RollVecEnv alone, random actions": alone, "  + VecMonitor, VecNormalize": wrapped}
    rates: dict[str, list[float]] = {name: [] for name in refs}
    for run in refs.values():  # numba compile or cache load, first-touch costs
        run()

    def measure() -> None:
        for _ in range(ns.repeats):
            for name, run in refs.items():
                rates[name].append(ns.ref_steps * n_envs / run())

    measure()
    _, env, _ = make_env(hp, n_envs, ns.seed, split="train")
    model = PPO(hp.policy, env, seed=ns.seed, device="cpu", **ppo_arguments(hp))
    timer = RolloutTimer()
    t0 = time.perf_counter()
    model.learn(total_timesteps=timesteps, callback=timer)
    ppo_s = time.perf_counter() - t0
    steps = int(model.num_timesteps)
    measure()

    header = f"{'task':<36} {'env-steps/s':>12} {'spread':>7} {'time s':>8} {'share':>6}"
    print(header)
    print("-" * len(header))
    print(f"{'PPO.learn (total)':<36} {steps / ppo_s:>12,.0f} {'':>7} {ppo_s:>8.1f} {1:>6.0%}")
    update_s = ppo_s - timer.collect_s
    print(
        f"{'  rollout collection':<36} {steps / timer.collect_s:>12,.0f} {'':>7} "
        f"{timer.collect_s:>8.1f} {timer.collect_s / ppo_s:>6.0%}"
    )
    print(
        f"{'  gradient updates (the rest)':<36} {'':>12} {'':>7} {update_s:>8.1f} "
        f"{update_s / ppo_s:>6.0%}"
    )
    for name, r in rates.items():
        med = statistics.median(r)
        spread = (max(r) - min(r)) / med
        env_s = steps / med
        print(f"{name:<36} {med:>12,.0f} {spread:>6.0%} {env_s:>8.1f} {env_s / ppo_s:>6.0%}")
    env_share = steps / statistics.median(rates["  + VecMonitor, VecNormalize"]) / ppo_s
    print(
        f"\n{steps:,} env-steps in {ppo_s:.1f} s: {steps / ppo_s:,.0f} env-steps/s; the "
        f"environment (with wrappers) is {env_share:.1%} of it, PPO's own work "
        f"{1 - env_share:.1%}"
    )
    print(
        "time s for the reference rows: PPO's env-steps at that rate; spread: (best - worst) / "
        "median over the blocks before and after training"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
