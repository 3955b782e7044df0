"""Speed of the paper's identification pipeline on the bundled 573-s recording.

Measures, in one run and on one machine, on ``tunnel-paper-seed0`` (the
paper's Table 1 experiment, 5731 samples at 10 Hz):

* the whole pipeline without the Monte Carlo noise study,
  ``identify(rec, IdentifyOptions(noise_runs=0))`` -- one warm-up call, then
  ``--repeats`` timed calls; median and IQR against the 50 ms target;
* the named reference measured in the same run: the output-error peer
  :func:`identification.methods.baselines.output_error` (``"constant"`` and
  ``"theta"``) on the same recording, with its ratio to the pipeline;
* the §3.3 Monte Carlo (4 noise levels x 100 runs = 400 runs) timed by
  calling :func:`identification.methods.noise.noise_study` directly with the pieces of
  one identification, median of ``--mc-repeats`` against the 5 s target;
* maximum likelihood (``method="ml"``) of both models in one call, against
  the 1 s target, and 100 posterior ``u_d`` traces drawn from its θ-model fit
  (:meth:`identification.methods.ml.MLFit.posterior_draws`), against 0.5 s;
* every other registered identification method
  (:data:`identification.methods.METHODS`) through
  ``methods.fit(recording, method, [model])`` -- its parameters *and* its
  ``u_d`` with the re-simulation (steps 8-9), from a fresh context each call.

With ``--against REF`` the pipeline, the output-error peer and the Monte Carlo
are also timed in a worktree of ``REF`` (``benchmarks/_against.py``), their
calls alternating with this checkout's, and the change is printed.

The timed calls of the four tasks are interleaved over one schedule, so that
a busy spell of a shared machine slows them alike.  Wall-clock times by
:func:`time.perf_counter`.  The exit status is 0 whatever
the timings unless ``--strict`` is given, when a missed target gives 1.

Run from the repository root::

    .venv/bin/python benchmarks/speed.py [--against REF]
"""

from __future__ import annotations

import os

# One OpenBLAS thread unless the environment names a number: what the rocketroll command
# runs with (rocketroll_common.numerics.one_blas_thread); OPENBLAS_NUM_THREADS=2 for the other.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import functools
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from _against import SERVE, Remote, serve, start_against
from _records import emit

from identification.instruments.bundled import load_bundled
from identification.methods.baselines import output_error
from identification.methods.noise import noise_study
from identification.methods.pipeline import Identification, IdentifyOptions, identify

if TYPE_CHECKING:
    from identification.recordings.recording import Recording

RECORDING = "tunnel-paper-seed0"
PIPELINE_TARGET_MS = 50.0
MONTE_CARLO_TARGET_MS = 5000.0
MONTE_CARLO_RUNS = 100
#: Targets: maximum likelihood on the 573-s recording (both models), and 100 posterior traces.
ML_TARGET_MS = 1000.0
POSTERIOR_TARGET_MS = 500.0
POSTERIOR_DRAWS = 100
#: A timed task: its name, the call, and how many timed calls it gets.
Task = tuple[str, Callable[[], object], int]


@dataclass(frozen=True)
class Timing:
    """Repeated wall-clock timings of one task, ms (``first_ms``: the untimed warm-up call)."""

    name: str
    samples_ms: tuple[float, ...]
    first_ms: float

    @property
    def median_ms(self) -> float:
        return float(np.median(self.samples_ms))

    @property
    def iqr_ms(self) -> float:
        q75, q25 = np.percentile(self.samples_ms, [75, 25])
        return float(q75 - q25)

    @property
    def min_ms(self) -> float:
        return float(np.min(self.samples_ms))


def time_interleaved(
    tasks: Sequence[tuple[str, Callable[[], object], int]],
    remote: Remote | None = None,
    common: Sequence[str] = (),
) -> tuple[list[Timing], dict[str, list[float]]]:
    """Time several tasks with their calls interleaved.

    Each task ``(name, func, repeats)`` is called once untimed (warm-up), then
    ``repeats`` times; the timed calls of all tasks are spread evenly over one
    schedule, so that a slow spell of the machine hits every task alike and
    the ratios between them stay meaningful.  With ``remote``, each timed call
    of a task in ``common`` is followed by the same call in the other
    checkout; its times (ms) are returned by name.
    """
    first: list[float] = []
    for _, func, _ in tasks:
        start = time.perf_counter()
        func()
        first.append((time.perf_counter() - start) * 1e3)
    events = sorted(
        ((k + 0.5) / repeats, i) for i, (_, _, repeats) in enumerate(tasks) for k in range(repeats)
    )
    samples: list[list[float]] = [[] for _ in tasks]
    other: dict[str, list[float]] = {name: [] for name in common}
    for _, i in events:
        name, func, _ = tasks[i]
        start = time.perf_counter()
        func()
        samples[i].append((time.perf_counter() - start) * 1e3)
        if remote is not None and name in other:
            other[name].append(remote.block(name) * 1e3)
    timings = [
        Timing(name, tuple(times), first_ms)
        for (name, _, _), times, first_ms in zip(tasks, samples, first, strict=True)
    ]
    return timings, other if remote is not None else {}


