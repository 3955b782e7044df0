"""Steps per second of RocketRoll-v0, single and batched, against Gymnasium's references.

In one run, with random actions drawn beforehand from a seeded generator (the
servo then moves on almost every substep, the costliest case for the exact
update), this measures:

* ``gym.make("RocketRoll-v0")`` -- with the wrappers ``gym.make`` adds and the
  default sensors -- against ``gym.make("Pendulum-v1")``, the named reference:
  **target: at least as fast** (ratio >= 1);
* ``gym.make_vec("RocketRoll-v0", num_envs=4096)`` (``RocketRollVectorEnv``,
  serial kernel, the default) and the same with ``parallel=True`` (numba's
  threads) against Gymnasium's ``CartPoleVectorEnv(num_envs=4096)``:
  **target: >= 10 M env-steps/s**; the CartPole row shows what this machine
  does with a numpy-batched classic-control env;
* ``RocketRollFlight-v0``, single and at 4096 envs, against the tunnel's rows:
  **target: at least 0.8 x** (the rocket changes every step, the
  traces are flown, the angle is the integrated gyro);
* with ``--flight-db DB --flight-recording NAME`` (a flight stored by ``rocketroll db
  add``), ``RocketRollFlight-v0`` flying that stored flight as its rocket (its own
  profile, measured scaling and recorded ``u_d``), single and batched, against the
  default flight's rows: **target: at least 0.8 x**;
* ``RocketRoll-v0`` with a rig beyond the model (:data:`RIG`: a 50-ms servo lag, 0.5° of
  backlash and 30 ms of sensor latency), and with every term on (the rig and each
  rocket's quadratic damping :data:`QUADRATIC`), single and batched, against the default
  rows: **target: at least 0.7 x** (with ``--against``, the default rows
  against the reference show what the rig's code costs a rocket without one).

With ``--against REF`` the RocketRoll rows are also timed in a worktree of
``REF`` (e.g. the last landed commit), block by block alternating with this
checkout (``benchmarks/_against.py``), and the change is printed with its
verdict against the target of no slowdown beyond 5 %.

Episodes reset as they end (single envs: ``reset()`` on truncation; vector
envs: their own NEXT_STEP autoreset), so resets are part of the cost.  Each
task runs ``--repeats`` timed blocks, interleaved task by task so that a busy
spell of a shared machine slows all alike; the table gives the median and
best block.  Compilation (numba, cached on disk after the first run) and the
default database build happen before timing and are reported separately.
Exit status 0 whatever the timings unless ``--strict``.

Run from the repository root::

    .venv/bin/python benchmarks/env_speed.py [--against REF]
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numba
import numpy as np
from _against import SERVE, Remote, serve, start_against
from _records import emit
from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

import rollenv  # noqa: F401  (registers RocketRoll-v0)

SINGLE_TARGET = 1.0  # RocketRoll-v0 / Pendulum-v1
VECTOR_TARGET = 10e6  # env-steps/s at 4096 envs
#: The flight env (per-step rocket, flown traces, integrated gyro) against the tunnel's.
FLIGHT_ID = "RocketRollFlight-v0"
FLIGHT_TARGET = 0.8
#: Largest slowdown against --against REF that still passes, as a fraction.
AGAINST_TOLERANCE = 0.05
#: A rig beyond the model (the environment's settings), and its target against the default.
RIG: dict[str, Any] = {"servo_lag_s": 0.05, "backlash_deg": 0.5, "sensor_latency_s": 0.03}
#: The quadratic damping each rocket of the rig's rows carries (15 % more at 30 °/s).
QUADRATIC = 0.15
RIG_TARGET = 0.7
#: Every task by its row's name: one timed block's runner and the env-steps of a block.
Tasks = dict[str, tuple[Callable[[], float], int]]


def _single_runner(env_id: str, steps: int, seed: int, **settings: Any) -> Callable[[], float]:
    env = gym.make(env_id, **settings)
    env.reset(seed=seed)
    actions = (
        np.random.default_rng(seed)
        .uniform(-1, 1, size=(steps, *(env.action_space.shape or ())))
        .astype(np.float32)
    )
    if env_id.startswith("Pendulum"):
        actions *= 2.0  # Pendulum's torque range is ±2

    def run() -> float:
        step, reset = env.step, env.reset
        t0 = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = step(a)
            if terminated or truncated:
                reset()
        return time.perf_counter() - t0

    return run


def _vector_runner(
    make: Callable[[], Any], steps: int, seed: int, discrete: bool
) -> Callable[[], float]:
    env = make()
    env.reset(seed=seed)
    n = env.num_envs
    rng = np.random.default_rng(seed)
    if discrete:
        actions = rng.integers(0, 2, size=(steps, n))
    else:
        actions = rng.uniform(-1, 1, size=(steps, n, 1)).astype(np.float32)

    def run() -> float:
        step = env.step
        t0 = time.perf_counter()
        for a in actions:
            step(a)
        return time.perf_counter() - t0

    return run


def _parse(argv: Sequence[str] | None) -> tuple[argparse.Namespace, list[str], bool]:
    """The options, the command-line words (less --serve-blocks) and whether to serve blocks."""
    words = list(sys.argv[1:] if argv is None else argv)
    serving = SERVE in words
    if serving:
        words.remove(SERVE)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--single-steps", type=int, default=20000, help="steps per timed block")
    parser.add_argument("--vector-steps", type=int, default=100, help="batched steps per block")
    parser.add_argument("--num-envs", type=int, default=4096, help="batch size (4096)")
    parser.add_argument("--repeats", type=int, default=5, help="timed blocks per task (5)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--against", metavar="REF", help="also time the RocketRoll rows in a checkout of REF"
    )
    parser.add_argument("--strict", action="store_true", help="exit 1 when a target is missed")
    parser.add_argument("--flight-db", help="a database holding a stored flight (rows of its own)")
    parser.add_argument("--flight-recording", help="the stored flight's name in --flight-db")
    ns = parser.parse_args(words)
    if (ns.flight_db is None) != (ns.flight_recording is None):
        parser.error("--flight-db and --flight-recording go together")
    return ns, words, serving


def _rig_runners(
    ns: argparse.Namespace,
) -> dict[str, tuple[Callable[[], float], Callable[[], float]]]:
    """The single and batched runners of each rig row by label (none where there is no rig)."""
    rig_rows: dict[str, dict[str, Any]] = {}
    if _has_rig():
        rig_rows = {"rig": RIG, "rig, q": {**RIG, "bank": _quadratic_bank()}}
    return {
        label: (
            _single_runner("RocketRoll-v0", ns.single_steps, ns.seed, **settings),
            _vector_runner(
                functools.partial(gym.make_vec, "RocketRoll-v0", num_envs=ns.num_envs, **settings),
                ns.vector_steps,
                ns.seed,
                discrete=False,
            ),
        )
        for label, settings in rig_rows.items()
    }


def _build_tasks(ns: argparse.Namespace) -> tuple[Tasks, list[str]]:
    """Every task by its row's name, with the steps of one block, and the rig rows' labels."""
    single = _single_runner("RocketRoll-v0", ns.single_steps, ns.seed)
    vector = _vector_runner(
        lambda: gym.make_vec("RocketRoll-v0", num_envs=ns.num_envs),
        ns.vector_steps,
        ns.seed,
        discrete=False,
    )
    vector_parallel = _vector_runner(
        lambda: gym.make_vec("RocketRoll-v0", num_envs=ns.num_envs, parallel=True),
        ns.vector_steps,
        ns.seed,
        discrete=False,
    )
    # The flight rows (an --against checkout older than the flight env serves the others).
    flying = FLIGHT_ID in gym.registry
    if flying:
        flight_single = _single_runner(FLIGHT_ID, ns.single_steps, ns.seed)
        flight_vector = _vector_runner(
            lambda: gym.make_vec(FLIGHT_ID, num_envs=ns.num_envs),
            ns.vector_steps,
            ns.seed,
            discrete=False,
        )
    stored = {"db": ns.flight_db, "recording": ns.flight_recording}
    if ns.flight_db is not None:
        stored_single = _single_runner(FLIGHT_ID, ns.single_steps, ns.seed, **stored)
        stored_vector = _vector_runner(
            lambda: gym.make_vec(FLIGHT_ID, num_envs=ns.num_envs, **stored),
            ns.vector_steps,
            ns.seed,
            discrete=False,
        )
    rig_runners = _rig_runners(ns)
    pendulum = _single_runner("Pendulum-v1", ns.single_steps, ns.seed)
    cartpole = _vector_runner(
        lambda: CartPoleVectorEnv(num_envs=ns.num_envs), ns.vector_steps, ns.seed, discrete=True
    )
    tasks: Tasks = {
        "RocketRoll-v0 (gym.make)": (single, ns.single_steps),
        "Pendulum-v1 (gym.make)": (pendulum, ns.single_steps),
        f"RocketRoll-v0 x {ns.num_envs} (make_vec)": (vector, ns.vector_steps * ns.num_envs),
        f"  same, parallel=True ({numba.get_num_threads()} thr.)": (
            vector_parallel,
            ns.vector_steps * ns.num_envs,
        ),
        f"CartPoleVectorEnv x {ns.num_envs}": (cartpole, ns.vector_steps * ns.num_envs),
    }
    if flying:
        tasks[f"{FLIGHT_ID} (gym.make)"] = (flight_single, ns.single_steps)
        tasks[f"{FLIGHT_ID} x {ns.num_envs} (make_vec)"] = (
            flight_vector,
            ns.vector_steps * ns.num_envs,
        )
    if ns.flight_db is not None:
        tasks[f"{FLIGHT_ID}, stored (gym.make)"] = (stored_single, ns.single_steps)
        tasks[f"{FLIGHT_ID}, stored x {ns.num_envs}"] = (
            stored_vector,
            ns.vector_steps * ns.num_envs,
        )
    for label, (rig_single, rig_vector) in rig_runners.items():
        tasks[f"RocketRoll-v0, {label} (gym.make)"] = (rig_single, ns.single_steps)
        tasks[f"RocketRoll-v0, {label} x {ns.num_envs}"] = (
            rig_vector,
            ns.vector_steps * ns.num_envs,
        )
    return tasks, list(rig_runners)


def _warm_up(tasks: Tasks) -> float:
    """Seconds of one untimed pass over every task (numba compile or cache load, page faults)."""
    warm = time.perf_counter()
    for run, _ in tasks.values():
        run()
    return time.perf_counter() - warm


def _time_blocks(
    tasks: Tasks, ours: list[str], remote: Remote | None, repeats: int
) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Steps/s of every block, tasks interleaved; REF's blocks of ``ours`` right after ours."""
    rates: dict[str, list[float]] = {name: [] for name in tasks}
    before: dict[str, list[float]] = {name: [] for name in ours}
    for _ in range(repeats):
        for name, (run, count) in tasks.items():
            rates[name].append(count / run())
            if remote is not None and name in ours:
                before[name].append(count / remote.block(name))
    if remote is not None:
        remote.close()
    return rates, before


