"""The stated loop's excitation as an instrument: is the rocket found under a rate loop?

A flight computer's rate loop feeds the turbulence back to the fin: output error reads the
fin as independent of the turbulence and is biased, direct ``ml`` is consistent only
through the loop's delay.  With the loop stated (the recording's ``loop.*`` lines, or
``identify --loop-gain/--loop-delay``), ``instrumental`` instruments the model's sample map
with the excitation on top of the loop.  This study flies the virtual tunnel (the reference
integrator, not the model's code) under the closed-loop study's rate loop
(``closed_loop_identification.spec_of``: its own rocket per seed, α 0.4-2 of either sign,
θ̄ ±6°, a 0.8-3 1/s, stops at ±15°, a PRBS dither of ±6° on the command, the command
logged at 25 Hz) in eight cases:

* ``delayed`` -- the loop reading the gyro 20-80 ms late;
* ``instant`` -- no delay: the fin a multiple of the rate just read, the gyro's noise in
  it;
* ``open-prbs`` -- no loop: the fin is the instrument;
* outside the model class, each on ``delayed``: ``servo-lag`` (the fin 50 ms behind the
  servo), ``backlash`` (1° of play), ``quadratic`` (a damping growing with the rate, 0.5
  of a at 30 °/s), ``theta`` (a damping that grows with |θ + θ̄|: the constant model fitted
  to an eq. 49 rocket);
* ``wrong-gain`` -- ``delayed`` with the loop's gain stated 30 % high (a user's slip):
  the excitation given back carries the rate, and the adequacy's excitation check should
  say so.

Each log is fitted by ``instrumental``, ``output-error`` and ``ml`` (the constant model).
Printed per case: how often each fits, the median |error| of α for each, how often the
instrumental 95 % intervals of α, θ̄ and a cover the truth (θ̄ with the turbulence's mean,
which the model's θ̄ carries), and its verdicts.  Targets, over ``delayed``, ``instant``
and ``open-prbs`` (the model's class): coverage 90-98 % for each parameter; on ``delayed``
the instrumental α error below output error's; the stated gain named wrong on at least
90 % of the ``wrong-gain`` logs and on at most 10 % of the ``delayed`` ones, where the
excitation check (the excitation explains ``u_d``: model error) fires on at most 10 %.
Direct ml is printed beside: it uses more of the log (the turbulence's spectrum) and is
the more precise where its noise model holds.

    .venv/bin/python benchmarks/instrumental.py --seeds 12 --jobs 2
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from _pool import run_jobs
from _records import emit
from closed_loop_identification import spec_of

import identification.methods.instrumental as instrumental
from identification.instruments.reference import Effects
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods import Context, fit
from identification.methods.pipeline import IdentifyOptions
from identification.methods.steps import IdentificationError
from identification.recordings.recording import Recording
from rocketroll_common.tables import Column, text_table

CASES = (
    "delayed",
    "instant",
    "open-prbs",
    "servo-lag",
    "backlash",
    "quadratic",
    "theta",
    "wrong-gain",
)
#: The cases inside the model's class: the coverage target's population.
IN_CLASS = ("delayed", "instant", "open-prbs")
PARAMETERS = ("alpha", "theta_bar", "a_per_s")
COVERAGE = (0.90, 0.98)
METHODS = ("instrumental", "output-error", "ml")
#: The adequacy's reason where the loop's excitation explains ``u_d`` (model error).
EXCITATION_CHECK = "the excitation on top of the stated loop explains"
#: The adequacy's reason where the stated loop's gain is not the one the log shows.
GAIN_CHECK = "the stated loop's gain"


def spec_for(case: str, seed: int) -> TunnelSpec:
    """The tunnel run of ``case``'s ``seed`` (module docstring)."""
    if case == "open-prbs":
        return spec_of("open-prbs", seed)
    spec = spec_of("loop-dither", seed)
    if case == "instant":
        return dataclasses.replace(spec, loop_delay=0.0)
    effects = {
        "servo-lag": Effects(servo_lag_s=0.05),
        "backlash": Effects(backlash_deg=1.0),
        "quadratic": Effects(quadratic_damping=0.5),
    }
    if case in effects:
        return dataclasses.replace(spec, effects=effects[case])
    if case == "theta":  # a(θ) = ᾱ·|θ + θ̄| + β̄: a doubling of the damping 8° from trim
        assert spec.beta_bar is not None
        return dataclasses.replace(spec, model="theta", alpha_bar=spec.beta_bar / 8.0)
    return spec


