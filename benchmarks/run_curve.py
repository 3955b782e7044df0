"""Learning curves of finished training runs: each checkpoint scored on the evaluation protocol.

``rocketroll train ... --checkpoint-freq N`` saves the model and its observation
normalisation every ``N`` env-steps under ``RUN/checkpoints/``.  This scores every
checkpoint of every ``--run LABEL=DIR`` (and the run's final model) on the protocol's
headline (test split, or ``--split train`` to choose between recipes; ``--episodes``
episodes, ``--seed``; on the default database or ``$ROCKETROLL_DB``, whichever database
the runs trained on; :mod:`agents.evaluate`), with the PID and the observer measured in
the same run as references.  Runs sharing a label are seeds of one recipe.  Training
never saw these scores: a run's committed model is its final one.

It prints one row per run (the headline at each checkpoint) and per label the median over
its runs at the env-steps where they all have a checkpoint and of their final models, and
how many runs end below the PID; ``--png`` draws headline against env-steps, every run.
Exit status 0 whatever the numbers; 2, naming it, for a run folder without
``settings.json`` (with a known env id) or ``model.zip``, or with another env id than the
first's.

Run from the repository root::

    .venv/bin/python benchmarks/run_curve.py \\
        --run ppo=runs/seeds/RocketRoll-v0/ppo/seed0 --run ppo=runs/seeds/RocketRoll-v0/ppo/seed1 \\
        --png build/run-curve.png
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from _curves import write_curves
from _records import emit
from tqdm.auto import tqdm

from agents.base import design_bank
from agents.evaluate import evaluate, headline_scores, protocol_episodes
from agents.learned import LearnedController
from agents.registry import make_controller
from rocketroll_common.tables import markdown_table
from rollenv.bank import load_bank, variant_config

_STEPS = re.compile(r"_(\d+)_steps\.zip$")


def checkpoints(run: Path, algorithm: str) -> list[tuple[int, Path | None]]:
    """``(env-steps, checkpoint)`` of ``run`` in order, the final model last (``None``)."""
    found = []
    for path in (run / "checkpoints").glob(f"{algorithm}_*_steps.zip"):
        match = _STEPS.search(path.name)
        if match:
            found.append((int(match.group(1)), path))
    found.sort()
    settings = json.loads((run / "settings.json").read_text(encoding="utf-8"))
    final = int(settings.get("env_steps") or (found[-1][0] if found else 0))
    # a checkpoint within 1 % of the end is the final model but for the last update(s):
    # the end is shown once, as the final model
    return [(n, p) for n, p in found if n < 0.99 * final] + [(final, None)]


def _refuse(message: str) -> NoReturn:
    print(f"run_curve.py: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _runs(items: Sequence[str]) -> list[tuple[str, Path, dict[str, Any]]]:
    """The runs named, each checked whole before anything is scored (exit 2 naming it)."""
    from rollenv import variant_ids

    runs = []
    for item in items:
        label, sep, folder = item.partition("=")
        if not sep or not label or not folder:
            _refuse(f"--run {item}: expected LABEL=DIR")
        path = Path(folder)
        settings_file = path / "settings.json"
        for required in (settings_file, path / "model.zip"):
            if not required.is_file():
                _refuse(f"--run {item}: {required} not found (a `rocketroll train` output?)")
        try:
            settings = json.loads(settings_file.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            _refuse(f"--run {item}: {settings_file}: not JSON ({exc})")
        if not isinstance(settings, dict) or settings.get("env_id") not in variant_ids():
            _refuse(f"--run {item}: {settings_file}: no known env_id")
        runs.append((label, path, settings))
    env_ids = {settings["env_id"] for _, _, settings in runs}
    if len(env_ids) != 1:
        _refuse(f"the runs are of several env ids: {', '.join(sorted(env_ids))}")
    return runs


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return value


def _controller(run: Path, checkpoint: Path | None, config: Any) -> LearnedController:
    """The run's model at ``checkpoint`` (None: the final one), its observer (where it reads
    one) designed on the train split as ``--policy`` designs it."""
    learned = LearnedController.load(run, checkpoint)
    if learned.needs_observer:
        learned.attach_observer(config, design_bank(config, None))
    return learned


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--run", action="append", required=True, metavar="LABEL=DIR", help="a finished run"
    )
    parser.add_argument(
        "--episodes", type=_positive, default=20, help="protocol episodes per score"
    )
    parser.add_argument("--seed", type=int, default=0, help="protocol seed (0)")
    parser.add_argument(
        "--split",
        choices=("test", "train"),
        default="test",
        help="the split whose episodes score (test; train to choose between recipes)",
    )
    parser.add_argument("--png", type=Path, help="write the curves here")
    args = parser.parse_args(argv)
    runs = _runs(args.run)
    env_id = str(runs[0][2]["env_id"])

    config = variant_config(env_id, {"split": args.split})
    bank = load_bank(config, None)
    specs = protocol_episodes(config, args.episodes, args.seed, bank=bank)

    def score(controller: Any) -> float:
        return float(headline_scores(evaluate(config, controller, specs, bank=bank)).mean())

    unit = "°" if config.task == "angle" else "°/s"
    references = {
        name: score(make_controller(name, config, env_id)) for name in ("pid", "observer")
    }
    print(f"{env_id}: headline on {args.episodes} {args.split} episodes (seed {args.seed})")
    for name, value in references.items():
        print(f"  {name:<9} {value:.2f} {unit}")
        episodes = f"{args.episodes} {args.split} episodes (seed {args.seed})"
        emit(f"{name.replace('pid', 'PID')} headline (same run)", value, unit, note=episodes)

    curves: list[tuple[str, Path, list[tuple[int, float]]]] = []
    work = [
        (label, run, s, checkpoints(run, str(s.get("algorithm", "ppo")))) for label, run, s in runs
    ]
    with tqdm(total=sum(len(w[3]) for w in work), unit="model", leave=False) as bar:
        for label, run, _, points in work:
            curve = []
            for steps, checkpoint in points:
                curve.append((steps, score(_controller(run, checkpoint, config))))
                bar.update()
            curves.append((label, run, curve))

    print()
    rows = [
        [f"{label} ({run})", ", ".join(f"{n / 1e6:g} M: {h:.2f}" for n, h in curve)]
        for label, run, curve in curves
    ]
    header = ["run", f"headline ({unit}) at each checkpoint, env-steps"]
    print("\n".join(markdown_table(header, rows)))
    print()
    for (label, run, curve), row in zip(curves, rows, strict=True):
        emit(
            f"{label} ({run}): headline at the last checkpoint ({curve[-1][0] / 1e6:g} M)",
            curve[-1][1],
            unit,
            note=row[1],
        )
    labels = list(dict.fromkeys(label for label, _, _ in curves))
    for label in labels:
        mine = [curve for lab, _, curve in curves if lab == label]
        # checkpoints at the env-steps every run has (their own ends apart), then the ends
        common = set.intersection(*({n for n, _ in c[:-1]} for c in mine))
        medians = [
            (n, statistics.median(h for c in mine for m, h in c[:-1] if m == n))
            for n in sorted(common)
        ]
        final = statistics.median(c[-1][1] for c in mine)
        ends = ", ".join(sorted({f"{c[-1][0] / 1e6:g} M" for c in mine}))
        below = sum(c[-1][1] < references["pid"] for c in mine)
        cells = "".join(f"{n / 1e6:g} M: {h:.2f}, " for n, h in medians)
        print(
            f"{label}: median of {len(mine)} run(s) {cells}final ({ends}): {final:.2f} {unit}; "
            f"final model below the PID ({references['pid']:.2f}) in {below}/{len(mine)}"
        )
        emit(
            f"{label}, median of {len(mine)} run(s): headline at the last checkpoint",
            final,
            unit,
            note=f"final models at {ends}"
            + (f"; medians at each checkpoint {cells.removesuffix(', ')}" if medians else ""),
        )
        emit(
            f"{label}: final model below the PID's {references['pid']:.2f}{unit}",
            below,
            f"of {len(mine)}",
        )

    if args.png is not None:
        write_curves(
            args.png,
            [(label, [n / 1e6 for n, _ in c], [h for _, h in c]) for label, _, c in curves],
            references,
            unit=unit,
            xlabel="training env-steps (millions)",
            title=f"{env_id}: checkpoints on {args.episodes} {args.split} episodes",
        )
        print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
