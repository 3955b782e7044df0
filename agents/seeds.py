"""Statistics over training seeds: a learned controller is its distribution, not one run.

``rocketroll seeds --run ppo:DIR --run ppo:DIR ... [--reference pid ...]`` runs
every trained run (one per training seed) and every reference controller
through the protocol of :mod:`agents.evaluate` (the same held-out episodes and
gyro noise), then reports per learner, on the headline
(:data:`agents.evaluate.HEADLINE`), the method of Agarwal et al., "Deep
reinforcement learning at the edge of the statistical precipice" (NeurIPS
2021):

* the score matrix ``S[run, episode]``;
* its **mean** and **interquartile mean** (IQM: the mean of the middle 50 %
  of all run × episode scores, robust to one bad seed yet not as coarse as the
  median);
* **95 % stratified-bootstrap confidence intervals** (percentile, by
  :func:`scipy.stats.bootstrap`): whole runs are resampled with replacement
  within each task, as ``rliable``'s ``StratifiedBootstrap`` does with tasks
  as strata.  A run is one training seed evaluated on every episode, so its
  episodes are not independent draws: resampling runs per episode (episodes
  as strata) would break a seed's persistent effect apart and give intervals
  that cover the truth far too rarely (7 of 40 in a test with a seed effect).
  Each task (environment id) is reported on its own, so within a report the
  stratified bootstrap is the bootstrap over its runs;
* the **probability of improvement over the PID**: ``P(X < Y)``, a run's score
  below the PID's on the same episode (lower is better; ties count half),
  averaged over episodes, with its interval from the same bootstrap;
* training wall time and env-steps/s from each run's ``settings.json``.

Runs are grouped into learners by the text before ``:`` of their ``--run``
value (``ppo``), or by a label given as ``LABEL=POLICY`` (``ppo-h8=ppo:DIR``).
Outputs (``--out``): ``seeds.md`` (the table), ``seeds.json`` (every score)
and ``seeds.png`` (per-run scores with the intervals, and the score
distributions: the share of run × episode scores below each level, the
references' as lines).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from agents.base import Evaluation
from agents.evaluate import (
    HEADLINE,
    env_id_setting,
    evaluate,
    headline_scores,
    pid_result,
    protocol_episodes,
    protocol_record,
    write_study,
)
from agents.registry import check_policy, make_controller
from agents.replay import (
    check_options,
    db_setting,
    env_options_setting,
    recording_setting,
    replay_config,
    split_setting,
    unreliable_note,
)
from rocketroll_common import tables
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, run_command, setting

__all__ = [
    "COMMAND",
    "Args",
    "LearnerStats",
    "learner_stats",
    "run",
]

FloatArray = NDArray[np.float64]

#: Bootstrap resamples (rliable's default is 2000 for interval estimates).
RESAMPLES = 2000


def iqm(scores: FloatArray, axis: int = -1) -> FloatArray:
    """Interquartile mean along ``axis``: 25 % trimmed from each end (``scipy.stats.trim_mean``)."""
    return np.asarray(stats.trim_mean(scores, 0.25, axis=axis))


@dataclass(frozen=True)
class LearnerStats:
    """A learner's scores over runs (training seeds) and episodes, and their summaries."""

    name: str
    runs: list[str]
    scores: FloatArray  # (runs, episodes), headline per episode
    mean: float
    mean_ci: tuple[float, float]
    iqm: float
    iqm_ci: tuple[float, float]
    p_beats: float | None  # P(run's score < the reference's), over episodes
    p_beats_ci: tuple[float, float] | None
    train_seconds: list[float | None]
    env_steps_per_s: list[float | None]

    @property
    def run_means(self) -> FloatArray:
        """Each run's mean headline over the episodes."""
        return np.asarray(self.scores.mean(axis=1))