def _timed(func: Callable[[], object]) -> Callable[[], float]:
    def run() -> float:
        start = time.perf_counter()
        func()
        return time.perf_counter() - start

    return run


def run_monte_carlo(result: Identification, runs: int) -> None:
    """The §3.3 noise study of ``identify`` with ``runs`` runs per level, alone."""
    opts = result.options
    noise_study(
        result.constant_model,
        result.grid,
        result.theta_fine,
        result.velocity_fine,
        levels_pct=opts.noise_levels_pct,
        runs=runs,
        seed=opts.noise_seed,
        interval_s=opts.ud_interval_s,
        smoothing_passes=opts.smoothing_passes,
    )


def verdict(median_ms: float, target_ms: float) -> str:
    return "PASS" if median_ms <= target_ms else "FAIL"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="benchmarks/speed.py",
        description=(
            f"Time identify() on the bundled {RECORDING} recording against a "
            f"{PIPELINE_TARGET_MS:g} ms median target, the output-error peer beside it, "
            f"and the 400-run Monte Carlo against {MONTE_CARLO_TARGET_MS / 1e3:g} s."
        ),
    )
    parser.add_argument("--repeats", type=int, default=30, help="timed pipeline calls (default 30)")
    parser.add_argument(
        "--peer-repeats", type=int, default=5, help="timed calls of each peer fit (default 5)"
    )
    parser.add_argument(
        "--mc-repeats", type=int, default=3, help="timed Monte Carlo studies (default 3)"
    )
    parser.add_argument(
        "--against", metavar="REF", help="also time the common tasks in a checkout of REF"
    )
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 when a target is missed"
    )
    parser.add_argument(
        "--busy",
        type=int,
        default=0,
        metavar="N",
        help="keep N cores busy (a spinning process each) while timing: a user's laptop is "
        "rarely idle (default 0)",
    )
    return parser


def _parse(argv: Sequence[str] | None) -> tuple[argparse.Namespace, list[str], bool]:
    """The options, the command-line words (less --serve-blocks) and whether to serve blocks."""
    words = list(sys.argv[1:] if argv is None else argv)
    serving = SERVE in words
    if serving:
        words.remove(SERVE)
    ns = build_parser().parse_args(words)
    for name in ("repeats", "peer_repeats", "mc_repeats"):
        if getattr(ns, name) < 1:
            raise SystemExit(f"--{name.replace('_', '-')} must be >= 1")
    return ns, words, serving


def _build_tasks(
    ns: argparse.Namespace,
    rec: Recording,
    options: IdentifyOptions,
    common: dict[str, Callable[[], object]],
    result: Identification,
    mc_name: str,
) -> tuple[list[Task], list[str]]:
    """Every timed task ``(name, func, repeats)`` in table order, and the methods judged."""
    from identification.methods import METHODS, fit, traits  # this checkout's (not in older ones)
    from identification.methods.ml import maximum_likelihood

    others = [  # the tunnel's methods (a flight method identifies flights only)
        m for m in METHODS.names() if m != "paper" and not traits(m).flight
    ]
    ml_theta = maximum_likelihood(rec, "theta", options=options)
    from identification.methods import Context
    from identification.methods.adequacy import adequacy

    context = Context(rec, options)
    judged = {m: fit(context, m, ["theta"])["theta"] for m in ("paper", *others)}
    tasks: list[Task] = [
        ("identify(noise_runs=0)", common["identify(noise_runs=0)"], ns.repeats),
        *(
            (
                f'output_error("{model}")',
                common[f'output_error("{model}")'],
                ns.peer_repeats,
            )
            for model in ("constant", "theta")
        ),
        (mc_name, lambda: run_monte_carlo(result, MONTE_CARLO_RUNS), ns.mc_repeats),
        (
            'fit(method="ml", both models)',
            functools.partial(fit, rec, "ml", ["constant", "theta"], options),
            ns.peer_repeats,
        ),
        (
            f"posterior_draws({POSTERIOR_DRAWS})",
            functools.partial(ml_theta.posterior_draws, POSTERIOR_DRAWS, 0),
            ns.peer_repeats,
        ),
        *(
            (
                f'fit(method="{method}", "{model}")',
                functools.partial(fit, rec, method, [model], options),
                ns.peer_repeats,
            )
            for method in others
            for model in traits(method).models
        ),
        *(
            (
                f'adequacy("{method}", "theta")',
                functools.partial(
                    adequacy,
                    context.measurements,
                    found.params,
                    found.disturbance,
                    found.metrics,
                    method=method,
                ),
                ns.repeats,
            )
            for method, found in judged.items()
        ),
    ]
    return tasks, list(judged)


