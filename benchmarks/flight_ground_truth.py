"""Ground truth of the flight identification: ``rocketroll record-flight`` logs, identified back.

For each truth (``--truth``; default all of :data:`TRUTHS`: the paper's
θ-dependent rocket and a constant-damping one, other gains and asymmetries of
either sign, a positive ᾱ, Dryden gusts, a heavy-tailed turbulence, an
angle-only log, and two stretches outside the model: a descent past apogee
and a supersonic one) and seed, the virtual flight
(:func:`identification.instruments.flightlog.run_flight`)
logs its ascent (the default, unless the truth says), and the ``flight`` method
(:func:`identification.methods.flightfit.identify_flight`, the truth's damping model)
identifies it on the part ``identify`` fits (to apogee, at or below Mach 0.8;
``--whole``: every sample).  Per flight: the relative error of ``α₀`` and ``β̄₀`` (the
scaled coefficients at the reference airspeed: ``C_δ``- and ``C_P``-like),
the error of θ̄ (°) and ᾱ₀, the RMS error of the damping ``a(θ)`` over the
flown fin angles (%), the re-simulation's rate MAE as a percentage of the
mean measured ``|rate|``, and the fit's time.  Below the table: the flight
targets (coefficients within 5 %, re-simulation under 2 %), PASS or FAIL
over every fit.

Since the flight method measures the airspeed scaling (fin torque ``∝ ρV^n``,
damping ``∝ ρV^m``), the coefficients are compared at the fit's reference
airspeed (the flight's mean), with the truth carried there by its own scaling
(:func:`identification.instruments.flightlog.truth_at`).

``--scaling`` flies the truth of ``--truth`` (default the paper's rocket, flown
tunnel turbulence, the recorder's default staircase and ascent) with every
``n`` in ``--n`` and ``m`` in ``--m`` at every logging rate in ``--hz``, and
prints per cell: the share of flights whose measured ``n`` and ``m`` lie within
two standard errors of the truth, the mean SE of ``n``, the share with α₀ and
β̄₀ within 5 %, the share where the likelihood-ratio test rejects eq. 4-8, and
(``--held-out``) the model-only rate R² on the last 30 % of the flight, fitted on
the first 70 %, as a share of the true model's own R² there.

``--joint K`` fits K flights of the rocket together
(:func:`identification.methods.flightfit.identify_flights`: one rocket, one
turbulence's statistics, one gyro; each flight its own filter), ``--seeds``
such fits per truth, and reports the first flight's re-simulation.

Run from the repository root::

    .venv/bin/python benchmarks/flight_ground_truth.py --seeds 10
    .venv/bin/python benchmarks/flight_ground_truth.py --seeds 10 --joint 3 --truth dryden
    .venv/bin/python benchmarks/flight_ground_truth.py --seeds 3 --truth paper-theta --jobs 1
    .venv/bin/python benchmarks/flight_ground_truth.py --scaling --seeds 10 --held-out
    .venv/bin/python benchmarks/flight_ground_truth.py --truth descent --truth supersonic --whole
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from _records import emit
from tqdm.auto import tqdm

from identification.instruments.flightlog import FlightLogSpec, run_flight, truth_at
from identification.methods.flight import flight_window, held_out_prediction, model_only_r2_of
from identification.methods.flightfit import flight_inputs, identify_flights
from identification.methods.pipeline import IdentifyOptions
from rocketroll_common.tables import Column, text_table

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
    "descent": (
        {"descent": 5.0},
        "the paper's rocket logged 5 s past apogee, falling tail-first (outside the model)",
    ),
    "supersonic": (
        {"ascent": "supersonic", "model": "constant"},
        "the supersonic ascent (peak Mach 1.04): fins compressible above Mach 0.8",
    ),
}


def one(
    truth: str,
    seed: int,
    joint: int = 1,
    extra: dict[str, Any] | None = None,
    held_out: bool = False,
    whole: bool = False,
) -> dict[str, Any]:
    """Fly, identify, compare: flights ``seed·joint`` to ``seed·joint + joint - 1``, fitted
    together (:func:`identification.methods.flightfit.identify_flights`), the first one's fit;
    ``extra`` recorder settings on top of the truth's.  Each flight is fitted on the part
    ``identify`` fits (:func:`identification.methods.flight.flight_window`: to apogee, at or
    below Mach 0.8), or ``whole``."""
    settings, _ = TRUTHS[truth]
    settings = {**settings, **(extra or {})}
    specs = [FlightLogSpec(seed=seed * joint + k, **settings) for k in range(joint)]
    recordings = [run_flight(spec) for spec in specs]
    if not whole:
        recordings = [flight_window(rec, IdentifyOptions()).part for rec in recordings]
    flights = [flight_inputs(rec) for rec in recordings]
    if joint > 1:  # one reference for all
        flights = [flight_inputs(rec, v_ref_mps=flights[0].v_ref_mps) for rec in recordings]
    spec = specs[0]
    start = time.perf_counter()
    fit = identify_flights(flights, spec.model)[0]
    seconds = time.perf_counter() - start
    params = truth_at(recordings[0], fit.inputs.v_ref_mps, fit.inputs.rho_ref_kgm3)
    p = fit.params
    theta = fit.inputs.theta
    a_true = params.damping(theta)
    a_fit = p.damping(theta)
    resim = fit.resimulate()
    errors = fit.std_errors
    test = fit.eq_4_8_test or {}
    row = {
        "truth": truth,
        "seed": seed,
        "alpha_pct": 100.0 * (p.alpha / params.alpha - 1.0),
        "beta_bar_pct": 100.0 * (p.beta_bar_per_s / params.beta_bar_per_s - 1.0),
        "theta_bar_deg": p.theta_bar_deg - params.theta_bar_deg,
        "alpha_bar": p.alpha_bar_per_deg_s - params.alpha_bar_per_deg_s,
        "damping_rms_pct": 100.0 * float(np.sqrt(np.mean((a_fit / a_true - 1.0) ** 2))),
        "resim_pct": resim["resim_rate_mae_pct"],
        "n_err": fit.scaling.torque_exponent - spec.torque_exponent,
        "m_err": fit.scaling.damping_exponent - spec.damping_exponent,
        "n_se": errors.get("torque_exponent", math.nan),
        "m_se": errors.get("damping_exponent", math.nan),
        "rejected": bool(test.get("rejected", False)),
        "seconds": seconds,
    }
    if held_out:
        out, late = held_out_prediction(fit.inputs, [spec.model], spec.servo_rate)
        r2 = out[spec.model].get("rate_r2", math.nan)
        if late is not None:
            true_here = truth_at(recordings[0], late.v_ref_mps, late.rho_ref_kgm3)
            own = model_only_r2_of(late, true_here, spec.scaling())
            row["held_out_ratio"] = r2 / own if own > 0 else math.nan
        else:
            row["held_out_ratio"] = math.nan
    return row


def _run(job: tuple[str, int, int, dict[str, Any], bool, bool]) -> dict[str, Any]:
    return {**one(*job), "cell": tuple(sorted(job[3].items()))}


COLUMNS = (
    ("alpha_pct", "α₀ err %"),
    ("beta_bar_pct", "β̄₀ err %"),
    ("damping_rms_pct", "a(θ) RMS %"),
    ("theta_bar_deg", "θ̄ err °"),
    ("alpha_bar", "ᾱ₀ err"),
    ("resim_pct", "re-sim %"),
)


#: The table of :func:`table`: the truth, its fits, then each metric of :data:`COLUMNS`.
TABLE_COLUMNS = (
    Column("truth", 16, "<"),
    Column("n", 3),
    *(Column(label, 22) for _, label in COLUMNS),
)


def table(rows: list[dict[str, Any]]) -> str:
    """Per truth: mean |error| and the worst (signed) error of each metric, and the time."""
    body = [["", "", *("mean|e| / worst" for _ in COLUMNS)]]  # under each metric's title
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
        body.append([truth, str(len(mine)), *cells])
    lines = text_table(TABLE_COLUMNS, body)
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
    emit(
        "coefficients α₀ and β̄₀ within 5 %: share of fits",
        len(coefficient) / n,
        "",
        at_least=1.0,
        note=f"{n} fits; worst α₀ {worst_alpha:.2f} %, worst β̄₀ {worst_beta:.2f} %",
    )
    emit(
        "re-simulated rate MAE under 2 % of mean |rate|: share of fits",
        len(resim) / n,
        "",
        at_least=1.0,
        note=f"{n} fits; worst {worst_resim:.2f} %",
    )
    return [
        f"coefficients α₀ and β̄₀ within 5 %: {len(coefficient)}/{n} fits "
        f"(worst α₀ {worst_alpha:.2f} %, worst β̄₀ {worst_beta:.2f} %) -- "
        f"{'PASS' if len(coefficient) == n else 'FAIL'}",
        f"re-simulated rate MAE under 2 % of mean |rate|: {len(resim)}/{n} fits "
        f"(worst {worst_resim:.2f} %) -- {'PASS' if len(resim) == n else 'FAIL'}",
    ]


def within_two_se(rows: list[dict[str, Any]], key: str) -> float:
    """The share of rows whose ``key`` error lies within two of its standard errors."""
    return float(np.mean([abs(r[f"{key}_err"]) <= 2.0 * r[f"{key}_se"] for r in rows]))


#: The table of :func:`scaling_table` (``--held-out`` adds a column).
SCALING_COLUMNS = (
    Column("n", 4),
    Column("m", 5),
    Column("Hz", 5),
    Column("flights", 8),
    Column("n in 2SE", 10),
    Column("m in 2SE", 10),
    Column("SE(n)", 8),
    Column("SE(m)", 8),
    Column("α₀ 5%", 8),
    Column("β̄₀ 5%", 8),
    Column("eq4-8 rej", 10),
)


def scaling_table(rows: list[dict[str, Any]]) -> str:
    """Per (n, m, logging rate): the scaling's recovery, the coefficients, the test."""
    cells: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        cells.setdefault(row["cell"], []).append(row)
    held = "held_out_ratio" in rows[0]
    columns = SCALING_COLUMNS + ((Column("held-out R² / true", 22),) if held else ())
    body = []
    for cell, mine in sorted(cells.items()):
        c = dict(cell)
        coefficient = np.mean([abs(r["alpha_pct"]) < 5 for r in mine])
        beta = np.mean([abs(r["beta_bar_pct"]) < 5 for r in mine])
        line = [
            f"{c['torque_exponent']:.1f}",
            f"{c['damping_exponent']:.1f}",
            f"{1.0 / c['log_dt']:.0f}",
            str(len(mine)),
            f"{within_two_se(mine, 'n'):.2f}",
            f"{within_two_se(mine, 'm'):.2f}",
            f"{np.nanmean([r['n_se'] for r in mine]):.3f}",
            f"{np.nanmean([r['m_se'] for r in mine]):.3f}",
            f"{coefficient:.2f}",
            f"{beta:.2f}",
            f"{np.mean([r['rejected'] for r in mine]):.2f}",
        ]
        if held:
            ratios = np.array([r["held_out_ratio"] for r in mine])
            line.append(f"{np.nanmin(ratios):7.3f} min, {np.mean(ratios >= 0.9):.2f} ≥0.9")
        body.append(line)
    return "\n".join(text_table(columns, body))


