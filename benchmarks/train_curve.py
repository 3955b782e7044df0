"""Learning curves against wall time: how fast a PPO recipe reaches the committed policy's and
the PID's score on the evaluation protocol's headline, over training seeds.

For each recipe (``--recipe LABEL=YAML[@THREADS]``: a hyperparameter file's
entry for ``--env-id`` and its torch threads) and each ``--seeds`` value this
trains PPO exactly as ``agents/train/`` builds it (``make_env``,
``algorithm_arguments``) and every ``--eval-every`` env-steps stops the clock and
scores the deterministic policy on the protocol (test split, ``--episodes``
episodes, seed 0; the headline of :mod:`agents.evaluate`).  The references are
measured in the same run: the committed policy of the env id and the PID.  The
seeds run one recipe after the other (seed 0 of every recipe, then seed 1, ...),
so a busy spell of a shared machine falls on all recipes alike.

It prints one row per recipe and seed (env-steps/s of training with the
evaluations not counted, the training wall time at which the headline first
reached the committed policy's and the PID's, the best), then per recipe the
median over seeds and how many seeds reached each score; a seed that never
reaches a score counts as slower than every seed that does.  ``--png`` draws
headline against training wall time, every seed of every recipe.  Exit status
0 whatever the numbers.

Run from the repository root::

    .venv/bin/python benchmarks/train_curve.py                # ppo.yml@1 vs ppo-fast.yml@2
    .venv/bin/python benchmarks/train_curve.py --recipe fast=agents/hyperparams/ppo-fast.yml@2 \\
        --timesteps 2000000 --seeds 0 1 2 3 4 --png build/curve.png
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from _curves import write_curves
from _recipes import DEFAULT_RECIPES, Recipe, parse_recipe
from _records import emit
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from agents.evaluate import evaluate, headline_scores, protocol_episodes
from agents.learned import LearnedController, ObservationNormalizer
from agents.memory import observation_names
from agents.registry import make_controller
from agents.train import (
    algorithm_arguments,
    load_hyperparameters,
    make_env,
    normalization_record,
    quiet_logger,
)
from rocketroll_common.tables import markdown_table
from rollenv.bank import load_bank, variant_config
from rollenv.config import RollConfig

#: The target: a recipe reaches the committed angle policy's headline within this much
#: training wall time (scoring not counted), per seed and as the median over seeds.
TARGET_S = 30.0
#: The env id whose committed policy the target is stated for.
TARGET_ENV = "RocketRoll-v0"


class Scorer(BaseCallback):
    """Every ``every`` env-steps: the clock stops, the policy is scored on the protocol."""

    def __init__(self, every: int, score: Any, normalize: Any, task: str, hp: Any) -> None:
        super().__init__()
        self.every, self.score, self.normalize, self.task = every, score, normalize, task
        self.hp = hp
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
        hp = self.hp
        settings = {
            "algorithm": "ppo",
            "env_settings": {"task": self.task},
            "hyperparameters": hp.layout.record(),
        }
        record = normalization_record(self.normalize, hp.layout)
        size = len(observation_names(hp.layout))
        controller = LearnedController(self.model, ObservationNormalizer(record, size), settings)
        self.curve.append((wall, self.num_timesteps, self.score(controller)))
        self.model.policy.set_training_mode(True)
        self.paused += time.perf_counter() - stopped

    def _on_step(self) -> bool:
        return True


def _median_time(times: list[float | None]) -> str:
    """The median of first-reach times, a seed that never reached counting as infinite."""
    reached = sum(t is not None for t in times)
    med = statistics.median(math.inf if t is None else t for t in times)
    cell = "not reached" if math.isinf(med) else f"{med:.0f} s"
    return f"{cell} ({reached}/{len(times)})"


def _emit_seed(
    name: str,
    reach: dict[str, float | None],
    best: tuple[float, int, float],
    references: dict[str, float],
    unit: str,
    target: float | None,
) -> None:
    """One seed's figures: the wall time to the committed policy's headline (the target),
    or, where it was not reached, the best headline (above the committed policy's)."""
    committed, pid = references["committed PPO"], references["PID"]
    wall, steps, head = best
    to_pid = f"the PID's {pid:.2f}{unit} " + (
        "not reached" if reach["PID"] is None else f"reached after {reach['PID']:.0f} s"
    )
    at = f"at {wall:.0f} s ({steps:,}) env-steps"
    time_to = reach["committed PPO"]
    if time_to is not None:
        emit(
            f"{name}: wall time to the committed PPO's {committed:.2f}{unit}",
            time_to,
            "s",
            at_most=target,
            note=f"best {head:.2f} {at}; {to_pid}",
        )
    else:  # not reached: the best headline stayed above the committed policy's
        emit(
            f"{name}: best headline",
            head,
            unit,
            at_most=None if target is None else committed,
            note=f"{at}; the committed PPO's {committed:.2f}{unit} not reached; {to_pid}",
        )


#: One evaluation on a curve: (training wall s, env-steps, headline).
Point = tuple[float, int, float]
#: One seed's row: (seed, env-steps/s, wall time to each reference or None, best point).
SeedRow = tuple[int, float, dict[str, float | None], Point]


def _parse(argv: Sequence[str] | None) -> tuple[argparse.Namespace, list[Recipe]]:
    """The command line and its recipes (exit 2 on a recipe whose policy reads the observer)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="RocketRoll-v0", help="environment id")
    parser.add_argument(
        "--recipe",
        action="append",
        metavar="LABEL=YAML[@THREADS]",
        help="a hyperparameter file to train with and its torch threads (repeatable; default: "
        "ppo.yml@1 and ppo-fast.yml@2)",
    )
    parser.add_argument("--timesteps", type=int, help="env-steps per run (default: the YAML's)")
    parser.add_argument("--eval-every", type=int, default=100_000, help="env-steps between scores")
    parser.add_argument("--episodes", type=int, default=20, help="protocol episodes per score")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="training seeds (0)")
    parser.add_argument("--png", type=Path, help="write the curves here")
    parser.add_argument(
        "--torch-threads", type=int, default=1, help="threads of a recipe without @THREADS (1)"
    )
    args = parser.parse_args(argv)
    recipes = [parse_recipe(item, args.torch_threads) for item in args.recipe or DEFAULT_RECIPES]
    for recipe in recipes:
        hp = load_hyperparameters(recipe.path, args.env_id)
        if hp.layout.observer:
            parser.error(
                f"--recipe {recipe.label}: a policy that reads the observer is not scored here "
                "(train it and score its checkpoints with benchmarks/run_curve.py)"
            )
    return args, recipes


def _protocol(env_id: str, episodes: int) -> tuple[RollConfig, Callable[[Any], float]]:
    """The test split's config and the scorer of a controller on the protocol: the mean
    headline over ``episodes`` test episodes (seed 0)."""
    config = variant_config(env_id, {"split": "test"})
    bank = load_bank(config, None)
    specs = protocol_episodes(config, episodes, 0, bank=bank)

    def score(controller: Any) -> float:
        return float(headline_scores(evaluate(config, controller, specs, bank=bank)).mean())

    return config, score


def _references(
    args: argparse.Namespace, config: RollConfig, score: Callable[[Any], float], unit: str
) -> dict[str, float]:
    """The committed policy's and the PID's headlines, measured in this run, printed and
    emitted."""
    references = {
        "committed PPO": score(make_controller("ppo", config, args.env_id)),
        "PID": score(make_controller("pid", config, args.env_id)),
    }
    print(
        f"{args.env_id}: headline on {args.episodes} test episodes (seed 0), {os.cpu_count()} CPUs"
    )
    for name, value in references.items():
        print(f"  {name:<14} {value:.2f} {unit}")
        emit(f"{name} headline (same run)", value, unit, note=f"{args.episodes} test episodes")
    return references


def _train_seed(
    args: argparse.Namespace,
    recipe: Recipe,
    seed: int,
    task: str,
    score: Callable[[Any], float],
    references: dict[str, float],
    unit: str,
    target: float | None,
) -> tuple[list[Point], SeedRow]:
    """Train one recipe on one seed, scoring it every ``--eval-every`` env-steps; print and
    emit its row; its curve and its row."""
    hp = load_hyperparameters(recipe.path, args.env_id)
    steps = int(args.timesteps or hp.n_timesteps or 1_000_000)
    torch.set_num_threads(recipe.threads)
    _, venv, normalize = make_env(hp, hp.n_envs, seed, split="train")
    model = PPO(hp.policy, venv, seed=seed, device="cpu", **algorithm_arguments(hp))
    model.set_logger(quiet_logger())
    scorer = Scorer(args.eval_every, score, normalize, task, hp)
    began = time.perf_counter()
    model.learn(total_timesteps=steps, callback=scorer)
    train_s = time.perf_counter() - began - scorer.paused
    venv.close()
    reach = {
        name: next((w for w, _, h in scorer.curve if h <= value), None)
        for name, value in references.items()
    }
    best = min(scorer.curve, key=lambda c: c[2])
    rate = model.num_timesteps / train_s
    cells = ", ".join(
        f"{n} {'not reached' if reach[n] is None else f'after {reach[n]:.0f} s'}"
        for n in references
    )
    print(
        f"  {recipe.label} seed {seed}: {model.num_timesteps:,} env-steps in "
        f"{train_s:.1f} s ({rate:,.0f} env-steps/s, {recipe.threads} thread(s)); "
        f"{cells}; best {best[2]:.2f} {unit}",
        flush=True,
    )
    name = f"{recipe.label} ({recipe.threads} thread(s)), seed {seed}"
    emit(
        f"{name}: env-steps/s",
        rate,
        "env-steps/s",
        note=f"{model.num_timesteps:,} env-steps in {train_s:.1f} s",
    )
    _emit_seed(name, reach, best, references, unit, target)
    return scorer.curve, (seed, rate, reach, best)


def _median_row(
    recipe: Recipe,
    runs: list[SeedRow],
    references: dict[str, float],
    unit: str,
    target: float | None,
) -> list[str]:
    """One recipe's medians over its seeds: emitted (the wall time to the committed policy's
    headline, or how many seeds reached it) and its table row."""
    names = list(references)
    committed = references["committed PPO"]
    rate = statistics.median(r[1] for r in runs)
    medians = [_median_time([r[2][n] for r in runs]) for n in names]
    best_median = statistics.median(r[3][2] for r in runs)
    times = [r[2]["committed PPO"] for r in runs]
    n_reached = sum(t is not None for t in times)
    median = statistics.median(math.inf if t is None else t for t in times)
    note = (
        f"best headline median {best_median:.2f}{unit}; env-steps/s median {rate:,.0f}; "
        f"median wall time to the PID's: {_median_time([r[2]['PID'] for r in runs])}"
    )
    name = f"{recipe.label}, median of {len(runs)}"
    if math.isfinite(median):
        emit(
            f"{name}: wall time to {committed:.2f}{unit}",
            median,
            "s",
            at_most=target,
            note=f"{n_reached} of {len(runs)} seeds reached it; {note}",
        )
    else:  # the median seed never reached it: fewer than half did
        emit(
            f"{name}: seeds that reached the committed PPO's {committed:.2f}{unit}",
            n_reached,
            f"of {len(runs)}",
            at_least=None if target is None else len(runs) // 2 + 1,
            note=f"the median wall time to it: not reached; {note}",
        )
    return [
        f"**{recipe.label}, median of {len(runs)}**",
        str(recipe.threads),
        "–",
        f"{rate:,.0f}",
        *medians,
        f"{best_median:.2f}",
    ]


def _print_table(
    recipes: Sequence[Recipe],
    rows: dict[str, list[SeedRow]],
    references: dict[str, float],
    unit: str,
    target: float | None,
    medians: bool,
) -> None:
    """Print the table of every recipe's seeds and, with ``medians`` (more than one seed),
    their medians."""
    names = list(references)
    header = [
        "recipe",
        "threads",
        "seed",
        "env-steps/s",
        *(f"wall to {n} ({references[n]:.2f} {unit})" for n in names),
        f"best ({unit}) at",
    ]
    table = []
    for recipe in recipes:
        for seed, rate, reach, (wall, steps, head) in rows[recipe.label]:
            reached = ["not reached" if reach[n] is None else f"{reach[n]:.0f} s" for n in names]
            at = f"{head:.2f} at {wall:.0f} s ({steps:,})"
            table.append(
                [recipe.label, str(recipe.threads), str(seed), f"{rate:,.0f}", *reached, at]
            )
        if medians:
            table.append(_median_row(recipe, rows[recipe.label], references, unit, target))
    print("\n".join(markdown_table(header, table)))


def _write_png(
    args: argparse.Namespace,
    curves: dict[tuple[str, int], list[Point]],
    references: dict[str, float],
    unit: str,
) -> None:
    """Draw headline against training wall time, every seed of every recipe, to ``--png``."""
    seeds = ", ".join(map(str, args.seeds))
    write_curves(
        args.png,
        [
            (label, [c[0] for c in curve], [c[2] for c in curve])
            for (label, _), curve in curves.items()
        ],
        references,
        unit=unit,
        xlabel=f"training wall time (s, scoring not counted; {os.cpu_count()} cores)",
        title=f"{args.env_id}: PPO learning curves against wall time (seeds {seeds})",
    )
    print(f"wrote {args.png}")


def main(argv: Sequence[str] | None = None) -> int:
    """Measure the references, train every recipe on every seed (seed by seed), print the
    table and draw the curves; exit 0."""
    args, recipes = _parse(argv)
    config, score = _protocol(args.env_id, args.episodes)
    unit = "°" if config.task == "angle" else "°/s"
    references = _references(args, config, score, unit)
    target = TARGET_S if args.env_id == TARGET_ENV else None
    curves: dict[tuple[str, int], list[Point]] = {}
    rows: dict[str, list[SeedRow]] = {r.label: [] for r in recipes}
    for seed in args.seeds:
        for recipe in recipes:
            curve, row = _train_seed(
                args, recipe, seed, config.task, score, references, unit, target
            )
            curves[recipe.label, seed] = curve
            rows[recipe.label].append(row)
    print()
    _print_table(recipes, rows, references, unit, target, medians=len(args.seeds) > 1)
    if args.png is not None:
        _write_png(args, curves, references, unit)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
