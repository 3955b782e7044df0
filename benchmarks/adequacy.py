"""Calibration of the fit-adequacy verdict (:mod:`identification.methods.adequacy`).

Right fits: the maximum-likelihood fit of three virtual-tunnel truths (the
paper's rocket; α 0.9 with θ̄ negative and a 0.3-s turbulence; a constant-damping
rocket with α 1.5, a = 4 1/s) on ramps, doublets and PRBS, 15-s and 60-s
records at 100 Hz with a rate gyro, over ``--seeds``.  Wrong fits, on purpose:
the same rockets with the gain held 30 % off (its ``u_d`` the posterior under
those parameters), and on the paper's truth at the first seed constant damping
fitted to a rocket whose damping rises steeply with the fin (ᾱ 0.06, β̄ 0.3) and
a model that reads the fin command through eq. 23's servo where the rig's was
ten times slower.

Prints one line per fit (verdict, figures, reasons) and the counts: "good" on
right fits and "not good" on wrong ones.  The thresholds were set on seeds 0-1
and checked on seeds 2-3 (``--first-seed 2 --seeds 2``).

    .venv/bin/python benchmarks/adequacy.py --seeds 2 --first-seed 2

``--suspects``: the effects the adequacy names (the fin's delay, the turbulence's
wandering intensity) on the named truths inside and outside the model, each
recorded as the truth records it (the paper's 10-Hz encoder; ``--hz`` for a
faster log with a 1 % gyro), fitted by ``ml``: how often each is suspected.

    .venv/bin/python benchmarks/adequacy.py --suspects --seeds 5
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import sys
from dataclasses import replace
from typing import Any

import numpy as np
from _records import emit
from _truths import SHAPE_TRUTHS, SHAPES, shape_command, spec_of

from identification.instruments.tunnel import run_tunnel, spec_from_command
from identification.methods.adequacy import Adequacy, adequacy
from identification.methods.ml import MLFit, innovation_checks, maximum_likelihood, posterior_given
from identification.methods.pipeline import model_inputs
from identification.model import Disturbance, RollParams
from identification.recordings.recording import Recording
from rocketroll_common.tables import Column, text_table


def metrics_of(found: MLFit) -> dict[str, Any]:
    """What ml's method puts in its metrics for the adequacy: its standard errors and the
    innovations' checks."""
    return {
        "std_errors": found.std_errors,
        "innovations": innovation_checks(found),
        "ar": found.ar.tolist(),
    }


#: Truths the suspects are counted on: inside the model, then outside it.
SUSPECT_TRUTHS = (
    "paper", "negative", "rising", "servo-lag", "latency", "quadratic", "gusty", "mismatch-all",
)  # fmt: skip
#: Per truth of :data:`SUSPECT_TRUTHS`: how often each suspect was named, and its figure.
SUSPECT_COLUMNS = (
    Column("truth", 14, "<"),
    Column("delay suspected", 16, ">", " "),
    Column("mean delay", 11, ">", " "),
    Column("intensity", 10, ">", " "),
    Column("mean ratio", 11, ">", " "),
)


def seeds_of(seeds: range) -> str:
    """``seeds`` in words, for a figure's note."""
    return f"seed {seeds.start}" if len(seeds) == 1 else f"seeds {seeds.start}-{seeds.stop - 1}"


def suspects(seeds: range, hz: float | None) -> None:
    """Per truth: how often the fin's delay and the wandering intensity are suspected."""
    print(text_table(SUSPECT_COLUMNS, [])[0])
    for truth in SUSPECT_TRUTHS:
        delays, ratios, flagged = [], [], [0, 0]
        for seed in seeds:
            spec = spec_of(truth, seed)
            if hz is not None:
                spec = dataclasses.replace(spec, log_dt=1.0 / hz, gyro_noise=1.0)
            rec = run_tunnel(spec)
            found = maximum_likelihood(rec, "theta")
            a = adequacy(
                model_inputs(rec, "theta", None), found.params, found.disturbance(),
                metrics_of(found),
            )  # fmt: skip
            delays.append(a.fin_delay_s)
            ratios.append(a.intensity_ratio)
            flagged[0] += any("the fin acts" in s for s in a.suspected)
            flagged[1] += any("intensity wanders" in s for s in a.suspected)
        n = len(delays)
        cells = [
            truth,
            f"{flagged[0]:>12d}/{n:<3d}",
            f"{1000 * np.mean(delays):.1f} ms",
            f"{flagged[1]:>6d}/{n:<3d}",
            f"{np.mean(ratios):.2f}",
        ]
        print(text_table(SUSPECT_COLUMNS, [cells])[1], flush=True)
        note = f"{seeds_of(seeds)}, " + (
            "as the truth records it" if hz is None else f"{hz:g}-Hz log, 1 % gyro"
        )
        figures = (
            ("share suspecting the fin's delay", flagged[0] / n, "", f"{flagged[0]}/{n}; "),
            ("mean fin delay", 1000 * float(np.mean(delays)), "ms", ""),
            ("share suspecting a wandering intensity", flagged[1] / n, "", f"{flagged[1]}/{n}; "),
            ("mean intensity ratio", float(np.mean(ratios)), "", ""),
        )
        for what, value, unit, count in figures:
            emit(f"suspects, {truth}: {what}", value, unit, note=count + note)