def _time_tasks(
    ns: argparse.Namespace,
    words: list[str],
    tasks: Sequence[Task],
    common: Sequence[str],
) -> tuple[list[Timing], dict[str, list[float]], str]:
    """The tasks timed (``--busy`` cores kept busy), REF's times of ``common``, REF's commit."""
    spinners = [
        subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(ns.busy)
    ]
    try:
        remote, commit = start_against(__file__, words, ns.against)
        timings, before = time_interleaved(tasks, remote, common)
        if remote is not None:
            remote.close()
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
    return timings, before, commit


def _print_table(rows: Sequence[tuple[Timing, float | None]]) -> None:
    """One line per task, with its target (None: a reference) and its ratio to the first."""
    from rocketroll_common.tables import Column, text_table  # (not in older checkouts)

    pipeline = rows[0][0]
    columns = (  # one timed task per line: its calls, their statistics, target and verdict
        Column("task", 30, "<"),
        Column("n", 3, ">", " "),
        Column("median ms", 10, ">", " "),
        Column("IQR ms", 8, ">", " "),
        Column("min ms", 8, ">", " "),
        Column("1st ms", 8, ">", " "),
        Column("target ms", 10, ">", " "),
        Column("x pipeline", 10, ">", " "),
        Column("verdict", 0, "<", "  "),
    )
    header = text_table(columns, [])[0]
    print()
    print(header)
    print("-" * len(header))
    for t, target in rows:
        ratio = t.median_ms / pipeline.median_ms
        target_text = f"{target:.0f}" if target is not None else "-"
        mark = verdict(t.median_ms, target) if target is not None else "(reference)"
        cells = [
            t.name,
            str(len(t.samples_ms)),
            f"{t.median_ms:.1f}",
            f"{t.iqr_ms:.1f}",
            f"{t.min_ms:.1f}",
            f"{t.first_ms:.1f}",
            target_text,
            f"{ratio:.2f}",
            mark,
        ]
        print(text_table(columns, [cells])[1])
        emit(
            f"{t.name}: median",
            t.median_ms,
            "ms",
            at_most=target,
            note=f"IQR {t.iqr_ms:.1f} ms over {len(t.samples_ms)} calls; {ratio:.2f}x the pipeline",
        )
    print()


def _print_ratios(
    pipeline: Timing,
    peers: Sequence[Timing],
    registered: Sequence[Timing],
    judged: Sequence[str],
    judging: Sequence[Timing],
) -> None:
    """The adequacy's share of each method's fit, and the output-error peer / the pipeline."""
    # What the adequacy adds to a fit of both models (fit() judges each model it fits).
    fitted = {"paper": pipeline.median_ms}
    for t in registered:
        name = t.name.split('"')[1]
        fitted[name] = fitted.get(name, 0.0) + t.median_ms
    shares = [
        f"{m} {100 * 2 * j.median_ms / fitted[m]:.0f} %"
        for m, j in zip(judged, judging, strict=True)
    ]
    print(
        "adequacy of both models / the fit of both models (target <= 20 %): "
        + ", ".join(shares)
        + " (the paper's fit: its pipeline, identify())"
    )
    peer_total = sum(p.median_ms for p in peers)
    print(
        f"peer / pipeline: constant {peers[0].median_ms / pipeline.median_ms:.2f}x, "
        f"theta {peers[1].median_ms / pipeline.median_ms:.2f}x, "
        f"both models {peer_total / pipeline.median_ms:.2f}x "
        "(the pipeline identifies both models plus u_d and the re-simulations)"
    )