def logged(case: str, spec: TunnelSpec) -> tuple[Recording, float]:
    """The log a user would hold (the command, not the fin), its stated loop's gain 30 %
    high for ``wrong-gain``; and the truth's share of samples at the stops."""
    rec = run_tunnel(spec)
    assert rec.fin_deg is not None
    at_stops = float(np.mean(np.abs(np.asarray(rec.fin_deg)) >= spec.stops - 1e-6))
    rec = dataclasses.replace(rec, fin_deg=None)
    if case == "wrong-gain":
        meta = {**rec.metadata, "loop.gain": repr(1.3 * float(rec.metadata["loop.gain"]))}
        rec = dataclasses.replace(rec, metadata=meta)
    return rec, at_stops


def one(case: str, seed: int, window_s: float) -> dict[str, Any]:
    """One log: the truth, and each method's α, the instrumental intervals and verdict
    (its integration window ``window_s``)."""
    instrumental.WINDOW_S = window_s  # in this process: a study of the window
    spec = spec_for(case, seed)
    rec, at_stops = logged(case, spec)
    truth = spec.params()
    true = {
        "alpha": truth.alpha,
        "theta_bar": truth.theta_bar_deg + spec.turbulence_mean,
        "a_per_s": truth.beta_bar_per_s,
    }
    row: dict[str, Any] = {"case": case, "seed": seed, "true": true, "at_stops": at_stops}
    context = Context(rec, IdentifyOptions())
    for method in METHODS:
        try:
            found = fit(context, method, ["constant"])["constant"]
        except IdentificationError as exc:
            row[method] = {"error": str(exc)}
            continue
        row[method] = {
            "alpha": found.params.alpha,
            "verdict": found.metrics["adequacy"]["verdict"],
            "reasons": found.metrics["adequacy"]["reasons"],
            "intervals": found.metrics.get("intervals"),
        }
    return row


COLUMNS = (
    Column("case", 11, "<"),
    Column("logs", 5),
    Column("IV fits", 8),
    Column("IV α err", 9),
    Column("OE α err", 9),
    Column("ml α err", 9),
    Column("α cover", 9),
    Column("θ̄ cover", 9),
    Column("a cover", 9),
    Column("IV unrel.", 10),
)


def _err(rows: list[dict[str, Any]], method: str) -> float:
    errors = [
        abs(r[method]["alpha"] / r["true"]["alpha"] - 1.0) for r in rows if "alpha" in r[method]
    ]
    return float(np.median(errors)) if errors else math.nan


def _covered(rows: list[dict[str, Any]], name: str) -> tuple[int, int]:
    fitted = [r for r in rows if "intervals" in r["instrumental"]]
    hits = sum(
        r["instrumental"]["intervals"][name]["low"]
        <= r["true"][name]
        <= r["instrumental"]["intervals"][name]["high"]
        for r in fitted
    )
    return hits, len(fitted)


def _summary(case: str, rows: list[dict[str, Any]]) -> list[str]:
    fitted = [r for r in rows if "alpha" in r["instrumental"]]
    cover = [f"{h}/{n}" for h, n in (_covered(rows, p) for p in PARAMETERS)]
    unreliable = sum(r["instrumental"]["verdict"] == "unreliable" for r in fitted)
    return [
        case,
        str(len(rows)),
        f"{len(fitted)}/{len(rows)}",
        *(f"{100 * _err(rows, m):.1f} %" for m in METHODS),
        *cover,
        f"{unreliable}/{len(fitted)}",
    ]


