"""Checkpoints of a run: the model, its ``VecNormalize`` statistics and (off-policy) its
replay buffer, saved together and resumed together."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agents.memory import PolicyLayout
from agents.train.hyperparams import algorithm_class
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import interrupts_held

#: SB3's ``VecNormalize`` statistics of the final model (``VecNormalize.load(path, venv)``).
VECNORMALIZE_FILE = "vecnormalize.pkl"


def _normalization_file(checkpoint: Path, algo: str = "ppo") -> Path:
    """The ``VecNormalize`` pickle SB3's ``CheckpointCallback`` saves beside ``checkpoint``."""
    return checkpoint.with_name(
        checkpoint.name.replace(f"{algo}_", f"{algo}_vecnormalize_", 1)
    ).with_suffix(".pkl")


def _replay_buffer_file(checkpoint: Path, algo: str) -> Path:
    """The replay buffer SB3's ``CheckpointCallback`` saves beside an off-policy ``checkpoint``."""
    return checkpoint.with_name(
        checkpoint.name.replace(f"{algo}_", f"{algo}_replay_buffer_", 1)
    ).with_suffix(".pkl")


def _checkpoint(model: Any, normalize: Any, folder: Path, algo: str = "ppo") -> Path:
    """Save a resumable checkpoint as SB3's ``CheckpointCallback`` names them (the model,
    its ``VecNormalize`` statistics, and for SAC/TD3 the replay buffer), whole: a second
    Ctrl-C waits for it."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{algo}_{model.num_timesteps}_steps.zip"
    with interrupts_held():
        model.save(path)
        if normalize is not None:
            normalize.save(str(_normalization_file(path, algo)))
        if algo != "ppo":
            model.save_replay_buffer(_replay_buffer_file(path, algo))
    return path


def _statistics_file(checkpoint: Path, algo: str) -> Path:
    """The ``VecNormalize`` statistics of ``checkpoint``: the checkpoint's own, or a finished
    run's ``vecnormalize.pkl`` beside its ``model.zip`` (neither may exist)."""
    stats = _normalization_file(checkpoint, algo)
    return stats if stats.is_file() else checkpoint.with_name(VECNORMALIZE_FILE)


def checkpoint_normalization(
    checkpoint: Path, algo: str, layout: PolicyLayout, *, required: bool = False
) -> dict[str, Any]:
    """The observation normalisation ``checkpoint`` (of a policy of ``layout``) was trained
    with, as ``normalize.json``
    holds a finished run's (:func:`agents.train.envs.normalization_record`); off when no
    statistics are beside it, unless ``required`` (the run normalised its observations):
    then ``FileNotFoundError`` naming them."""
    import pickle

    from agents.train.envs import normalization_record

    checkpoint = Path(checkpoint)
    stats = _statistics_file(checkpoint, algo)
    saved = None
    if stats.is_file():
        with stats.open("rb") as handle:
            saved = pickle.load(handle)
    elif required:
        raise FileNotFoundError(
            f"{checkpoint}: its VecNormalize statistics "
            f"({_normalization_file(checkpoint, algo).name}, beside it) are not found; the run "
            "normalised its observations"
        )
    return normalization_record(saved, layout)


def checkpoint_callback(**settings: Any) -> Any:
    """SB3's ``CheckpointCallback`` (``settings`` its arguments) whose periodic saves a
    Ctrl-C does not cut short: it is held until the files are whole, then stops the run,
    which saves its own resumable checkpoint (an interrupt inside torch's zip writer left
    a traceback and no clean stop)."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    class WholeCheckpoints(CheckpointCallback):
        def _on_step(self) -> bool:
            with interrupts_held():
                return bool(super()._on_step())

    return WholeCheckpoints(**settings)


def _resume(
    checkpoint: Path, train_env: Any, normalize: Any, device: str, algo: str = "ppo"
) -> Any:
    """The model of ``checkpoint`` on ``train_env``, with its normalisation statistics
    (a checkpoint's ``ppo_vecnormalize_N_steps.pkl``, or a finished run's
    ``vecnormalize.pkl`` beside its ``model.zip``) and, for SAC/TD3, its replay buffer
    (a checkpoint's ``sac_replay_buffer_N_steps.pkl``: a finished run keeps none, so
    only checkpoints resume; without it training would restart its learning on a few
    fresh transitions)."""
    import pickle

    checkpoint = Path(checkpoint)
    buffer = _replay_buffer_file(checkpoint, algo)
    if algo != "ppo" and not buffer.is_file():
        raise UsageError(
            f"--resume {checkpoint}: {algo.upper()} goes on from a checkpoint with its replay "
            f"buffer beside it ({buffer.name}); a finished run's model.zip has none"
        )
    stats = _statistics_file(checkpoint, algo)
    if normalize is None and stats.is_file():
        raise UsageError(
            f"--resume {checkpoint}: it was trained with VecNormalize ({stats.name} is beside "
            "it) but the hyperparameters say normalize: false"
        )
    try:
        model = algorithm_class(algo).load(checkpoint, env=train_env, device=device)
    except ValueError as exc:
        if "spaces do not match" not in str(exc):
            raise
        raise UsageError(
            f"--resume {checkpoint}: it was trained on another observation or action than the "
            "hyperparameters make (history, observer, residual, flight_clock, integral must "
            "be those it was trained with)"
        ) from exc
    if normalize is not None:
        if not stats.is_file():
            raise UsageError(
                f"--resume {checkpoint}: its VecNormalize statistics "
                f"{_normalization_file(checkpoint, algo).name} (or {VECNORMALIZE_FILE}) are not "
                "beside it"
            )
        with stats.open("rb") as handle:
            saved = pickle.load(handle)
        normalize.obs_rms = saved.obs_rms
        normalize.ret_rms = saved.ret_rms
    if algo != "ppo":
        model.load_replay_buffer(buffer)
    return model