def _print_verdicts(
    targeted: Sequence[tuple[Timing, float]], watched: Sequence[Timing], first_call_ms: float
) -> list[str]:
    """The notes under the table, a noise warning for ``watched``; the tasks that missed."""
    missed = [t.name for t, target in targeted if t.median_ms > target]
    print(
        f"first identify() call of the process: {first_call_ms:.0f} ms (one-off costs); "
        "1st ms: each task's untimed warm-up call after it; verdicts use the median; "
        "timed calls of all tasks interleaved"
    )
    noisy = [t.name for t in watched if t.iqr_ms > 0.25 * t.median_ms]
    if noisy:
        print(
            f"warning: IQR above 25 % of the median for {', '.join(noisy)}: the machine was "
            "busy or throttled during the run; compare min ms, or rerun"
        )
    if missed:
        print(f"missed targets: {', '.join(missed)}")
    else:
        print("all targets met")
    return missed


def _print_against(
    ref: str, commit: str, common: Sequence[Timing], before: dict[str, list[float]]
) -> None:
    """This checkout's medians of the ``common`` tasks against REF's, with the change."""
    from rocketroll_common.tables import Column, text_table  # (not in older checkouts)

    print(f"\nthis checkout against {ref} ({commit[:12]}), the same calls alternating:")
    against = (
        Column("task", 30, "<"),
        Column("this median ms", 15, ">", " "),
        Column("REF median ms", 14, ">", " "),
        Column("change", 8, ">", " "),
    )
    rows = []
    for t in common:
        old = float(np.median(before[t.name]))
        rows.append([t.name, f"{t.median_ms:.1f}", f"{old:.1f}", f"{t.median_ms / old - 1:+.1%}"])
    print("\n".join(text_table(against, rows)))


def main(argv: Sequence[str] | None = None) -> int:
    """Time the tasks, print the table and the verdicts; 1 with --strict if a target is missed."""
    ns, words, serving = _parse(argv)

    rec = load_bundled(RECORDING)
    options = IdentifyOptions(noise_runs=0)
    # Tasks every checkout has (the named reference included), by the name they are asked for.
    common: dict[str, Callable[[], object]] = {
        "identify(noise_runs=0)": lambda: identify(rec, options),
        **{
            f'output_error("{model}")': functools.partial(output_error, rec, model)
            for model in ("constant", "theta")
        },
    }
    if serving:
        result = identify(rec, options)
        n_levels = len(result.options.noise_levels_pct)
        common[f"noise_study ({n_levels} x {MONTE_CARLO_RUNS} runs)"] = lambda: run_monte_carlo(
            result, MONTE_CARLO_RUNS
        )
        for func in common.values():
            func()
        return serve({name: _timed(func) for name, func in common.items()})
    print(
        f"recording {rec.name}: {rec.n_samples} samples, {rec.duration_s:.1f} s; "
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"{os.cpu_count()} CPU(s), {platform.machine()}; OpenBLAS threads "
        f"{os.environ['OPENBLAS_NUM_THREADS']}; {ns.busy} core(s) kept busy"
    )

    # The first identify() is the process's first call: it pays one-off costs.
    start = time.perf_counter()
    result = identify(rec, options)
    first_call_ms = (time.perf_counter() - start) * 1e3
    n_levels = len(result.options.noise_levels_pct)
    mc_name = f"noise_study ({n_levels} x {MONTE_CARLO_RUNS} runs)"
    tasks, judged = _build_tasks(ns, rec, options, common, result, mc_name)
    timings, before, commit = _time_tasks(ns, words, tasks, [*common, mc_name])
    pipeline, *peers = timings[:3]
    monte_carlo, ml_both, posterior = timings[3:6]
    registered = timings[6 : len(timings) - len(judged)]
    judging = timings[len(timings) - len(judged) :]

    # The tasks with a target, in the table's order (the others are references).
    targeted = [
        (pipeline, PIPELINE_TARGET_MS),
        (monte_carlo, MONTE_CARLO_TARGET_MS),
        (ml_both, ML_TARGET_MS),
        (posterior, POSTERIOR_TARGET_MS),
    ]
    _print_table(
        [
            targeted[0],
            *((peer, None) for peer in peers),
            *targeted[1:],
            *((t, None) for t in (*registered, *judging)),
        ]
    )
    _print_ratios(pipeline, peers, registered, judged, judging)
    missed = _print_verdicts(targeted, [pipeline, *peers, monte_carlo], first_call_ms)
    if before:
        _print_against(ns.against, commit, [pipeline, *peers, monte_carlo], before)
    return 1 if ns.strict and missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