def _line(kind: str, label: str, a: Adequacy) -> str:
    return (
        f"{kind:6s} {label:42s} {a.verdict:10s} R² {a.rate_r2:6.3f} ahead {a.ahead_r2:6.3f} "
        f"fin {a.fin_share:5.3f} (p {a.fin_share_p:.2g}) |u_d|/range {a.ud_range_fraction:5.2f} "
        f"α SE {a.alpha_rel_se:5.3f} innov {a.innovation_acf:5.3f}  {'; '.join(a.reasons)}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=2, help="seeds per truth and shape")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--suspects", action="store_true", help="count the named suspects")
    parser.add_argument("--hz", type=float, default=None, help="with --suspects: log rate")
    args = parser.parse_args(argv)
    if args.suspects:
        suspects(range(args.first_seed, args.first_seed + args.seeds), args.hz)
        return 0
    counts = {"right": [0, 0], "wrong": [0, 0]}

    def record(
        kind: str, label: str, rec: Recording, params: RollParams, dist: Disturbance,
        metrics: dict, model: str,
    ) -> None:  # fmt: skip
        a = adequacy(model_inputs(rec, model, None), params, dist, metrics)
        counts[kind][0] += 1
        counts[kind][1] += (a.verdict == "good") == (kind == "right")
        print(_line(kind, label, a), flush=True)

    seeds = range(args.first_seed, args.first_seed + args.seeds)
    for name, (shape, length), seed in itertools.product(SHAPE_TRUTHS, SHAPES, seeds):
        command = shape_command(name, (shape, length), seed)
        model = "constant" if "constant" in SHAPE_TRUTHS[name] else "theta"
        rec = run_tunnel(spec_from_command(command))
        found = maximum_likelihood(rec, model)
        label = f"{name} {shape} {length} s, seed {seed}"
        record("right", label, rec, found.params, found.disturbance(), metrics_of(found), model)
        off = replace(found.params, alpha=1.3 * found.params.alpha)
        given = posterior_given(
            rec, off, found.ar.tolist(), found.sd_deg, gyro_noise=found.gyro_noise
        )
        record("wrong", label + ", α +30 %", rec, off, given.disturbance(),
               {"innovations": innovation_checks(given)}, model)  # fmt: skip
        if seed == args.first_seed and name == "paper":
            steep = run_tunnel(spec_from_command(command + " --alpha-bar 0.06 --beta-bar 0.3"))
            f = maximum_likelihood(steep, "constant")
            record("wrong", label + ", constant a on a(θ)", steep, f.params, f.disturbance(),
                   metrics_of(f), "constant")  # fmt: skip
            slow = run_tunnel(spec_from_command(command + " --servo-rate 15"))
            f = maximum_likelihood(slow, model)
            record("wrong", label + ", servo 10x slower", slow, f.params, f.disturbance(),
                   metrics_of(f), model)  # fmt: skip
    (n_right, good), (n_wrong, caught) = counts["right"], counts["wrong"]
    print(f"\nright fits judged good: {good}/{n_right}; wrong ones not good: {caught}/{n_wrong}")
    over = seeds_of(seeds)
    emit("right fits judged good: share", good / n_right, "", note=f"{good}/{n_right}; {over}")
    emit(
        "wrong fits judged not good: share",
        caught / n_wrong,
        "",
        note=f"{caught}/{n_wrong}; {over}",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
