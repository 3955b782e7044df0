"""Ground-truth recovery of the paper's method and of the output-error peer.

For each virtual-tunnel seed (the paper's Table 1 experiment with known
parameters and a known disturbance), this script runs

* the paper's method, ``identify(rec, IdentifyOptions(noise_runs=0))``, and
* the peer, ``output_error(rec, "constant")`` and ``output_error(rec, "theta")``
  (:mod:`identification.baselines`: nonlinear least squares on the simulated
  roll rate),

and compares them with the truth the tunnel recorded:

* α, relative error in %;
* θ̄, error in °;
* the constant damping ``a`` (eq. 29), relative error in % -- for a
  θ-dependent truth (eq. 49, the tunnel's default) there is no single true
  ``a``; the reference is then ``a(θ)`` averaged over the run's step fin
  levels (``Identification.truth()["a_per_s"]``);
* the damping curve ``a(θ)`` over the step fin levels ``f``: RMS and signed
  mean of ``â(f) - a_true(f)``, 1/s, for both models (the constant model's
  ``â`` is flat);
* ᾱ and β̄ of the θ-dependent model (eq. 48);
* for the paper's method only, the identified disturbance ``u_d`` against the
  tunnel's true ``u_d``: mean absolute error, ° (the peer does not identify
  ``u_d``: it treats the disturbance as output noise).

Per metric and method the table gives, over seeds, the mean absolute error,
the SD of the signed error, the bias (signed mean) and the worst error (the
signed value with the largest magnitude).  The summary below the table is
computed from those numbers.

Run from the repository root::

    .venv/bin/python benchmarks/ground_truth.py --seeds 20
"""

from __future__ import annotations

import argparse
import csv
import math
import time
import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm.auto import tqdm

from identification.baselines import OutputErrorFit, output_error
from identification.model import RollParams, damping
from identification.pipeline import Identification, IdentifyOptions, identify
from identification.tunnel import TunnelSpec, run_tunnel
from rocketroll_common.arrays import FloatArray

PAPER = "paper"
PEER = "peer"
METHOD_TITLES = {PAPER: "paper's method", PEER: "output-error peer"}


@dataclass(frozen=True)
class Metric:
    """One row of the table.

    ``key`` names the per-seed column; ``paper``/``peer`` say which estimate
    of each method the row uses (``None``: not applicable).
    """

    key: str
    label: str
    unit: str
    paper: str | None
    peer: str | None
    summary: str


METRICS: tuple[Metric, ...] = (
    Metric("alpha_pct", "α, constant-model fit", "%", "α (steady state)", "constant", "α"),
    Metric("alpha_theta_pct", "α, θ-model fit", "%", "α (steady state)", "theta", "α (θ fit)"),
    Metric("theta_bar_deg", "θ̄, constant-model fit", "°", "θ̄ (steady state)", "constant", "θ̄"),
    Metric("theta_bar_theta_deg", "θ̄, θ-model fit", "°", "θ̄ (steady state)", "theta", "θ̄ (θ fit)"),
    Metric(
        "a_const_pct", "constant a vs averaged truth", "%", "constant", "constant", "constant a"
    ),
    Metric("a_rms_const", "a(θ) RMS, constant model", "1/s", "constant", "constant", ""),
    Metric("a_rms_theta", "a(θ) RMS, θ model", "1/s", "theta", "theta", ""),
    Metric("a_mean_theta", "a(θ) mean offset, θ model", "1/s", "theta", "theta", "a(θ)"),
    Metric("alpha_bar", "ᾱ, θ model", "1/(°s)", "theta", "theta", "ᾱ"),
    Metric("beta_bar", "β̄, θ model", "1/s", "theta", "theta", "β̄"),
    Metric("ud_theta_mae", "u_d,θ MAE vs true u_d", "°", "theta", None, ""),
    Metric("ud_const_mae", "u_d,constant MAE vs true u_d", "°", "constant", None, ""),
)


def relative_pct(estimate: float, truth: float) -> float:
    return 100.0 * (estimate - truth) / truth


