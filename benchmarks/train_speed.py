"""Wall time and env-steps/s of PPO training on RocketRoll: recipes before and after, side by
side in the same run, each against its environment stepping alone.

For each recipe (``--recipe LABEL=YAML[@THREADS]``, repeatable; default: the
default recipe, ``ppo.yml``, with 1 torch thread, *before*, and the throughput
recipe ``ppo-fast.yml`` with 2, *after*) this measures, in one run:

* **PPO training**: ``PPO.learn`` on ``VecNormalize(VecMonitor(RollVecEnv))``
  exactly as ``agents/train/`` builds it (no evaluation, no checkpoints,
  no progress bar), split into rollout collection (env steps plus the
  policy's forward passes, timed by a callback) and the gradient updates.
  The recipes train in alternating blocks (``--blocks``; ``learn`` continued
  with ``reset_num_timesteps=False``), so a busy spell of a shared machine
  slows all of them alike;
* **the reference in the same run**: each recipe's adapter alone
  (:class:`agents.vecenv.RollVecEnv`, its ``num_envs``) stepping with random
  actions drawn beforehand, and the same through the wrappers PPO sees;
  timed in blocks before *and* after training (median over all blocks).

The ``env share`` column is the environment's (with wrappers) time for PPO's
number of env-steps as a fraction of PPO's wall time; ``speed-up`` is each
recipe's env-steps/s over the first recipe's.  Exit status 0 whatever the
timings.

Run from the repository root::

    .venv/bin/python benchmarks/train_speed.py                      # before/after, 0.5 M each
    .venv/bin/python benchmarks/train_speed.py --env-id RocketRollRate-v0 \\
        --recipe agents/hyperparams/ppo.yml@1 --recipe fast=agents/hyperparams/ppo-fast.yml@1
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import stable_baselines3
import torch
from _recipes import DEFAULT_RECIPES, Recipe, parse_recipe
from _records import emit
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from agents.train import algorithm_arguments, load_hyperparameters, make_env, quiet_logger
from agents.vecenv import RollVecEnv
from rocketroll_common.tables import Column, text_table

#: The training speed a recipe should reach on this machine (env-steps/s).
TARGET_STEPS_S = 50_000.0
#: One recipe per line: its settings, PPO's speed and shares, and its environment alone.
COLUMNS = (
    Column("recipe", 16, "<"),
    Column("envs", 5, ">", " "),
    Column("thr", 3, ">", " "),
    Column("env-steps", 10, ">", " "),
    Column("wall s", 7, ">", " "),
    Column("env-steps/s", 12, ">", " "),
    Column("rollout", 8, ">", " "),
    Column("updates", 8, ">", " "),
    Column("env alone/s", 12, ">", " "),
    Column("+wrappers/s", 12, ">", " "),
    Column("env share", 9, ">", " "),
    Column("speed-up", 8, ">", " "),
)


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


@dataclass
class _Run:
    """One recipe's model, timers and reference steppers."""

    recipe: Recipe
    n_envs: int
    model: Any
    timer: RolloutTimer
    alone: Callable[[], float]
    wrapped: Callable[[], float]
    ppo_s: float = 0.0
    rates: dict[str, list[float]] = field(default_factory=lambda: {"alone": [], "wrapped": []})


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="RocketRoll-v0", help="environment id")
    parser.add_argument(
        "--recipe",
        action="append",
        metavar="LABEL=YAML[@THREADS]",
        help="a hyperparameter file and its torch threads (repeatable; default: ppo.yml@1 and "
        "ppo-fast.yml@2)",
    )
    parser.add_argument(
        "--timesteps", type=int, default=500_000, help="env-steps per recipe (500000)"
    )
    parser.add_argument("--blocks", type=int, default=5, help="alternating training blocks (5)")
    parser.add_argument("--ref-steps", type=int, default=2000, help="batched steps per ref block")
    parser.add_argument("--repeats", type=int, default=3, help="ref blocks before and after (3)")
    parser.add_argument("--seed", type=int, default=0)
    ns = parser.parse_args(argv)
    if ns.timesteps < 1 or ns.blocks < 1:
        raise SystemExit("--timesteps and --blocks must be positive")
    recipes = [parse_recipe(item, 1) for item in ns.recipe or DEFAULT_RECIPES]

    print(
        f"python {platform.python_version()}, numpy {np.__version__}, torch {torch.__version__}, "
        f"stable-baselines3 {stable_baselines3.__version__}, {os.cpu_count()} CPU(s), "
        f"{platform.machine()}"
    )
    print(f"{ns.env_id}: {ns.timesteps:,} env-steps per recipe in {ns.blocks} alternating blocks\n")
    runs = []
    for recipe in recipes:
        hp = load_hyperparameters(recipe.path, ns.env_id)
        alone = _stepper(RollVecEnv(hp.n_envs, ns.env_id, seed=ns.seed), ns.ref_steps, ns.seed)
        _, wrapped_env, _ = make_env(hp, hp.n_envs, ns.seed, split="train")
        wrapped = _stepper(wrapped_env, ns.ref_steps, ns.seed)
        alone()  # numba compile or cache load, first-touch costs
        wrapped()
        _, env, _ = make_env(hp, hp.n_envs, ns.seed, split="train")
        torch.set_num_threads(recipe.threads)
        model = PPO(hp.policy, env, seed=ns.seed, device="cpu", **algorithm_arguments(hp))
        model.set_logger(quiet_logger())
        runs.append(_Run(recipe, hp.n_envs, model, RolloutTimer(), alone, wrapped))
        print(
            f"  {recipe.label}: {hp.n_envs} envs x {model.n_steps} steps, batch "
            f"{model.batch_size}, {model.n_epochs} epochs, {recipe.threads} torch thread(s) "
            f"({recipe.path})"
        )

    def measure() -> None:
        for _ in range(ns.repeats):
            for run in runs:
                torch.set_num_threads(run.recipe.threads)
                run.rates["alone"].append(ns.ref_steps * run.n_envs / run.alone())
                run.rates["wrapped"].append(ns.ref_steps * run.n_envs / run.wrapped())

    measure()
    for block in range(ns.blocks):
        for run in runs:
            torch.set_num_threads(run.recipe.threads)
            target = ns.timesteps * (block + 1) // ns.blocks
            chunk = target - run.model.num_timesteps
            if chunk <= 0:  # a rollout larger than a block: the next block catches up
                continue
            t0 = time.perf_counter()
            run.model.learn(total_timesteps=chunk, callback=run.timer, reset_num_timesteps=False)
            run.ppo_s += time.perf_counter() - t0
    measure()

    header = text_table(COLUMNS, [])[0]
    print()
    print(header)
    print("-" * len(header))
    first = 0.0
    for run in runs:
        steps = int(run.model.num_timesteps)
        rate = steps / run.ppo_s
        first = first or rate
        alone_rate = statistics.median(run.rates["alone"])
        wrapped_rate = statistics.median(run.rates["wrapped"])
        cells = [
            run.recipe.label,
            str(run.n_envs),
            str(run.recipe.threads),
            f"{steps:,}",
            f"{run.ppo_s:.1f}",
            f"{rate:,.0f}",
            f"{run.timer.collect_s / run.ppo_s:.0%}",
            f"{1 - run.timer.collect_s / run.ppo_s:.0%}",
            f"{alone_rate:,.0f}",
            f"{wrapped_rate:,.0f}",
            f"{steps / wrapped_rate / run.ppo_s:.1%}",
            f"{rate / first:.1f}x",
        ]
        print(text_table(COLUMNS, [cells])[1])
        emit(
            f"{run.recipe.label}, {run.n_envs} envs, {run.recipe.threads} thread(s)",
            rate,
            "env-steps/s",
            at_least=TARGET_STEPS_S,
            note=f"{steps:,} env-steps in {run.ppo_s:.1f} s; environment share "
            f"{steps / wrapped_rate / run.ppo_s:.1%}",
        )
    spreads = [(max(r) - min(r)) / statistics.median(r) for run in runs for r in run.rates.values()]
    print(
        "\nrollout / updates: shares of PPO's wall time (rollout = env steps + the policy's "
        "forward passes + the buffer);\nenv alone, +wrappers: medians of the reference blocks "
        f"before and after training (largest spread (best - worst) / median: {max(spreads):.0%});"
        "\nenv share: the environment with its wrappers at that rate, as a share of PPO's wall time"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
