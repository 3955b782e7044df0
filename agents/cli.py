"""``rocketroll`` commands of the agents layer: ``train``, ``eval``, ``seeds``, ``robustness``,
``sweep``, ``tune``.

Training's commands are here (:data:`TRAIN_COMMAND` and its off-policy siblings: the
arguments dataclasses of :mod:`agents.train` and a function), as are the sweep's
(:mod:`agents.sweep`); the others live beside what they run (:data:`agents.evaluate.COMMAND`,
:data:`agents.tune.COMMAND`, ...). ``python -m agents.train`` and ``rocketroll train ppo``
are one command.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import agents.sweep
import agents.train
from agents import evaluate, robustness, seeds, tune
from agents.replay import (
    check_options,
    db_setting,
    env_options_setting,
    fitted_settings,
    options_config,
    recording_setting,
    replay_options,
)
from agents.sweep import ResultStore, SweepSpec, expand, load_spec, points, report, run_sweep
from agents.sweep.runner import ray_module
from agents.train import Args, SACArgs, TD3Args
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, setting

__all__ = [
    "COMMANDS",
    "RECIPE_COMMAND",
    "SAC_COMMAND",
    "SWEEP_COMMAND",
    "TD3_COMMAND",
    "TRAIN_COMMAND",
    "SweepReportArgs",
    "SweepRunArgs",
]


def _train(args: Args) -> int:
    agents.train.train(args)
    return 0


#: ``rocketroll train ppo`` (``python -m agents.train``).
TRAIN_COMMAND = Command(
    "ppo",
    "train PPO on a RocketRoll environment (Stable-Baselines3)",
    Args,
    _train,
    agents.train.__doc__ or "",
)
#: ``rocketroll train sac`` and ``rocketroll train td3``: the same script, off-policy.
SAC_COMMAND = Command(
    "sac",
    "train SAC on a RocketRoll environment (Stable-Baselines3)",
    SACArgs,
    _train,
    agents.train.__doc__ or "",
)
TD3_COMMAND = Command(
    "td3",
    "train TD3 on a RocketRoll environment (Stable-Baselines3)",
    TD3Args,
    _train,
    agents.train.__doc__ or "",
)


@dataclass(frozen=True)
class RecipeArgs:
    """``rocketroll train recipe``."""

    name: str | None = setting(
        None, help="a shipped recipe (none: list them)", positional=True, metavar="NAME"
    )
    out: Path | None = setting(
        None, "write a copy of the recipe to this file (to edit it)", output="file"
    )

    def __post_init__(self) -> None:
        check(self)
        shipped = agents.train.shipped_recipes()
        if self.name is not None and self.name not in shipped:
            raise UsageError(
                f"NAME {self.name}: no shipped recipe of that name (those are: "
                f"{', '.join(shipped)})"
            )
        if self.out is not None and self.name is None:
            raise UsageError("--out copies one recipe: name it (rocketroll train recipe NAME)")


def _recipe(args: RecipeArgs) -> int:
    from rocketroll_common.files import write_atomic
    from rocketroll_common.specs import load_yaml

    if args.name is None:
        for name in agents.train.shipped_recipes():
            document, _ = load_yaml(agents.train.recipe_path(name))
            keys = ", ".join(map(str, document)) if isinstance(document, dict) else "?"
            print(f"{name:<14} {keys}")
        print(f"(in {agents.train.HYPERPARAMS_DIR}; rocketroll train ppo --hyperparams NAME)")
        return 0
    path = agents.train.recipe_path(args.name)
    if args.out is None:
        print(path)  # for rl-zoo: -conf "$(rocketroll train recipe ppo)"
        return 0
    write_atomic(args.out, path.read_text(encoding="utf-8"))
    print(f"wrote {args.out}: a copy of {path}")
    return 0


#: ``rocketroll train recipe [NAME]``: the shipped hyperparameter files, by name.
RECIPE_COMMAND = Command(
    "recipe",
    "the shipped hyperparameter recipes: list them, print one's path (for rl-zoo's -conf) "
    "or --out a copy",
    RecipeArgs,
    _recipe,
)


# ---------------------------------------------------------------------------- sweep
@dataclass(frozen=True)
class SweepRunArgs:
    """``rocketroll sweep run``."""

    spec: Path = setting(help="the sweep spec (YAML)", positional=True, metavar="SPEC", input=True)
    out: Path | None = setting(
        None,
        "folder of the results store and trial outputs (default: runs/sweeps/NAME)",
        output="folder",
    )
    jobs: int = setting(1, "trials run side by side (worker processes)", ge=1, le=256)
    db: str | None = db_setting()
    progress: bool = setting(True, "show the progress bar")
    ray: str | None = setting(
        None,
        "run the trials on Ray Tune: 'auto' (this machine's cluster, or a local instance) or "
        "a cluster's ADDRESS (HOST:6379); the optional extra rocketroll[ray]",
        metavar="ADDRESS",
    )
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()

    def __post_init__(self) -> None:
        check(self)
        check_options(self.settings)


def _sweep_run(args: SweepRunArgs) -> int:
    settings = replay_options(args.settings, args.recording)
    if args.recording is not None:
        spec = load_spec(args.spec, settings)
        for env_id in spec.env_ids:
            settings, note = fitted_settings(env_id, settings, None, args.db)
            if note:
                print(note)
    spec = load_spec(args.spec, settings)
    if args.ray:
        ray_module(args.ray)  # refused before anything is made or printed
    _check_replays(spec, args.db)
    out = args.out if args.out is not None else Path("runs") / "sweeps" / spec.name
    trials = expand(spec)
    print(f"rocketroll sweep: {spec.name} ({spec.source}), {len(trials)} trials, out {out}")
    with ResultStore(out / "results.sqlite") as store:
        skipped = len({t.id for t in trials} & store.done())
    records = run_sweep(
        spec, out, jobs=args.jobs, db=args.db, progress=args.progress, ray=args.ray, trials=trials
    )
    failed = [r for r in records if r["status"] == "failed"]
    print(
        f"ran {len(records)} trials ({len(failed)} failed), skipped {skipped} already done; "
        f"results in {out / 'results.sqlite'}"
    )
    return 1 if failed else 0


def _check_replays(spec: SweepSpec, db: str | None) -> None:
    """Refuse (:class:`disturbances.bank.BankError`, one line) a sweep whose database lacks
    a replay it asks for, before any trial: every trial would fail on it.  The designs
    read the train split (all its recordings), the evaluation the test split."""
    from rollenv.bank import load_bank

    for env_id in spec.env_ids:
        for point in points(spec.settings):
            evaluated = options_config(env_id, point, "test")
            load_bank(evaluated, db)
            load_bank(dataclasses.replace(evaluated, split="train", recording=None), db)


@dataclass(frozen=True)
class SweepReportArgs:
    """``rocketroll sweep report``."""

    sweep_dir: Path = setting(
        help="the sweep's folder (holding results.sqlite)", positional=True, metavar="DIR"
    )
    name: str | None = setting(None, "only the trials of this sweep name (default: all)")
    out: Path | None = setting(
        None,
        "folder for report.md and one report-N.png per table (default: DIR)",
        output="folder",
        files=("report.md",),  # and the figures, checked as they are written
    )
    seed: int = setting(0, "seed of the bootstrap", ge=0, le=2**31 - 1)

    def __post_init__(self) -> None:
        check(self)


def _sweep_report(args: SweepReportArgs) -> int:
    from agents.seeds import markdown_table, plot
    from rocketroll_common.files import write_all_atomic
    from rollenv.bank import variant_config

    store_path = args.sweep_dir / "results.sqlite"
    if not store_path.is_file():
        raise UsageError(f"{store_path}: no results store (run `rocketroll sweep run` first)")
    with ResultStore(store_path) as store:
        rows = store.rows(args.name)
    if not rows:
        raise UsageError(
            f"{store_path}: no trials{f' of sweep {args.name!r}' if args.name else ''}"
        )
    out = args.out if args.out is not None else args.sweep_dir
    text = [f"# Sweep report: {store_path}\n"]
    files: dict[str | os.PathLike[str], str | bytes] = {}
    for n, table in enumerate(report(rows, args.seed), start=1):
        task = variant_config(table["env_id"], table["settings"]).task
        unit = "°" if task == "angle" else "°/s"
        where = ", ".join(f"{k}={v}" for k, v in sorted(table["settings"].items()))
        title = f"{table['env_id']}" + (f" ({where})" if where else "")
        title += f", {table['episodes']} test episodes, seed {table['eval_seed']}"
        text.append(f"## {n}. {title}\n")
        text.append(markdown_table(table["learners"], table["reference_results"], unit))
        for name, label in sorted(table["best"].items()):
            text.append(f"best settings of {name}: {label}  ")
        if table["failed"]:
            text.append(f"failed trials (not scored): {', '.join(table['failed'])}  ")
        text.append("")
        if table["learners"]:
            png = out / f"report-{n}.png"
            files[png] = plot(table["learners"], table["reference_results"], unit, title)
            text.append(f"![{title}: learners over seeds and the references]({png.name})\n")
    document = "\n".join(text)
    print(document, end="")
    files[out / "report.md"] = document
    write_all_atomic(files, folder=out, what="--out" if args.out is not None else "DIR")
    print(
        f"wrote {out / 'report.md'}"
        + (f" and {len(files) - 1} figure(s)" if len(files) > 1 else "")
    )
    return 0


#: ``rocketroll sweep run`` and ``rocketroll sweep report``.
SWEEP_COMMAND = Command(
    "sweep",
    "sweeps over controllers, settings, seeds and tasks, resumable, into a results store",
    description=agents.sweep.__doc__ or "",
    subcommands=(
        Command(
            "run",
            "run (or resume) a sweep spec",
            SweepRunArgs,
            _sweep_run,
            agents.sweep.__doc__ or "",
        ),
        Command(
            "report",
            "tables and plots of a sweep: seeds' statistics, P(beats PID), best settings",
            SweepReportArgs,
            _sweep_report,
            (report.__doc__ or "").split("\n\n", 1)[-1],
        ),
    ),
)


#: The commands of this layer, by name.
COMMANDS: dict[str, Command] = {
    "train": Command(
        "train",
        "train a controller (PPO, SAC, TD3; Stable-Baselines3)",
        description=agents.train.__doc__ or "",
        subcommands=(TRAIN_COMMAND, SAC_COMMAND, TD3_COMMAND, RECIPE_COMMAND),
    ),
    "eval": evaluate.COMMAND,
    "seeds": seeds.COMMAND,
    "robustness": robustness.COMMAND,
    "sweep": SWEEP_COMMAND,
    "tune": Command(
        "tune",
        "re-tune a controller's design on train episodes (the PID's bandwidth)",
        description=tune.__doc__ or "",
        subcommands=(tune.COMMAND,),
    ),
}