def parameter_errors(
    est_const: RollParams,
    est_theta: RollParams,
    truth: RollParams,
    a_truth_avg: float,
    levels: FloatArray,
) -> dict[str, float]:
    """Errors of one method's constant- and θ-model estimates (signed, per seed)."""
    a_true = damping(truth, levels)
    diff_const = damping(est_const, levels) - a_true
    diff_theta = damping(est_theta, levels) - a_true
    return {
        "alpha_pct": relative_pct(est_const.alpha, truth.alpha),
        "alpha_theta_pct": relative_pct(est_theta.alpha, truth.alpha),
        "theta_bar_deg": est_const.theta_bar_deg - truth.theta_bar_deg,
        "theta_bar_theta_deg": est_theta.theta_bar_deg - truth.theta_bar_deg,
        "a_const_pct": relative_pct(est_const.beta_bar_per_s, a_truth_avg),
        "a_rms_const": float(np.sqrt(np.mean(diff_const**2))),
        "a_rms_theta": float(np.sqrt(np.mean(diff_theta**2))),
        "a_mean_theta": float(np.mean(diff_theta)),
        "alpha_bar": est_theta.alpha_bar_per_deg_s - truth.alpha_bar_per_deg_s,
        "beta_bar": est_theta.beta_bar_per_s - truth.beta_bar_per_s,
    }


def disturbance_mae(result: Identification, model: str, true_ud: FloatArray) -> float:
    """MAE of the identified ``u_d`` against the truth of the same intervals.

    The identified trace has ``N_total`` values, one per 0.1 s interval; the
    tunnel's ``ud_true_deg`` holds its value over each sample interval, so the
    first ``N_total`` truth samples are the same intervals.
    """
    u = result.disturbances[model].u_d_deg
    return float(np.mean(np.abs(u - true_ud[: u.size])))


def study_seed(
    seed: int, model: Literal["theta", "constant"]
) -> tuple[dict[str, float], dict[str, float], dict[str, float]]:
    """One seed: per-method errors and bookkeeping (timings, optimiser status)."""
    rec = run_tunnel(TunnelSpec(seed=seed, model=model))
    truth = rec.truth()
    if truth is None or rec.ud_true_deg is None:
        raise RuntimeError(f"seed {seed}: the tunnel recording carries no ground truth")

    start = time.perf_counter()
    result = identify(rec, IdentifyOptions(noise_runs=0))
    paper_s = time.perf_counter() - start
    start = time.perf_counter()
    fits: dict[str, OutputErrorFit] = {m: output_error(rec, m) for m in ("constant", "theta")}
    peer_s = time.perf_counter() - start

    true_avg = result.truth()
    assert true_avg is not None
    levels = result.segments.step_levels_deg
    a_avg = true_avg["a_per_s"]
    paper = parameter_errors(result.constant_model, result.theta_model, truth, a_avg, levels)
    paper["ud_theta_mae"] = disturbance_mae(result, "theta", rec.ud_true_deg)
    paper["ud_const_mae"] = disturbance_mae(result, "constant", rec.ud_true_deg)
    peer = parameter_errors(fits["constant"].params, fits["theta"].params, truth, a_avg, levels)
    info = {
        "paper_s": paper_s,
        "peer_s": peer_s,
        "peer_nfev": float(fits["constant"].nfev + fits["theta"].nfev),
        "peer_failures": float(sum(not f.success for f in fits.values())),
        "a_truth_avg": a_avg,
        "outlier_step": float(
            -1 if result.damping_vs_fin.outlier is None else result.damping_vs_fin.outlier + 1
        ),
    }
    return paper, peer, info


@dataclass(frozen=True)
class Stats:
    mean_abs: float
    sd: float
    bias: float
    worst: float
    n: int

    @property
    def standard_error(self) -> float:
        return self.sd / math.sqrt(self.n) if self.n > 1 else math.nan

    @property
    def significant(self) -> bool:
        """Bias beyond two standard errors of the mean (about 95 %)."""
        se = self.standard_error
        return bool(np.isfinite(se) and abs(self.bias) > 2.0 * se)


