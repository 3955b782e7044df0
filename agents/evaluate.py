"""The evaluation protocol: the same seeded held-out episodes for every controller.

Episodes are drawn once from the *test* split by the environment's own
distribution (trace window, setpoint schedule) with seeds derived from
``--seed``, stored as reset options (:meth:`RocketRollEnv.replay_options`)
and replayed for every controller with the same seed, so every controller
meets the same turbulence, setpoints and gyro noise.  Metrics per episode
and aggregated (mean ± SD and worst case) go to a Markdown table, a JSON
file and PNG plots.

``rocketroll eval --policy pid|ppo[:PATH]|oracle|trim [--policy ...]``, or
``python -m agents.evaluate`` with the same arguments.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.base import Controller
from disturbances.bank import TraceBank
from rollenv import ENV_IDS
from rollenv.bank import load_bank, make_config
from rollenv.cli import parse_setting
from rollenv.core import RollConfig
from rollenv.env import RocketRollEnv

__all__ = [
    "METRICS",
    "EpisodeSpec",
    "Evaluation",
    "Rollout",
    "evaluate",
    "main",
    "markdown_table",
    "metrics",
    "protocol_episodes",
    "register",
]

FloatArray = NDArray[np.float64]

#: Metric name → (description, "max" if larger is worse else "min").
METRICS: dict[str, tuple[str, str]] = {
    "rms_error": ("RMS tracking error over the episode", "max"),
    "max_error": ("largest |tracking error|", "max"),
    "settled_rms_error": ("RMS error in the last quarter of each setpoint period", "max"),
    "fin_travel_dps": ("fin travel per second, °/s", "max"),
    "rate_limit_pct": ("% of time the servo moves at its rate limit", "max"),
    "range_limit_pct": ("% of steps ending with the fin at its range limit", "max"),
    "return": ("sum of rewards", "min"),
}


@dataclass(frozen=True)
class EpisodeSpec:
    """One protocol episode: the reset seed and the options that fix its draw."""

    index: int
    seed: int
    trace: str
    start: int
    setpoints: tuple[float, ...]

    def options(self) -> dict[str, Any]:
        """``reset(options=...)`` for this episode."""
        return {"trace": self.trace, "start": self.start, "setpoints": list(self.setpoints)}


@dataclass(frozen=True)
class Rollout:
    """What happened in one episode, per control step (index 0: after reset).

    Angles in °, rates in °/s, the error in the task's unit.
    """

    time_s: FloatArray
    angle_deg: FloatArray
    rate_dps: FloatArray
    fin_deg: FloatArray
    command_deg: FloatArray
    u_d_deg: FloatArray
    setpoint: FloatArray
    error: FloatArray
    reward: FloatArray


@dataclass
class Evaluation:
    """A controller's protocol result."""

    name: str
    episodes: list[dict[str, float]]
    aggregate: dict[str, dict[str, float]]
    rollouts: list[Rollout] = field(repr=False)
    seconds: float = 0.0


def _env(config: RollConfig, bank: TraceBank) -> RocketRollEnv:
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
    env = _env(config, bank)
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=episodes)
    specs = []
    for i, s in enumerate(seeds.tolist()):
        env.reset(seed=s)
        options = env.replay_options()
        specs.append(
            EpisodeSpec(i, s, options["trace"], options["start"], tuple(options["setpoints"]))
        )
    return specs


def run_episode(env: RocketRollEnv, controller: Controller, spec: EpisodeSpec) -> Rollout:
    """Run ``controller`` through episode ``spec`` of ``env``."""
    obs, info = env.reset(seed=spec.seed, options=spec.options())
    controller.reset(env)
    n = env.config.max_episode_steps + 1
    rows = np.empty((n, 9))
    rows[0] = _row(info, 0.0)
    truncated = False
    k = 0
    while not truncated:
        obs, reward, _, truncated, info = env.step(controller.act(obs, env))
        k += 1
        rows[k] = _row(info, float(reward))
    cols = rows[: k + 1].T
    return Rollout(*(np.ascontiguousarray(c) for c in cols))


