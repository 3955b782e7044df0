"""A sweep's report: one table per env id and settings point, with the statistics over
seeds of each learned controller, P(beats PID) and the best settings."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from typing import Any

import numpy as np


def report(rows: Sequence[dict[str, Any]], seed: int = 0) -> list[dict[str, Any]]:
    """The sweep's statistics: one table per env id and settings point.

    In each, a learned controller's trials of one label (its name and grid
    values) are one learner's runs, one per training seed, summarised as
    ``rocketroll seeds`` does (:func:`agents.seeds.learner_stats`: mean, IQM,
    95 % stratified-bootstrap intervals, P(beats PID) against the table's
    ``pid`` trial); every other controller is a reference row.  Failed trials
    are counted, not scored.  Per learned controller, ``best`` is the label
    of the lowest mean headline.
    """
    from agents.base import Evaluation
    from agents.evaluate import HEADLINE
    from agents.seeds import learner_stats

    tables: dict[tuple[str, str, int, int], dict[str, Any]] = {}
    for row in rows:
        spec = row["spec"]
        # one table per protocol: the same episodes for every row in it
        key = (
            row["env_id"],
            json.dumps(spec["settings"], sort_keys=True),
            int(spec["episodes"]),
            int(spec["eval_seed"]),
        )
        table = tables.setdefault(
            key,
            {
                "env_id": row["env_id"],
                "episodes": key[2],
                "eval_seed": key[3],
                "settings": spec["settings"],
                "learned": {},
                "references": [],
                "failed": [],
            },
        )
        if row["status"] != "done":
            table["failed"].append(row["controller"])
        elif spec["train"]:  # one learner: one recipe (label and content), its seeds
            recipe = {k: v for k, v in spec.items() if k not in ("seed", "hyperparams")}
            version = hashlib.sha256(
                json.dumps(recipe, sort_keys=True, default=str).encode("utf-8")
            ).hexdigest()[:6]
            table["learned"].setdefault((row["controller"], version), []).append(row)
        else:
            table["references"].append(row)
    out = []
    for _, table in sorted(tables.items()):
        refs = [
            Evaluation(
                r["controller"],
                [{"episode": i, HEADLINE: v} for i, v in enumerate(r["episode_headline"])],
                {},
                [],
            )
            for r in table["references"]
        ]
        pids = [r for r in table["references"] if (r["spec"]["policy"] or "").startswith("pid")]
        pid = min(pids, key=lambda r: (r["spec"]["policy"] != "pid", r["id"]), default=None)
        labels = [label for label, _ in table["learned"]]
        learners = []
        controller_of: dict[str, str] = {}  # learner's label -> its spec's controller
        for (label, version), runs in sorted(table["learned"].items()):
            runs = sorted(runs, key=lambda r: r["seed"])
            if labels.count(label) > 1:  # the same label from two versions of a recipe
                label = f"{label} [{version}]"
            controller_of[label] = runs[0]["spec"]["controller"]
            scores = np.array([r["episode_headline"] for r in runs], dtype=float)
            reference = None if pid is None else np.array(pid["episode_headline"], dtype=float)
            learners.append(
                learner_stats(
                    label,
                    [f"seed {r['seed']}" for r in runs],
                    scores,
                    reference,
                    seed=seed,
                    train_seconds=[r["train_s"] for r in runs],
                    env_steps_per_s=[r["env_steps_per_s"] for r in runs],
                )
            )
        best: dict[str, str] = {}
        for stats in sorted(learners, key=lambda s: s.mean):
            best.setdefault(controller_of[stats.name], stats.name)
        out.append({**table, "learners": learners, "reference_results": refs, "best": best})
    return out