def stats_of(values: Sequence[float]) -> Stats:
    x = np.asarray(values, dtype=float)
    return Stats(
        mean_abs=float(np.mean(np.abs(x))),
        sd=float(np.std(x, ddof=1)) if x.size > 1 else math.nan,
        bias=float(np.mean(x)),
        worst=float(x[np.argmax(np.abs(x))]),
        n=int(x.size),
    )


def ljust(text: str, width: int) -> str:
    """``str.ljust`` by displayed width (θ̄ is θ plus a combining macron)."""
    shown = sum(not unicodedata.combining(c) for c in text)
    return text + " " * max(0, width - shown)


def rjust(text: str, width: int) -> str:
    shown = sum(not unicodedata.combining(c) for c in text)
    return " " * max(0, width - shown) + text


def fmt(value: float, unit: str) -> str:
    if not np.isfinite(value):
        return "-"
    if unit == "1/(°s)":
        return f"{value:+.4f}"
    if unit == "%":
        return f"{value:+.2f}"
    return f"{value:+.3f}"


def print_table(
    per_seed: dict[str, list[dict[str, float]]],
) -> dict[tuple[str, str], Stats]:
    cols = ("mean|e|", "SD", "bias", "worst")
    width = 8
    method_block = " ".join(f"{c:>{width}s}" for c in cols)
    head1 = (
        f"{'metric':33s} {'unit':>6s} | {METHOD_TITLES[PAPER]:^35s} | {METHOD_TITLES[PEER]:^35s}"
    )
    head2 = f"{'':33s} {'':>6s} | {method_block} | {method_block}"
    print(head1)
    print(head2)
    print("-" * len(head2))
    table: dict[tuple[str, str], Stats] = {}
    for metric in METRICS:
        cells = []
        for method, which in ((PAPER, metric.paper), (PEER, metric.peer)):
            if which is None:
                cells.append(" ".join(f"{'n/a':>{width}s}" for _ in cols))
                continue
            s = stats_of([row[metric.key] for row in per_seed[method]])
            table[(method, metric.key)] = s
            # mean|e| is a magnitude: shown unsigned.
            mean_text = fmt(s.mean_abs, metric.unit).lstrip("+")
            values = (
                mean_text,
                fmt(s.sd, metric.unit).lstrip("+"),
                fmt(s.bias, metric.unit),
                fmt(s.worst, metric.unit),
            )
            cells.append(" ".join(f"{v:>{width}s}" for v in values))
        print(f"{ljust(metric.label, 33)} {rjust(metric.unit, 6)} | {cells[0]} | {cells[1]}")
    return table


def describe_bias(metric: Metric, s: Stats, method: str) -> str:
    unit = "" if metric.unit == "%" else f" {metric.unit}"
    if metric.key == "a_const_pct":
        what = "constant a"
        ref = " relative to the averaged truth"
    elif metric.unit == "%":
        what, ref = metric.summary, " relative"
    else:
        what, ref = metric.summary, ""
    value = fmt(s.bias, metric.unit) + ("%" if metric.unit == "%" else unit)
    verdict = "biased" if s.significant else "not significantly biased"
    t = s.bias / s.standard_error if np.isfinite(s.standard_error) and s.standard_error else 0.0
    return f"{METHOD_TITLES[method]}: {what} {verdict} ({value}{ref}, t = {t:+.1f})"


