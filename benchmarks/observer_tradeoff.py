"""What the observer-based controller's LQR can reach at all: error against fin travel.

A deployable controller learns each control step's ``u_d`` only from the rate
that step leaves behind; the part of ``u_d`` its AR model cannot predict (the
innovation) acts in full before any fin can answer.  This script simulates the
design's own linear model -- the nominal rocket of the train split at trim,
the secant servo of :meth:`agents.observer.ObserverController._design`, the
train split's AR turbulence -- with *perfect* sensors and the true AR model,
for a range of fin-move weights, and prints the RMS angle error (zero
setpoint) against the fin travel.  No sensor noise, no model error, no
quantisation: a floor for the observer's scores in ``rocketroll eval``, and
the reason its error cannot reach a given level within a given fin travel.

Run from the repository root::

    .venv/bin/python benchmarks/observer_tradeoff.py                   # default replay
    .venv/bin/python benchmarks/observer_tradeoff.py --method paper    # the paper's
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np
from _records import emit

from agents.observer import ObserverController, make_observer
from agents.registry import Design
from rocketroll_common.tables import markdown_table
from rollenv.bank import variant_config


def simulate(controller: ObserverController, steps: int, seed: int) -> tuple[float, float]:
    """RMS angle error (°) and fin travel (°/s) of the linear design model under the
    controller's gain, ``u_d[k]`` unknown when the command of step ``k`` is chosen."""
    ob = controller.observer
    trim = -controller.rocket.theta_bar_deg
    t_rest, c_rest = ob.step_model(trim, trim)
    move = max(controller.turbulence.innovation_sd, 0.1)
    _, c_moved = ob.step_model(trim, trim + move)
    to_command = [(c_moved[r] - c_rest[r]) / move for r in (0, 1)]
    to_u = [t_rest[0, 2], t_rest[1, 2]]
    ar, gain = ob.ar, controller.gain
    sd = controller.turbulence.innovation_sd
    rng = np.random.default_rng(seed)
    v = psi = fin = 0.0
    lags = np.zeros(ar.size)
    angles, moves = np.empty(steps), np.empty(steps)
    for k in range(steps):
        predicted = float(ar @ lags)
        state = np.concatenate([[v, psi, predicted], lags[:-1], [0.0, fin]])
        command = float(gain @ state)
        u = predicted + sd * rng.standard_normal()
        v, psi = (
            t_rest[0, 0] * v
            + to_command[0] * command
            + (to_u[0] - to_command[0]) * fin
            + to_u[0] * u,
            psi
            + t_rest[1, 0] * v
            + to_command[1] * command
            + (to_u[1] - to_command[1]) * fin
            + to_u[1] * u,
        )
        moves[k] = abs(command - fin)
        fin = command
        lags = np.concatenate([[u], lags[:-1]])
        angles[k] = psi
    return float(np.sqrt(np.mean(angles[100:] ** 2))), float(moves.mean() / ob.h / ob.per)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--method", default="ml", help="replay of the train split (ml, paper)")
    parser.add_argument("--steps", type=int, default=30_000, help="control steps simulated")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--moves",
        type=float,
        nargs="+",
        default=[1e-2, 5e-3, 3e-3, 1e-3, 3e-4, 1e-4],
        help="fin-move weights of the LQR cost",
    )
    args = parser.parse_args(argv)
    config = variant_config("RocketRoll-v0", {"method": args.method, "setpoint": "zero"})
    base = make_observer(Design(config, "RocketRoll-v0"))
    t = base.turbulence
    print(f"train split of {args.method}: {t.source}, AR {np.round(t.ar, 3).tolist()}, ")
    print(f"  innovation {t.innovation_sd:.2f}° per {t.dt_s:g}-s step; perfect sensors")
    rows = []
    for weight in args.moves:
        controller = ObserverController(config, base.rocket, t, {"move": weight})
        rms, travel = simulate(controller, args.steps, args.seed)
        rows.append([f"{weight:g}", f"{rms:.3f}", f"{travel:.1f}"])
        setting = f"{args.method} replay, move weight {weight:g}"
        note = f"perfect sensors, {args.steps} steps, seed {args.seed}"
        emit(f"{setting}: RMS angle error", rms, "°", note=note)
        emit(f"{setting}: fin travel", travel, "°/s", note=note)
    header = ["move weight", "RMS angle error (°)", "fin travel (°/s)"]
    print("\n".join(markdown_table(header, rows)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
