"""Does a controller's score on a stored flight predict its score on the real rocket?

For each seed and truth (``--n``: the fin torque's true airspeed exponent; the
recorder's default rocket, ascent, staircase and flown tunnel turbulence
otherwise), a virtual flight (:func:`identification.instruments.flightlog.run_flight`) is
identified and stored as a user would (``db add --posterior 8``: the flight
method, its measured scaling, ``u_d`` and posterior draws), and the controllers
of ``--policies`` are designed on it (``rocketroll eval --env-id
RocketRollFlight-v0 --recording NAME``'s designs).  Each is then scored, over the
same protocol (``--episodes``):

* on the **replay** -- ``RocketRollFlight-v0`` flying the stored flight as its
  rocket with the posterior draws of its ``u_d`` (the default), and with the
  smoothed ``u_d`` (``disturbance=replay``);
* on the **truth** -- the same environment flying the true rocket, carried
  along the flight by its true scaling, through the ``u_d`` it really flew
  (``ud_true_deg``), from a database that holds the truth in place of the fit.

Printed per seed and controller: the regulation RMS on the truth and on each
replay and their ratio replay / truth (1.00: the replay predicts the score;
below: it flatters), and below the table the ratios' mean and range per
controller and replay.  A ratio within [0.9, 1.1] is the fidelity asked of the
tunnel's replays (``benchmarks/closed_loop.py``).

    .venv/bin/python benchmarks/flight_fidelity.py --seeds 5
    .venv/bin/python benchmarks/flight_fidelity.py --seeds 5 --policies trim,pid,observer,mpc
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from _records import emit

from agents.evaluate import evaluate, protocol_episodes
from agents.registry import make_controller
from disturbances.db import DisturbanceDB
from disturbances.ingest import identification_rows, trace_summary
from disturbances.rows import checksum
from identification.instruments.flightlog import FlightLogSpec, run_flight, truth_reference
from identification.methods import Context
from rocketroll_common.tables import Column, text_table
from rollenv.bank import load_bank, stored_flight_config, variant_config

ENV_ID = "RocketRollFlight-v0"
POSTERIOR = 8


def _truth_rows(rows: tuple[Any, list[Any], list[Any]], recording: Any) -> tuple[Any, ...]:
    """The identification rows of a flight with the truth in place of each fit: the true
    rocket at its own reference with its true scaling, the true u_d as its identified trace
    (no posterior draws)."""
    stored, identifications, traces = rows
    truth = recording.truth()
    reference = truth_reference(recording)
    facts = {
        "v_ref_mps": reference.v_ref_mps,
        "rho_ref_kgm3": reference.rho_ref_kgm3,
        "torque_exponent": reference.scaling.torque_exponent,
        "damping_exponent": reference.scaling.damping_exponent,
    }
    true_u = np.asarray(recording.ud_true_deg[:-1], dtype=float)
    idents = [
        dataclasses.replace(row, params=truth, metrics={**dict(row.metrics), **facts})
        for row in identifications
    ]
    kept = [
        dataclasses.replace(
            trace,
            params=truth,
            u_d_deg=true_u,
            checksum=checksum(true_u),
            statistics=trace_summary(true_u),
            flight_reference=reference,
        )
        for trace in traces
        if trace.kind == "identified"
    ]
    return stored, idents, kept


def one(seed: int, n: float, policies: Sequence[str], episodes: int, root: Path) -> list[dict]:
    """Fly, store the fit and the truth, design on the fit, score on both."""
    spec = FlightLogSpec(seed=seed, torque_exponent=n, name=f"flight-{seed}-n{n:g}")
    recording = run_flight(spec)
    rows = identification_rows(Context(recording), ["flight"], posterior=POSTERIOR)
    fitted, true = root / f"fit-{seed}-{n:g}.sqlite", root / f"truth-{seed}-{n:g}.sqlite"
    with DisturbanceDB(fitted, create=True) as db:
        db.store(rows[0:1], rows[1], rows[2])
    with DisturbanceDB(true, create=True) as db:
        stored, idents, traces = _truth_rows(rows, recording)
        db.store([stored], idents, traces)
    settings = {"recording": recording.name}
    config = stored_flight_config(variant_config(ENV_ID, {**settings, "split": "test"}), fitted)
    truth_config = stored_flight_config(
        variant_config(ENV_ID, {**settings, "split": "test", "disturbance": "replay"}), true
    )
    replays = {
        "posterior": (config, load_bank(config, fitted)),
        "smoothed": (
            dataclasses.replace(config, disturbance="replay"),
            load_bank(dataclasses.replace(config, disturbance="replay"), fitted),
        ),
    }
    truth_bank = load_bank(truth_config, true)
    truth_specs = protocol_episodes(truth_config, episodes, seed, bank=truth_bank)
    out = []
    for policy in policies:
        controller = make_controller(policy, config, ENV_ID, db=str(fitted))
        on_truth = evaluate(truth_config, controller, truth_specs, bank=truth_bank)
        row = {"seed": seed, "n": n, "policy": controller.name}
        row["truth"] = on_truth.aggregate["regulation_rms_error"]["mean"]
        for name, (replay_config, bank) in replays.items():
            specs = protocol_episodes(replay_config, episodes, seed, bank=bank)
            result = evaluate(replay_config, controller, specs, bank=bank)
            row[name] = result.aggregate["regulation_rms_error"]["mean"]
        out.append(row)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5, help="flights per truth (seeds 0..N-1)")
    parser.add_argument("--n", type=float, nargs="+", default=[2.0, 1.5], help="true n")
    parser.add_argument("--policies", default="trim,pid", help="comma-separated controllers")
    parser.add_argument("--episodes", type=int, default=8, help="protocol episodes")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.episodes < 1:
        parser.error("--seeds and --episodes must be at least 1")
    policies = [p for p in args.policies.split(",") if p]
    started = time.perf_counter()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as folder:
        for n in args.n:
            for seed in range(args.seeds):
                rows += one(seed, n, policies, args.episodes, Path(folder))
                print(f"  flight seed {seed}, n {n:g}: done", file=sys.stderr)
    columns = (
        Column("n", 4),
        Column("seed", 5),
        Column("controller", 12, "<", "  "),
        Column("truth °", 9),
        Column("posterior °", 12),
        Column("ratio", 7),
        Column("smoothed °", 11),
        Column("ratio", 7),
    )
    cells = (
        [
            f"{r['n']:.1f}",
            f"{r['seed']}",
            r["policy"],
            f"{r['truth']:.3f}",
            f"{r['posterior']:.3f}",
            f"{r['posterior'] / r['truth']:.2f}",
            f"{r['smoothed']:.3f}",
            f"{r['smoothed'] / r['truth']:.2f}",
        ]
        for r in rows
    )
    print("\n".join(text_table(columns, cells)))
    print(f"\n{len(rows)} scores in {time.perf_counter() - started:.0f} s; ratio replay / truth:")
    for n in args.n:
        for policy in sorted({r["policy"] for r in rows}):
            mine = [r for r in rows if r["policy"] == policy and r["n"] == n]
            for replay in ("posterior", "smoothed"):
                ratios = np.array([r[replay] / r["truth"] for r in mine])
                within = int(np.sum(np.abs(ratios - 1.0) <= 0.1))
                emit(
                    f"n {n:g}, {policy}, {replay} replay: mean ratio replay / truth",
                    float(ratios.mean()),
                    "",
                    at_least=0.9,
                    at_most=1.1,
                    note=f"range [{ratios.min():.2f}, {ratios.max():.2f}], {within}/{ratios.size} "
                    "flights within [0.9, 1.1]",
                )
                print(
                    f"  n {n:g}, {policy:<12} {replay:<10} mean {ratios.mean():.2f}, range "
                    f"[{ratios.min():.2f}, {ratios.max():.2f}], within [0.9, 1.1]: "
                    f"{within}/{ratios.size}"
                )
    return 0 if all(math.isfinite(r["posterior"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
