"""A learned memory against the explicit one: sb3-contrib's RecurrentPPO (an LSTM in place of a
recipe's observation history) on a PPO recipe's env stack and reward, scored as it trains.

The toolkit's learned policies are MLPs given their memory by hand (the last observations
and actions, :mod:`agents.memory`).  This probe trains the recurrent policy Stable-Baselines3's
contrib package offers on the same environments, with the same reward, normalisation and
PPO keywords as the recipe (``--hyperparams``'s entry for ``--env-id``, its ``history``
dropped), with its own rollout layout (``--envs``, ``--n-steps``, ``--batch``: the LSTM's
sequences make small minibatches slow).  Every ``--every`` env-steps the clock stops and the
deterministic policy, its LSTM state carried through each episode, is scored on the
protocol (``--split``'s episodes, train by default: a recipe is chosen on them; the PID is
measured in the same run on the same episodes).  It is a probe: a RecurrentPPO run is not a
``rocketroll train`` recipe and ``--policy`` does not load it.  Needs ``sb3-contrib`` (dev
extra).  Exit status 0 whatever the numbers; 2 with one line on bad input.

Run from the repository root::

    .venv/bin/python benchmarks/recurrent_probe.py --seed 1 --timesteps 6000000 \\
        --envs 64 --n-steps 128 --batch 2048 --every 1000000
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import torch
from _records import emit
from stable_baselines3.common.callbacks import BaseCallback

from agents.evaluate import evaluate, headline_scores, protocol_episodes
from agents.registry import make_controller
from agents.train import algorithm_arguments, load_hyperparameters, make_env, quiet_logger
from rocketroll_common.errors import UsageError
from rocketroll_common.tables import markdown_table
from rollenv.bank import load_bank, variant_config


class RecurrentController:
    """A RecurrentPPO policy as a protocol controller: the training normalisation's statistics
    frozen at the moment of scoring, the LSTM state carried through the episode."""

    name = "RecurrentPPO"

    def __init__(self, model: Any, normalize: Any) -> None:
        self.model = model
        rms = normalize.obs_rms
        self.mean, self.scale = rms.mean.copy(), np.sqrt(rms.var + normalize.epsilon)
        self.clip = float(normalize.clip_obs)
        self.state: Any = None
        self.start = np.ones(1, dtype=bool)

    def reset(self, env: Any) -> None:
        self.state, self.start = None, np.ones(1, dtype=bool)

    def act(self, obs: np.ndarray, env: Any) -> np.ndarray:
        seen = (np.asarray(obs, np.float64) - self.mean) / self.scale
        seen = np.clip(seen, -self.clip, self.clip)
        action, self.state = self.model.predict(
            seen.astype(np.float32).reshape(1, -1),
            state=self.state,
            episode_start=self.start,
            deterministic=True,
        )
        self.start[:] = False
        return np.asarray(action, dtype=np.float32).reshape(1)


class Scorer(BaseCallback):
    """Every ``every`` env-steps: the clock stops, the policy is scored."""

    def __init__(self, every: int, score: Any, normalize: Any) -> None:
        super().__init__()
        self.every, self.score, self.normalize = every, score, normalize
        self.next = every
        self.paused = 0.0
        self.curve: list[tuple[int, float]] = []

    def _on_rollout_end(self) -> None:
        if self.num_timesteps < self.next:
            return
        self.next += self.every
        stopped = time.perf_counter()
        self.curve.append((self.num_timesteps, self.score(self.model, self.normalize)))
        self.model.policy.set_training_mode(True)
        print(f"  {self.num_timesteps:>12,} env-steps: {self.curve[-1][1]:.2f}", flush=True)
        self.paused += time.perf_counter() - stopped

    def _on_step(self) -> bool:
        return True


def _refuse(message: str) -> NoReturn:
    print(f"recurrent_probe.py: {message}", file=sys.stderr)
    raise SystemExit(2)


def _positive(text: str) -> int:
    try:
        value = int(float(text))
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default="RocketRoll-v0", help="environment id")
    parser.add_argument(
        "--hyperparams",
        type=Path,
        default=Path("agents/hyperparams/ppo-history.yml"),
        help="the PPO recipe whose env stack, reward and keywords to train with",
    )
    parser.add_argument("--seed", type=int, default=0, help="training seed (0)")
    parser.add_argument("--timesteps", type=_positive, default=6_000_000, help="env-steps")
    parser.add_argument("--envs", type=_positive, default=64, help="environments (64)")
    parser.add_argument("--n-steps", type=_positive, default=128, help="rollout length (128)")
    parser.add_argument("--batch", type=_positive, default=2048, help="minibatch size (2048)")
    parser.add_argument("--lstm", type=_positive, default=64, help="LSTM hidden size (64)")
    parser.add_argument("--every", type=_positive, default=1_000_000, help="env-steps a score")
    parser.add_argument("--episodes", type=_positive, default=20, help="protocol episodes")
    parser.add_argument("--split", choices=("train", "test"), default="train", help="(train)")
    parser.add_argument("--torch-threads", type=_positive, default=1, help="(1)")
    args = parser.parse_args(argv)
    try:
        from sb3_contrib import RecurrentPPO
    except ImportError:
        _refuse("needs sb3-contrib (pip install sb3-contrib; the dev extra has it)")
    if (args.envs * args.n_steps) % args.batch:
        _refuse(
            f"--envs {args.envs} x --n-steps {args.n_steps} is not a multiple of --batch "
            f"{args.batch}"
        )
    try:
        hp = load_hyperparameters(args.hyperparams, args.env_id)
    except UsageError as exc:
        _refuse(str(exc))
    if hp.layout.observer or hp.layout.incremental or hp.layout.flight_clock or hp.layout.integral:
        _refuse(f"--hyperparams {args.hyperparams}: the probe takes a recipe of history alone")
    hp = dataclasses.replace(hp, layout=dataclasses.replace(hp.layout, history=0))
    torch.set_num_threads(args.torch_threads)

    config = variant_config(args.env_id, {"split": args.split})
    bank = load_bank(config, None)
    specs = protocol_episodes(config, args.episodes, 0, bank=bank)

    def score_controller(controller: Any) -> float:
        return float(headline_scores(evaluate(config, controller, specs, bank=bank)).mean())

    def score(model: Any, normalize: Any) -> float:
        return score_controller(RecurrentController(model, normalize))

    unit = "°" if config.task == "angle" else "°/s"
    pid = score_controller(make_controller("pid", config, args.env_id))
    print(f"{args.env_id}: headline on {args.episodes} {args.split} episodes (seed 0)")
    print(f"  PID {pid:.2f} {unit}")
    emit("PID headline (same run)", pid, unit, note=f"{args.episodes} {args.split} episodes")
    kwargs = algorithm_arguments(hp)
    kwargs.update(n_steps=args.n_steps, batch_size=args.batch)
    policy_kwargs = dict(kwargs.pop("policy_kwargs", {}) or {})
    policy_kwargs.update(lstm_hidden_size=args.lstm, enable_critic_lstm=False, shared_lstm=False)
    _, venv, normalize = make_env(hp, args.envs, args.seed, split="train")
    if normalize is None:
        _refuse(f"--hyperparams {args.hyperparams}: the probe needs normalize: true")
    model = RecurrentPPO(
        "MlpLstmPolicy",
        venv,
        seed=args.seed,
        device="cpu",
        policy_kwargs=policy_kwargs,
        **kwargs,
    )
    print(
        f"RecurrentPPO (LSTM {args.lstm}), {args.envs} envs x {args.n_steps} steps, batch "
        f"{args.batch}, seed {args.seed}, {hp.source}'s reward and keywords:"
    )
    model.set_logger(quiet_logger())
    scorer = Scorer(args.every, score, normalize)
    began = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=scorer)
    train_s = time.perf_counter() - began - scorer.paused
    venv.close()
    if not scorer.curve or scorer.curve[-1][0] != model.num_timesteps:
        scorer.curve.append((model.num_timesteps, score(model, normalize)))
    cells = ", ".join(f"{n / 1e6:g} M: {h:.2f}" for n, h in scorer.curve)
    print()
    rate = model.num_timesteps / train_s
    header = ["seed", "env-steps/s", f"headline ({unit}) at each env-step count", "PID"]
    print(
        "\n".join(markdown_table(header, [[str(args.seed), f"{rate:,.0f}", cells, f"{pid:.2f}"]]))
    )
    emit(
        f"seed {args.seed}: env-steps/s",
        rate,
        "env-steps/s",
        note=f"{model.num_timesteps:,} env-steps in {train_s:.1f} s, scoring not counted",
    )
    (last, final), (best_at, best) = scorer.curve[-1], min(scorer.curve, key=lambda c: c[1])
    emit(f"seed {args.seed}: headline at {last / 1e6:g} M", final, unit, note=cells)
    emit(
        f"seed {args.seed}: best headline",
        best,
        unit,
        note=f"at {best_at / 1e6:g} M env-steps; the PID's {pid:.2f}{unit}",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
