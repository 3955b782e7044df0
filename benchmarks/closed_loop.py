"""Closed-loop fidelity: does a controller's score on a replay predict its score on the rocket?

For each virtual-tunnel truth (``benchmarks/_truths.py``) and seed, the tunnel
records a run with known rocket parameters and a known turbulence ``u_d``.
Every identification method (``--methods``) identifies the recording; its
θ-model parameters and ``u_d`` trace are what the disturbance database would
replay.  A method with a posterior (``ml``) also gives ``--draws`` posterior
``u_d`` traces.  Then each controller (``--policies``: trim, PID, the
observer, the MPC, PPO, the oracle) runs on each task (``--tasks``: angle
with setpoint steps, angle held at zero, rate with setpoint steps) over the
same episode windows (the same start, setpoints and gyro noise) twice:

* **true**: the tunnel's true parameters with the true ``u_d``: what the real
  rocket would score;
* **replay**: the method's parameters with the method's ``u_d`` (for the
  posterior, the mean score over its draws): what the environment scores.

The controllers are the shipped ones, designed on the default database's
train split, the same in both runs.  Per recording the score of a metric is
the mean over its windows; the table gives, per method, task, controller and
metric, the ratio replay / true averaged over recordings, its SD over them
and its range, and a verdict per method against the replay's floor: every
averaged RMS, settled-RMS and headline (regulation RMS) ratio of the
deployable controllers within [0.90, 1.10] and the oracle's within [0.80,
1.25], on every task and every truth.

Truths outside the model (``servo-lag``, ``quadratic``, ``latency``, ``gusty``,
``mismatch-all``: ``benchmarks/_truths.py``) fly their true rocket on the
independent reference integrator (``benchmarks/_reference_env.py``:
:mod:`identification.instruments.reference` in closed loop, the environment's sensors and
reward); ``--reference`` flies every true rocket there (with no effects it
scores what the environment scores).  Below the ratios, the **ranking
agreement**: per replay, the controller pairs it orders against the truth on
the headline, pairs within each other's 95 % interval over seeds counted as
ties.

What a user knows of the rig: ``--stated FACTORS`` replays the posterior
draws identified and replayed on the truth's servo lag, backlash and latency
off by each factor, ``--identified`` on what ``identify --actuation`` finds
(with ``--hz``, a 100-Hz log with a measured fin); ``--rig-design`` adds the
observer and the MPC designed on each of those rigs (rows ``observer+rig``,
``mpc+rig``), scored on the truth and on that replay.  ``--fit-quadratic-damping`` adds
the posterior draws identified with a damping growing with the roll rate searched (the
replay ``... q searched`` carries it where the test admits it) and says where it did.

The oracle's errors are hundredths of a degree, set by rare events (a
setpoint step whose slew ends just as the settled window begins, a gust
beyond the fin's reach), so its ratios need many windows and draws: with 4
windows and 4 draws over 5 seeds, three of its cells on the paper's truth
read 1.25-1.85; with 8 and 8 over 10 seeds, 1.03-1.15.

Run from the repository root::

    .venv/bin/python benchmarks/closed_loop.py --seeds 10 --jobs 2     # 10 seeds x 4 truths
    .venv/bin/python benchmarks/closed_loop.py --seeds 2 --truth paper --policies pid
    .venv/bin/python benchmarks/closed_loop.py --seeds 3 --truth latency --methods ml
    .venv/bin/python benchmarks/closed_loop.py --seeds 2 --truth latency --methods ml \
        --stated 1 --rig-design --policies pid,observer,mpc
    .venv/bin/python benchmarks/closed_loop.py --seeds 2 --truth quadratic-strong \
        --methods ml --fit-quadratic-damping --policies pid,observer
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import functools
import math
import multiprocessing
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from _records import emit
from _reference_env import ReferenceRollEnv
from _truths import TRUTHS, spec_of
from tqdm.auto import tqdm

from agents.base import Controller, EpisodeSpec
from agents.evaluate import HEADLINE, env_on, metrics, run_episode
from agents.registry import make_controller
from disturbances.bank import TraceBank
from identification.instruments.reference import Effects
from identification.instruments.tunnel import run_tunnel
from identification.methods import Context, fit, tunnel_methods
from identification.methods.actuation import identify_actuation
from identification.methods.pipeline import IdentifyOptions
from identification.model import RIG_LIMITS, Rig, RollParams
from identification.recordings.recording import Recording, StatedRig
from rocketroll_common.arrays import FloatArray
from rocketroll_common.tables import Column, text_table
from rollenv.bank import variant_config
from rollenv.config import RollConfig
from rollenv.env import RocketRollEnv

#: name -> (environment id, settings on top of it)
TASKS: dict[str, tuple[str, dict[str, object]]] = {
    "angle-steps": ("RocketRoll-v0", {}),
    "angle-zero": ("RocketRoll-v0", {"setpoint": "zero"}),
    "rate-steps": ("RocketRollRate-v0", {}),
}
#: The metrics compared, and the floor on their averaged ratio per controller.
SCORES = ("rms_error", "settled_rms_error", HEADLINE)
BOUNDS = {"oracle": (0.80, 1.25)}
DEFAULT_BOUNDS = (0.90, 1.10)
DEFAULT_TRUTHS = ("paper", "negative", "rising", "staircase-laplace")


@dataclass(frozen=True)
class Rocket:
    """One replayable rocket: parameters and a ``u_d`` trace held per ``dt_s``; ``effects``
    where it is a true rocket outside the model (or checked on the reference integrator),
    which :class:`_reference_env.ReferenceRollEnv` flies; ``rig`` a replay's linkage and
    latency (the environment's own, as the database would give it)."""

    params: RollParams
    u_d_deg: FloatArray
    effects: Effects | None = None
    rig: Rig | None = None
    dt_s: float = 0.1


def stated(effects: Effects, factor: float) -> Rig:
    """What a user states of the rocket's linkage and sensors: the truth's servo lag,
    backlash and latency, each off by ``factor``."""
    return Rig(
        min(effects.servo_lag_s * factor, RIG_LIMITS["lag_s"]),
        min(effects.backlash_deg * factor, RIG_LIMITS["backlash_deg"]),
        min(effects.latency_s * factor, RIG_LIMITS["latency_s"]),
    )


def _posterior(
    rec: Recording, method: str, rig: Rig, draws: int, seed: int, quadratic: bool = False
) -> list[Rocket] | None:
    """The posterior draws of ``method`` on ``rec`` identified with the fin ``rig`` shapes
    (and ``quadratic``: the quadratic damping searched), each replayed on that rig (None:
    the method has no posterior)."""
    options = IdentifyOptions(noise_runs=0, rig=StatedRig.of(rig), fit_quadratic_damping=quadratic)
    found = fit(Context(rec, options), method, ["theta"])["theta"]
    if found.sample_posterior is None or not draws:
        return None
    dt = found.disturbance.interval_s
    return [
        Rocket(found.params, np.asarray(u), rig=rig, dt_s=dt)
        for u in found.sample_posterior(draws, seed)
    ]


def rockets_of(
    truth: str,
    seed: int,
    methods: Sequence[str],
    draws: int,
    reference: bool = False,
    stated_factors: Sequence[float] = (),
    hz: float | None = None,
    identified: bool = False,
    quadratic: bool = False,
) -> tuple[Rocket, dict[str, list[Rocket]]]:
    """The true rocket of one recording and, per replay, what it would replay (the true one
    on the reference integrator where it is outside the model, or ``reference``); with
    ``stated_factors``, the posterior draws of the recording identified and replayed with
    the linkage and latency a user states (the truth's, off by each factor); with
    ``identified``, with what :func:`identification.methods.actuation.identify_actuation` finds.
    ``hz``: the recording logged at this rate with a 1 % gyro and a measured fin (default:
    the truth's own, the paper's 10-Hz encoder); ``quadratic``: also the posterior draws
    identified with the quadratic damping searched (``identify --fit-quadratic-damping``:
    the replay carries it where it is admitted)."""
    spec = spec_of(truth, seed)
    if hz is not None:
        spec = dataclasses.replace(spec, log_dt=1.0 / hz, gyro_noise=1.0, measured_fin=True)
    rec = run_tunnel(spec)
    if rec.ud_true_deg is None:
        raise RuntimeError(f"{truth} seed {seed}: no true u_d")
    effects = spec.effects if (spec.effects.any or reference) else None
    u_true = np.asarray(rec.ud_true_deg[:-1], dtype=float)
    true = Rocket(spec.params(), u_true, effects, dt_s=spec.log_dt)
    context = Context(rec, IdentifyOptions(noise_runs=0))
    replays: dict[str, list[Rocket]] = {}
    for method in methods:
        found = fit(context, method, ["theta"])["theta"]
        dt = found.disturbance.interval_s
        replays[method] = [Rocket(found.params, np.asarray(found.disturbance.u_d_deg), dt_s=dt)]
        if found.sample_posterior is not None and draws:
            replays[f"{method} posterior"] = [
                Rocket(found.params, np.asarray(u), dt_s=dt)
                for u in found.sample_posterior(draws, seed)
            ]
    rigs = {f"stated x{f:g}": stated(spec.effects, f) for f in stated_factors}
    if identified:
        rigs["identified"] = identify_actuation(rec).rig
    for label, rig in rigs.items():  # identified and replayed on the rig stated or found
        for method in methods:
            drawn = _posterior(rec, method, rig, draws, seed)
            if drawn is not None:
                replays[f"{method} posterior, {label}"] = drawn
    for method in methods if quadratic else ():
        drawn = _posterior(rec, method, Rig(), draws, seed, quadratic=True)
        if drawn is not None:
            replays[f"{method} posterior, q searched"] = drawn
    return true, replays


def env_of(config: RollConfig, rocket: Rocket) -> RocketRollEnv:
    """The environment of ``config`` replaying one rocket (on the reference integrator, with
    its effects, where it has them)."""
    bank = TraceBank.from_arrays([rocket.u_d_deg], rocket.dt_s, rocket.params, rig=rocket.rig)
    if rocket.effects is not None:
        return ReferenceRollEnv(config, bank, rocket.effects)
    return env_on(config, bank)


def windows(
    config: RollConfig, true: Rocket, length: int, count: int, seed: int
) -> list[EpisodeSpec]:
    """``count`` episode windows spread over the first ``length`` control steps, each with
    the setpoints the true env draws for it (``start``: in control steps)."""
    env = env_of(config, true)
    uid = env.bank.traces[0].uid
    span = length - config.max_episode_steps - 1
    starts = np.linspace(0, span, count).astype(int)
    specs = []
    for i, start in enumerate(starts.tolist()):
        own = round(start * config.dt_s / true.dt_s)
        env.reset(seed=seed * 1000 + i, options={"trace": uid, "start": own})
        options = env.replay_options()
        specs.append(EpisodeSpec(i, seed * 1000 + i, uid, start, tuple(options["setpoints"])))
    env.close()
    return specs


def score(
    config: RollConfig, controller: Controller, rocket: Rocket, specs: Sequence[EpisodeSpec]
) -> dict[str, float]:
    """Mean of each compared metric over the windows, on ``rocket``."""
    env = env_of(config, rocket)
    uid = env.bank.traces[0].uid
    totals = dict.fromkeys(SCORES, 0.0)
    for spec in specs:
        own = round(spec.start * config.dt_s / rocket.dt_s)  # the window in its samples
        history = run_episode(
            env, controller, EpisodeSpec(spec.index, spec.seed, uid, own, spec.setpoints)
        )
        values = metrics(history, config)
        for name in SCORES:
            totals[name] += values[name] / len(specs)
    env.close()
    return totals


@functools.cache
def _controller(task: str, policy: str, rig: Rig | None = None) -> Controller:
    """The shipped controller of ``policy`` for ``task`` (made once per process); with
    ``rig``, designed on it (the observer and the MPC read it)."""
    config = _config(task)
    return make_controller(policy, config if rig is None else config.with_rig(rig), TASKS[task][0])


#: The controllers that design on a rig, and the name of their rows designed on a replay's.
RIG_DESIGNS = {"observer": "observer+rig", "mpc": "mpc+rig"}


@functools.cache
def _config(task: str) -> RollConfig:
    return variant_config(TASKS[task][0], TASKS[task][1])


def recording_rows(
    truth: str,
    seed: int,
    methods: Sequence[str],
    draws: int,
    tasks: Sequence[str],
    policies: Sequence[str],
    count: int,
    reference: bool = False,
    stated_factors: Sequence[float] = (),
    hz: float | None = None,
    identified: bool = False,
    rig_design: bool = False,
    quadratic: bool = False,
) -> list[dict[str, object]]:
    """Every score of one recording: per task, controller, replay and metric, the true
    score, the replayed one and their ratio (one CSV row each).  With ``rig_design``, each
    replay on a rig (stated or identified) also scores the observer and the MPC designed on
    that rig (:data:`RIG_DESIGNS`), on the truth and on the replay."""
    true, replays = rockets_of(
        truth, seed, methods, draws, reference, stated_factors, hz, identified, quadratic
    )
    every = [true, *(r for rs in replays.values() for r in rs)]
    seconds = min(r.u_d_deg.size * r.dt_s for r in every)
    rows: list[dict[str, object]] = []
    for task in tasks:
        config = _config(task)
        length = int(seconds / config.dt_s + 1e-9)
        specs = windows(config, true, length, count, seed)
        runs: list[tuple[str, Controller, dict[str, list[Rocket]]]] = [
            (policy, _controller(task, policy), replays) for policy in policies
        ]
        for replay, rockets in replays.items():
            rig = rockets[0].rig
            if not rig_design or rig is None or rig.ideal:
                continue
            for policy in (p for p in policies if p in RIG_DESIGNS):
                designed = _controller(task, policy, rig)
                runs.append((RIG_DESIGNS[policy], designed, {replay: rockets}))
        for policy, controller, scored in runs:
            base = score(config, controller, true, specs)
            for replay, rockets in scored.items():
                got = [score(config, controller, r, specs) for r in rockets]
                for name in SCORES:
                    value = float(np.mean([g[name] for g in got]))
                    rows.append(
                        {
                            "truth": truth,
                            "seed": seed,
                            "task": task,
                            "controller": policy,
                            "replay": replay,
                            "metric": name,
                            "true": base[name],
                            "replayed": value,
                            "ratio": value / base[name],
                            "quadratic_damping": rockets[0].params.quadratic_damping,
                        }
                    )
    return rows


def ranking_lines(
    rows: Sequence[dict[str, object]], tasks: Sequence[str], policies: Sequence[str]
) -> list[str]:
    """Ranking agreement on the headline: per replay, truth and task, the controller pairs
    the replay orders against the truth.  A pair whose true scores (over the truth's
    seeds) lie within each other's 95 % interval is a tie and cannot be misordered."""
    scores: dict[tuple[str, str, str, str], tuple[list[float], list[float]]] = {}
    for row in rows:
        if row["metric"] != HEADLINE:
            continue
        key = (str(row["replay"]), str(row["truth"]), str(row["task"]), str(row["controller"]))
        true, replayed = scores.setdefault(key, ([], []))
        true.append(float(row["true"]))  # type: ignore[arg-type]
        replayed.append(float(row["replayed"]))  # type: ignore[arg-type]

    def interval(values: list[float]) -> tuple[float, float, float]:
        x = np.asarray(values)
        half = 1.96 * float(np.std(x, ddof=1)) / math.sqrt(x.size) if x.size > 1 else 0.0
        return float(x.mean()), float(x.mean()) - half, float(x.mean()) + half

    lines = ["Ranking agreement on the headline (controller pairs the replay orders against the "
             "truth; pairs within each other's 95 % interval over seeds are ties):"]  # fmt: skip
    replays = list(dict.fromkeys(k[0] for k in scores))
    truths = list(dict.fromkeys(k[1] for k in scores))
    for replay in replays:
        against = pairs = ties = 0
        cells = []
        for truth in truths:
            for task in tasks:
                mine = [p for p in policies if (replay, truth, task, p) in scores]
                bad = 0
                for i, first in enumerate(mine):
                    for second in mine[i + 1 :]:
                        t1, r1 = scores[(replay, truth, task, first)]
                        t2, r2 = scores[(replay, truth, task, second)]
                        m1, lo1, hi1 = interval(t1)
                        m2, lo2, hi2 = interval(t2)
                        pairs += 1
                        if lo2 <= m1 <= hi2 or lo1 <= m2 <= hi1:
                            ties += 1
                            continue
                        if (m1 < m2) != (float(np.mean(r1)) < float(np.mean(r2))):
                            bad += 1
                if bad:
                    cells.append(f"{truth}/{task} {bad}")
                against += bad
        lines.append(
            f"  {replay}: {against} of {pairs} pairs against the truth ({ties} ties)"
            + (f": {', '.join(cells)}" if cells else "")
        )
    return lines


def quadratic_lines(rows: Sequence[dict[str, object]]) -> list[str]:
    """Per replay and truth: the recordings whose identification kept a quadratic damping,
    and the coefficients it kept."""
    kept: dict[tuple[str, str], dict[int, float]] = {}
    for row in rows:
        if not str(row["replay"]).endswith("q searched"):
            continue
        key = (str(row["replay"]), str(row["truth"]))
        seed, q = row["seed"], row["quadratic_damping"]
        assert isinstance(seed, int) and isinstance(q, float)
        kept.setdefault(key, {})[seed] = q
    lines = ["Quadratic damping kept in the replay (admitted at p < 0.01), per truth:"]
    for (replay, truth), by_seed in kept.items():
        values = [q for q in by_seed.values() if q != 0.0]
        lines.append(
            f"  {replay}, {truth}: {len(values)} of {len(by_seed)} recordings"
            + (f" (q = {', '.join(f'{q:.3g}' for q in sorted(values))})" if values else "")
        )
    return lines


#: The statistics of each ratio row, after the replay, task, controller and metric.
RATIO_COLUMNS = ("ratio", "SD", "min", "max")


def summarise(values: Sequence[float]) -> tuple[float, float, float, float]:
    x = np.asarray(values, dtype=float)
    sd = float(np.std(x, ddof=1)) if x.size > 1 else math.nan
    return float(np.mean(x)), sd, float(np.min(x)), float(np.max(x))


def _parser() -> argparse.ArgumentParser:
    """The command line: what to score, how many of each, and what else to replay."""
    parser = argparse.ArgumentParser(
        prog="benchmarks/closed_loop.py",
        description="Closed-loop fidelity of each identification method's replay against the "
        "virtual tunnel's truth, per controller and task.",
    )
    parser.add_argument("--seeds", type=int, default=5, help="seeds per truth (default 5)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument(
        "--truth",
        action="append",
        choices=(*TRUTHS, "all"),
        help=f"a named truth (repeat; default: {', '.join(DEFAULT_TRUTHS)})",
    )
    parser.add_argument(
        "--methods",
        default=None,
        help="comma-separated methods (default: every tunnel method that fits the θ model)",
    )
    parser.add_argument(
        "--policies",
        default="trim,pid,observer,mpc,ppo,oracle",
        help="comma-separated controllers",
    )
    parser.add_argument(
        "--tasks", default=",".join(TASKS), help=f"comma-separated tasks ({', '.join(TASKS)})"
    )
    parser.add_argument(
        "--windows", type=int, default=8, help="60-s windows per recording (default 8)"
    )
    parser.add_argument(
        "--draws", type=int, default=8, help="posterior draws per recording (default 8)"
    )
    parser.add_argument(
        "--jobs", type=int, default=1, help="recordings scored in parallel processes (default 1)"
    )
    parser.add_argument("--csv", type=Path, default=None, help="per-recording scores to a CSV")
    parser.add_argument("--strict", action="store_true", help="exit 1 if no method passes")
    parser.add_argument(
        "--reference",
        action="store_true",
        help="fly every true rocket on the independent reference integrator (with no effects "
        "it must score what the environment scores: a check of both)",
    )
    parser.add_argument(
        "--stated",
        default="",
        metavar="FACTORS",
        help="also replay the posterior draws with the servo lag, backlash and latency a user "
        "states: the truth's times each comma-separated factor (e.g. 0.8,1,1.2)",
    )
    parser.add_argument(
        "--identified",
        action="store_true",
        help="also replay the posterior draws with the servo lag, backlash and latency that "
        "identify --actuation finds in each recording",
    )
    parser.add_argument(
        "--hz",
        type=float,
        default=None,
        help="log each recording at this rate with a 1 %% gyro and a measured fin column "
        "(default: the truth's own, the paper's 10-Hz encoder)",
    )
    parser.add_argument(
        "--rig-design",
        action="store_true",
        help="with --stated or --identified: also score the observer and the MPC designed on "
        "each replay's rig (rows observer+rig, mpc+rig), on the truth and on that replay",
    )
    parser.add_argument(
        "--fit-quadratic-damping",
        action="store_true",
        help="also replay the posterior draws identified with a damping growing with the roll "
        "rate searched, carried where it is admitted (identify --fit-quadratic-damping)",
    )
    return parser


@dataclass(frozen=True)
class Plan:
    """What a run scores, as the command line states it once checked."""

    truths: list[str]
    seeds: range
    methods: tuple[str, ...]
    policies: list[str]
    tasks: list[str]
    stated_factors: tuple[float, ...]


def _parse(argv: Sequence[str] | None) -> tuple[argparse.Namespace, Plan]:
    """The parsed command line and its plan (exit 2 on a setting out of range or unknown)."""
    parser = _parser()
    ns = parser.parse_args(argv)
    if ns.hz is not None and not 1.0 <= ns.hz <= 1000.0:
        parser.error("--hz: a rate in [1, 1000] Hz")
    try:
        stated_factors = tuple(float(f) for f in ns.stated.split(",") if f.strip())
    except ValueError:
        parser.error(f"--stated: comma-separated numbers, got {ns.stated!r}")
    if any(not 0.0 <= f <= 10.0 for f in stated_factors):
        parser.error("--stated: factors in [0, 10]")
    truths = list(dict.fromkeys(ns.truth or DEFAULT_TRUTHS))
    if "all" in truths:
        truths = list(TRUTHS)
    replayed = tunnel_methods(["theta"])  # the replays fly each method's θ model
    methods = replayed if ns.methods is None else tuple(ns.methods.split(","))
    for method in methods:
        if method not in replayed:
            parser.error(f"--methods: {method!r} is not one of {', '.join(replayed)}")
    policies = ns.policies.split(",")
    tasks = ns.tasks.split(",")
    for task in tasks:
        if task not in TASKS:
            parser.error(f"--tasks: unknown task {task!r}; known: {', '.join(TASKS)}")
    if ns.seeds < 1 or ns.windows < 1 or ns.draws < 0 or ns.jobs < 1:
        parser.error("--seeds, --windows and --jobs must be >= 1, --draws >= 0")
    for task in tasks:  # the shipped controllers exist (fail here, not in a worker)
        for policy in policies:
            _controller(task, policy)
    seeds = range(ns.first_seed, ns.first_seed + ns.seeds)
    return ns, Plan(truths, seeds, methods, policies, tasks, stated_factors)


def _score_recordings(ns: argparse.Namespace, plan: Plan) -> list[list[dict[str, object]]]:
    """The rows of every recording (truth, then seed), scored here or in ``--jobs`` processes."""
    jobs = [
        (
            truth,
            seed,
            plan.methods,
            ns.draws,
            tuple(plan.tasks),
            tuple(plan.policies),
            ns.windows,
            ns.reference,
            plan.stated_factors,
            ns.hz,
            ns.identified,
            ns.rig_design,
            ns.fit_quadratic_damping,
        )
        for truth in plan.truths
        for seed in plan.seeds
    ]
    if ns.jobs == 1:
        done = (recording_rows(*job) for job in jobs)
        return list(tqdm(done, total=len(jobs), desc="recordings", unit="rec"))
    # spawn: the parent holds torch's threads, which a fork would copy mid-state.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(ns.jobs, mp_context=context) as pool:
        futures = [pool.submit(recording_rows, *job) for job in jobs]
        for _ in tqdm(as_completed(futures), total=len(jobs), desc="recordings", unit="rec"):
            pass
        return [f.result() for f in futures]


#: ratios[(replay, task, policy, metric)][truth] -> that truth's per-recording ratios
Ratios = dict[tuple[str, str, str, str], dict[str, list[float]]]


def _ratios_of(
    results: Sequence[list[dict[str, object]]],
) -> tuple[Ratios, list[dict[str, object]]]:
    """Every recording's ratios gathered per replay, task, controller, metric and truth, and
    all the rows in order."""
    ratios: Ratios = {}
    rows: list[dict[str, object]] = []
    for found in results:
        for row in found:
            key = (str(row["replay"]), str(row["task"]), str(row["controller"]), str(row["metric"]))
            ratio = row["ratio"]
            assert isinstance(ratio, float)
            ratios.setdefault(key, {}).setdefault(str(row["truth"]), []).append(ratio)
            rows.append(row)
    return ratios, rows


def _print_ratios(
    ratios: Ratios, tasks: Sequence[str], scored: Sequence[str]
) -> dict[str, list[tuple[str, bool]]]:
    """Print the table of ratios averaged over recordings; per replay, each
    task/controller/metric cell and whether it is within the floor."""
    replays_seen = list(dict.fromkeys(k[0] for k in ratios))
    columns = (
        Column("replay", 30, "<"),
        Column("task", 12, "<", " "),
        Column("controller", 10, "<", " "),
        Column("metric", 18, "<", " "),
        *(Column(title, 7 if title == "ratio" else 6, ">", " ") for title in RATIO_COLUMNS),
        Column("in floor", 0, "<", "  "),
    )
    header = text_table(columns, [])[0]
    print("replay score / true score, per recording, averaged over recordings:")
    print(header)
    print("-" * len(header))
    verdicts: dict[str, list[tuple[str, bool]]] = {r: [] for r in replays_seen}
    for replay in replays_seen:
        for task in tasks:
            for policy in scored:
                for name in SCORES:
                    by_truth = ratios.get((replay, task, policy, name))
                    if by_truth is None:  # a rig design: only on the replays with a rig
                        continue
                    mean, sd, lo, hi = summarise([r for rs in by_truth.values() for r in rs])
                    low, high = BOUNDS.get(policy, DEFAULT_BOUNDS)
                    # The floor holds per truth: the ratio averaged over each truth's seeds.
                    ok = all(low <= float(np.mean(rs)) <= high for rs in by_truth.values())
                    verdicts[replay].append((f"{task}/{policy}/{name}", ok))
                    cells = [replay, task, policy, name, *(f"{v:.3f}" for v in (mean, sd, lo, hi))]
                    print(text_table(columns, [[*cells, "yes" if ok else "NO"]])[1])
        print()
    return verdicts


def _print_verdicts(verdicts: dict[str, list[tuple[str, bool]]]) -> None:
    """Print and emit, per replay, the share of its cells within the floor."""
    print(
        "Verdict per replay (floor: deployable controllers within [0.90, 1.10], the oracle within "
        "[0.80, 1.25], averaged over each truth's seeds, every task and truth):"
    )
    for replay, checks in verdicts.items():
        missed = [c for c, ok in checks if not ok]
        emit(
            f"{replay}: share of task/controller/metric cells within the floor",
            (len(checks) - len(missed)) / len(checks),
            "",
            at_least=1.0,
            note=f"{len(checks) - len(missed)}/{len(checks)}"
            + (f"; outside: {', '.join(missed[:6])}" if missed else ""),
        )
        print(
            f"  {replay}: {len(checks) - len(missed)}/{len(checks)} within the floor"
            + (
                f"; outside: {', '.join(missed[:6])}{' ...' if len(missed) > 6 else ''}"
                if missed
                else ""
            )
        )


def _write_csv(path: Path, rows: Sequence[dict[str, object]]) -> None:
    """Every recording's rows to a CSV, one per task, controller, replay and metric."""
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def main(argv: Sequence[str] | None = None) -> int:
    """Score every recording's replays against its truth, print the ratios, the verdicts and
    the ranking agreement; exit 1 under ``--strict`` if no replay passes."""
    ns, plan = _parse(argv)
    seeds = plan.seeds
    print(
        f"truths {', '.join(plan.truths)}; seeds {seeds[0]}-{seeds[-1]}; "
        f"methods {', '.join(plan.methods)}; controllers {', '.join(plan.policies)}; "
        f"tasks {', '.join(plan.tasks)}; {ns.windows} windows of 60 s per recording; "
        f"{ns.draws} posterior draws"
    )
    began = time.perf_counter()
    ratios, rows = _ratios_of(_score_recordings(ns, plan))
    print(f"\n{time.perf_counter() - began:.0f} s\n")
    scored = list(dict.fromkeys(k[2] for k in ratios))  # the policies, then the rig designs
    verdicts = _print_ratios(ratios, plan.tasks, scored)
    _print_verdicts(verdicts)
    print()
    for line in ranking_lines(rows, plan.tasks, scored):
        print(line)
    if ns.fit_quadratic_damping:
        print()
        for line in quadratic_lines(rows):
            print(line)
    if ns.csv is not None:
        _write_csv(ns.csv, rows)
        print(f"\nwrote {ns.csv}")
    passed = any(all(ok for _, ok in checks) for checks in verdicts.values())
    return 1 if ns.strict and not passed else 0


if __name__ == "__main__":
    raise SystemExit(main())
