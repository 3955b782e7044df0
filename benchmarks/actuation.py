"""Servo lag, backlash, sensor latency and quadratic damping identified over truths with
and without them.

For each truth (``benchmarks/_truths.py``) and seed, the virtual tunnel records
the paper's schedule at ``--hz`` with a 1 % gyro and, unless ``--no-fin``, a
measured fin column; :func:`identification.methods.actuation.identify_actuation` looks
for each optional term at its level.  Per truth the table gives how often each
term was admitted, the mean estimate where it was, and the true value: on a
truth without a term it should stay out (the rig inside the model keeps the
model), on one with it come in near the truth (servo lag within 20 %, latency
within one logging interval, quadratic damping within 25 %).  For the quadratic
damping, which long records tell only weakly, it also counts the recordings
whose 95 % interval covers the truth (``covered``) and gives the estimates of
every recording, admitted or not.

Run from the repository root::

    .venv/bin/python benchmarks/actuation.py --seeds 5 --jobs 2
    .venv/bin/python benchmarks/actuation.py --seeds 5 --hz 10 --no-fin --truth latency
    .venv/bin/python benchmarks/actuation.py --seeds 5 --hz 10 --no-fin --truth paper \
        --truth negative --truth quadratic --jobs 2
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Sequence

import numpy as np
from _pool import run_jobs
from _records import emit
from _truths import TRUTHS, spec_of

from identification.instruments.tunnel import run_tunnel
from identification.methods.actuation import LEVEL, identify_actuation
from rocketroll_common.tables import Column, text_table

DEFAULT_TRUTHS = ("paper", "negative", "servo-lag", "latency", "quadratic", "mismatch-all")
#: term -> the truth's value of it (Effects' field)
TRUE_VALUE = {
    "servo lag": "servo_lag_s",
    "backlash": "backlash_deg",
    "sensor latency": "latency_s",
    "quadratic damping": "quadratic_damping",
}
#: term -> the unit of its value
UNIT = {
    "servo lag": "s",
    "backlash": "°",
    "sensor latency": "s",
    "quadratic damping": "× a(θ)",
}
#: Per truth and term: its true value, how many recordings admitted it, the estimates.
COLUMNS = (
    Column("truth", 14, "<"),
    Column("term", 15, "<", " "),
    Column("true", 7, ">", " "),
    Column("admitted", 9, ">", " "),
    Column("mean estimate", 14, ">", " "),
    Column("range", 17, ">", " "),
)


def one(
    truth: str, seed: int, hz: float, fin: bool
) -> list[tuple[str, float, bool, float, float, bool]]:
    """(term, true value, admitted, estimate where admitted, estimate, whether its interval
    covers the truth) of one recording (the last two NaN and False without an interval)."""
    spec = dataclasses.replace(
        spec_of(truth, seed), log_dt=1.0 / hz, gyro_noise=1.0, measured_fin=fin
    )
    found = identify_actuation(run_tunnel(spec))
    out = []
    for term in found.terms:
        true = float(getattr(spec.effects, TRUE_VALUE[term.name]))
        estimate = term.value if term.admitted else float("nan")
        raw, covered = float("nan"), False
        if term.estimate is not None and term.interval is not None:
            raw = term.estimate
            covered = term.interval[0] <= true <= term.interval[1]
        out.append((term.name, true, term.admitted, estimate, raw, covered))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks/actuation.py", description=__doc__)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--truth", action="append", choices=tuple(TRUTHS))
    parser.add_argument("--hz", type=float, default=100.0, help="logging rate (default 100)")
    parser.add_argument("--no-fin", action="store_true", help="no measured fin column")
    parser.add_argument("--jobs", type=int, default=1)
    ns = parser.parse_args(argv)
    if ns.seeds < 1 or ns.jobs < 1 or not ns.hz > 0:
        parser.error("--seeds and --jobs must be >= 1, --hz > 0")
    truths = list(dict.fromkeys(ns.truth or DEFAULT_TRUTHS))
    jobs = [(t, s, ns.hz, not ns.no_fin) for t in truths for s in range(ns.seeds)]
    print(
        f"truths {', '.join(truths)}; {ns.seeds} seeds; {ns.hz:g} Hz, 1 % gyro, "
        f"{'no measured fin' if ns.no_fin else 'measured fin'}; each term at p < {LEVEL:g}"
    )
    began = time.perf_counter()
    results = run_jobs(one, jobs, ns.jobs, "recordings", "rec")
    print(f"{time.perf_counter() - began:.0f} s\n")
    header = text_table(COLUMNS, [])[0]
    print(header)
    print("-" * len(header))
    for truth in truths:
        rows = [r for (t, *_), r in zip(jobs, results, strict=True) if t == truth]
        for k, (name, true, *_) in enumerate(rows[0]):
            admitted = [r[k][2] for r in rows]
            estimates = np.array([r[k][3] for r in rows if r[k][2]])
            mean = f"{estimates.mean():.4g}" if estimates.size else "-"
            span = f"{estimates.min():.3g}-{estimates.max():.3g}" if estimates.size else "-"
            share = f"{sum(admitted):4d}/{len(admitted):<4d}"
            print(text_table(COLUMNS, [[truth, name, f"{true:.3g}", share, mean, span]])[1])
            unit = UNIT.get(name, "")
            truly = f"true {true:.3g} {unit}".rstrip()
            emit(
                f"{truth}, {name}: share of recordings admitting it",
                sum(admitted) / len(admitted),
                "",
                note=f"{sum(admitted)}/{len(admitted)}; {truly}",
            )
            if estimates.size:
                emit(
                    f"{truth}, {name}: mean estimate where admitted",
                    float(estimates.mean()),
                    unit,
                    note=f"{truly}; range {span}",
                )
            raw = np.array([r[k][4] for r in rows])
            if np.isfinite(raw).any():
                covered = sum(r[k][5] for r in rows)
                print(
                    f"{'':14s} {'':15s} covered {covered}/{len(rows)}; every estimate "
                    f"{', '.join(f'{x:.3g}' for x in raw)}"
                )
                emit(
                    f"{truth}, {name}: share of 95 % intervals covering the truth",
                    covered / len(rows),
                    "",
                    note=f"{covered}/{len(rows)}; {truly}",
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
