"""Ground truth of the flight identification: ``rocketroll flight`` logs, identified back.

For each truth (``--truth``; default all of :data:`TRUTHS`: the paper's
θ-dependent rocket and a constant-damping one, other gains and asymmetries of
either sign, a positive ᾱ, Dryden gusts, a heavy-tailed turbulence, an
angle-only log) and seed, the virtual flight (:func:`disturbances.flightlog.run_flight`)
logs the default ascent, and the ``flight`` method
(:func:`identification.flightfit.identify_flight`, the truth's damping model)
identifies it.  Per flight: the relative error of ``α₀`` and ``β̄₀`` (the
scaled coefficients at the reference airspeed: ``C_δ``- and ``C_P``-like),
the error of θ̄ (°) and ᾱ₀, the RMS error of the damping ``a(θ)`` over the
flown fin angles (%), the re-simulation's rate MAE as a percentage of the
mean measured ``|rate|``, and the fit's time.  Below the table: the flight
targets (coefficients within 5 %, re-simulation under 2 %), PASS or FAIL
over every fit.

``--joint K`` fits K flights of the rocket together
(:func:`identification.flightfit.identify_flights`: one rocket, one
turbulence's statistics, one gyro; each flight its own filter), ``--seeds``
such fits per truth, and reports the first flight's re-simulation.

Run from the repository root::

    .venv/bin/python benchmarks/flight_ground_truth.py --seeds 10
    .venv/bin/python benchmarks/flight_ground_truth.py --seeds 10 --joint 3 --truth dryden
    .venv/bin/python benchmarks/flight_ground_truth.py --seeds 3 --truth paper-theta --jobs 1
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from disturbances.flightlog import FlightLogSpec, run_flight
from identification.flightfit import flight_inputs, identify_flights

#: Name -> (FlightLogSpec settings, what it tests).
TRUTHS: dict[str, tuple[dict[str, Any], str]] = {
    "paper-theta": ({}, "the paper's a(θ) rocket (eq. 49), tunnel turbulence flown"),
    "paper-constant": ({"model": "constant"}, "constant a = 1.314 (eq. 46)"),
    "fast-negative": (
        {"model": "constant", "alpha": 1.2, "beta": -3.0, "beta_bar": 0.8},
        "α 1.2, θ̄ -2.5°, a 0.8",
    ),
    "slow-rising": (
        {"alpha": 0.4, "beta": 1.0, "alpha_bar": 0.02, "beta_bar": 1.5},
        "α 0.4, θ̄ +2.5°, ᾱ +0.02 (damping rising with fin angle)",
    ),
    "dryden": ({"turbulence": "dryden"}, "Dryden roll gust, light (the flight env's default)"),
    "dryden-moderate": (
        {"turbulence": "dryden", "severity": "moderate"},
        "Dryden roll gust, moderate: β̄₀'s own SE is ~4.5 % on one flight",
    ),
    "laplace": (
        {"distribution": "laplace", "turbulence_sd": 12.0, "correlation_time": 0.3},
        "heavy-tailed (Laplace) tunnel turbulence, SD 12°, τ 0.3 s",
    ),
    "angle-only": (
        {"no_gyro": True, "encoder_counts": 4096, "model": "constant"},
        "no gyro: a 4096-count angle only",
    ),
}


def one(truth: str, seed: int, joint: int = 1) -> dict[str, Any]:
    """Fly, identify, compare: flights ``seed·joint`` to ``seed·joint + joint - 1``, fitted
    together (:func:`identification.flightfit.identify_flights`), the first one's fit."""
    settings, _ = TRUTHS[truth]
    specs = [FlightLogSpec(seed=seed * joint + k, **settings) for k in range(joint)]
    flights = [flight_inputs(run_flight(spec)) for spec in specs]
    spec = specs[0]
    params = spec.params()
    start = time.perf_counter()
    fit = identify_flights(flights, spec.model)[0]
    seconds = time.perf_counter() - start
    p = fit.params
    theta = fit.inputs.theta
    a_true = params.damping(theta)
    a_fit = p.damping(theta)
    resim = fit.resimulate()
    return {
        "truth": truth,
        "seed": seed,
        "alpha_pct": 100.0 * (p.alpha / params.alpha - 1.0),
        "beta_bar_pct": 100.0 * (p.beta_bar_per_s / params.beta_bar_per_s - 1.0),
        "theta_bar_deg": p.theta_bar_deg - params.theta_bar_deg,
        "alpha_bar": p.alpha_bar_per_deg_s - params.alpha_bar_per_deg_s,
        "damping_rms_pct": 100.0 * float(np.sqrt(np.mean((a_fit / a_true - 1.0) ** 2))),
        "resim_pct": resim["resim_rate_mae_pct"],
        "seconds": seconds,
    }


