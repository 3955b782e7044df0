"""A sweep's trials: the points of its spec (a grid or a seeded random sample), each with an
id that is the hash of what decides its result, trained (if learned) and evaluated."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import json
import os
import shutil
import subprocess
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.replay import (
    options_config,
)
from agents.sweep.spec import ControllerSpec, SweepSpec, entry_with, points
from rocketroll_common import __version__


# ----------------------------------------------------------------------------- trials
@dataclass(frozen=True)
class Trial:
    """One point of a sweep: everything that decides its result (and so its id)."""

    sweep: str
    env_id: str
    controller: ControllerSpec
    params: dict[str, Any]
    settings: dict[str, Any]
    seed: int | None
    episodes: int
    eval_seed: int
    #: A learned controller's effective hyperparameter entry (its file's, with the grid's
    #: values and the settings as env_kwargs): what the id hashes, not the file's path.
    recipe: dict[str, Any] | None = None

    def spec(self) -> dict[str, Any]:
        """The trial as plain data (what the store keeps and the id hashes)."""
        c = self.controller
        return {
            "env_id": self.env_id,
            "controller": c.name,
            "policy": c.policy,
            "train": c.train,
            "hyperparams": c.hyperparams,
            "timesteps": c.timesteps,
            "params": self.params,
            "settings": self.settings,
            "seed": self.seed,
            "episodes": self.episodes,
            "eval_seed": self.eval_seed,
            "recipe": self.recipe,
        }

    @property
    def id(self) -> str:
        """16 hex digits of the SHA-256 of :meth:`spec` without the recipe file's path (its
        content is in ``recipe``: an edited file makes new trials, a moved one does not; the
        sweep's name is not in it either: the same trial in two sweeps is one experiment)."""
        spec = self.spec()
        del spec["hyperparams"]
        text = json.dumps(spec, sort_keys=True, default=str)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]

    @property
    def label(self) -> str:
        """``controller`` with its searched values, for tables (``ppo lr=0.0003``)."""
        parts = [self.controller.name]
        parts += [f"{k}={v}" for k, v in sorted(self.params.items())]
        parts += [f"{k}={v}" for k, v in sorted(self.settings.items())]
        return " ".join(parts)


def expand(spec: SweepSpec) -> list[Trial]:
    """The trials of ``spec``: the full grid, or (``kind: random``) ``trials`` of its
    points drawn without replacement with ``search_seed``, in grid order.  A random
    sample of ``k`` points is the first ``k`` of one seeded permutation, so a larger
    sample contains a smaller one.  Repeated points (a value listed twice) are one trial."""
    trials: dict[str, Trial] = {}
    for env_id in spec.env_ids:
        for settings in points(spec.settings):
            for controller in spec.controllers:
                seeds: Sequence[int | None] = spec.seeds if controller.learned else [None]
                for params in points(controller.grid):
                    recipe = None
                    if controller.learned:
                        assert controller.hyperparams is not None and controller.train
                        # The disturbance set is trained on too (checked with the entry,
                        # before any trial); training reads the whole train split, so a
                        # recording chooses only what is evaluated.
                        trained_on = {
                            f"env_kwargs.{k}": v for k, v in settings.items() if k != "recording"
                        }
                        recipe = entry_with(
                            Path(controller.hyperparams),
                            env_id,
                            controller.train,
                            {**params, **trained_on},
                        )
                    for seed in seeds:
                        trial = Trial(
                            spec.name,
                            env_id,
                            controller,
                            params,
                            settings,
                            seed,
                            spec.episodes,
                            spec.eval_seed,
                            recipe,
                        )
                        trials.setdefault(trial.id, trial)
    found = list(trials.values())
    if spec.kind == "random" and spec.trials is not None and spec.trials < len(found):
        order = np.random.default_rng(spec.search_seed).permutation(len(found))
        found = [found[i] for i in np.sort(order[: spec.trials])]
    return found