def scaling_verdicts(rows: list[dict[str, Any]]) -> list[str]:
    """The scaling targets over every flight of ``--scaling``."""
    n_ok = within_two_se(rows, "n")
    m_ok = within_two_se(rows, "m")
    fast = [r for r in rows if dict(r["cell"])["log_dt"] <= 0.002]
    se_n = max((r["n_se"] for r in fast), default=math.nan)
    coef = np.mean([abs(r["alpha_pct"]) < 5 and abs(r["beta_bar_pct"]) < 5 for r in rows])
    low = [r["rejected"] for r in rows if dict(r["cell"])["torque_exponent"] <= 1.3]
    eq = [
        not r["rejected"]
        for r in rows
        if (dict(r["cell"])["torque_exponent"], dict(r["cell"])["damping_exponent"]) == (2.0, 1.0)
    ]

    def verdict(ok: bool) -> str:
        return "PASS" if ok else "FAIL"

    note = f"{len(rows)} flights of --scaling"
    emit("scaling: n within 2 SE, share of flights", n_ok, "", at_least=0.9, note=note)
    emit("scaling: m within 2 SE, share of flights", m_ok, "", at_least=0.9, note=note)
    emit("scaling: α₀ and β̄₀ within 5 %, share of flights", coef, "", at_least=0.9, note=note)
    if fast:
        emit("scaling: SE(n) at 500 Hz, at most", se_n, "", at_most=0.15)
    if low:
        emit("scaling: eq. 4-8 rejected at n 1.3, share", float(np.mean(low)), "", at_least=0.9)
    if eq:
        emit("scaling: eq. 4-8 accepted at n 2, m 1, share", float(np.mean(eq)), "", at_least=0.9)

    lines = [
        f"n within 2 SE: {n_ok:.2f}, m within 2 SE: {m_ok:.2f} of flights (≥ 0.90) -- "
        f"{verdict(n_ok >= 0.9 and m_ok >= 0.9)}",
        f"α₀ and β̄₀ within 5 %: {coef:.2f} of flights (≥ 0.90) -- {verdict(coef >= 0.9)}",
    ]
    if fast:
        lines.append(f"SE(n) at 500 Hz: at most {se_n:.3f} (≤ 0.15) -- {verdict(se_n <= 0.15)}")
    if low:
        share = float(np.mean(low))
        lines.append(f"eq. 4-8 rejected at n 1.3: {share:.2f} (≥ 0.90) -- {verdict(share >= 0.9)}")
    if eq:
        share = float(np.mean(eq))
        lines.append(
            f"eq. 4-8 accepted where it holds (n 2, m 1): {share:.2f} (≥ 0.90) -- "
            f"{verdict(share >= 0.9)}"
        )
    if "held_out_ratio" in rows[0]:
        share = float(np.mean([r["held_out_ratio"] >= 0.9 for r in rows]))
        emit("held-out R² ≥ 0.9 × the true model's: share of flights", share, "", at_least=1.0)
        lines.append(
            f"held-out R² ≥ 0.9 × the true model's: {share:.2f} of flights -- "
            f"{verdict(share == 1.0)}"
        )
    return lines


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
    parser.add_argument(
        "--scaling", action="store_true", help="the grid of true scalings (--n, --m, --hz)"
    )
    parser.add_argument("--n", type=float, nargs="+", default=[1.3, 1.6, 2.0], help="true n")
    parser.add_argument("--m", type=float, nargs="+", default=[0.7, 1.0], help="true m")
    parser.add_argument("--hz", type=float, nargs="+", default=[100.0, 500.0], help="log rates")
    parser.add_argument(
        "--held-out", action="store_true", help="with --scaling: the held-out prediction too"
    )
    parser.add_argument(
        "--whole",
        action="store_true",
        help="fit every sample: no cut at apogee or Mach 0.8 (what the cuts buy)",
    )
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.jobs < 1 or args.joint < 1:
        parser.error("--seeds, --jobs and --joint must be at least 1")
    if args.scaling:
        return scaling_main(args)
    truths = args.truth or list(TRUTHS)
    jobs: list[tuple[str, int, int, dict[str, Any], bool, bool]] = [
        (truth, seed, args.joint, {}, False, args.whole)
        for truth in truths
        for seed in range(args.seeds)
    ]
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


def scaling_main(args: argparse.Namespace) -> int:
    """``--scaling``: the grid of true scalings and logging rates."""
    truth = (args.truth or ["paper-theta"])[0]
    cells = [
        {"torque_exponent": n, "damping_exponent": m, "log_dt": round(1.0 / hz, 6)}
        for hz in args.hz
        for n in args.n
        for m in args.m
    ]
    jobs = [
        (truth, seed, 1, cell, args.held_out, args.whole)
        for cell in cells
        for seed in range(args.seeds)
    ]
    print(f"truth {truth}: {TRUTHS[truth][1]}; {len(cells)} scalings x {args.seeds} seeds")
    start = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(tqdm(pool.map(_run, jobs), total=len(jobs), desc="flights"))
    print(scaling_table(rows))
    print(f"{len(rows)} flights in {time.perf_counter() - start:.0f} s ({args.jobs} processes)")
    for line in scaling_verdicts(rows):
        print(line)
    return 0 if all(math.isfinite(r["n_err"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
