"""The evaluation protocol: the same seeded held-out episodes for every controller.

Episodes are drawn once from the *test* split by the environment's own
distribution (trace window, setpoint schedule) with seeds derived from
``--seed``, stored as reset options (:meth:`RocketRollEnv.replay_options`)
and replayed for every controller with the same seed, so every controller
meets the same turbulence, setpoints and gyro noise.  Metrics per episode
and aggregated (mean ± SD and worst case) go to a Markdown table, a JSON
file and PNG plots.

``rocketroll eval --policy POLICY [--policy ...]``, or ``python -m
agents.evaluate`` with the same arguments; ``--help`` lists every controller
of the registry of :mod:`agents.registry` (trim, pid[:OMEGA],
pid-tunnel[:OMEGA], observer, mpc[:HORIZON], ppo[:DIR], sac:DIR, td3:DIR,
oracle, and what plugins add).
"""

from __future__ import annotations

import json
import os
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from agents.base import Controller, EpisodeSpec, Evaluation, FlightView
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
    recording_setting,
    replay_config,
    split_setting,
    unreliable_note,
)
from disturbances.bank import TraceBank
from rocketroll_common import tables
from rocketroll_common.arrays import nan_to_none
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, run_command, setting, to_argv
from rollenv import variant_ids
from rollenv.bank import load_bank
from rollenv.config import RollConfig
from rollenv.env import RocketRollEnv
from rollenv.history import EpisodeHistory, HistoryRecorder

__all__ = [
    "COMMAND",
    "HEADLINE",
    "METRICS",
    "Args",
    "EpisodeSpec",
    "Evaluation",
    "check_unique_names",
    "env_id_setting",
    "evaluate",
    "headline_scores",
    "markdown_table",
    "metrics",
    "paired_difference",
    "pid_result",
    "protocol_episodes",
    "protocol_record",
    "run",
    "write_study",
]


#: Metric name → (description, "max" if larger is worse else "min").  The first is the
#: headline (:data:`HEADLINE`).
METRICS: dict[str, tuple[str, str]] = {
    "regulation_rms_error": (
        "headline: RMS error once each setpoint change is REGULATION_AFTER_S old",
        "max",
    ),
    "settle_time_s": ("time from a setpoint change to within SETTLE_BAND for 1 s, s", "max"),
    "settled_rms_error": ("RMS error in the last quarter of each setpoint period", "max"),
    "rms_error": ("RMS tracking error over the episode", "max"),
    "max_error": ("largest |tracking error|", "max"),
    "fin_travel_dps": ("fin travel per second, °/s", "max"),
    "rate_limit_pct": ("% of time the servo moves at its rate limit", "max"),
    "range_limit_pct": ("% of steps ending with the fin at its range limit", "max"),
    "return": ("sum of rewards", "min"),
}

#: The protocol's headline metric: the controller's turbulence rejection, not the rocket's slew.
HEADLINE = "regulation_rms_error"

#: Time after a setpoint change (or the episode's start) from which the error counts in the
#: headline, per task, s.  The largest steps the schedules draw need up to 7.6 s (angle, a
#: 163° step) and 0.9 s (rate, 18 °/s) even with the oracle's perfect preview -- the servo's
#: rate and range limits and the rocket's top roll rate set them -- so before these times the
#: error measures the rocket, after them the controller.  Never more than 3/4 of a period.
REGULATION_AFTER_S: dict[str, float] = {"angle": 7.5, "rate": 2.0}

#: Band (° or °/s) the error must enter and stay in for SETTLE_HOLD_S to count as settled.
SETTLE_BAND: dict[str, float] = {"angle": 2.0, "rate": 2.0}
SETTLE_HOLD_S = 1.0


def env_on(config: RollConfig, bank: TraceBank) -> RocketRollEnv:
    """The environment of ``config`` replaying ``bank`` (a protocol's, or any other)."""
    settings = {f.name: getattr(config, f.name) for f in fields(config)}
    return RocketRollEnv(bank=bank, **settings)


