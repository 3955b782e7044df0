"""Do the observer and the MPC gain by designing on the rig?  The headline with and without.

On each task (``--env-ids``) and each rig (``--rigs``: a servo lag, backlash, a
sensor latency, all three; each at ``--levels`` times the virtual tunnel's
mismatch levels: 50 ms, 0.5°, 30 ms), the environment replays the test split
with that rig (``--set servo_lag_s=... backlash_deg=... sensor_latency_s=...``)
and each controller runs the protocol's episodes (``--episodes``, seed 0):

* the PID (which knows no rig: the reference row);
* the observer and the MPC designed on the model's ideal rig (what they were
  before they read the rig);
* the observer and the MPC designed on the rig the environment flies (the
  default: ``rocketroll eval --set ...`` designs on the settings it is given);
* with ``--stated F,...``, designed on that rig with every value times ``F``
  (a user's bench figures off by ``F``).

Prints the headline (mean over the episodes, regulation RMS: ° on the angle
tasks, °/s on the rate task) per controller and rig, and per rig the verdict
on the target: a design on the rig at least as good as the ideal design
(within 2 % of it: the protocol's episodes are shared, so the difference is
paired) and, with ``--strict``, exit 1 where one is not.

Run from the repository root::

    .venv/bin/python benchmarks/rig_control.py                        # ~4 min
    .venv/bin/python benchmarks/rig_control.py --levels 1,1.5 --stated 0.8,1.2
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Sequence

import numpy as np
from _records import emit
from _truths import TRUTHS

from agents.base import Controller
from agents.evaluate import HEADLINE, evaluate, protocol_episodes
from agents.registry import make_controller
from identification.instruments.reference import Effects
from identification.model import Rig
from rocketroll_common.tables import markdown_table
from rollenv.bank import load_bank, variant_config
from rollenv.config import RollConfig

#: Rig cases -> the Rig fields they set (at the virtual tunnel's mismatch levels).
RIGS: dict[str, tuple[str, ...]] = {
    "none": (),
    "lag": ("lag_s",),
    "backlash": ("backlash_deg",),
    "latency": ("latency_s",),
    "all three": ("lag_s", "backlash_deg", "latency_s"),
}
#: How much worse than the ideal design a design on the rig may score (paired episodes).
TOLERANCE = 1.02


def level_rig(case: str, level: float) -> Rig:
    """The rig of ``case`` at ``level`` times the mismatch truths' levels."""
    mismatch = TRUTHS["mismatch-all"][1]["effects"]
    assert isinstance(mismatch, Effects)
    full = {
        "lag_s": mismatch.servo_lag_s,
        "backlash_deg": mismatch.backlash_deg,
        "latency_s": mismatch.latency_s,
    }
    return Rig(**{name: level * full[name] for name in RIGS[case]})


def scaled(rig: Rig, factor: float) -> Rig:
    """``rig`` with every value times ``factor``."""
    return Rig(**{f.name: factor * getattr(rig, f.name) for f in dataclasses.fields(rig)})


def designed(policy: str, config: RollConfig, env_id: str, rig: Rig) -> Controller:
    """``policy`` for ``config``, designed on ``rig`` whatever the environment flies."""
    return make_controller(policy, config.with_rig(rig), env_id)


def headlines(env_id: str, rig: Rig, stated: Sequence[float], episodes: int) -> dict[str, float]:
    """Each controller's mean headline on ``env_id`` flying ``rig``."""
    settings = {
        "split": "test",
        "servo_lag_s": rig.lag_s,
        "backlash_deg": rig.backlash_deg,
        "sensor_latency_s": rig.latency_s,
    }
    config = variant_config(env_id, settings)
    bank = load_bank(config, None)
    specs = protocol_episodes(config, episodes, 0, bank=bank)
    controllers = {"PID": make_controller("pid", config, env_id)}
    for policy in ("observer", "mpc"):
        controllers[f"{policy}, ideal rig"] = designed(policy, config, env_id, Rig())
        controllers[f"{policy}, on the rig"] = make_controller(policy, config, env_id)
        for factor in stated:
            controllers[f"{policy}, rig x{factor:g}"] = designed(
                policy, config, env_id, scaled(rig, factor)
            )
    return {
        name: float(np.mean([e[HEADLINE] for e in evaluate(config, c, specs, bank=bank).episodes]))
        for name, c in controllers.items()
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--env-ids",
        default="RocketRoll-v0,RocketRollRate-v0,RocketRollFlight-v0",
        help="tasks, comma separated",
    )
    parser.add_argument("--rigs", default=",".join(RIGS), help=f"of {', '.join(RIGS)}")
    parser.add_argument("--levels", default="1", help="multiples of the mismatch levels")
    parser.add_argument("--stated", default="", help="design rigs off by these factors")
    parser.add_argument("--episodes", type=int, default=20, help="protocol episodes per task")
    parser.add_argument("--strict", action="store_true", help="exit 1 if a target is missed")
    args = parser.parse_args(argv)
    cases = args.rigs.split(",")
    for case in cases:
        if case not in RIGS:
            parser.error(f"--rigs: unknown rig {case!r} (choose from {', '.join(RIGS)})")
    levels = [float(x) for x in args.levels.split(",")]
    stated = [float(x) for x in args.stated.split(",") if x]
    began = time.perf_counter()
    missed = judged = 0
    for env_id in args.env_ids.split(","):
        unit = "°/s" if "Rate" in env_id else "°"
        print(f"\n{env_id}: regulation RMS ({unit}), mean of {args.episodes} test episodes")
        rows: dict[str, dict[str, float]] = {}
        for case in cases:
            for level in [1.0] if case == "none" else levels:
                label = case if case == "none" else f"{case} x{level:g}"
                rows[label] = headlines(env_id, level_rig(case, level), stated, args.episodes)
                print(f"  {label}: done ({time.perf_counter() - began:.0f} s)", flush=True)
        names = list(next(iter(rows.values())))
        table = [[name, *(f"{r[name]:.3f}" for r in rows.values())] for name in names]
        print("\n".join(markdown_table(["controller", *rows], table)))
        for label, row in rows.items():
            for policy in ("observer", "mpc"):
                ideal, rigged = row[f"{policy}, ideal rig"], row[f"{policy}, on the rig"]
                ratio = rigged / ideal
                ok = ratio <= TOLERANCE
                missed += not ok
                judged += 1
                print(
                    f"  {label}, {policy}: on the rig {rigged:.3f} vs ideal {ideal:.3f} "
                    f"({ratio:.2f}x): {'met' if ok else 'MISSED'}"
                )
                emit(
                    f"{env_id}, {label}, {policy}: headline, design on the rig / on the ideal rig",
                    ratio,
                    "",
                    at_most=TOLERANCE,
                    note=f"on the rig {rigged:.3f} {unit}, ideal {ideal:.3f} {unit}, mean of "
                    f"{args.episodes} paired test episodes; target: within "
                    f"{100 * (TOLERANCE - 1):.0f} % of the ideal design",
                )
    print(f"\n{missed} targets missed; {time.perf_counter() - began:.0f} s")
    emit(
        "targets missed",
        missed,
        "",
        at_most=0,
        note=f"of {judged}: designs on the rig more than {100 * (TOLERANCE - 1):.0f} % "
        "worse than the ideal design" + ("" if args.strict else " (exit 0 without --strict)"),
    )
    return 1 if (missed and args.strict) else 0


if __name__ == "__main__":
    raise SystemExit(main())
