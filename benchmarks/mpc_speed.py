"""Is the MPC faster than real time?  Time per control step against the 10-ms target.

Runs the protocol's episodes (test split, ``--episodes``, seed 0) of both
tunnel tasks and the flight's angle task (scheduled: the first flight builds
each control step's QP, once per controller, which the worst time shows) with
the MPC (``--policy mpc``) and, as the reference measured in the same run and
on the same observations, the observer's LQR (``--policy observer``: the same
Kalman filter, no QP), timing each ``act`` call with ``time.perf_counter``.
Prints median, 99th percentile and worst time per
step, the QP's share (MPC minus LQR at the median) and the verdict against
the target: median under 10 ms, one tenth of the 0.1-s control period.

Run from the repository root::

    .venv/bin/python benchmarks/mpc_speed.py                  # 10 episodes per task
    .venv/bin/python benchmarks/mpc_speed.py --horizon 40 --strict
    .venv/bin/python benchmarks/mpc_speed.py --rig            # designed on a rig
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import numpy as np
from _records import emit

from agents.base import FlightView
from agents.evaluate import env_on, protocol_episodes
from agents.registry import make_controller
from rocketroll_common.tables import Column, text_table
from rollenv.bank import load_bank, variant_config

TARGET_MS = 10.0
#: One task and controller per line: its times per step (ms) and how many steps.
COLUMNS = (
    Column("task", 20, "<"),
    Column("controller", 10, "<", " "),
    Column("median", 8, ">", " "),
    Column("p99", 8, ">", " "),
    Column("worst", 8, ">", " "),
    Column("steps", 7, ">", " "),
)


def step_times(
    env_id: str, policy: str, episodes: int, settings: dict[str, float] | None = None
) -> np.ndarray:
    """Seconds per ``act`` call over the protocol's episodes (``settings``: the
    environment's, e.g. a rig the controllers then design on)."""
    config = variant_config(env_id, {"split": "test", **(settings or {})})
    bank = load_bank(config, None)
    controller = make_controller(policy, config, env_id)
    env = env_on(config, bank)
    times = []
    for spec in protocol_episodes(config, episodes, 0, bank=bank):
        obs, _ = env.reset(seed=spec.seed, options=spec.options())
        view = FlightView(env)
        controller.reset(view)
        truncated = False
        while not truncated:
            began = time.perf_counter()
            action = controller.act(obs, view)
            times.append(time.perf_counter() - began)
            obs, _, _, truncated, _ = env.step(action)
    return np.array(times)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10, help="protocol episodes per task")
    parser.add_argument("--horizon", type=int, default=None, help="MPC horizon (default 20)")
    parser.add_argument("--strict", action="store_true", help="exit 1 if the target is missed")
    parser.add_argument(
        "--rig",
        action="store_true",
        help="the environment with a servo lag, backlash and latency (50 ms, 0.5°, 30 ms), "
        "which the observer and the MPC design on (the lag's drive one more state)",
    )
    args = parser.parse_args(argv)
    settings = (
        {"servo_lag_s": 0.05, "backlash_deg": 0.5, "sensor_latency_s": 0.03} if args.rig else {}
    )
    mpc = "mpc" if args.horizon is None else f"mpc:{args.horizon}"
    missed = False
    rig = ", the rig of --rig" if args.rig else ""
    print(f"time per control step, {args.episodes} test episodes per task{rig} (ms)")
    print(text_table(COLUMNS, [])[0])
    for env_id in ("RocketRoll-v0", "RocketRollRate-v0", "RocketRollFlight-v0"):
        medians = {}
        for policy in ("observer", mpc):
            t = 1e3 * step_times(env_id, policy, args.episodes, settings)
            medians[policy] = float(np.median(t))
            emit(
                f"{env_id}, {policy}: median per step",
                medians[policy],
                "ms",
                at_most=TARGET_MS if policy == mpc else None,
                note=f"p99 {np.percentile(t, 99):.3f} ms, worst {t.max():.3f} ms, {t.size} steps",
            )
            cells = [
                env_id,
                policy,
                f"{np.median(t):.3f}",
                f"{np.percentile(t, 99):.3f}",
                f"{t.max():.3f}",
                str(t.size),
            ]
            print(text_table(COLUMNS, [cells])[1])
        qp = medians[mpc] - medians["observer"]
        ok = medians[mpc] < TARGET_MS
        missed |= not ok
        print(
            f"  {mpc}: median {medians[mpc]:.3f} ms vs target {TARGET_MS:.0f} ms: "
            f"{'met' if ok else 'MISSED'} ({TARGET_MS / medians[mpc]:.0f}x margin); "
            f"the QP adds {qp:.3f} ms to the observer's LQR ({medians['observer']:.3f} ms)"
        )
    return 1 if (missed and args.strict) else 0


if __name__ == "__main__":
    raise SystemExit(main())