def protocol_episodes(
    config: RollConfig,
    episodes: int = 20,
    seed: int = 0,
    *,
    db: str | os.PathLike[str] | None = None,
    bank: TraceBank | None = None,
) -> list[EpisodeSpec]:
    """The protocol's episodes of ``config.split``: ``episodes`` draws of the env itself.

    Episode ``i`` has the trace window and setpoint schedule that
    ``env.reset(seed=s_i)`` draws, with ``s_i`` the ``i``-th integer of
    ``np.random.default_rng(seed)``; the same arguments always give the same
    episodes.  Replayed through reset options with the same seed, what the
    env still draws (the gyro noise; an initial angle or randomised rocket
    when those options are on) differs from that first draw, but is the same
    for every controller.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    bank = load_bank(config, db) if bank is None else bank
    env = env_on(config, bank)
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=episodes)
    specs = []
    for i, s in enumerate(seeds.tolist()):
        env.reset(seed=s)
        options = env.replay_options()
        specs.append(
            EpisodeSpec(i, s, options["trace"], options["start"], tuple(options["setpoints"]))
        )
    return specs


def run_episode(
    env: RocketRollEnv,
    controller: Controller,
    spec: EpisodeSpec,
    transitions: dict[str, list[Any]] | None = None,
) -> EpisodeHistory:
    """Run ``controller`` through episode ``spec`` of ``env``; its history, step by step.

    The controller sees a :class:`~agents.base.FlightView` of ``env`` unless it
    declares ``sees_truth`` (the oracle).  ``transitions``, if given, gets what
    an agent saw and did, as Gymnasium returned it: ``observations`` (one more
    than the steps), ``actions``, ``rewards``, ``terminations``,
    ``truncations`` (lists, appended to)."""
    obs, _ = env.reset(seed=spec.seed, options=spec.options())
    handle: Any = env if getattr(controller, "sees_truth", False) else FlightView(env)
    controller.reset(handle)
    recorder = HistoryRecorder(env.config.max_episode_steps + 1)
    core = env.core
    recorder.record(core, 0)
    if transitions is not None:
        for key in ("observations", "actions", "rewards", "terminations", "truncations"):
            transitions.setdefault(key, [])
        transitions["observations"].append(obs)
    truncated = False
    while not truncated:
        action = controller.act(obs, handle)
        obs, reward, terminated, truncated, _ = env.step(action)
        recorder.record(core, 0, float(reward))
        if transitions is not None:
            transitions["observations"].append(obs)
            transitions["actions"].append(np.asarray(action, dtype=np.float32).copy())
            transitions["rewards"].append(float(reward))
            transitions["terminations"].append(bool(terminated))
            transitions["truncations"].append(bool(truncated))
    return recorder.history(env.config.task, env.config.fin_range_deg, spec.trace)


def _since_change(setpoint: np.ndarray) -> np.ndarray:
    """Samples since the last setpoint change (or since the episode's start), per sample."""
    index = np.arange(setpoint.size)
    changed = np.flatnonzero(np.diff(setpoint) != 0) + 1
    last = np.zeros(setpoint.size, dtype=int)
    last[changed] = changed
    return np.asarray(index - np.maximum.accumulate(last))


def settling(rollout: EpisodeHistory, config: RollConfig) -> tuple[np.ndarray, np.ndarray]:
    """Time from each setpoint change until the error stays within ``SETTLE_BAND`` for 1 s
    (10 consecutive control steps), s, and whether each step settled.

    A step that does not settle before the next change (or the episode's end)
    counts as the whole time it had (censored: its time is a lower bound).
    Both empty if the setpoint never changes.
    """
    inside = np.abs(rollout.error) < SETTLE_BAND[config.task]
    hold = max(1, round(SETTLE_HOLD_S / config.dt_s))
    changes = np.flatnonzero(np.diff(rollout.setpoint) != 0) + 1
    ends = [*changes[1:].tolist(), inside.size][: changes.size]
    times, settled_steps = [], []
    for start, end in zip(changes.tolist(), ends, strict=True):
        window = inside[start:end]
        # run[j]: the window is inside for `hold` samples from j on
        run = np.convolve(window, np.ones(hold), "valid") == hold if window.size >= hold else []
        settled = np.flatnonzero(run)
        times.append((settled[0] if settled.size else end - start) * config.dt_s)
        settled_steps.append(bool(settled.size))
    return np.asarray(times, dtype=float), np.asarray(settled_steps, dtype=bool)


def metrics(rollout: EpisodeHistory, config: RollConfig) -> dict[str, float]:
    """The protocol's metrics of one episode (see :data:`METRICS`).

    Over the steps after reset: the headline, the RMS error over the samples
    at least ``REGULATION_AFTER_S`` (at most 3/4 of a period) after the last
    setpoint change or the start (in flight: after a change only -- the rocket
    leaves its rail on its setpoint, and the boost is what it must hold); the
    mean time to settle after a setpoint
    change (NaN if the setpoint never changes); the settled RMS over the last
    quarter of each setpoint period, 7.5-10 s after a change by default (the
    episode's last quarter if no period ends within it); RMS and largest
    |error|; fin travel ``Σ|Δθ|/T``; time at the rate limit, the time the
    servo needs at 150 °/s to reach each command, capped at the step (the
    servo is a pure rate limiter, so this is the time it is moving, to within
    a substep); steps ending with ``|θ| = 40°``; the return.  Beside them, two
    counts that are not metrics: ``setpoint_steps``, the setpoint changes timed,
    and ``unsettled_steps``, those that never settled (their time to settle is
    the whole time they had).
    """
    error = rollout.error[1:]
    fin = rollout.fin_deg
    duration = len(error) * config.dt_s
    steps = np.arange(1, len(error) + 1)
    period = config.setpoint_period_steps
    settled = (steps % period) >= period - max(period // 4, 1)
    if not settled.any():  # a period as long as the episode: its last quarter
        settled = steps > len(error) - max(len(error) // 4, 1)
    after = min(round(REGULATION_AFTER_S[config.task] / config.dt_s), (3 * period) // 4)
    since = _since_change(rollout.setpoint)
    if config.flight is not None:  # launched on its setpoint: nothing to settle at the start
        since = np.where(
            np.cumsum(np.diff(rollout.setpoint, prepend=rollout.setpoint[0]) != 0) > 0, since, after
        )
    regulating = since[1:] >= after
    if not regulating.any():
        regulating = settled
    settle, settled_steps = settling(rollout, config)
    travel = np.abs(np.diff(fin))
    needed = np.abs(rollout.command_deg[1:] - fin[:-1]) / config.rate_limit_dps
    at_range = np.abs(fin[1:]) >= config.fin_range_deg * (1 - 1e-9)
    return {
        "regulation_rms_error": float(np.sqrt(np.mean(error[regulating] ** 2))),
        "settle_time_s": float(settle.mean()) if settle.size else float("nan"),
        "settled_rms_error": float(np.sqrt(np.mean(error[settled] ** 2))),
        "rms_error": float(np.sqrt(np.mean(error**2))),
        "max_error": float(np.max(np.abs(error))),
        "fin_travel_dps": float(travel.sum() / duration),
        "rate_limit_pct": float(100 * np.minimum(needed, config.dt_s).sum() / duration),
        "range_limit_pct": float(100 * np.mean(at_range)),
        "return": float(rollout.reward[1:].sum()),
        "setpoint_steps": int(settle.size),
        "unsettled_steps": int(np.count_nonzero(~settled_steps)),
    }


def aggregate(episodes: Sequence[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Mean, SD (ddof 1) and worst case of each metric over the episodes that define it.

    A metric no episode defines (the time to settle with the setpoint held)
    aggregates to NaN."""
    out = {}
    for name, (_, worse) in METRICS.items():
        values = np.array([e[name] for e in episodes])
        values = values[~np.isnan(values)]
        if not values.size:
            out[name] = {"mean": float("nan"), "sd": float("nan"), "worst": float("nan")}
            continue
        out[name] = {
            "mean": float(values.mean()),
            "sd": float(values.std(ddof=1)) if values.size > 1 else 0.0,
            "worst": float(values.max() if worse == "max" else values.min()),
        }
    return out


def paired_difference(
    result: Evaluation, reference: Evaluation, metric: str = HEADLINE
) -> tuple[float, float]:
    """Mean and standard error of ``result − reference`` over their common episodes.

    Both met the same episodes and gyro noise, so the per-episode difference
    removes what the episodes share (how rough each trace is) and its SEM is
    the one that says whether two controllers differ."""
    mine = {e["episode"]: e[metric] for e in result.episodes}
    theirs = {e["episode"]: e[metric] for e in reference.episodes}
    common = sorted(set(mine) & set(theirs))
    diff = np.array([mine[i] - theirs[i] for i in common])
    diff = diff[~np.isnan(diff)]
    if diff.size < 2:
        return (float(diff.mean()) if diff.size else float("nan")), float("nan")
    return float(diff.mean()), float(diff.std(ddof=1) / np.sqrt(diff.size))


def evaluate(
    config: RollConfig,
    controller: Controller,
    specs: Sequence[EpisodeSpec],
    *,
    db: str | os.PathLike[str] | None = None,
    bank: TraceBank | None = None,
    progress: bool = False,
    transitions: list[dict[str, Any]] | None = None,
) -> Evaluation:
    """Run ``controller`` through every episode of ``specs``; with ``transitions``, append
    each episode's observations, actions, rewards, ... there (:func:`run_episode`), with its
    ``seed`` and ``options``."""
    bank = load_bank(config, db) if bank is None else bank
    env = env_on(config, bank)
    rollouts, episodes = [], []
    began = time.perf_counter()
    iterator: Any = specs
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(specs, desc=f"{controller.name:>6}", unit="ep", leave=False)
    for spec in iterator:
        steps: dict[str, Any] | None = None
        if transitions is not None:
            steps = {"seed": spec.seed, "options": spec.options()}
            transitions.append(steps)
        rollout = run_episode(env, controller, spec, steps)
        rollouts.append(rollout)
        episodes.append({"episode": spec.index, **metrics(rollout, config)})
    env.close()
    return Evaluation(
        controller.name, episodes, aggregate(episodes), rollouts, time.perf_counter() - began
    )


# ------------------------------------------------------------------------- reports
def pid_result(results: Sequence[Evaluation]) -> Evaluation | None:
    """The row the others are compared with: the (first) PID if evaluated, else none."""
    return next((r for r in results if r.name.split()[0] == "PID"), None)


def headline_scores(result: Evaluation) -> NDArray[np.float64]:
    """The headline of each episode of ``result``, in episode order."""
    episodes = sorted(result.episodes, key=lambda e: e["episode"])
    return np.array([e[HEADLINE] for e in episodes])


def markdown_table(results: Sequence[Evaluation], config: RollConfig) -> str:
    """The results as a Markdown table (mean ± SD, worst case in brackets).

    The headline comes first, then its paired difference to the PID (mean ±
    SEM over the common episodes, and how many SEMs that is, where the SEM shows: a
    difference shown ``± 0.00`` -- episodes that are copies of one another, as on a
    recording too short for more than one window -- gets no count, which would be a
    ratio of rounding noise).  Under it, where a step never settled, the line of
    :func:`unsettled_note`."""
    unit = "°" if config.task == "angle" else "°/s"
    reference = pid_result(results)
    header = [
        "controller",
        f"**regulation RMS** ({unit})",
        f"vs PID ({unit})",
        "time to settle (s)",
        f"settled RMS ({unit})",
        f"RMS error ({unit})",
        f"max error ({unit})",
        "fin travel (°/s)",
        "at rate limit (%)",
        "at range limit (%)",
        "return",
    ]
    rows = []
    for r in results:
        a = r.aggregate

        def cell(name: str, digits: int = 2, agg: dict[str, dict[str, float]] = a) -> str:
            m = agg[name]
            if np.isnan(m["mean"]):
                return "–"
            return f"{m['mean']:.{digits}f} ± {m['sd']:.{digits}f} [{m['worst']:.{digits}f}]"

        versus = "–"
        if reference is not None and r is not reference:
            mean, sem = paired_difference(r, reference)
            if not np.isnan(sem):
                z = f" ({abs(mean) / sem:.1f} SEM)" if sem >= 0.005 else ""
                versus = f"{mean:+.2f} ± {sem:.2f}{z}"
        rows.append(
            [
                r.name,
                cell(HEADLINE),
                versus,
                cell("settle_time_s", 1),
                cell("settled_rms_error"),
                cell("rms_error"),
                cell("max_error", 1),
                cell("fin_travel_dps", 1),
                cell("rate_limit_pct", 1),
                cell("range_limit_pct", 1),
                cell("return", 1),
            ]
        )
    unsettled = unsettled_note(results)
    lines = tables.markdown_table(header, rows)
    return "\n".join(lines) + "\n" + ("" if unsettled is None else f"\n{unsettled}\n")


def unsettled_note(results: Sequence[Evaluation]) -> str | None:
    """The line under the table that says which controllers' time to settle counts setpoint
    steps that never settled (each as the whole time it had: the mean is then a lower bound);
    None where every step settled."""
    counts = []
    for r in results:
        unsettled = sum(int(e.get("unsettled_steps", 0)) for e in r.episodes)
        if unsettled:
            steps = sum(int(e.get("setpoint_steps", 0)) for e in r.episodes)
            counts.append(f"{r.name} {unsettled} of {steps}")
    if not counts:
        return None
    return (
        "Setpoint steps that never settled, each counted in the time to settle as the whole "
        f"time it had (the mean is then a lower bound): {', '.join(counts)}."
    )


def protocol_record(args: Any, note: str | None = None, **extra: Any) -> dict[str, Any]:
    """The protocol a study's JSON record states: ``args``' environment, split, episodes
    and seed, the headline metric, ``extra`` (what the study adds), and ``note`` (a
    caution printed under its table) where there is one."""
    return {
        "env_id": args.env_id,
        "split": args.split,
        "episodes": args.episodes,
        "seed": args.seed,
        "headline": HEADLINE,
        **extra,
        **({} if note is None else {"note": note}),
    }


def write_study(out: Path, stem: str, table: str, record: dict[str, Any], figure: bytes) -> None:
    """A study's table, JSON record (NaN as null) and figure written into ``out`` together
    (all or none), as ``stem``.md, ``stem``.json and ``stem``.png; their names printed."""
    from rocketroll_common.files import write_all_atomic

    text = json.dumps(nan_to_none(record), indent=1, allow_nan=False) + "\n"
    files: dict[str | os.PathLike[str], str | bytes] = {
        out / f"{stem}.md": table,
        out / f"{stem}.json": text,
        out / f"{stem}.png": figure,
    }
    write_all_atomic(files, folder=out)
    print(f"wrote {out}/{stem}.md, {stem}.json, {stem}.png")


def to_json(
    results: Sequence[Evaluation],
    config: RollConfig,
    specs: Sequence[EpisodeSpec],
    protocol: dict[str, Any],
) -> dict[str, Any]:
    """Everything needed to compare and to reproduce: protocol, episodes, metrics."""
    return {
        "protocol": {
            **protocol,
            "config": asdict(config),
            "episodes": [asdict(s) for s in specs],
            "metrics": {k: v[0] for k, v in METRICS.items()},
            "headline": HEADLINE,
        },
        "controllers": {
            r.name: nan_to_none(
                {"aggregate": r.aggregate, "episodes": r.episodes, "seconds": r.seconds}
            )
            for r in results
        },
    }


# ---------------------------------------------------------------------------- CLI
def _variant_ids() -> tuple[str, ...]:
    return variant_ids()


def env_id_setting() -> Any:
    """The ``--env-id`` setting of the commands that run the protocol (eval, seeds,
    robustness)."""
    return setting(
        "RocketRoll-v0",
        "environment id: RocketRoll-v0 (angle task), RocketRollRate-v0 (rate task), ...",
        choices=_variant_ids,
        always=True,
    )


def check_unique_names(controllers: Sequence[Controller]) -> None:
    """Refuse (``UsageError``) two controllers of one name: their rows would merge."""
    names = [c.name for c in controllers]
    if len(set(names)) < len(names):
        raise UsageError(f"two --policy values give controllers of one name: {', '.join(names)}")


@dataclass(frozen=True)
class Args:
    """``rocketroll eval`` / ``python -m agents.evaluate``."""

    env_id: str = env_id_setting()
    policy: list[str] = setting(
        default_factory=default_policies,
        help=lambda: f"controller to evaluate, in table order (repeatable): {policy_help()}",
        metavar="POLICY",
        always=True,
    )
    split: Literal["train", "test"] = split_setting()
    episodes: int = setting(20, "number of protocol episodes", ge=1, le=100_000, always=True)
    seed: int = setting(
        0,
        "seed of the protocol's episodes (trace windows, setpoints, gyro noise)",
        ge=0,
        le=2**31 - 1,
        always=True,
    )
    out: Path | None = setting(
        None,
        "folder for table.md, results.json, episode.png, errors.png (none: print only)",
        output="folder",
        files=("table.md", "results.json", "episode.png", "errors.png"),
    )
    db: str | None = db_setting()
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()
    minari: str | None = setting(
        None,
        "also save every episode as a Minari dataset per controller, PREFIX-<controller>-v0 "
        "(offline RL; the optional extra rocketroll[minari])",
        metavar="PREFIX",
    )

    def __post_init__(self) -> None:
        check(self)
        repeated = sorted({p for p in self.policy if self.policy.count(p) > 1})
        if repeated:
            raise UsageError(f"--policy {repeated[0]} is given twice")
        check_options(self.settings)
        for policy in unnamed_defaults(self.policy, default_policies(), self.env_id):
            check_policy(policy, self.env_id)  # before any database is opened
        if self.minari is not None:  # the extra and the prefix; the ids once named
            from agents.datasets import check_minari

            check_minari(self.minari, [])


def run(args: Args) -> list[Evaluation]:
    """Evaluate, print the table, write the outputs."""
    args = replace(args, policy=unnamed_defaults(args.policy, default_policies(), args.env_id))
    config, bank, settings, episode_note = replay_config(
        args.env_id, args.settings, args.recording, args.split, args.db
    )
    try:
        controllers = [make_controller(p, config, args.env_id, db=args.db) for p in args.policy]
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    check_unique_names(controllers)
    if args.minari is not None:  # refuse before any work
        from agents.datasets import check_minari

        check_minari(args.minari, [c.name for c in controllers])
    print(
        f"rocketroll eval: {args.env_id}, split={args.split}, {args.episodes} episodes, "
        f"seed={args.seed}"
    )
    print(f"  policies: {', '.join(args.policy)}")
    draws = {"posterior": "posterior draws", "replay": "identified traces"}
    print(
        f"  replay: {config.method}'s {draws.get(str(config.disturbance), config.disturbance)}"
        f" of u_d, {config.model} model"
        + ("" if config.recording is None else f", recording {config.recording}")
        + ("" if config.profile is None else f", flown on {config.profile}")
    )
    if episode_note:
        print(episode_note)
    caution = unreliable_note([bank], args.db)  # a recording stored with --accept-unreliable
    specs = protocol_episodes(config, args.episodes, args.seed, bank=bank)
    steps: dict[str, list[dict[str, Any]]] = {c.name: [] for c in controllers}
    keep = args.minari is not None
    results = [
        evaluate(
            config, c, specs, bank=bank, progress=True, transitions=steps[c.name] if keep else None
        )
        for c in controllers
    ]
    table = markdown_table(results, config) + ("" if caution is None else f"\n{caution}\n")
    print(table, end="")
    if args.out is not None:
        from agents.plots import plot_episode, plot_errors
        from rocketroll_common.files import write_all_atomic

        out = Path(args.out)
        protocol = {
            "env_id": args.env_id,
            "split": args.split,
            "seed": args.seed,
            "n_episodes": args.episodes,
            "policies": list(args.policy),
            "settings": settings,
            "bank": bank.description,
            "command": command_of(args),
            **({} if caution is None else {"note": caution}),
        }
        text = json.dumps(to_json(results, config, specs, protocol), indent=1, allow_nan=False)
        episode_png, _ = plot_episode(results, config)
        write_all_atomic(  # every file or none
            {
                out / "table.md": table,
                out / "results.json": text + "\n",
                out / "episode.png": episode_png,
                out / "errors.png": plot_errors(results, config, HEADLINE),
            },
            folder=out,
        )
        print(f"wrote {out}/table.md, results.json, episode.png, errors.png")
    if args.minari is not None:
        from agents.datasets import write_minari

        env_settings = {**settings, "split": args.split}
        about = (
            f"rocketroll eval on {args.env_id} ({args.episodes} protocol episodes, seed "
            f"{args.seed}, {args.split} split)"
        )
        ids = write_minari(args.minari, steps, args.env_id, env_settings, about)
        print(f"wrote Minari datasets {', '.join(ids)} (minari.load_dataset)")
    return results


def command_of(args: Args) -> str:
    """The ``rocketroll eval`` command line that repeats ``args`` (the parser reads it back)."""
    return shlex.join(["rocketroll", "eval", *to_argv(args)])


def _run(args: Args) -> int:
    run(args)
    return 0


#: ``rocketroll eval``.
COMMAND = Command(
    "eval",
    "evaluate controllers on held-out episodes (table, JSON, plots)",
    Args,
    _run,
    __doc__ or "",
)

if __name__ == "__main__":
    sys.exit(run_command(COMMAND, sys.argv[1:], "python -m agents.evaluate"))