@functools.cache  # once per process: every trial of a run comes from the same checkout
def _git_revision() -> str | None:
    """The checkout's commit (with ``-dirty`` for uncommitted changes), None outside git."""
    root = Path(__file__).resolve().parent.parent
    try:
        rev = subprocess.run(
            ["git", "-C", str(root), "describe", "--always", "--dirty", "--abbrev=40"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return rev or None


def _record(trial: Trial) -> dict[str, Any]:
    """A trial's record before its result: what it is and what ran it."""
    return {
        "id": trial.id,
        "sweep": trial.sweep,
        "env_id": trial.env_id,
        "controller": trial.label,
        "seed": trial.seed,
        "spec": trial.spec(),
        "version": __version__,
        "git_revision": _git_revision(),
    }


def failed_record(trial: Trial, error: str, wall_s: float = 0.0) -> dict[str, Any]:
    """The record of a trial that gave no result of its own (its worker died)."""
    return {**_record(trial), "status": "failed", "error": error, "wall_s": wall_s}


def run_trial(trial: Trial, root: str | os.PathLike[str], db: str | None = None) -> dict[str, Any]:
    """Train (a learned controller) and evaluate one trial; its store record.

    Never raises for the trial's own failure: the record then has status
    ``failed`` and the error (its last traceback lines).  Output of training
    and evaluation is captured, not printed (trials may run side by side).
    """
    began = time.perf_counter()
    record = _record(trial)
    folder = Path(root) / "trials" / trial.id
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            record.update(_train_and_evaluate(trial, folder, db))
        record["status"] = "done"
    except Exception as exc:  # a failed trial is a result, not a crash
        lines = traceback.format_exception(exc)
        record["status"] = "failed"
        record["error"] = f"{type(exc).__name__}: {exc}\n" + "".join(lines[-6:])
    record["wall_s"] = time.perf_counter() - began
    return record


def _train_and_evaluate(trial: Trial, folder: Path, db: str | None) -> dict[str, Any]:
    import yaml

    from agents.evaluate import HEADLINE, evaluate, headline_scores, protocol_episodes
    from agents.registry import make_controller
    from rollenv.bank import load_bank

    c = trial.controller
    artifacts: dict[str, str] = {}
    out: dict[str, Any] = {}
    policy = c.policy
    if c.learned:
        from agents.train import TRAIN_ARGS, train

        assert trial.recipe is not None and c.train is not None
        entry = trial.recipe
        shutil.rmtree(folder, ignore_errors=True)  # a retried trial starts afresh
        folder.mkdir(parents=True)
        hyperparams = folder / "hyperparams.yml"
        hyperparams.write_text(yaml.safe_dump({trial.env_id: entry}), encoding="utf-8")
        run = folder / "run"
        args = TRAIN_ARGS[c.train](
            env_id=trial.env_id,
            hyperparams=hyperparams,
            out=run,
            seed=int(trial.seed or 0),
            timesteps=c.timesteps,
            db=db,
            eval_freq=0,
            checkpoint_freq=0,
            progress_bar=False,
        )
        settings = train(args)
        out["train_s"] = float(settings["train_time_s"])
        out["env_steps_per_s"] = float(settings["env_steps_per_s"])
        artifacts.update(run=str(run), model=str(run / "model.zip"), hyperparams=str(hyperparams))
        policy = f"{c.train}:{run}"
    assert policy is not None
    config = options_config(trial.env_id, trial.settings, "test")
    controller = make_controller(policy, config, trial.env_id, db=db)
    bank = load_bank(config, db)
    specs = protocol_episodes(config, trial.episodes, trial.eval_seed, bank=bank)
    result = evaluate(config, controller, specs, bank=bank)
    scores = headline_scores(result)
    out.update(
        headline=HEADLINE,
        headline_mean=float(np.nanmean(scores)) if np.isfinite(scores).any() else None,
        metrics={k: v["mean"] for k, v in result.aggregate.items()},
        episode_headline=scores.tolist(),
        artifacts=artifacts,
    )
    return out