def _row(info: dict[str, Any], reward: float) -> tuple[float, ...]:
    return (
        info["time_s"],
        info["roll_deg"],
        info["roll_rate_dps"],
        info["fin_deg"],
        info["fin_cmd_deg"],
        info["u_d_deg"],
        info["setpoint"],
        info["tracking_error"],
        reward,
    )


def metrics(rollout: Rollout, config: RollConfig) -> dict[str, float]:
    """The protocol's metrics of one episode (see :data:`METRICS`).

    Over the steps after reset: RMS and largest |error|; the settled RMS over
    the last quarter of each setpoint period, 7.5-10 s after a change by
    default (turbulence rejection with the slews, even of 180°, done; the
    episode's last quarter if no period ends within it); fin travel ``Σ|Δθ|/T``; time
    at the rate limit, the time the servo needs at 150 °/s to reach each
    command, capped at the step (the servo is a pure rate limiter, so this is
    the time it is moving, to within a substep); steps ending with
    ``|θ| = 40°``; the return.
    """
    error = rollout.error[1:]
    fin = rollout.fin_deg
    duration = len(error) * config.dt_s
    steps = np.arange(1, len(error) + 1)
    period = config.setpoint_period_steps
    settled = (steps % period) >= period - max(period // 4, 1)
    if not settled.any():  # a period as long as the episode: its last quarter
        settled = steps > len(error) - max(len(error) // 4, 1)
    travel = np.abs(np.diff(fin))
    needed = np.abs(rollout.command_deg[1:] - fin[:-1]) / config.rate_limit_dps
    at_range = np.abs(fin[1:]) >= config.fin_range_deg * (1 - 1e-9)
    return {
        "rms_error": float(np.sqrt(np.mean(error**2))),
        "max_error": float(np.max(np.abs(error))),
        "settled_rms_error": float(np.sqrt(np.mean(error[settled] ** 2))),
        "fin_travel_dps": float(travel.sum() / duration),
        "rate_limit_pct": float(100 * np.minimum(needed, config.dt_s).sum() / duration),
        "range_limit_pct": float(100 * np.mean(at_range)),
        "return": float(rollout.reward[1:].sum()),
    }


def aggregate(episodes: Sequence[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Mean, SD (ddof 1) and worst case of each metric over episodes."""
    out = {}
    for name, (_, worse) in METRICS.items():
        values = np.array([e[name] for e in episodes])
        out[name] = {
            "mean": float(values.mean()),
            "sd": float(values.std(ddof=1)) if values.size > 1 else 0.0,
            "worst": float(values.max() if worse == "max" else values.min()),
        }
    return out


def evaluate(
    config: RollConfig,
    controller: Controller,
    specs: Sequence[EpisodeSpec],
    *,
    db: str | os.PathLike[str] | None = None,
    bank: TraceBank | None = None,
    progress: bool = False,
) -> Evaluation:
    """Run ``controller`` through every episode of ``specs``."""
    bank = load_bank(config, db) if bank is None else bank
    env = _env(config, bank)
    rollouts, episodes = [], []
    began = time.perf_counter()
    iterator: Any = specs
    if progress:
        from tqdm.auto import tqdm

        iterator = tqdm(specs, desc=f"{controller.name:>6}", unit="ep", leave=False)
    for spec in iterator:
        rollout = run_episode(env, controller, spec)
        rollouts.append(rollout)
        episodes.append({"episode": spec.index, **metrics(rollout, config)})
    env.close()
    return Evaluation(
        controller.name, episodes, aggregate(episodes), rollouts, time.perf_counter() - began
    )


# ------------------------------------------------------------------------- reports
def markdown_table(results: Sequence[Evaluation], config: RollConfig) -> str:
    """The results as a Markdown table (mean ± SD, worst case in brackets)."""
    unit = "°" if config.task == "angle" else "°/s"
    head = (
        f"| controller | RMS error ({unit}) | max error ({unit}) | settled RMS ({unit}) "
        f"| fin travel (°/s) | at rate limit (%) | at range limit (%) | return |"
    )
    lines = [head, "|" + "---|" * 8]
    for r in results:
        a = r.aggregate

        def cell(name: str, digits: int = 2, agg: dict[str, dict[str, float]] = a) -> str:
            m = agg[name]
            return f"{m['mean']:.{digits}f} ± {m['sd']:.{digits}f} [{m['worst']:.{digits}f}]"

        lines.append(
            f"| {r.name} | {cell('rms_error')} | {cell('max_error', 1)} "
            f"| {cell('settled_rms_error')} | {cell('fin_travel_dps', 1)} "
            f"| {cell('rate_limit_pct', 1)} | {cell('range_limit_pct', 1)} | {cell('return', 1)} |"
        )
    return "\n".join(lines) + "\n"


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
        },
        "controllers": {
            r.name: {"aggregate": r.aggregate, "episodes": r.episodes, "seconds": r.seconds}
            for r in results
        },
    }


# ----------------------------------------------------------------------- policies
POLICY_HELP = (
    "trim | pid[:OMEGA] | oracle | ppo[:DIR] (DIR: a `rocketroll train ppo` output; "
    "default: the committed policy agents/policies/ENV_ID)"
)


def make_controller(
    text: str, config: RollConfig, *, db: str | os.PathLike[str] | None = None
) -> Controller:
    """The controller a ``--policy`` value names (designs use the *train* split only)."""
    from agents.nominal import NominalModel, TrimController

    kind, _, arg = text.partition(":")
    train = replace(config, split="train")
    if kind in ("trim", "pid"):
        model = NominalModel.from_bank(load_bank(train, db))
        if kind == "trim":
            if arg:
                raise ValueError(f"--policy trim takes no argument, got {text!r}")
            return TrimController(model, config.fin_range_deg)
        from agents.pid import PIDController

        try:
            omega = float(arg) if arg else None
        except ValueError:
            raise ValueError(f"--policy pid:OMEGA needs a number, got {text!r}") from None
        pid = PIDController.for_env(config, model, omega)
        if arg:
            pid.name = f"PID ω={omega:g}"
        return pid
    if kind == "oracle":
        from agents.oracle import OracleController

        if arg:
            raise ValueError(f"--policy oracle takes no argument, got {text!r}")
        return OracleController(config)
    if kind == "ppo":
        from agents.ppo import PPOController

        env_id = next(i for i, task in ENV_IDS.items() if task == config.task)
        path = Path(arg) if arg else Path(__file__).parent / "policies" / env_id
        ppo = PPOController.load(path)
        try:
            ppo.require_task(config.task)
        except ValueError as exc:
            raise ValueError(f"--policy {text}: {exc} ({env_id})") from None
        if arg:
            ppo.name = f"PPO {path.name}"
        return ppo
    raise ValueError(f"unknown --policy {text!r}; use {POLICY_HELP}")


# ---------------------------------------------------------------------------- CLI
@dataclass
class Args:
    """``rocketroll eval`` / ``python -m agents.evaluate``."""

    env_id: str = "RocketRoll-v0"
    """RocketRoll-v0 (angle task) or RocketRollRate-v0 (rate task)."""
    policy: list[str] = field(default_factory=lambda: ["trim", "pid", "ppo", "oracle"])
    """Controllers to evaluate, in table order."""
    split: str = "test"
    """Database split the episodes come from (the held-out test split)."""
    episodes: int = 20
    """Number of protocol episodes."""
    seed: int = 0
    """Seed of the protocol's episodes (trace windows, setpoints, gyro noise)."""
    out: Path | None = None
    """Directory for table.md, results.json, episode.png, errors.png (none: print only)."""
    db: Path | None = None
    """Database file (default: $ROCKETROLL_DB or the default database)."""
    settings: dict[str, Any] = field(default_factory=dict)
    """Environment options for every episode (``--set setpoint=zero``), as for gym.make."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The :class:`Args` fields as options."""
    d = Args()
    parser.add_argument(
        "--env-id", default=d.env_id, help="RocketRoll-v0 (angle) or RocketRollRate-v0 (rate)"
    )
    parser.add_argument(
        "--policy",
        action="append",
        default=None,
        metavar="POLICY",
        help=f"{POLICY_HELP}; repeat for several (default: trim, pid, ppo, oracle)",
    )
    parser.add_argument("--split", default=d.split, choices=("train", "test"))
    parser.add_argument("--episodes", type=int, default=d.episodes)
    parser.add_argument("--seed", type=int, default=d.seed)
    parser.add_argument("--out", type=Path, default=None, help="output directory")
    parser.add_argument("--db", type=Path, default=None, help="database file")
    parser.add_argument(
        "--set",
        dest="settings",
        type=parse_setting,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an environment option for every episode, e.g. setpoint=zero (repeatable)",
    )


def run(args: Args) -> list[Evaluation]:
    """Evaluate, print the table, write the outputs."""
    from rocketroll_common.errors import UsageError

    if args.env_id not in ENV_IDS:
        raise UsageError(f"--env-id must be one of {', '.join(ENV_IDS)}, not {args.env_id!r}")
    if args.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    repeated = sorted({p for p in args.policy if args.policy.count(p) > 1})
    if repeated:
        raise UsageError(f"--policy {repeated[0]} is given twice")
    task = ENV_IDS[args.env_id]
    fixed = sorted({"task", "split"} & set(args.settings))
    if fixed:
        raise UsageError(
            f"--set {fixed[0]}=... is not allowed: the task follows --env-id, the split --split"
        )
    try:
        config = make_config(args.env_id, {**args.settings, "task": task, "split": args.split})
        controllers = [make_controller(p, config, db=args.db) for p in args.policy]
    except (ValueError, FileNotFoundError) as exc:
        raise UsageError(str(exc)) from exc
    names = [c.name for c in controllers]
    if len(set(names)) < len(names):
        raise UsageError(f"two --policy values give controllers of one name: {', '.join(names)}")
    print(f"rocketroll eval: {args.env_id}, split={args.split}, {args.episodes} episodes, ")
    print(f"  seed={args.seed}, policies: {', '.join(args.policy)}")
    bank = load_bank(config, args.db)
    specs = protocol_episodes(config, args.episodes, args.seed, bank=bank)
    results = [evaluate(config, c, specs, bank=bank, progress=True) for c in controllers]
    table = markdown_table(results, config)
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
            "settings": dict(args.settings),
            "bank": bank.description,
            "command": command_of(args),
        }
        text = json.dumps(to_json(results, config, specs, protocol), indent=1, allow_nan=False)
        episode_png, _ = plot_episode(results, config)
        write_all_atomic(  # every file or none
            {
                out / "table.md": table,
                out / "results.json": text + "\n",
                out / "episode.png": episode_png,
                out / "errors.png": plot_errors(results, config),
            }
        )
        print(f"wrote {out}/table.md, results.json, episode.png, errors.png")
    return results


def command_of(args: Args) -> str:
    """The ``rocketroll eval`` command line that repeats ``args``."""
    parts = ["rocketroll eval", f"--env-id {args.env_id}"]
    parts += [f"--policy {p}" for p in args.policy]
    parts += [f"--split {args.split}", f"--episodes {args.episodes}", f"--seed {args.seed}"]
    parts += [f"--set {k}={v}" for k, v in args.settings.items()]
    if args.db is not None:
        parts.append(f"--db {args.db}")
    if args.out is not None:
        parts.append(f"--out {args.out}")
    return " ".join(parts)


def parse_args(argv: Sequence[str] | None = None) -> Args:
    """Command-line arguments as :class:`Args`."""
    parser = argparse.ArgumentParser(prog="python -m agents.evaluate", description=__doc__)
    add_arguments(parser)
    return _args(parser.parse_args(argv))


def _args(ns: argparse.Namespace) -> Args:
    d = Args()
    return Args(
        env_id=ns.env_id,
        policy=ns.policy or d.policy,
        split=ns.split,
        episodes=ns.episodes,
        seed=ns.seed,
        out=ns.out,
        db=ns.db,
        settings=dict(ns.settings),
    )


def register(subparsers: Any) -> None:
    """``rocketroll eval``."""
    parser = subparsers.add_parser(
        "eval",
        help="evaluate controllers on held-out episodes (table, JSON, plots)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(parser)
    parser.set_defaults(handler=lambda ns: (run(_args(ns)), 0)[1])


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m agents.evaluate``."""
    from rocketroll_common.errors import RocketrollError

    try:
        run(parse_args(argv))
    except RocketrollError as exc:
        print(f"python -m agents.evaluate: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
