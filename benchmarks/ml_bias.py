"""Where does maximum likelihood's small a(θ) offset come from? A paired diagnostic.

``ground_truth.py`` finds ml's damping curve a(θ) offset by a few hundredths of
1/s, significant only when 120 recordings are pooled.  This script fits the
same turbulence seeds three ways, so that the differences are paired:

* **quantised**: the tunnel's recording, the 1024-count encoder (what the
  filter models as white noise of variance q²/12);
* **white**: the ideal angle plus white Gaussian noise of exactly that
  variance, with the filter told q (the filter's own measurement model: no
  model error at all);
* **exact**: the ideal angle, unquantised (the filter's variance floor).

If the quantised and white offsets agree, the encoder's quantisation is not
the cause; if the white (correctly specified) offset differs from zero, the
offset is a finite-sample property of the estimator.  Offsets are the mean of
``â(θ) - a(θ)`` over fin angles -20..20° (1/s), with their standard errors.

Run from the repository root::

    .venv/bin/python benchmarks/ml_bias.py --seeds 40              # the paper's truth
    .venv/bin/python benchmarks/ml_bias.py --seeds 40 --truth rising
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import replace
from unittest import mock

import numpy as np
from _records import emit
from _truths import TRUTHS, spec_of
from tqdm.auto import tqdm

from identification.instruments.tunnel import run_tunnel
from identification.methods import ml, rollspace
from identification.model import damping

VARIANTS = ("quantised", "white", "exact")
LEVELS = np.linspace(-20.0, 20.0, 9)


def offsets(truth: str, seed: int) -> list[float]:
    """a(θ) offset of the θ-model fit of one seed, per variant."""
    spec = spec_of(truth, seed)
    if spec.no_encoder or not spec.encoder_counts:
        raise SystemExit(f"--truth {truth}: needs an encoder")
    q = 360.0 / spec.encoder_counts
    quantised = run_tunnel(spec)
    exact = run_tunnel(replace(spec, encoder_counts=0))
    assert exact.roll_deg is not None
    noise = np.random.default_rng(1000 + seed).standard_normal(exact.n_samples) * q / math.sqrt(12)
    white = replace(exact, roll_deg=np.asarray(exact.roll_deg) + noise)
    out = []
    for variant, rec in zip(VARIANTS, (quantised, white, exact), strict=True):
        if variant == "white":  # the filter told the resolution the noise stands for
            with mock.patch.object(rollspace, "quantum_of", lambda values: q):
                found = ml.maximum_likelihood(rec, "theta")
        else:
            found = ml.maximum_likelihood(rec, "theta")
        diff = damping(found.params, LEVELS) - damping(spec.params(), LEVELS)
        out.append(float(np.mean(diff)))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="benchmarks/ml_bias.py", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--seeds", type=int, default=40, help="paired seeds (default 40)")
    parser.add_argument("--truth", default="paper", choices=[t for t in TRUTHS if t != "gyro"])
    ns = parser.parse_args(argv)
    if ns.seeds < 2:
        parser.error("--seeds must be at least 2")
    rows = np.array(
        [offsets(ns.truth, seed) for seed in tqdm(range(ns.seeds), desc=ns.truth, unit="seed")]
    )
    se = rows.std(axis=0, ddof=1) / math.sqrt(ns.seeds)
    print(f"\ntruth {ns.truth}, seeds 0-{ns.seeds - 1}: a(θ) offset over θ = -20..20°, 1/s")
    over = f"seeds 0-{ns.seeds - 1}, mean of â(θ) - a(θ) over θ = -20..20°"
    for k, name in enumerate(VARIANTS):
        print(f"  {name:10s} {rows[:, k].mean():+.4f} ± {se[k]:.4f}")
        emit(
            f"{ns.truth}, {name}: a(θ) offset",
            float(rows[:, k].mean()),
            "1/s",
            note=f"± {se[k]:.4f} 1/s SEM; {over}",
        )
    for a, b in ((0, 1), (1, 2)):
        d = rows[:, a] - rows[:, b]
        d_se = d.std(ddof=1) / math.sqrt(ns.seeds)
        print(f"  {VARIANTS[a]} - {VARIANTS[b]:9s} {d.mean():+.4f} ± {d_se:.4f} (paired)")
        emit(
            f"{ns.truth}, {VARIANTS[a]} - {VARIANTS[b]}: a(θ) offset difference",
            float(d.mean()),
            "1/s",
            note=f"± {d_se:.4f} 1/s SEM, paired; {over}",
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
