"""``rocketroll env``: run RocketRoll episodes from the shell and save rendered frames."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, setting
from rocketroll_common.tables import Column, text_table
from rollenv import task_of

__all__ = ["COMMANDS", "AscentArgs", "RolloutArgs", "rollout", "show_ascent"]

POLICIES = ("zero", "random")


def rollout(
    env_id: str,
    policy: str,
    episodes: int,
    seed: int,
    settings: dict[str, Any],
    frames_path: Path | None = None,
    frames: int = 6,
    db: str | Path | None = None,
) -> list[dict[str, float]]:
    """Run ``episodes`` episodes of ``env_id`` under ``policy``; one summary per episode.

    ``policy`` is ``"zero"`` (fins at 0°: open loop) or ``"random"`` (uniform
    actions from a generator seeded with ``seed``).  With ``frames_path`` the
    first episode is rendered and ``frames`` frames, evenly spaced over it,
    are saved side by side as one PNG.
    """
    import gymnasium as gym

    import rollenv  # noqa: F401  (registers the ids)

    if policy not in POLICIES:
        raise UsageError(f"--policy must be one of {', '.join(POLICIES)}, not {policy!r}")
    kwargs = dict(settings)
    if db is not None:
        kwargs["db"] = db
    try:
        env = gym.make(env_id, render_mode="rgb_array" if frames_path else None, **kwargs)
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    rng = np.random.default_rng(seed)
    summaries = []
    strip: list[np.ndarray] = []
    try:
        for episode in range(episodes):
            _, info = env.reset(seed=seed if episode == 0 else None)
            steps = env.unwrapped.config.max_episode_steps  # type: ignore[attr-defined]
            wanted = (
                set(np.linspace(0, steps, frames).round().astype(int).tolist())
                if frames_path is not None and episode == 0
                else set()
            )
            total, sq_error, u_abs, travel, n = 0.0, 0.0, 0.0, 0.0, 0
            fin = info["fin_deg"]
            if 0 in wanted:
                strip.append(np.asarray(env.render()))
            done = False
            while not done:
                action = (
                    np.zeros(1, dtype=np.float32)
                    if policy == "zero"
                    else rng.uniform(-1.0, 1.0, size=1).astype(np.float32)
                )
                _, reward, terminated, truncated, info = env.step(action)
                n += 1
                total += float(reward)
                sq_error += info["tracking_error"] ** 2
                u_abs += abs(info["u_d_deg"])
                travel += abs(info["fin_deg"] - fin)
                fin = info["fin_deg"]
                if n in wanted:
                    strip.append(np.asarray(env.render()))
                done = terminated or truncated
            duration = n * env.unwrapped.config.dt_s  # type: ignore[attr-defined]
            summaries.append(
                {
                    "episode": float(episode),
                    "steps": float(n),
                    "return": total,
                    "rms_error": math.sqrt(sq_error / n),
                    "mean_abs_u_d_deg": u_abs / n,
                    "fin_travel_dps": travel / duration,
                    "trace": info["trace"],
                    "start_s": info["start_s"],
                }
            )
    finally:
        env.close()
    if frames_path is not None and strip:
        _save_strip(strip, frames_path)
    return summaries


def _save_strip(frames: list[np.ndarray], path: Path) -> None:
    """Frames side by side in rows of three, one PNG, written atomically."""
    import matplotlib.image

    from rocketroll_common.files import write_atomic

    per_row = min(3, len(frames))
    rows = -(-len(frames) // per_row)
    h, w, _ = frames[0].shape
    canvas = np.full((rows * h, per_row * w, 3), 255, dtype=np.uint8)
    for k, frame in enumerate(frames):
        r, c = divmod(k, per_row)
        canvas[r * h : (r + 1) * h, c * w : (c + 1) * w] = frame
    buffer = io.BytesIO()
    matplotlib.image.imsave(buffer, canvas, format="png")
    write_atomic(path, buffer.getvalue())


def _variant_ids() -> tuple[str, ...]:
    from rollenv import variant_ids

    return variant_ids()


@dataclass(frozen=True)
class RolloutArgs:
    """``rocketroll env rollout``."""

    env_id: str = setting(
        "RocketRoll-v0", "environment id", flag="--id", choices=_variant_ids, metavar="ID"
    )
    policy: Literal["zero", "random"] = setting("random", "policy")
    episodes: int = setting(3, "episodes", ge=1, le=100_000)
    seed: int = setting(0, "seed of the env and the policy", ge=0, le=2**63 - 1)
    frames: Path | None = setting(
        None, "save frames of the first episode to this PNG", output="file", kind="png"
    )
    frames_count: int = setting(6, "frames in the PNG", ge=1, le=100)
    db: str | None = setting(
        None, "database (default: the default database)", metavar="DB", input=True, kind="sqlite"
    )
    set: dict[str, Any] = setting(
        default_factory=dict,
        help="environment option, e.g. --set split=test --set sensors=false (repeatable)",
        metavar="KEY=VALUE",
    )

    def __post_init__(self) -> None:
        check(self)


def run_rollout(args: RolloutArgs) -> int:
    """Run the episodes, print one line each, save the frames."""
    summaries = rollout(
        args.env_id,
        args.policy,
        args.episodes,
        args.seed,
        dict(args.set),
        frames_path=args.frames,
        frames=args.frames_count,
        db=args.db,
    )
    unit = "°/s" if task_of(args.env_id) == "rate" else "°"
    print(f"{args.env_id}, policy {args.policy}, seed {args.seed}")
    columns = (
        Column("episode", 7),
        Column("steps", 6, gap=" "),
        Column("return", 10, gap=" "),
        Column("RMS error", 11, gap=" "),
        Column("fin travel", 12, gap=" "),
        Column("mean |u_d|", 11, gap=" "),
        Column("trace (start)", gap="  "),
    )
    rows = [
        [
            str(int(s["episode"])),
            str(int(s["steps"])),
            f"{s['return']:.1f}",
            f"{s['rms_error']:>8.2f} {unit:<2}",
            f"{s['fin_travel_dps']:>8.1f} °/s",
            f"{s['mean_abs_u_d_deg']:>9.2f} °",
            f"{s['trace']} ({s['start_s']:g} s)",
        ]
        for s in summaries
    ]
    print("\n".join(text_table(columns, rows)))
    if args.frames is not None:
        print(f"frames: {args.frames}")
    return 0


@dataclass(frozen=True)
class AscentArgs:
    """``rocketroll env ascent``."""

    flight: str = setting(
        "default",
        "the ascent: 'default', 'supersonic' (Mach 1.04 on a bigger motor), a rocket YAML "
        "(identification/data/ascent-default.yml's keys) or a recorded V(t) CSV (time_s, "
        "airspeed_mps[, altitude_m])",
        metavar="FLIGHT",
        input=True,
    )
    plot: Path | None = setting(
        None, "save V, h, q and Mach against time to this PNG", output="file", kind="png"
    )

    def __post_init__(self) -> None:
        check(self)


def show_ascent(args: AscentArgs) -> int:
    """Print the flight's summary and what it does to the roll model; plot it."""
    from rollenv.flight import flight_schedule

    try:
        schedule = flight_schedule(args.flight, 0.1, 0.01)
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    profile = schedule.profile
    gain, damping = schedule.scales[:, 0], schedule.scales[:, 1]
    print(profile.source)
    print(
        f"  max {profile.max_speed_mps * 3.6:.0f} km/h ({profile.max_speed_mps:.1f} m/s, Mach "
        f"{profile.max_mach:.2f}), max q {profile.max_dynamic_pressure_pa / 1e3:.1f} kPa, "
        f"burnout {profile.burnout_s:.2f} s, apogee {profile.apogee_m:.0f} m at "
        f"{profile.apogee_s:.2f} s"
    )
    print(
        f"  episode: {schedule.steps} control steps from {schedule.start_s:.2f} s "
        f"({schedule.v_ref_mps * 3.6:.0f} km/h) to apogee; the roll model's gain x "
        f"{gain.max():.2f} and damping x {damping.max():.2f} at most (eq. 4-8)"
    )
    if args.plot is not None:
        from rocketroll_common.files import write_atomic
        from rocketroll_common.plotting import png_bytes
        from rocketroll_physics.ascent import plot_profile

        write_atomic(args.plot, png_bytes(plot_profile(profile), dpi=110))
        print(f"plot: {args.plot}")
    return 0


#: The commands of this layer, by name.
COMMANDS: dict[str, Command] = {
    "env": Command(
        "env",
        "run RocketRoll episodes (Gymnasium environment)",
        description=__doc__ or "",
        subcommands=(
            Command(
                "rollout",
                "run episodes with a zero or random policy; print a summary; save frames",
                RolloutArgs,
                run_rollout,
            ),
            Command(
                "ascent",
                "the ascent a flight variant flies (RocketRollFlight-v0): summary and plot",
                AscentArgs,
                show_ascent,
                aliases=("flight",),
            ),
        ),
    )
}