def _print_table(rates: dict[str, list[float]], med: dict[str, float]) -> None:
    """The table: each task's blocks, median and best steps/s and their spread."""
    from rocketroll_common.tables import Column, text_table  # this checkout's (not older ones')

    columns = (
        Column("task", 38, "<"),
        Column("blocks", 6, ">", " "),
        Column("median steps/s", 15, ">", " "),
        Column("best steps/s", 13, ">", " "),
        Column("spread", 7, ">", " "),
    )
    rows = []
    for name, r in rates.items():
        spread = (max(r) - min(r)) / med[name]
        rows.append([name, str(len(r)), f"{med[name]:,.0f}", f"{max(r):,.0f}", f"{spread:.0%}"])
    header, *lines = text_table(columns, rows)
    print("\n".join([header, "-" * len(header), *lines]))


def _verdicts(med: dict[str, float], ns: argparse.Namespace, rig_labels: list[str]) -> bool:
    """Print and emit each target's figures and verdict; whether all of them passed."""
    names = list(med)
    ratio = med[names[0]] / med[names[1]]
    vec = med[names[2]]
    vec_parallel = med[names[3]]
    cart_ratio = vec / med[names[4]]
    ok_single = ratio >= SINGLE_TARGET
    ok_vector = vec >= VECTOR_TARGET
    emit("RocketRoll-v0 / Pendulum-v1, single env", ratio, "x", at_least=SINGLE_TARGET)
    emit(
        f"vector env, {ns.num_envs} envs",
        vec / 1e6,
        "M env-steps/s",
        at_least=VECTOR_TARGET / 1e6,
        note=f"{cart_ratio:.2f}x CartPoleVectorEnv in the same run",
    )
    emit(
        f"vector env, {ns.num_envs} envs, parallel=True",
        vec_parallel / 1e6,
        "M env-steps/s",
        at_least=VECTOR_TARGET / 1e6,
    )
    print()
    print(
        f"single: RocketRoll-v0 / Pendulum-v1 = {ratio:.2f} (target >= {SINGLE_TARGET:g}): "
        f"{'PASS' if ok_single else 'FAIL'}"
    )
    print(
        f"batched: {vec / 1e6:.2f} M env-steps/s at {ns.num_envs} envs (target >= "
        f"{VECTOR_TARGET / 1e6:g} M): {'PASS' if ok_vector else 'FAIL'}; "
        f"{cart_ratio:.2f} x CartPoleVectorEnv"
    )
    print(
        f"batched, parallel=True: {vec_parallel / 1e6:.2f} M env-steps/s "
        f"({vec_parallel / vec:.2f} x serial): "
        f"{'PASS' if vec_parallel >= VECTOR_TARGET else 'FAIL'}"
    )
    ok_flight = _flight_verdicts(med, ns)
    ok_rig = _rig_verdicts(med, ns.num_envs, rig_labels)
    return ok_single and ok_vector and ok_flight and ok_rig


