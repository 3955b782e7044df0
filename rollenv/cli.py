"""``rocketroll env``: run RocketRoll episodes from the shell and save rendered frames."""

from __future__ import annotations

import argparse
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from rocketroll_common.errors import UsageError

__all__ = ["parse_setting", "register", "rollout"]

POLICIES = ("zero", "random")


def parse_setting(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` with VALUE read as a bool, int, float or string."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    value: Any = raw
    if raw.lower() in ("true", "false"):
        value = raw.lower() == "true"
    else:
        for kind in (int, float):
            try:
                value = kind(raw)
                break
            except ValueError:
                continue
    return key, value


def rollout(
    env_id: str,
    policy: str,
    episodes: int,
    seed: int,
    settings: dict[str, Any],
    frames_path: Path | None = None,
    frames: int = 6,
    db: Path | None = None,
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


def _cmd_rollout(ns: argparse.Namespace) -> int:
    if ns.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {ns.episodes}")
    if ns.frames_count < 1:
        raise UsageError(f"--frames-count must be >= 1, got {ns.frames_count}")
    settings = dict(ns.set or [])
    summaries = rollout(
        ns.env_id,
        ns.policy,
        ns.episodes,
        ns.seed,
        settings,
        frames_path=ns.frames,
        frames=ns.frames_count,
        db=ns.db,
    )
    unit = "°/s" if "Rate" in ns.env_id else "°"
    print(f"{ns.env_id}, policy {ns.policy}, seed {ns.seed}")
    print(
        f"{'episode':>7} {'steps':>6} {'return':>10} {'RMS error':>11} {'fin travel':>12} "
        f"{'mean |u_d|':>11}  trace (start)"
    )
    for s in summaries:
        print(
            f"{int(s['episode']):>7} {int(s['steps']):>6} {s['return']:>10.1f} "
            f"{s['rms_error']:>8.2f} {unit:<2} {s['fin_travel_dps']:>8.1f} °/s "
            f"{s['mean_abs_u_d_deg']:>9.2f} °  {s['trace']} ({s['start_s']:g} s)"
        )
    if ns.frames is not None:
        print(f"frames: {ns.frames}")
    return 0


def register(subparsers: Any) -> None:
    """Add ``rocketroll env ...`` to the top-level parser."""
    env = subparsers.add_parser(
        "env", help="run RocketRoll-v0 episodes (Gymnasium environment)", description=__doc__
    )
    sub = env.add_subparsers(dest="env_command", required=True, metavar="SUBCOMMAND")
    p = sub.add_parser(
        "rollout",
        help="run episodes with a zero or random policy; print a summary; save frames",
    )
    p.add_argument(
        "--id",
        dest="env_id",
        default="RocketRoll-v0",
        choices=("RocketRoll-v0", "RocketRollRate-v0"),
        help="environment id",
    )
    p.add_argument("--policy", choices=POLICIES, default="random", help="policy (random)")
    p.add_argument("--episodes", type=int, default=3, help="episodes (3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the env and the policy (0)")
    p.add_argument("--frames", type=Path, help="save frames of the first episode to this PNG")
    p.add_argument("--frames-count", type=int, default=6, help="frames in the PNG (6)")
    p.add_argument("--db", type=Path, help="database file (default: the default database)")
    p.add_argument(
        "--set",
        type=parse_setting,
        action="append",
        metavar="KEY=VALUE",
        help="environment option, e.g. --set split=test --set sensors=false (repeatable)",
    )
    p.set_defaults(handler=_cmd_rollout)
