"""Training recipes named on a benchmark's command line: ``LABEL=YAML[@THREADS]``.

A recipe is a hyperparameter file's entry for the env id (``agents/train/``'s
layout) and the number of torch threads it trains with: the threads are part of
a recipe's speed (big batches gain from a second core, small ones lose), so the
old and the new settings are compared each with its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from agents.train import HYPERPARAMS_DIR

__all__ = ["DEFAULT_RECIPES", "Recipe", "parse_recipe"]

#: Before and after: the default recipe (16 envs x 256 steps, batch 256,
#: 1 thread) and the throughput recipe (512 envs x 32 steps, batch 8192, 2 threads).
DEFAULT_RECIPES = (
    f"ppo.yml={HYPERPARAMS_DIR / 'ppo.yml'}@1",
    f"ppo-fast.yml={HYPERPARAMS_DIR / 'ppo-fast.yml'}@2",
)


@dataclass(frozen=True)
class Recipe:
    """A label, a hyperparameter file and the torch threads to train with."""

    label: str
    path: Path
    threads: int


def parse_recipe(item: str, default_threads: int) -> Recipe:
    """``LABEL=YAML[@THREADS]`` (``YAML`` alone: its file name is the label).

    Raises ``SystemExit`` naming the item when it is malformed or the file is missing.
    """
    label, sep, rest = item.partition("=")
    if not sep:
        label, rest = "", item
    path, at, threads = rest.partition("@")
    if at:
        if not threads.isdigit() or int(threads) < 1:
            raise SystemExit(f"--recipe {item}: THREADS after '@' must be a positive integer")
        n = int(threads)
    else:
        n = default_threads
    file = Path(path)
    if not file.is_file():
        raise SystemExit(f"--recipe {item}: {path}: no such file")
    return Recipe(label or file.name, file, n)