def _flight_verdicts(med: dict[str, float], ns: argparse.Namespace) -> bool:
    """Print and emit the flight env's ratios (and the stored flight's); whether they passed."""
    names = list(med)
    flight_single_ratio = med[names[5]] / med[names[0]]
    flight_vector_ratio = med[names[6]] / med[names[2]]
    ok_flight = min(flight_single_ratio, flight_vector_ratio) >= FLIGHT_TARGET
    for how, value in (("single", flight_single_ratio), ("batched", flight_vector_ratio)):
        emit(f"{FLIGHT_ID} / RocketRoll-v0, {how}", value, "x", at_least=FLIGHT_TARGET)
    print(
        f"flight: {FLIGHT_ID} / RocketRoll-v0 = {flight_single_ratio:.2f} single, "
        f"{flight_vector_ratio:.2f} batched (target >= {FLIGHT_TARGET:g}): "
        f"{'PASS' if ok_flight else 'FAIL'}"
    )
    if ns.flight_db is not None:
        stored_single_ratio = med[names[7]] / med[names[5]]
        stored_vector_ratio = med[names[8]] / med[names[6]]
        ok_stored = min(stored_single_ratio, stored_vector_ratio) >= FLIGHT_TARGET
        ok_flight &= ok_stored
        print(
            f"stored flight: {ns.flight_recording} / {FLIGHT_ID} = {stored_single_ratio:.2f} "
            f"single, {stored_vector_ratio:.2f} batched (target >= {FLIGHT_TARGET:g}): "
            f"{'PASS' if ok_stored else 'FAIL'}"
        )
    return ok_flight


