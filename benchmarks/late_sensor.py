"""Does the likelihood find a late sensor itself, and does finding it unbias the rocket?

A gyro read late, or a fin logged ahead of the roll it drives, makes the roll look slower
than the fin.  Where no latency is stated, ``ml`` searches one as a term of its fit
(:func:`identification.methods.actuation.latency_term`), and ``output-error``, whose rate
error cannot tell it, fits the fin delayed by the one that search admits.  This study flies
three truths unlike each other, none of them the model's own code:

* ``pilot`` -- the virtual tunnel (the reference integrator, its own sensor latency): 25 Hz,
  ~20 s of bank-to-bank ramps and dwells, an aileron convention (α −2.9), a 2.4 1/s, a gyro
  only and the measured fin -- a fin commanded per sample behind a fast servo, so the
  logged fin is a staircase;
* ``stick`` -- a pilot's stick made outside the toolkit (``_truths.stick_log``: scipy's
  ``solve_ivp``, a continuous aileron, the same rocket);
* ``doublets`` -- the tunnel, a rocket of the other sign on doublets at 50 Hz, 30 s (α 1.8,
  θ̄ −3°, a 1.5 1/s);

each with the roll read 0 or 40 ms late and turbulence of 0.7° or 1.5°, and fits each log
by ``ml`` and ``output-error`` (constant model) twice: searching the latency, and with
``--sensor-latency 0`` stated (the fits before the search).  Printed per truth, latency and
turbulence: how often the latency is admitted, its median estimate, and the median and
largest |error| of α and of a either way.  Targets: admitted on at least 90 % of the late
logs at 0.7°, on at most 5 % of the logs without a latency (each turbulence).

    .venv/bin/python benchmarks/late_sensor.py --seeds 10 --jobs 2
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from _pool import run_jobs
from _records import emit
from _truths import STICK, stick_log

from identification.instruments.reference import Effects
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods import Context, fit
from identification.methods.pipeline import IdentifyOptions
from identification.recordings.recording import StatedRig
from rocketroll_common.tables import Column, text_table

TRUTHS: dict[str, dict[str, Any]] = {
    "pilot": {
        "model": "constant", "alpha": -2.9, "beta": -1.45, "beta_bar": 2.4,
        "schedule": "ramps", "steps": 12, "ramp": 0.6, "dwell_min": 1.0, "dwell_max": 2.0,
        "lead": 1.0, "fin_range": 10.0, "log_dt": 0.04,
    },
    "stick": {"alpha": STICK["alpha"], "beta_bar": STICK["a_per_s"]},
    "doublets": {
        "model": "constant", "alpha": 1.8, "beta": -5.4, "beta_bar": 1.5,
        "schedule": "doublets", "lead": 1.0, "fin_range": 8.0, "log_dt": 0.02,
        "duration": 30.0,
    },
}  # fmt: skip
LATENCIES_S = (0.0, 0.04)
#: The methods fitted, each searching the latency and with none stated.
METHODS = ("ml", "output-error")
TURBULENCE_DEG = (0.7, 1.5)
#: Admitted on at least this share of the late logs at the lower turbulence.
FOUND = 0.9
#: Admitted on at most this share of the logs without a latency.
INVENTED = 0.05


def one(truth: str, latency_s: float, turbulence_deg: float, seed: int) -> dict[str, Any]:
    """One log fitted by ml and output error with the search and with no latency stated."""
    if truth == "stick":
        rec = stick_log(seed, latency_s, turbulence_deg)
    else:
        rec = run_tunnel(
            TunnelSpec(
                seed=seed, gyro_noise=1.0, no_encoder=True, measured_fin=True,
                turbulence_sd=turbulence_deg, correlation_time=1.0,
                effects=Effects(latency_s=latency_s), **TRUTHS[truth],
            )
        )  # fmt: skip
    none = IdentifyOptions(rig=StatedRig(sensor_latency_s=0.0))
    searched, stated = Context(rec), Context(rec, none)
    fits = [fit(c, m, ["constant"])["constant"] for m in METHODS for c in (searched, stated)]
    term = fits[0].metrics["sensor_latency"]
    return {
        "truth": truth,
        "latency": latency_s,
        "turbulence": turbulence_deg,
        "admitted": bool(term["admitted"]),
        "estimate": float(term["estimate_s"]),
        "alpha": tuple(f.params.alpha for f in fits),
        "a": tuple(f.params.beta_bar_per_s for f in fits),
    }


COLUMNS = (
    Column("truth", 9, "<"),
    Column("late ms", 8),
    Column("turb. °", 8),
    Column("logs", 5),
    Column("admitted", 9),
    Column("est. ms", 8),
    *(
        Column(f"{label} {which}", 14)
        for label in ("ml α %", "ml a %", "OE α %", "OE a %")
        for which in ("found", "none")
    ),
)


def _errors(rows: list[dict[str, Any]], key: str, which: int) -> str:
    true = TRUTHS[rows[0]["truth"]]
    value = true["alpha"] if key == "alpha" else true["beta_bar"]
    err = np.abs([100.0 * (r[key][which] - value) / abs(value) for r in rows])
    return f"{np.median(err):.1f} ({np.max(err):.1f})"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks/late_sensor.py", description=__doc__)
    parser.add_argument("--seeds", type=int, default=10, help="logs per cell (default 10)")
    parser.add_argument("--jobs", type=int, default=1)
    ns = parser.parse_args(argv)
    if ns.seeds < 1 or ns.jobs < 1:
        parser.error("--seeds and --jobs must be >= 1")
    cells = [(t, lat, sd) for t in TRUTHS for lat in LATENCIES_S for sd in TURBULENCE_DEG]
    jobs = [(*cell, seed) for cell in cells for seed in range(ns.seeds)]
    print(
        f"{len(jobs)} logs: truths {', '.join(TRUTHS)}, the roll read "
        f"{' or '.join(f'{1000 * x:g}' for x in LATENCIES_S)} ms late, turbulence "
        f"{' or '.join(f'{x:g}' for x in TURBULENCE_DEG)}°; ml and output error (constant) "
        "searching the latency and with none stated"
    )
    began = time.perf_counter()
    rows = run_jobs(one, jobs, ns.jobs, "logs", "log")
    elapsed = time.perf_counter() - began
    print(f"{elapsed:.0f} s on {ns.jobs} process(es)\n")
    table, ok = [], True
    for truth, latency, sd in cells:
        cell = [
            r for r in rows if (r["truth"], r["latency"], r["turbulence"]) == (truth, latency, sd)
        ]
        admitted = sum(r["admitted"] for r in cell)
        found = [1000.0 * r["estimate"] for r in cell if r["admitted"]]
        table.append(
            [
                truth, f"{1000 * latency:g}", f"{sd:g}", str(len(cell)),
                f"{admitted}/{len(cell)}", f"{np.median(found):.0f}" if found else "-",
                *(
                    _errors(cell, key, 2 * method + which)
                    for method in range(len(METHODS))
                    for key in ("alpha", "a")
                    for which in (0, 1)
                ),
            ]
        )  # fmt: skip
        share = admitted / len(cell)
        name = f"{truth} {1000 * latency:g} ms {sd:g}°"
        if latency > 0 and sd == min(TURBULENCE_DEG):
            emit(f"admitted, {name}", share, "", at_least=FOUND)
            ok &= share >= FOUND
        elif latency == 0:
            emit(f"admitted, {name}", share, "", at_most=INVENTED)
            ok &= share <= INVENTED
    print("\n".join(text_table(COLUMNS, table)))
    print(
        "admitted: the latency's likelihood-ratio test admits it at 1 %; est.: its median "
        "estimate where admitted; α %, a %: median (largest) |error| of ml's and output "
        "error's (OE) α and a, the fits searching the latency (found) and with none stated "
        "(none)"
    )
    print(f"\ntargets: {'met' if ok else 'NOT met'}")
    emit("compute", elapsed, "s", note=f"{len(jobs)} logs on {ns.jobs} process(es)")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
