"""Robustness: every controller, designed once, on worlds other than the one it was designed for.

``rocketroll robustness [--env-id ID] [--policy P ...]`` designs each
controller on the default environment (its train split, as ``rocketroll
eval`` does) and then runs it, unchanged, through the protocol's held-out
episodes of each *condition*: the same environment with one thing changed.

=====================  ==============================================================
condition              what changes
=====================  ==============================================================
default                nothing: ml's posterior draws of ``u_d`` (the eval table)
surrogates             IAAFT surrogates of the paper's traces (same spectrum and
                       distribution, new phases: turbulence no recording had)
randomised rockets     α, θ̄, β̄, ᾱ drawn at each reset over the database's range
                       (the env's ``domain_randomization``)
u_d x1.5               the turbulence 50 % stronger (``disturbance_scale``)
paper replay           the paper method's identified rockets and ``u_d`` traces
output-error replay    the output-error method's
=====================  ==============================================================

A condition's episodes are drawn by :func:`agents.evaluate.protocol_episodes`
from its own bank with the same ``--seed``.  The table gives the headline
(:data:`agents.evaluate.HEADLINE`) mean ± standard error over the episodes,
and the factor on the controller's default score; the figure the same as
grouped bars (log scale).  Outputs (``--out``): ``robustness.md``,
``robustness.json``, ``robustness.png``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from agents.base import Controller
from agents.evaluate import (
    check_unique_names,
    env_id_setting,
    evaluate,
    headline_scores,
    protocol_episodes,
    protocol_record,
    write_study,
)
from agents.registry import (
    check_policy,
    default_policies,
    make_controller,
    policy_help,
    unnamed_defaults,
)
from agents.replay import (
    check_options,
    db_setting,
    env_options_setting,
    options_config,
    recording_setting,
    replay_config,
    split_setting,
    unreliable_note,
)
from rocketroll_common import tables
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, run_command, setting
from rollenv.bank import load_bank
from rollenv.config import RollConfig

__all__ = ["COMMAND", "CONDITIONS", "Args", "run"]

#: Condition name → the environment settings it changes.
CONDITIONS: dict[str, dict[str, Any]] = {
    "default": {},
    "surrogates": {"method": "paper", "disturbance": "surrogate"},
    "randomised rockets": {"domain_randomization": True},
    "u_d x1.5": {"disturbance_scale": 1.5},
    "paper replay": {"method": "paper"},
    "output-error replay": {"method": "output-error"},
}


def _default_policy() -> list[str]:
    """Every default controller but trim (which has nothing to be robust about) and the
    causal limit."""
    # the causal limit's turbulence model is the design split's: in another world it is
    # not that world's limit
    return [p for p in default_policies() if p not in ("trim", "causal-oracle")]


@dataclass(frozen=True)
class Args:
    """``rocketroll robustness`` / ``python -m agents.robustness``."""

    env_id: str = env_id_setting()
    policy: list[str] = setting(
        default_factory=_default_policy,
        help=lambda: f"controller, in table order (repeatable): {policy_help()}",
        metavar="POLICY",
        always=True,
    )
    condition: list[str] = setting(
        default_factory=lambda: list(CONDITIONS),
        help=lambda: f"condition, in table order (repeatable): {', '.join(CONDITIONS)}",
        metavar="CONDITION",
        always=True,
    )
    episodes: int = setting(20, "protocol episodes per condition", ge=2, le=100_000, always=True)
    seed: int = setting(0, "seed of the protocol's episodes", ge=0, le=2**31 - 1, always=True)
    split: Literal["train", "test"] = split_setting()
    out: Path | None = setting(
        None,
        "folder for robustness.md, robustness.json, robustness.png (none: print only)",
        output="folder",
        files=("robustness.md", "robustness.json", "robustness.png"),
    )
    db: str | None = db_setting()
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()

    def __post_init__(self) -> None:
        check(self)
        check_options(self.settings)
        for name in self.condition:
            if name not in CONDITIONS:
                raise UsageError(
                    f"--condition {name!r}: unknown; one of {', '.join(map(repr, CONDITIONS))}"
                )
        for values, flag in ((self.condition, "--condition"), (self.policy, "--policy")):
            repeated = sorted({v for v in values if values.count(v) > 1})
            if repeated:
                raise UsageError(f"{flag} {repeated[0]} is given twice")
        for policy in unnamed_defaults(self.policy, _default_policy(), self.env_id):
            check_policy(policy, self.env_id)  # before any database is opened


def markdown_table(
    scores: dict[str, dict[str, np.ndarray]], conditions: Sequence[str], unit: str
) -> str:
    """Rows: controllers; columns: conditions; cells: headline mean ± SEM (× default)."""
    rows = []
    for name, per in scores.items():
        base = per["default"].mean() if "default" in per else None
        cells = []
        for c in conditions:
            x = per[c]
            cell = f"{x.mean():.2f} ± {x.std(ddof=1) / np.sqrt(x.size):.2f}"
            if base is not None and c != "default" and base > 0:
                cell += f" (×{x.mean() / base:.1f})"
            cells.append(cell)
        rows.append([name, *cells])
    header = ["controller", *(f"{c} ({unit})" for c in conditions)]
    return "\n".join(tables.markdown_table(header, rows)) + "\n"


def plot(
    scores: dict[str, dict[str, np.ndarray]], conditions: Sequence[str], unit: str, title: str
) -> bytes:
    """Grouped bars: the headline per condition (groups) and controller (bars), ± SEM."""
    from agents.plots import COLOURS
    from rocketroll_common.plotting import new_figure, png_bytes

    fig = new_figure(figsize=(11, 4.8))
    ax = fig.subplots()
    names = list(scores)
    width = 0.8 / max(len(names), 1)
    x = np.arange(len(conditions))
    for i, name in enumerate(names):
        means = np.array([scores[name][c].mean() for c in conditions])
        sems = np.array(
            [scores[name][c].std(ddof=1) / np.sqrt(scores[name][c].size) for c in conditions]
        )
        colour = COLOURS[(i + 1) % len(COLOURS)]
        ax.bar(
            x + (i - (len(names) - 1) / 2) * width,
            means,
            width,
            yerr=sems,
            capsize=2,
            color=colour,
            label=name,
        )
    ax.set_xticks(x, list(conditions))
    ax.set_yscale("log")
    ax.set_ylabel(f"regulation RMS ({unit}, headline), mean ± SEM")
    ax.grid(alpha=0.3, axis="y", which="both")
    ax.legend(frameon=False, fontsize=8, ncol=len(names))
    ax.set_title(title)
    fig.tight_layout()
    return png_bytes(fig, dpi=110)


def _condition_config(args: Args, condition: str) -> RollConfig:
    """The environment of ``condition``: the ``--set`` options with the condition's changes
    on top; a condition that replays another method takes that method's own disturbance
    unless it names one (``--set disturbance=posterior`` is ml's, not the paper's)."""
    changes = CONDITIONS[condition]
    options = dict(args.settings)
    if "method" in changes and "disturbance" not in changes:
        options.pop("disturbance", None)
    return options_config(args.env_id, {**options, **changes}, args.split)


def run(args: Args) -> dict[str, dict[str, np.ndarray]]:
    """Design every controller once, evaluate it under every condition, report."""
    args = replace(args, policy=unnamed_defaults(args.policy, _default_policy(), args.env_id))
    design, _, settings, episode_note = replay_config(
        args.env_id, args.settings, args.recording, args.split, args.db
    )
    args = replace(args, settings=settings)  # every condition on the same recording, episode
    configs = {c: _condition_config(args, c) for c in args.condition}
    banks = {}
    for condition, config in configs.items():  # every condition's replay, before any work
        try:
            banks[condition] = load_bank(config, args.db)
        except ValueError as exc:
            raise UsageError(f"--condition {condition!r}: {exc}") from exc
    try:
        controllers: list[Controller] = [
            make_controller(p, design, args.env_id, db=args.db) for p in args.policy
        ]
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    check_unique_names(controllers)
    unit = "°" if design.task == "angle" else "°/s"
    print(
        f"rocketroll robustness: {args.env_id}, split={args.split}, {args.episodes} episodes "
        f"per condition, seed={args.seed}; controllers designed on the default environment"
    )
    if episode_note:
        print(episode_note)
    caution = unreliable_note(list(banks.values()), args.db)  # stored --accept-unreliable
    scores: dict[str, dict[str, np.ndarray]] = {c.name: {} for c in controllers}
    for condition, config in configs.items():
        bank = banks[condition]
        specs = protocol_episodes(config, args.episodes, args.seed, bank=bank)
        print(f"  {condition}: {bank.description}")
        for controller in controllers:
            result = evaluate(config, controller, specs, bank=bank, progress=True)
            scores[controller.name][condition] = headline_scores(result)
    table = markdown_table(scores, args.condition, unit)
    table += "" if caution is None else f"\n{caution}\n"
    print(table, end="")
    if args.out is not None:
        record = {
            "protocol": protocol_record(
                args,
                caution,
                conditions={c: CONDITIONS[c] for c in args.condition},
                policies=list(args.policy),
            ),
            "scores": {n: {c: v.tolist() for c, v in per.items()} for n, per in scores.items()},
        }
        title = f"{args.env_id}: controllers designed on the default replay, under other worlds"
        figure = plot(scores, args.condition, unit, title)
        write_study(Path(args.out), "robustness", table, record, figure)
    return scores


def _run(args: Args) -> int:
    run(args)
    return 0


#: ``rocketroll robustness``.
COMMAND = Command(
    "robustness",
    "controllers designed once, evaluated on surrogates, randomised rockets, stronger "
    "turbulence and other methods' replays",
    Args,
    _run,
    __doc__ or "",
)

if __name__ == "__main__":
    sys.exit(run_command(COMMAND, sys.argv[1:], "python -m agents.robustness"))