def _targets(rows: list[dict[str, Any]]) -> bool:
    ok = True

    def state(figure: str, value: float, low: float | None, high: float | None, note: str) -> None:
        nonlocal ok
        met = (low is None or value >= low) and (high is None or value <= high)
        ok &= met
        print(f"  {'PASS' if met else 'FAIL'}  {figure}: {value:.4g} ({note})")
        emit(figure, value, "", at_least=low, at_most=high, note=note)

    inside = [r for r in rows if r["case"] in IN_CLASS]
    for p in PARAMETERS:
        hits, n = _covered(inside, p)
        state(f"{p}: share of instrumental 95 % intervals covering the truth (model's class)",
              hits / max(n, 1), *COVERAGE, f"{hits}/{n} logs")  # fmt: skip
    by = {c: [r for r in rows if r["case"] == c] for c in CASES}
    if by["delayed"]:
        iv, oe = _err(by["delayed"], "instrumental"), _err(by["delayed"], "output-error")
        state("delayed loop: instrumental α error over output error's (median)", iv / oe,
              None, 1.0, f"{100 * iv:.1f} % against {100 * oe:.1f} %")  # fmt: skip
    for case, low, high in (("wrong-gain", 0.9, None), ("delayed", None, 0.1)):
        fitted = [r for r in by[case] if "verdict" in r["instrumental"]]
        if fitted:
            named = sum(any(GAIN_CHECK in t for t in r["instrumental"]["reasons"])
                        for r in fitted)  # fmt: skip
            state(f"{case}: instrumental fits whose stated loop gain is named wrong",
                  named / len(fitted), low, high, f"{named}/{len(fitted)} logs")  # fmt: skip
        if case == "delayed" and fitted:
            named = sum(any(EXCITATION_CHECK in t for t in r["instrumental"]["reasons"])
                        for r in fitted)  # fmt: skip
            state(f"{case}: instrumental fits whose u_d the loop's excitation explains",
                  named / len(fitted), None, 0.1, f"{named}/{len(fitted)} logs")  # fmt: skip
    return ok


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks/instrumental.py", description=__doc__)
    parser.add_argument("--seeds", type=int, default=12, help="logs per case (default 12)")
    parser.add_argument("--case", action="append", choices=CASES)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument(
        "--window", type=float, default=instrumental.WINDOW_S,
        help=f"the instrumental fit's integration window, s (default {instrumental.WINDOW_S})",
    )  # fmt: skip
    ns = parser.parse_args(argv)
    if ns.seeds < 1 or ns.jobs < 1 or not ns.window > 0:
        parser.error("--seeds and --jobs must be >= 1, --window > 0")
    cases = list(dict.fromkeys(ns.case or CASES))
    jobs = [(c, s, ns.window) for c in cases for s in range(ns.seeds)]
    print(
        f"{len(jobs)} logs: cases {', '.join(cases)} ({ns.seeds} each); 42 s at 25 Hz, stops "
        "±15°, 1 % gyro, the command logged; instrumental (window "
        f"{ns.window:g} s), output error and ml (constant model)"
    )
    began = time.perf_counter()
    rows = run_jobs(one, jobs, ns.jobs, "logs", "log")
    elapsed = time.perf_counter() - began
    print(f"{elapsed:.0f} s on {ns.jobs} process(es)\n")
    table = [_summary(c, [r for r in rows if r["case"] == c]) for c in cases]
    print("\n".join(text_table(COLUMNS, table)))
    print(
        "α err: median |error| of α (IV instrumental, OE output error); cover: the "
        "instrumental 95 % interval holds the truth; IV unrel.: instrumental fits judged "
        "unreliable"
    )
    for r in rows:
        error = r["instrumental"].get("error")
        if error:
            print(f"  {r['case']} seed {r['seed']}: instrumental refused: {error}")
    print("\ntargets")
    ok = _targets(rows)
    emit("compute", elapsed, "s", note=f"{len(jobs)} logs on {ns.jobs} process(es)")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
