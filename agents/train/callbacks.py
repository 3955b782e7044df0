"""The held-out evaluation during training: the same seeded test-split episodes at every
evaluation, deterministic actions, the mean return and the RMS true tracking error."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np


# ----------------------------------------------------------------------------- evaluation
def make_eval_callback_class() -> type:
    """:class:`HeldOutEval`, built lazily so importing this module does not import SB3."""
    from stable_baselines3.common.callbacks import EvalCallback

    class HeldOutEval(EvalCallback):
        """SB3's ``EvalCallback`` on the test split, logging the RMS true tracking error.

        Every evaluation runs the same episodes (the adapter is reseeded with
        ``seed`` first).  No best model is saved: the run's result is the final
        model, and the test split is never used to select one.
        """

        def __init__(self, eval_env: Any, adapter: Any, seed: int, **kwargs: Any) -> None:
            super().__init__(eval_env, best_model_save_path=None, **kwargs)
            self.adapter = adapter
            self.eval_seed = seed
            self.history: list[tuple[int, float, float]] = []
            self._sq = 0.0
            self._count = 0

        def continue_from(self, steps: int) -> None:
            """Take over the evaluations a run resumed at ``steps`` already logged in this
            folder (those up to ``steps``), so that resuming keeps them."""
            import numpy as np

            if self.log_path is None:
                return
            folder = Path(self.log_path).parent
            npz = folder / "evaluations.npz"
            if npz.is_file():
                with np.load(npz) as saved:
                    keep = saved["timesteps"] <= steps
                    self.evaluations_timesteps = saved["timesteps"][keep].tolist()
                    self.evaluations_results = saved["results"][keep].tolist()
                    self.evaluations_length = saved["ep_lengths"][keep].tolist()
            csv_path = folder / "tracking_error.csv"
            if csv_path.is_file():
                rows = csv_path.read_text(encoding="utf-8").splitlines()[1:]
                for row in rows:
                    t, r, e = row.split(",")
                    if int(t) <= steps:
                        self.history.append((int(t), float(r), float(e)))

        def _on_step(self) -> bool:
            evaluating = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
            if evaluating:
                self.adapter.seed(self.eval_seed)
                self._sq, self._count = 0.0, 0
            result: bool = super()._on_step()
            if evaluating:
                rms = math.sqrt(self._sq / max(self._count, 1))
                self.history.append((self.num_timesteps, self.last_mean_reward, rms))
                if self.log_path is not None:
                    _write_history(Path(self.log_path).parent / "tracking_error.csv", self.history)
                if self.verbose >= 1:
                    print(f"Eval RMS tracking error (test split): {rms:.3f}")
            return result

        def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
            super()._log_success_callback(locals_, globals_)
            error = float(locals_["info"]["tracking_error"])
            self._sq += error * error
            self._count += 1
            if locals_["done"]:  # the latest value is what the logger dumps
                self.logger.record("eval/rms_tracking_error", math.sqrt(self._sq / self._count))

    return HeldOutEval


def _write_history(path: Path, history: list[tuple[int, float, float]]) -> None:
    lines = ["timesteps,mean_reward,rms_tracking_error"]
    lines += [f"{t},{r!r},{e!r}" for t, r, e in history]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def evaluate_held_out(model: Any, eval_env: Any, adapter: Any, seed: int) -> dict[str, float]:
    """Deterministic episodes of ``eval_env`` (one per env of ``adapter``), seeded with ``seed``.

    Returns the mean return (raw rewards) and the RMS of the true tracking
    error over every step of every episode.
    """
    from stable_baselines3.common.evaluation import evaluate_policy

    sq = [0.0, 0.0]

    def collect(locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        error = float(locals_["info"]["tracking_error"])
        sq[0] += error * error
        sq[1] += 1

    adapter.seed(seed)
    rewards, _ = evaluate_policy(
        model,
        eval_env,
        n_eval_episodes=adapter.num_envs,
        deterministic=True,
        return_episode_rewards=True,
        callback=collect,
    )
    return {
        "episodes": float(len(rewards)),  # type: ignore[arg-type]
        "mean_reward": float(np.mean(rewards)),
        "rms_tracking_error": math.sqrt(sq[0] / max(sq[1], 1.0)),
    }