def _rig_verdicts(med: dict[str, float], num_envs: int, rig_labels: list[str]) -> bool:
    """Print and emit each rig row's ratios to the default rows; whether they all passed."""
    names = list(med)
    ok_rig = True
    words_of = {"rig": "lag, play, latency", "rig, q": "and each rocket's quadratic damping"}
    for label in rig_labels:
        rig_single_ratio = med[f"RocketRoll-v0, {label} (gym.make)"] / med[names[0]]
        rig_vector_ratio = med[f"RocketRoll-v0, {label} x {num_envs}"] / med[names[2]]
        ok = min(rig_single_ratio, rig_vector_ratio) >= RIG_TARGET
        ok_rig = ok_rig and ok
        emit(f"{label} / RocketRoll-v0, single", rig_single_ratio, "x", at_least=RIG_TARGET)
        emit(f"{label} / RocketRoll-v0, batched", rig_vector_ratio, "x", at_least=RIG_TARGET)
        print(
            f"{label} ({words_of[label]}): / RocketRoll-v0 = {rig_single_ratio:.2f} single, "
            f"{rig_vector_ratio:.2f} batched (target >= {RIG_TARGET:g}): "
            f"{'PASS' if ok else 'FAIL'}"
        )
    return ok_rig


def _print_against(
    ref: str, commit: str, med: dict[str, float], before: dict[str, list[float]]
) -> bool:
    """Print this checkout's rows against REF's with the change's verdict; whether all passed."""
    from rocketroll_common.tables import Column, text_table  # this checkout's (not older ones')

    ok_against = True
    print(f"\nthis checkout against {ref} ({commit[:12]}), same blocks alternating:")
    against = (
        Column("task", 38, "<"),
        Column("this steps/s", 14, ">", " "),
        Column("REF steps/s", 13, ">", " "),
        Column("change", 8, ">", " "),
        Column("verdict", 0, "<", "  "),
    )
    print(text_table(against, [])[0])
    for name, blocks in before.items():
        old = statistics.median(blocks)
        change = med[name] / old - 1.0
        ok = change >= -AGAINST_TOLERANCE
        ok_against &= ok
        cells = [
            name,
            f"{med[name]:,.0f}",
            f"{old:,.0f}",
            f"{change:+.1%}",
            f"{'PASS' if ok else 'FAIL'} (no slowdown beyond {AGAINST_TOLERANCE:.0%})",
        ]
        print(text_table(against, [cells])[1])
    return ok_against


