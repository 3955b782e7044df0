"""Checkpoints of a run: the model, its ``VecNormalize`` statistics and (off-policy) its
replay buffer, saved together and resumed together."""

from __future__ import annotations

import zipfile
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


def checkpoint_files(checkpoint: Path, algo: str, normalize: bool) -> list[Path]:
    """The files of the checkpoint ``checkpoint`` (a model zip) as they are saved: the
    model, its ``VecNormalize`` statistics when the run normalises, and for SAC/TD3 the
    replay buffer."""
    files = [checkpoint]
    if normalize:
        files.append(_normalization_file(checkpoint, algo))
    if algo != "ppo":
        files.append(_replay_buffer_file(checkpoint, algo))
    return files


def planned_checkpoints(
    folder: Path, algo: str, start: int, steps: int, every: int, n_envs: int, normalize: bool
) -> list[Path]:
    """The files SB3's ``CheckpointCallback`` (:func:`checkpoint_callback`, saving every
    ``max(every // n_envs, 1)`` of its calls, ``n_envs`` env-steps each) writes into
    ``folder`` over ``steps`` env-steps from ``start``: named by the env-steps at each
    save."""
    if not every:
        return []
    stride = max(every // n_envs, 1) * n_envs
    saves = -(-max(steps, 0) // stride)
    return [
        file
        for k in range(1, saves + 1)
        for file in checkpoint_files(
            folder / f"{algo}_{start + k * stride}_steps.zip", algo, normalize
        )
    ]


def checkpoint_problem(path: Path) -> str | None:
    """What keeps ``path`` from being a Stable-Baselines3 model to go on from (None: it
    is one: a zip archive holding SB3's ``data``)."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
    except (OSError, zipfile.BadZipFile):
        return "not a Stable-Baselines3 model (a zip archive such as checkpoints/ppo_N_steps.zip)"
    if "data" not in names:
        return "a zip archive, but not a Stable-Baselines3 model (it holds no data entry)"
    return None


def save_checkpoint(model: Any, normalize: Any, folder: Path, algo: str = "ppo") -> Path:
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


def checkpoint_callback(*, recorded_in: Path | None = None, **settings: Any) -> Any:
    """SB3's ``CheckpointCallback`` (``settings`` its arguments) whose periodic saves a
    Ctrl-C does not cut short: it is held until the files are whole, then stops the run,
    which saves its own resumable checkpoint (an interrupt inside torch's zip writer left
    a traceback and no clean stop).  With ``recorded_in`` (the run's output folder) each
    save's files are added to that folder's manifest as rocketroll's
    (:func:`rocketroll_common.files.record_outputs`)."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    from rocketroll_common.files import record_outputs

    class WholeCheckpoints(CheckpointCallback):
        def _on_step(self) -> bool:
            with interrupts_held():
                going_on = bool(super()._on_step())
                if recorded_in is not None and self.n_calls % self.save_freq == 0:
                    saved = Path(self._checkpoint_path(extension="zip"))
                    files = checkpoint_files(saved, self.name_prefix, self.save_vecnormalize)
                    record_outputs(recorded_in, [f.relative_to(recorded_in) for f in files])
                return going_on

    return WholeCheckpoints(**settings)


def resume_model(
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
