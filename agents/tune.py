"""Re-tuning a controller's design on train episodes: ``rocketroll tune pid``.

The PID's gains are placed on a nominal rocket (:meth:`agents.pid.PIDGains.place`);
what is left to choose is the closed-loop bandwidth ω.  :func:`tune_bandwidth`
sweeps it over *train*-split episodes of the evaluation protocol -- tuning
never sees the test split -- and ``rocketroll tune pid`` (or ``python -m
agents.tune``) prints each ω's metrics and the gains of the best one, to pass
back with ``rocketroll eval --policy pid:OMEGA``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

from agents.evaluate import (
    HEADLINE,
    evaluate,
    protocol_episodes,
)
from agents.nominal import NominalModel
from agents.pid import PIDController, PIDGains
from agents.replay import (
    check_options,
    db_setting,
    env_options_setting,
    recording_setting,
    replay_config,
)
from rocketroll_common.settings import Command, check, run_command, setting
from rollenv import variant_ids
from rollenv.bank import find_bank
from rollenv.config import RollConfig

__all__ = ["COMMAND", "TuneArgs", "tune", "tune_bandwidth"]


def tune_bandwidth(
    config: RollConfig,
    model: NominalModel,
    omegas: Sequence[float],
    *,
    episodes: int = 30,
    seed: int = 0,
    db: str | None = None,
    zeta: float = 1.0,
    tf_s: float = 0.0,
) -> list[tuple[float, dict[str, float]]]:
    """``(ω, mean of each protocol metric)`` for each ``ω`` on train-split protocol episodes.

    The evaluation protocol's episodes are drawn with ``split`` forced to
    ``"train"``, so tuning never sees the test split.
    """
    config = replace(config, split="train")
    specs = protocol_episodes(config, episodes=episodes, seed=seed, db=db)
    out = []
    for omega in omegas:
        pid = PIDController.scheduled(config, model, omega, zeta, tf_s)  # fixed in the tunnel
        result = evaluate(config, pid, specs, db=db)
        out.append((float(omega), {k: v["mean"] for k, v in result.aggregate.items()}))
    return out


@dataclass(frozen=True)
class TuneArgs:
    """``rocketroll tune pid`` / ``python -m agents.tune``."""

    env_id: str = setting("RocketRoll-v0", "environment id", choices=variant_ids, always=True)
    db: str | None = db_setting()
    episodes: int = setting(30, "train episodes per ω", ge=1, le=100_000)
    seed: int = setting(0, "seed of the train episodes", ge=0, le=2**63 - 1)
    omegas: tuple[float, ...] = setting(
        (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 8.0, 10.0),
        "closed-loop bandwidths to try, rad/s (comma-separated)",
        gt=0.0,
        le=1000.0,
    )
    metric: Literal["regulation_rms_error", "settled_rms_error", "rms_error", "return"] = setting(
        HEADLINE,
        "what the best ω optimises (default: the protocol's headline, the RMS error once each "
        "setpoint step has been made; the plain rms_error is mostly the steps' slews, which "
        "the rocket, not the bandwidth, sets)",
    )
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()

    def __post_init__(self) -> None:
        check(self)
        check_options(self.settings)


def tune(args: TuneArgs) -> int:
    """Re-tune the PID for a database and print the gains."""
    from agents.base import Design
    from disturbances.bank import BankError

    try:
        config, _, _, note = replay_config(
            args.env_id, args.settings, args.recording, "train", args.db
        )
    except BankError:
        if args.recording is None and "recording" not in args.settings:
            raise
        # no part of the recording in the train split: its rockets, as the designs read
        others = {k: v for k, v in args.settings.items() if k != "recording"}
        config, _, _, note = replay_config(args.env_id, others, None, "train", args.db)
        replayed = args.recording or args.settings["recording"]
        print(f"  {replayed} has no part in the train split: tuned on the train split's rockets")
    else:
        replayed = config.recording
    if note:
        print(note)
    task = config.task
    # The rocket eval's PID is placed on: its design bank (the train split, or the part of
    # the replayed recording there).
    model = NominalModel.from_bank(Design(config, args.env_id, db=args.db).train_bank)
    print(f"nominal model: {model.source}")
    print(f"  a = {model.a_per_s:.4g} 1/s, α = {model.alpha:.4g}, θ̄ = {model.theta_bar_deg:.4g}°")
    results = tune_bandwidth(
        config, model, args.omegas, episodes=args.episodes, seed=args.seed, db=args.db
    )
    unit = "°" if task == "angle" else "°/s"
    print(f"  ω (rad/s)  regulation RMS ({unit})  RMS error ({unit})  settled RMS ({unit})  return")
    for omega, m in results:
        print(
            f"  {omega:9.2f}  {m[HEADLINE]:19.4f}  {m['rms_error']:14.4f}  "
            f"{m['settled_rms_error']:16.4f}  {m['return']:8.1f}"
        )
    sign = -1.0 if args.metric == "return" else 1.0
    best = min(results, key=lambda r: sign * r[1][args.metric])[0]
    gains = PIDGains.place(model, task, best)
    where = " (at the tunnel's airspeed; in flight scheduled on q)" if config.flight else ""
    print(
        f"best ω by {args.metric} = {best:g} rad/s: kp = {gains.kp:.4g}, ki = {gains.ki:.4g}, "
        f"kd = {gains.kd:.4g}, k_ff = {gains.k_ff:.4g}, trim = {gains.trim_deg:.4g}°{where}"
    )
    # the user's own --set options: eval fits its episode to the held-out trace itself
    same = "".join(f" --set {k}={v}" for k, v in args.settings.items() if k != "recording")
    same += f" --db {args.db}" if args.db is not None else ""
    held = (
        None
        if replayed is None
        else find_bank(replace(config, recording=replayed, split="test"), args.db)
    )
    if held is not None:
        same += f" --recording {replayed}"  # its held-out part, where eval replays
    print(f"use it with: rocketroll eval --env-id {args.env_id} --policy pid:{best:g}{same}")
    return 0


#: ``rocketroll tune pid``.
COMMAND = Command(
    "pid",
    "sweep the PID's bandwidth ω over train episodes and print the best gains",
    TuneArgs,
    tune,
    __doc__ or "",
)

if __name__ == "__main__":
    sys.exit(run_command(COMMAND, sys.argv[1:], "python -m agents.tune"))