def _stratified_interval(scores: FloatArray, statistic: Any, seed: int) -> tuple[float, float]:
    """95 % percentile interval of ``statistic(S)`` with whole runs (rows) resampled."""
    if scores.shape[0] < 2:
        return (float("nan"), float("nan"))
    samples = tuple(scores[:, j] for j in range(scores.shape[1]))

    def of_samples(*columns: FloatArray, axis: int = -1) -> FloatArray:
        # each column (..., runs): stack to (..., runs, episodes) and reduce
        matrix = np.stack(columns, axis=-1)
        return np.asarray(statistic(matrix))

    result = stats.bootstrap(
        samples,
        of_samples,
        n_resamples=RESAMPLES,
        vectorized=True,
        paired=True,  # one index draw for every column: whole runs
        confidence_level=0.95,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    ci = result.confidence_interval
    return float(ci.low), float(ci.high)


def _mean(matrix: FloatArray) -> FloatArray:
    return np.asarray(matrix.mean(axis=(-2, -1)))


def _iqm(matrix: FloatArray) -> FloatArray:
    flat = matrix.reshape(*matrix.shape[:-2], -1)
    return iqm(flat, axis=-1)


def learner_stats(
    name: str,
    runs: Sequence[str],
    scores: FloatArray,
    reference: FloatArray | None,
    *,
    seed: int = 0,
    train_seconds: Sequence[float | None] = (),
    env_steps_per_s: Sequence[float | None] = (),
) -> LearnerStats:
    """The summaries of a ``(runs, episodes)`` score matrix (lower is better).

    ``reference``: the reference controller's score per episode (the PID),
    for the probability of improvement; ``None`` leaves it out.
    """
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 2 or scores.size == 0:
        raise ValueError(f"{name}: scores must be a (runs, episodes) matrix, got {scores.shape}")
    p_beats = p_ci = None
    if reference is not None:
        ref = np.asarray(reference, dtype=float)
        if ref.shape != scores.shape[1:]:
            raise ValueError(f"{name}: one reference score per episode, got {ref.shape}")

        def improvement(matrix: FloatArray) -> FloatArray:
            wins = (matrix < ref).astype(float) + 0.5 * (matrix == ref)
            return np.asarray(wins.mean(axis=(-2, -1)))

        p_beats = float(improvement(scores))
        p_ci = _stratified_interval(scores, improvement, seed)
    return LearnerStats(
        name=name,
        runs=list(runs),
        scores=scores,
        mean=float(scores.mean()),
        mean_ci=_stratified_interval(scores, _mean, seed),
        iqm=float(iqm(scores.ravel())),
        iqm_ci=_stratified_interval(scores, _iqm, seed),
        p_beats=p_beats,
        p_beats_ci=p_ci,
        train_seconds=list(train_seconds) or [None] * len(runs),
        env_steps_per_s=list(env_steps_per_s) or [None] * len(runs),
    )


# ----------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class Args:
    """``rocketroll seeds`` / ``python -m agents.seeds``."""

    env_id: str = env_id_setting()
    run: list[str] = setting(
        default_factory=list,
        help="a trained run, as --policy takes it (ppo:DIR), optionally LABEL=POLICY; runs of "
        "one label (default: the policy's name) are one learner's seeds (repeatable, >= 2 "
        "per learner)",
        metavar="[LABEL=]POLICY",
        always=True,
    )
    reference: list[str] = setting(
        default_factory=lambda: ["pid", "observer", "mpc", "oracle"],
        help="a controller evaluated once beside the learners (repeatable); the first "
        "PID among them is the one the probability of improvement is against",
        metavar="POLICY",
        always=True,
    )
    split: Literal["train", "test"] = split_setting()
    episodes: int = setting(20, "number of protocol episodes", ge=1, le=100_000, always=True)
    seed: int = setting(
        0, "seed of the protocol's episodes and of the bootstrap", ge=0, le=2**31 - 1, always=True
    )
    out: Path | None = setting(
        None,
        "folder for seeds.md, seeds.json, seeds.png (none: print only)",
        output="folder",
        files=("seeds.md", "seeds.json", "seeds.png"),
    )
    db: str | None = db_setting()
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()

    def __post_init__(self) -> None:
        check(self)
        check_options(self.settings)
        if not self.run:
            raise UsageError("--run: give the trained runs, e.g. --run ppo:runs/ppo/seed0 ...")
        groups = _groups(self.run)
        for label, runs in groups.items():
            if len(runs) < 2:
                raise UsageError(
                    f"--run: learner {label!r} has {len(runs)} run; statistics over seeds "
                    "need at least 2 (5 or more for intervals worth reading)"
                )
        every = [p for runs in groups.values() for p in runs]
        repeated = sorted({p for p in every if every.count(p) > 1})
        if repeated:
            raise UsageError(f"--run {repeated[0]} is given twice")
        for policy in [*every, *self.reference]:
            check_policy(policy, self.env_id)  # before any database is opened


def _groups(values: Sequence[str]) -> dict[str, list[str]]:
    """``[LABEL=]POLICY`` values by label (default: the policy's name before ``:``)."""
    groups: dict[str, list[str]] = {}
    for value in values:
        label, sep, policy = value.partition("=")
        if not sep:
            label, policy = value.partition(":")[0], value
        groups.setdefault(label, []).append(policy)
    return groups


def _training_record(policy: str) -> tuple[float | None, float | None]:
    """Wall time (s) and env-steps/s from a run's ``settings.json``, if it has one."""
    _, _, folder = policy.partition(":")
    path = Path(folder) / "settings.json"
    if not folder or not path.is_file():
        return None, None
    record = json.loads(path.read_text(encoding="utf-8"))
    return record.get("wall_time_s"), record.get("env_steps_per_s")


def markdown_table(
    learners: Sequence[LearnerStats], references: Sequence[Evaluation], unit: str
) -> str:
    """The learners' statistics and the references' headline, as a Markdown table."""
    header = [
        "controller",
        "runs",
        f"mean ({unit}) [95 % CI]",
        f"IQM ({unit}) [95 % CI]",
        "P(beats PID) [95 % CI]",
        f"per run ({unit})",
        "train wall (s)",
        "env-steps/s",
    ]
    rows = []

    def num(x: float | None, digits: int) -> str:
        return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"

    for s in learners:
        p = "–"
        if s.p_beats is not None and s.p_beats_ci is not None:
            p = f"{s.p_beats:.2f} [{num(s.p_beats_ci[0], 2)}, {num(s.p_beats_ci[1], 2)}]"
        walls = [w for w in s.train_seconds if w is not None]
        rates = [r for r in s.env_steps_per_s if r is not None]
        rows.append(
            [
                s.name,
                str(len(s.runs)),
                f"{s.mean:.2f} [{num(s.mean_ci[0], 2)}, {num(s.mean_ci[1], 2)}]",
                f"{s.iqm:.2f} [{num(s.iqm_ci[0], 2)}, {num(s.iqm_ci[1], 2)}]",
                p,
                ", ".join(f"{x:.2f}" for x in s.run_means),
                num(float(np.mean(walls)) if walls else None, 0),
                num(float(np.mean(rates)) if rates else None, 0),
            ]
        )
    for r in references:
        score = headline_scores(r)
        rows.append([r.name, "1", f"{score.mean():.2f}", f"{iqm(score):.2f}", *["–"] * 4])
    return "\n".join(tables.markdown_table(header, rows)) + "\n"


def plot(
    learners: Sequence[LearnerStats], references: Sequence[Evaluation], unit: str, title: str
) -> bytes:
    """Per-run scores with the intervals (left), score distributions (right), PNG.

    Learners in strong colours, references as thin lines in colours of their own."""
    from rocketroll_common.plotting import new_figure, png_bytes

    strong = ("#D55E00", "#CC79A7", "#E69F00", "#56B4E9")
    thin = ("#0072B2", "#009E73", "#999999", "#000000")
    fig = new_figure(figsize=(11, 4.5))
    left, right = fig.subplots(1, 2)
    rng = np.random.default_rng(0)
    for i, s in enumerate(learners):
        colour = strong[i % len(strong)]
        means = s.run_means
        left.scatter(i + rng.uniform(-0.12, 0.12, means.size), means, color=colour, s=30, zorder=3)
        for x, value, ci, marker in (
            (i + 0.3, s.mean, s.mean_ci, "o"),
            (i + 0.4, s.iqm, s.iqm_ci, "s"),
        ):
            if np.all(np.isfinite(ci)):
                bar = [[value - ci[0]], [ci[1] - value]]
                left.errorbar(x, value, yerr=bar, fmt=marker, color="black", capsize=3, ms=4)
        ordered = np.sort(s.scores.ravel())
        share = np.arange(1, ordered.size + 1) / ordered.size
        label = f"{s.name} ({len(s.runs)} runs)"
        right.step(ordered, share, where="post", color=colour, lw=2.2, label=label)
    for k, r in enumerate(references):
        colour = thin[k % len(thin)]
        score = headline_scores(r)
        left.axhline(score.mean(), color=colour, ls="--", lw=1.2, label=r.name)
        ordered = np.sort(score)
        share = np.arange(1, ordered.size + 1) / ordered.size
        right.step(ordered, share, where="post", color=colour, ls="--", lw=1.2, label=r.name)
    left.set_xticks(range(len(learners)), [s.name for s in learners])
    left.set_xlim(-0.5, len(learners) - 0.3)
    left.set_yscale("log")
    left.set_ylabel(f"regulation RMS ({unit}), mean over episodes")
    left.set_title("each run (dots); mean ● and IQM ■ with 95 % CI; references dashed", fontsize=10)
    left.legend(frameon=False, fontsize=8)
    left.grid(alpha=0.3, which="both", axis="y")
    right.set_xscale("log")
    right.set_xlabel(f"regulation RMS per episode ({unit})")
    right.set_ylabel("share of run × episode scores below")
    right.set_title("score distributions", fontsize=10)
    right.legend(frameon=False, fontsize=8)
    right.grid(alpha=0.3, which="both")
    fig.suptitle(title)
    fig.tight_layout()
    return png_bytes(fig, dpi=110)


def run(args: Args) -> tuple[list[LearnerStats], list[Evaluation]]:
    """Evaluate every run and reference, print the table, write the outputs."""
    groups = _groups(args.run)
    config, bank, _, episode_note = replay_config(
        args.env_id, args.settings, args.recording, args.split, args.db
    )
    try:
        controllers = {
            label: [make_controller(p, config, args.env_id, db=args.db) for p in runs]
            for label, runs in groups.items()
        }
        references = [make_controller(p, config, args.env_id, db=args.db) for p in args.reference]
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    unit = "°" if config.task == "angle" else "°/s"
    total = sum(len(r) for r in groups.values())
    print(
        f"rocketroll seeds: {args.env_id}, split={args.split}, {args.episodes} episodes, "
        f"seed={args.seed}; {total} runs of {len(groups)} learner(s), headline {HEADLINE}"
    )
    if episode_note:
        print(episode_note)
    caution = unreliable_note([bank], args.db)  # a recording stored with --accept-unreliable
    specs = protocol_episodes(config, args.episodes, args.seed, bank=bank)
    evaluated_refs = [evaluate(config, c, specs, bank=bank, progress=True) for c in references]
    pid = pid_result(evaluated_refs)
    learners = []
    for label, ctrls in controllers.items():
        results = [evaluate(config, c, specs, bank=bank, progress=True) for c in ctrls]
        records = [_training_record(p) for p in groups[label]]
        learners.append(
            learner_stats(
                label,
                groups[label],
                np.stack([headline_scores(r) for r in results]),
                None if pid is None else headline_scores(pid),
                seed=args.seed,
                train_seconds=[w for w, _ in records],
                env_steps_per_s=[s for _, s in records],
            )
        )
    table = markdown_table(learners, evaluated_refs, unit)
    table += "" if caution is None else f"\n{caution}\n"
    print(table, end="")
    if args.out is not None:
        record = {
            "protocol": protocol_record(args, caution, resamples=RESAMPLES, bank=bank.description),
            "learners": {
                s.name: {
                    "runs": s.runs,
                    "scores": s.scores.tolist(),
                    "mean": s.mean,
                    "mean_ci": list(s.mean_ci),
                    "iqm": s.iqm,
                    "iqm_ci": list(s.iqm_ci),
                    "p_beats_pid": s.p_beats,
                    "p_beats_pid_ci": None if s.p_beats_ci is None else list(s.p_beats_ci),
                    "train_seconds": s.train_seconds,
                    "env_steps_per_s": s.env_steps_per_s,
                }
                for s in learners
            },
            "references": {r.name: headline_scores(r).tolist() for r in evaluated_refs},
        }
        title = f"{args.env_id}: headline over training seeds ({args.episodes} test episodes)"
        figure = plot(learners, evaluated_refs, unit, title)
        write_study(Path(args.out), "seeds", table, record, figure)
    return learners, evaluated_refs


def _run(args: Args) -> int:
    run(args)
    return 0


#: ``rocketroll seeds``.
COMMAND = Command(
    "seeds",
    "a learned controller over training seeds: mean, IQM, bootstrap CIs, P(beats PID)",
    Args,
    _run,
    __doc__ or "",
)

if __name__ == "__main__":
    sys.exit(run_command(COMMAND, sys.argv[1:], "python -m agents.seeds"))