def print_summary(
    table: dict[tuple[str, str], Stats],
    info: list[dict[str, float]],
    model: str,
) -> None:
    print()
    print("Summary (bias = signed mean over seeds; 'biased' = |bias| > 2 standard errors):")
    for method in (PAPER, PEER):
        for metric in METRICS:
            if not metric.summary or (method, metric.key) not in table:
                continue
            if method == PAPER and metric.key in ("alpha_theta_pct", "theta_bar_theta_deg"):
                continue  # the same steady-state α, θ̄ as the constant-model row
            print("  " + describe_bias(metric, table[(method, metric.key)], method))
    better: list[str] = []
    worse: list[str] = []
    for metric in METRICS:
        if (PAPER, metric.key) in table and (PEER, metric.key) in table:
            p = table[(PAPER, metric.key)].mean_abs
            q = table[(PEER, metric.key)].mean_abs
            (better if p < q else worse).append(f"{metric.label} ({p:.3g} vs {q:.3g})")
    print("  mean |error| lower for the paper's method: " + ("; ".join(better) or "none"))
    print("  mean |error| lower for the peer: " + ("; ".join(worse) or "none"))
    ud = table[(PAPER, "ud_theta_mae")]
    print(
        f"  paper's method: u_d,θ recovered with a mean absolute error of {ud.bias:.2f}° "
        f"(worst seed {ud.worst:.2f}°)"
    )
    failures = int(sum(row["peer_failures"] for row in info))
    outliers = sum(row["outlier_step"] > 0 for row in info)
    print(
        f"  output-error optimiser: {failures} non-converged fits of {2 * len(info)}, "
        f"{np.mean([row['peer_nfev'] for row in info]):.1f} simulations per seed (both models)"
    )
    print(f"  paper's step 7 left a step out as an outlier in {outliers} of {len(info)} seeds")
    print(
        f"  median wall time per seed (noisy; benchmarks/speed.py times properly): paper's method "
        f"{1e3 * np.median([r['paper_s'] for r in info]):.0f} ms, "
        f"peer (both models) {1e3 * np.median([r['peer_s'] for r in info]):.0f} ms"
    )
    if model == "theta":
        avg = np.mean([row["a_truth_avg"] for row in info])
        print(
            f"  (θ-dependent truth: the 'averaged truth' of the constant a is a(θ) averaged "
            f"over the step levels, {avg:.4f} 1/s)"
        )


def write_csv(
    path: Path,
    seeds: Sequence[int],
    per_seed: dict[str, list[dict[str, float]]],
    info: list[dict[str, float]],
) -> None:
    rows = []
    for i, seed in enumerate(seeds):
        row: dict[str, float | int] = {"seed": seed}
        for method in (PAPER, PEER):
            row.update({f"{method}_{k}": v for k, v in per_seed[method][i].items()})
        row.update(info[i])
        rows.append(row)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="benchmarks/ground_truth.py",
        description=(
            "Recovery of the tunnel's ground truth by the paper's method and by the "
            "output-error peer, over several turbulence seeds."
        ),
    )
    parser.add_argument("--seeds", type=int, default=20, help="number of seeds (default 20)")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument(
        "--model",
        choices=("theta", "constant"),
        default="theta",
        help="the tunnel's true roll model: eq. 49 (theta, default) or eq. 29 (constant)",
    )
    parser.add_argument("--csv", type=Path, default=None, help="write per-seed rows to this CSV")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    ns = build_parser().parse_args(argv)
    if ns.seeds < 1 or ns.first_seed < 0:
        raise SystemExit("--seeds must be >= 1 and --first-seed >= 0")
    model: Literal["theta", "constant"] = ns.model
    seeds = list(range(ns.first_seed, ns.first_seed + ns.seeds))
    truth = TunnelSpec(model=model).params()
    print(
        f"ground truth ({model} model): α = {truth.alpha:.4f}, θ̄ = {truth.theta_bar_deg:.4f}°, "
        f"ᾱ = {truth.alpha_bar_per_deg_s:+.4f} 1/(°s), β̄ = {truth.beta_bar_per_s:.4f} 1/s; "
        f"seeds {seeds[0]}-{seeds[-1]} ({len(seeds)}), Table 1 schedule"
    )
    per_seed: dict[str, list[dict[str, float]]] = {PAPER: [], PEER: []}
    info: list[dict[str, float]] = []
    for seed in tqdm(seeds, desc="seeds", unit="seed"):
        paper, peer, extra = study_seed(seed, model)
        per_seed[PAPER].append(paper)
        per_seed[PEER].append(peer)
        info.append(extra)
    print()
    table = print_table(per_seed)
    print_summary(table, info, model)
    if ns.csv is not None:
        write_csv(ns.csv, seeds, per_seed, info)
        print(f"\nwrote {ns.csv}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