def _run(job: tuple[str, int, int]) -> dict[str, Any]:
    return one(*job)


COLUMNS = (
    ("alpha_pct", "α₀ err %"),
    ("beta_bar_pct", "β̄₀ err %"),
    ("damping_rms_pct", "a(θ) RMS %"),
    ("theta_bar_deg", "θ̄ err °"),
    ("alpha_bar", "ᾱ₀ err"),
    ("resim_pct", "re-sim %"),
)


def table(rows: list[dict[str, Any]]) -> str:
    """Per truth: mean |error| and the worst (signed) error of each metric, and the time."""
    head = f"{'truth':<16}{'n':>3}" + "".join(f"{label:>22}" for _, label in COLUMNS)
    lines = [head, f"{'':<19}" + "".join(f"{'mean|e| / worst':>22}" for _ in COLUMNS)]
    for truth in TRUTHS:
        mine = [r for r in rows if r["truth"] == truth]
        if not mine:
            continue
        cells = []
        for key, _ in COLUMNS:
            values = np.array([r[key] for r in mine])
            worst = values[np.argmax(np.abs(values))]
            digits = 4 if key == "alpha_bar" else 2
            cells.append(f"{np.mean(np.abs(values)):.{digits}f} / {worst:+.{digits}f}")
        lines.append(f"{truth:<16}{len(mine):>3}" + "".join(f"{c:>22}" for c in cells))
    times = [r["seconds"] for r in rows]
    lines.append(f"fit time per flight: median {np.median(times):.1f} s, max {max(times):.1f} s")
    return "\n".join(lines)


def verdicts(rows: list[dict[str, Any]]) -> list[str]:
    """The flight targets over every flight run."""
    n = len(rows)
    coefficient = [r for r in rows if abs(r["alpha_pct"]) < 5 and abs(r["beta_bar_pct"]) < 5]
    resim = [r for r in rows if r["resim_pct"] < 2.0]
    worst_alpha = max(abs(r["alpha_pct"]) for r in rows)
    worst_beta = max(abs(r["beta_bar_pct"]) for r in rows)
    worst_resim = max(r["resim_pct"] for r in rows)
    return [
        f"coefficients α₀ and β̄₀ within 5 %: {len(coefficient)}/{n} fits "
        f"(worst α₀ {worst_alpha:.2f} %, worst β̄₀ {worst_beta:.2f} %) -- "
        f"{'PASS' if len(coefficient) == n else 'FAIL'}",
        f"re-simulated rate MAE under 2 % of mean |rate|: {len(resim)}/{n} fits "
        f"(worst {worst_resim:.2f} %) -- {'PASS' if len(resim) == n else 'FAIL'}",
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10, help="fits per truth (seeds 0..N-1)")
    parser.add_argument(
        "--truth", action="append", choices=sorted(TRUTHS), help="repeatable; default: all"
    )
    parser.add_argument("--jobs", type=int, default=2, help="processes")
    parser.add_argument(
        "--joint",
        type=int,
        default=1,
        help="flights of one rocket fitted together per fit (--seeds fits of this many)",
    )
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.jobs < 1 or args.joint < 1:
        parser.error("--seeds, --jobs and --joint must be at least 1")
    truths = args.truth or list(TRUTHS)
    jobs = [(truth, seed, args.joint) for truth in truths for seed in range(args.seeds)]
    print("truths:")
    for truth in truths:
        print(f"  {truth:<16}{TRUTHS[truth][1]}")
    start = time.perf_counter()
    if args.jobs == 1:
        rows = [_run(job) for job in tqdm(jobs, desc="fits")]
    else:
        with ProcessPoolExecutor(args.jobs) as pool:
            rows = list(tqdm(pool.map(_run, jobs), total=len(jobs), desc="fits"))
    print(table(rows))
    each = "" if args.joint == 1 else f" of {args.joint} flights each"
    print(f"{len(rows)} fits{each} in {time.perf_counter() - start:.0f} s ({args.jobs} processes)")
    for line in verdicts(rows):
        print(line)
    return 0 if all(math.isfinite(r["alpha_pct"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