def main(argv: Sequence[str] | None = None) -> int:
    """Time every task, print the table and the verdicts; 1 with --strict if a target is missed."""
    ns, words, serving = _parse(argv)
    if not serving:
        print(
            f"python {platform.python_version()}, numpy {np.__version__}, gymnasium "
            f"{gym.__version__}, numba {numba.__version__} ({numba.get_num_threads()} threads), "
            f"{os.cpu_count()} CPU(s), {platform.machine()}"
        )
    t0 = time.perf_counter()
    tasks, rig_labels = _build_tasks(ns)
    setup = time.perf_counter() - t0
    warmup = _warm_up(tasks)
    if serving:
        return serve({name: run for name, (run, _) in tasks.items()})

    ours = [
        name
        for name in tasks
        if name.lstrip().startswith(("RocketRoll-v0", "same")) and ", rig" not in name
    ]
    remote, commit = start_against(__file__, words, ns.against)
    rates, before = _time_blocks(tasks, ours, remote, ns.repeats)

    med = {name: statistics.median(r) for name, r in rates.items()}
    print(f"setup (database, construction) {setup:.1f} s; untimed warm-up pass {warmup:.1f} s\n")
    _print_table(rates, med)
    passed = _verdicts(med, ns, rig_labels)
    if remote is not None:
        passed &= _print_against(ns.against, commit, med, before)
    print("spread: (best - worst) / median over the blocks; a large spread means a busy machine")
    return 1 if ns.strict and not passed else 0


def _quadratic_bank() -> Any:
    """The default environment's bank, every rocket's damping growing by :data:`QUADRATIC`."""
    from disturbances.bank import TraceBank

    bank = gym.make("RocketRoll-v0").unwrapped.bank  # type: ignore[attr-defined]
    traces = [
        dataclasses.replace(t, params=dataclasses.replace(t.params, quadratic_damping=QUADRATIC))
        for t in bank.traces
    ]
    return TraceBank(traces, f"{bank.description}, q = {QUADRATIC:g}")


def _has_rig() -> bool:
    """Whether this checkout's environments take a rig and a rocket's quadratic damping (an
    --against checkout may not)."""
    from identification.model import RollParams
    from rollenv.config import RollConfig

    return "servo_lag_s" in {f.name for f in dataclasses.fields(RollConfig)} and (
        "quadratic_damping" in {f.name for f in dataclasses.fields(RollParams)}
    )


if __name__ == "__main__":
    sys.exit(main())
