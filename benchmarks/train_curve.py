"""Learning curves against wall time: how fast a PPO recipe reaches the committed policy's and
the PID's score on the evaluation protocol's headline.

For each recipe (a hyperparameter file's entry for ``--env-id``) this trains
PPO exactly as ``agents/train.py`` builds it (``make_env``, ``ppo_arguments``,
1 torch thread) and every ``--eval-every`` env-steps stops the clock and
scores the deterministic policy on the protocol (test split, ``--episodes``
episodes, seed 0; the headline of :mod:`agents.evaluate`).  The references
are measured in the same run: the committed policy of the env id and the
PID.  It prints per recipe the env-steps/s of training (evaluations not
counted), the wall time at which its headline first reached the committed
policy's and the PID's, and its best; and writes a PNG of headline against
training wall time, all recipes side by side.  Exit status 0 whatever the
numbers.

Run from the repository root::

    .venv/bin/python benchmarks/train_curve.py                   # ppo.yml against ppo-fast.yml
    .venv/bin/python benchmarks/train_curve.py --recipe fast=agents/hyperparams/ppo-fast.yml \\
        --timesteps 3000000 --png build/curve.png
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from agents.evaluate import evaluate, headline_scores, protocol_episodes
from agents.ppo import ObservationNormalizer, PPOController
from agents.registry import make_controller
from agents.train import (
    HYPERPARAMS_DIR,
    load_hyperparameters,
    make_env,
    normalization_record,
    ppo_arguments,
)
from rollenv.bank import load_bank, variant_config

DEFAULT_RECIPES = (
    f"ppo.yml={HYPERPARAMS_DIR / 'ppo.yml'}",
    f"ppo-fast.yml={HYPERPARAMS_DIR / 'ppo-fast.yml'}",
)


class Scorer(BaseCallback):
    """Every ``every`` env-steps: the clock stops, the policy is scored on the protocol."""

    def __init__(self, every: int, score: Any, normalize: Any, task: str) -> None:
        super().__init__()
        self.every, self.score, self.normalize, self.task = every, score, normalize, task
        self.next = every
        self.paused = 0.0
        self.began = 0.0
        self.curve: list[tuple[float, int, float]] = []  # (train wall s, env-steps, headline)

    def _on_training_start(self) -> None:
        self.began = time.perf_counter()

    def _on_rollout_end(self) -> None:
        if self.num_timesteps < self.next:
            return
        self.next += self.every
        stopped = time.perf_counter()
        wall = stopped - self.began - self.paused
        settings = {"algorithm": "ppo", "env_settings": {"task": self.task}}
        record = normalization_record(self.normalize)
        controller = PPOController(self.model, ObservationNormalizer(record), settings)
        self.curve.append((wall, self.num_timesteps, self.score(controller)))
        self.model.policy.set_training_mode(True)
        self.paused += time.perf_counter() - stopped

    def _on_step(self) -> bool:
        return True


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="RocketRoll-v0", help="environment id")
    parser.add_argument(
        "--recipe",
        action="append",
        metavar="LABEL=YAML",
        help="a hyperparameter file to train with (repeatable; default: ppo.yml and ppo-fast.yml)",
    )
    parser.add_argument("--timesteps", type=int, help="env-steps per recipe (default: the YAML's)")
    parser.add_argument("--eval-every", type=int, default=100_000, help="env-steps between scores")
    parser.add_argument("--episodes", type=int, default=20, help="protocol episodes per score")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--png", type=Path, help="write the curves here")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch threads (1)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.torch_threads)

    config = variant_config(args.env_id, {"split": "test"})
    bank = load_bank(config, None)
    specs = protocol_episodes(config, args.episodes, 0, bank=bank)

    def score(controller: Any) -> float:
        return float(headline_scores(evaluate(config, controller, specs, bank=bank)).mean())

    references = {
        "committed PPO": score(make_controller("ppo", config, args.env_id)),
        "PID": score(make_controller("pid", config, args.env_id)),
    }
    unit = "°" if config.task == "angle" else "°/s"
    print(f"{args.env_id}: headline on {args.episodes} test episodes (seed 0)")
    for name, value in references.items():
        print(f"  {name:<14} {value:.2f} {unit}")
    curves: dict[str, list[tuple[float, int, float]]] = {}
    rows = []
    for item in args.recipe or DEFAULT_RECIPES:
        label, _, path = item.partition("=")
        hp = load_hyperparameters(path, args.env_id)
        steps = int(args.timesteps or hp.n_timesteps or 1_000_000)
        _, venv, normalize = make_env(hp, hp.n_envs, args.seed, split="train")
        model = PPO(hp.policy, venv, seed=args.seed, **ppo_arguments(hp))
        scorer = Scorer(args.eval_every, score, normalize, config.task)
        began = time.perf_counter()
        model.learn(total_timesteps=steps, callback=scorer)
        train_s = time.perf_counter() - began - scorer.paused
        venv.close()
        curves[label] = scorer.curve
        reach = {
            name: next((w for w, _, h in scorer.curve if h <= value), None)
            for name, value in references.items()
        }
        best = min(scorer.curve, key=lambda c: c[2])
        rows.append((label, hp.n_envs, model.num_timesteps / train_s, reach, best))
        print(
            f"  {label}: {model.num_timesteps:,} env-steps in {train_s:.1f} s "
            f"({model.num_timesteps / train_s:,.0f} env-steps/s, scores not counted)",
            flush=True,
        )
    print()
    names = list(references)
    print(
        "| recipe | envs | env-steps/s | "
        + " | ".join(f"wall to {n} ({references[n]:.2f} {unit})" for n in names)
        + f" | best ({unit}) at |"
    )
    print("|---|---|---|" + "---|" * len(names) + "---|")
    for label, envs, rate, reach, (wall, steps, head) in rows:
        cells = " | ".join(
            "not reached" if reach[n] is None else f"{reach[n]:.0f} s" for n in names
        )
        at = f"{head:.2f} at {wall:.0f} s ({steps:,})"
        print(f"| {label} | {envs} | {rate:,.0f} | {cells} | {at} |")
    if args.png is not None:
        from rocketroll_common.plotting import new_figure, png_bytes

        fig = new_figure(figsize=(7.5, 4.5))
        ax = fig.subplots()
        for label, curve in curves.items():
            data = np.array(curve)
            ax.plot(data[:, 0], data[:, 2], marker="o", ms=3, label=label)
        for (name, value), style in zip(references.items(), ("--", ":"), strict=False):
            ax.axhline(value, color="black", ls=style, lw=1, label=f"{name} {value:.2f} {unit}")
        ax.set_yscale("log")
        ax.set_xlabel(
            f"training wall time (s, scoring not counted; {os.cpu_count()} cores, "
            f"{args.torch_threads} torch thread(s))"
        )
        ax.set_ylabel(f"headline: regulation RMS ({unit})")
        ax.set_title(f"{args.env_id}: PPO learning curves against wall time (seed {args.seed})")
        ax.grid(alpha=0.3, which="both")
        ax.legend(frameon=False, fontsize=8)
        fig.tight_layout()
        args.png.parent.mkdir(parents=True, exist_ok=True)
        args.png.write_bytes(png_bytes(fig, dpi=110))
        print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
