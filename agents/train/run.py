"""A training run: its arguments (:class:`Args`, :class:`SACArgs`, :class:`TD3Args`) and
:func:`train`, read top to bottom (the package's docstring)."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import pickle
import platform
import shlex
import sys
import time
import warnings
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from agents.memory import observation_names
from agents.replay import (
    check_options,
    db_setting,
    env_options_setting,
    fitted_settings,
    options_config,
    recording_setting,
)
from agents.train.callbacks import evaluate_held_out, make_eval_callback_class
from agents.train.checkpoints import (
    VECNORMALIZE_FILE,
    checkpoint_callback,
    checkpoint_files,
    checkpoint_problem,
    planned_checkpoints,
    resume_model,
    save_checkpoint,
)
from agents.train.envs import make_env, normalization_record
from agents.train.hyperparams import (
    ALGORITHMS,
    DEFAULT_HYPERPARAMS,
    HYPERPARAMS_DIR,
    Hyperparameters,
    algorithm_arguments,
    algorithm_class,
    load_hyperparameters,
    recipe_path,
)
from rocketroll_common.errors import Interrupted, SettingError, UsageError
from rocketroll_common.files import check_folder_files, record_outputs, write_all_atomic
from rocketroll_common.settings import check, parse, setting, to_argv
from rocketroll_common.tables import Column, text_table


def _variant_ids() -> tuple[str, ...]:
    from rollenv import variant_ids

    return variant_ids()


#: Most environments stepped side by side (training and its evaluation): ppo-fast.yml
#: runs 512, the vector env is benchmarked at 4096.
MAX_ENVS = 4096
#: Most checkpoints one run may write (each is a few MB).
MAX_CHECKPOINTS = 200
#: Largest share of this machine's memory a run's rollout or replay buffer may take.
MEMORY_SHARE = 0.5
#: The files of a finished run in its output folder (and VECNORMALIZE_FILE when it
#: normalises); beside them SB3 writes the checkpoints, the evaluations and the logs.
RESULT_FILES = ("model.zip", "normalize.json", "settings.json")


@dataclass(frozen=True)
class Args:
    """Arguments of a training run (``rocketroll train ppo --help``)."""

    #: The algorithm (``rocketroll train ALGO``); :class:`SACArgs`, :class:`TD3Args` set theirs.
    ALGO: ClassVar[str] = "ppo"

    env_id: str = setting(
        "RocketRoll-v0",
        "environment: RocketRoll-v0 (hold the roll angle), RocketRollRate-v0 (track a roll "
        "rate), ...",
        choices=_variant_ids,
        always=True,
    )
    timesteps: int | None = setting(
        None,
        "environment steps to train for (default: n_timesteps of the hyperparameter file); "
        "PPO trains whole rollouts of --envs x n_steps, so at least one",
        ge=1,
        le=10**12,
    )
    seed: int = setting(
        0, "seed of torch, SB3 and the environments' generator", ge=0, le=2**32 - 1, always=True
    )
    envs: int | None = setting(
        None,
        "environments stepped side by side (default: n_envs of the hyperparameter file)",
        ge=1,
        le=MAX_ENVS,
    )
    out: Path | None = setting(
        None,
        "output folder (default: runs/<algorithm>/<env-id>/seed<seed>)",
        output="folder",
        files=RESULT_FILES,  # and the checkpoints and logs: train() checks them
    )
    db: str | None = db_setting()
    hyperparams: Path = setting(
        DEFAULT_HYPERPARAMS,
        "YAML file of hyperparameters keyed by environment id, or the name of a shipped "
        "recipe (ppo-history: agents/hyperparams/ppo-history.yml; rocketroll train recipe "
        "lists them)",
        input=True,
    )
    eval_freq: int = setting(
        100_000,
        "evaluate on the test split every this many environment steps (0: only at the end)",
        ge=0,
        le=10**12,
    )
    eval_episodes: int = setting(
        20, "test-split episodes per evaluation (run side by side)", ge=1, le=MAX_ENVS
    )
    eval_seed: int = setting(
        1000,
        "seed of the evaluation episodes: every evaluation runs the same ones",
        ge=0,
        le=2**32 - 1,
    )
    checkpoint_freq: int = setting(
        250_000,
        "save a checkpoint every this many environment steps (0: never)",
        ge=0,
        le=10**12,
    )
    resume: Path | None = setting(
        None,
        "continue from this checkpoint (model zip; its VecNormalize pickle is found beside it), "
        "e.g. the one an interrupted run saved",
        input=True,
    )
    progress_bar: bool = setting(True, "show SB3's progress bar (rich)")
    torch_threads: int = setting(
        1,
        "torch's intra-op threads: on a 2-core machine 1 suits ppo.yml's small batches, 2 "
        "ppo-fast.yml's big ones (benchmarks/train_speed.py)",
        ge=1,
        le=1024,
    )
    verbose: int = setting(
        0, "SB3's verbosity: 0 quiet, 1 its training table after each update", ge=0, le=2
    )
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()

    def __post_init__(self) -> None:
        check(self)
        check_options(self.settings)
        if self.db is not None and "://" not in self.db and not Path(self.db).is_file():
            raise SettingError("db", f"{self.db}: no such file")
        recipe_path(self.hyperparams)  # an unknown recipe's name, before any work
        if self.resume is not None and not Path(self.resume).is_file():
            raise SettingError("resume", f"{self.resume}: no such file")
        if self.resume is not None and not zipfile.is_zipfile(self.resume):
            raise SettingError(
                "resume", f"{self.resume}: not a checkpoint (the model zip a run saved)"
            )
        if self.resume is not None and (problem := checkpoint_problem(self.resume)):
            raise SettingError("resume", f"{self.resume}: {problem}")


# ----------------------------------------------------------------------------- arguments
def parse_args(argv: Sequence[str], cls: type[Args] = Args) -> Args:
    """:class:`Args` (or ``cls``) from command-line words (as ``rocketroll train ALGO``
    reads them)."""
    args: Args = parse(cls, argv, prog=f"rocketroll train {cls.ALGO}")
    return args


def command_of(args: Args) -> str:
    """The ``rocketroll train ALGO`` command line that reproduces ``args``."""
    return shlex.join(["rocketroll", "train", args.ALGO, *to_argv(args)])


def _versions() -> dict[str, str]:
    import gymnasium
    import numba
    import stable_baselines3
    import torch

    from rocketroll_common import __version__

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "gymnasium": gymnasium.__version__,
        "numba": numba.__version__,
        "rocketroll": __version__,
        "platform": platform.platform(),
        "cpu_count": str(os.cpu_count()),
    }


def _jsonable(value: Any) -> Any:
    """``value`` with paths, classes and schedules as strings, for settings.json."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, type):
        return value.__name__
    return repr(value)


def _print_table(rows: list[tuple[str, Any]]) -> None:
    """``name | value`` rows as a plain-text table."""
    width = max(len(name) for name, _ in rows)
    header, *lines = text_table(
        (Column("setting", width, "<"), Column("value", gap=" | ")),
        [(name, str(value)) for name, value in rows],
    )
    print("\n".join([header, f"{'-' * width}-+-{'-' * 40}", *lines]) + "\n")


# ----------------------------------------------------------------------------- training
def _memory_bytes() -> int | None:
    """This machine's physical memory, where the system tells it."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return None


def _integral_line(hp: Hyperparameters) -> str:
    """The error integral of ``hp`` as the run's table shows it."""
    line = f"in the observation, time constant {hp.layout.integral:g} s"
    if hp.layout.integral_clip is not None:
        line += f", integrand clipped at {hp.layout.integral_clip:g}"
    return line


def _check_size(
    args: Args,
    hp: Hyperparameters,
    algo: str,
    n_envs: int,
    steps: int,
    kwargs: dict[str, Any],
) -> None:
    """Refuse, before anything is allocated, a run whose checkpoints or buffer would swamp
    the disk or the memory."""
    if args.checkpoint_freq and steps // args.checkpoint_freq > MAX_CHECKPOINTS:
        raise UsageError(
            f"--checkpoint-freq {args.checkpoint_freq:,} over {steps:,} env-steps writes "
            f"{steps // args.checkpoint_freq:,} checkpoints, more than {MAX_CHECKPOINTS}: give "
            f"at least --checkpoint-freq {-(-steps // MAX_CHECKPOINTS):,}, or 0 for none"
        )
    width = len(observation_names(hp.layout)) + 1
    if algo == "ppo":  # SB3's rollout buffer: observation, action and six float32s a step
        n_steps = int(kwargs.get("n_steps", 2048))
        need, what = 4 * n_steps * n_envs * (width + 6), f"--envs {n_envs} x n_steps {n_steps}"
    else:  # the replay buffer: observation and next observation, action, reward, done
        size = int(kwargs.get("buffer_size", 1_000_000))
        need, what = 4 * size * (2 * width + 3), f"buffer_size {size:,}"
    memory = _memory_bytes()
    if memory is not None and need > MEMORY_SHARE * memory:
        raise UsageError(
            f"{what} ({hp.source}) needs a {need / 2**30:.1f} GiB buffer, more than half of "
            f"this machine's {memory / 2**30:.1f} GiB"
        )


def _run_files(
    out: Path, args: Args, hp: Hyperparameters, n_envs: int, start: int, steps: int
) -> tuple[list[Path], list[Path]]:
    """The files a run from ``start`` over ``steps`` env-steps writes into ``out`` (paths
    in it): its results, and what SB3 writes itself (the evaluations, the log, the
    periodic checkpoints)."""
    normalizes = hp.normalize is not None
    results = [Path(name) for name in RESULT_FILES]
    if normalizes:
        results.append(Path(VECNORMALIZE_FILE))
    resumed_log = (out / "logs" / "progress.csv").exists()  # as _logger names it
    log = f"progress_from_{start}.csv" if resumed_log else "progress.csv"
    library = [Path("eval/evaluations.npz"), Path("eval/tracking_error.csv"), Path("logs") / log]
    checkpoints = planned_checkpoints(
        out / "checkpoints", args.ALGO, start, steps, args.checkpoint_freq, n_envs, normalizes
    )
    return results, library + [p.relative_to(out) for p in checkpoints]


def _planned(
    args: Args,
    hp: Hyperparameters,
    algo: str,
    n_envs: int,
    timesteps: int,
    algo_kwargs: dict[str, Any],
) -> int:
    """The env-steps the run will train: PPO's whole rollouts, checked against its batch."""
    planned = timesteps
    if algo == "ppo":
        n_steps = int(algo_kwargs.get("n_steps", 2048))
        batch_size = int(algo_kwargs.get("batch_size", 64))
        rollout = n_steps * n_envs
        if rollout % batch_size != 0 or rollout < 2:
            raise UsageError(
                f"--envs {n_envs} x n_steps {n_steps} = {rollout} steps per rollout is "
                f"not a multiple of batch_size {batch_size} ({hp.source}, {hp.env_id})"
            )
        if args.resume is None and timesteps < rollout:
            raise UsageError(
                f"--timesteps {timesteps:,} is less than one rollout: --envs {n_envs} x n_steps "
                f"{n_steps} ({hp.source}) = {rollout:,} env-steps; train at least that, or use "
                "fewer --envs"
            )
        planned = -(-timesteps // rollout) * rollout  # PPO trains whole rollouts
    return planned


def _setting_rows(
    args: Args,
    hp: Hyperparameters,
    out: Path,
    n_envs: int,
    planned: int,
    timesteps: int,
    database: str,
) -> list[tuple[str, Any]]:
    """The run's settings as the table printed before training."""
    rows: list[tuple[str, Any]] = [
        ("env_id", args.env_id),
        (
            "timesteps",
            f"{planned:,}"
            if planned == timesteps or args.resume is not None
            else f"{planned:,} (whole rollouts: {timesteps:,} asked)",
        ),
        ("seed", args.seed),
        ("envs", n_envs),
        ("out", out),
        ("hyperparams", hp.source),
        ("torch threads", args.torch_threads),
        (
            "eval",
            f"{args.eval_episodes} test-split episodes "
            + (f"every {args.eval_freq:,} steps" if args.eval_freq else "at the end"),
        ),
        ("checkpoints", f"every {args.checkpoint_freq:,} steps" if args.checkpoint_freq else "off"),
        ("resume", args.resume if args.resume is not None else "-"),
        ("policy", hp.policy),
        ("normalize", hp.normalize if hp.normalize is not None else "off"),
        ("history", f"{hp.layout.history} steps" if hp.layout.history else "off"),
        ("observer estimate", "in the observation" if hp.layout.observer else "off"),
        *(
            (("residual", f"x {hp.layout.residual:g} on the observer's command"),)
            if hp.layout.residual
            else ()
        ),
        *(
            (("incremental", f"x {hp.layout.incremental:g}: a change of the last command"),)
            if hp.layout.incremental
            else ()
        ),
        *(
            (("flight clock", "the flight's gain and damping in the observation"),)
            if hp.layout.flight_clock
            else ()
        ),
        *((("error integral", _integral_line(hp)),) if hp.layout.integral else ()),
        *((("action noise", f"{hp.noise[0]}, sd {hp.noise[1]}"),) if hp.noise else ()),
        *((k, hp.algo_kwargs[k]) for k in hp.algo_kwargs),
        ("env_kwargs", hp.env_kwargs or "-"),
        ("database", database),
    ]
    return rows


def _record(
    args: Args,
    hp: Hyperparameters,
    algo: str,
    n_envs: int,
    timesteps: int,
    config: Any,
    database: str,
) -> dict[str, Any]:
    """What ``settings.json`` says of the run's settings (its outcome comes after)."""
    return {
        "env_id": args.env_id,
        "algorithm": algo,
        "result": "model.zip is the final model; the test split was not used to select it",
        "args": _jsonable(dataclasses.asdict(args)),
        "hyperparameters": _jsonable(
            {
                "n_envs": n_envs,
                "n_timesteps": timesteps,
                "policy": hp.policy,
                "normalize": hp.normalize,
                "env_kwargs": hp.env_kwargs,
                **hp.layout.record(),
                **({"noise_type": hp.noise[0], "noise_std": hp.noise[1]} if hp.noise else {}),
                **hp.algo_kwargs,
            }
        ),
        "hyperparameter_file": hp.source,
        "env_settings": _jsonable(dataclasses.asdict(config)),
        "database": database,
    }


def _callbacks(
    args: Args,
    algo: str,
    out: Path,
    n_envs: int,
    eval_env: Any,
    eval_adapter: Any,
    normalize: Any,
) -> tuple[Any, list[Any]]:
    """The held-out evaluation and, with ``--checkpoint-freq``, the checkpoints: the
    evaluation's callback and the list of both."""
    held_out = make_eval_callback_class()(
        eval_env,
        eval_adapter,
        args.eval_seed,
        n_eval_episodes=args.eval_episodes,
        eval_freq=max(args.eval_freq // n_envs, 1) if args.eval_freq else 0,
        log_path=str(out / "eval"),
        deterministic=True,
        verbose=1,
    )
    callbacks: list[Any] = [held_out]
    if args.checkpoint_freq:
        callbacks.append(
            checkpoint_callback(
                save_freq=max(args.checkpoint_freq // n_envs, 1),
                save_path=str(out / "checkpoints"),
                name_prefix=algo,
                save_vecnormalize=normalize is not None,
                save_replay_buffer=algo != "ppo",  # SAC/TD3 go on with what they collected
                recorded_in=out,
            )
        )
    return held_out, callbacks


def _learn(
    model: Any,
    args: Args,
    algo: str,
    out: Path,
    timesteps: int,
    callbacks: list[Any],
    normalize: Any,
    library: list[Path],
) -> None:
    """``model.learn`` to ``timesteps``; Ctrl-C saves a resumable checkpoint and raises
    :class:`~rocketroll_common.errors.Interrupted` naming it."""
    from stable_baselines3.common.callbacks import CallbackList

    try:
        with warnings.catch_warnings():
            if args.progress_bar:  # tqdm's rich bar announces itself as experimental
                from tqdm import TqdmExperimentalWarning

                warnings.filterwarnings("ignore", category=TqdmExperimentalWarning)
            model.learn(
                total_timesteps=max(timesteps - model.num_timesteps, 0),
                callback=CallbackList(callbacks),
                progress_bar=args.progress_bar,
                reset_num_timesteps=args.resume is None,
            )
    except KeyboardInterrupt:
        # Named by the env-steps collected, as SB3's own checkpoints are: a rollout cut
        # short (at most n_steps x n_envs steps) is counted but collected again on resume.
        named = out / "checkpoints" / f"{algo}_{model.num_timesteps}_steps.zip"
        files = [f.relative_to(out) for f in checkpoint_files(named, algo, normalize is not None)]
        record_outputs(out, library)
        try:
            check_folder_files(out, files, "--out")
        except UsageError as exc:
            raise Interrupted(
                f"after {model.num_timesteps:,} env-steps; not saved: {exc}"
            ) from None
        saved = save_checkpoint(model, normalize, out / "checkpoints", algo)
        record_outputs(out, files)
        again = to_argv(dataclasses.replace(args, resume=saved, out=out))
        raise Interrupted(
            f"after {model.num_timesteps:,} env-steps; saved the resumable checkpoint {saved} "
            f"(go on with: {shlex.join(['rocketroll', 'train', algo, *again])})"
        ) from None
    except BaseException:
        record_outputs(out, library)  # what SB3 wrote before the failure is the run's
        raise


def train(args: Args, command_line: Sequence[str] | None = None) -> dict[str, Any]:
    """Train PPO as ``args`` says; write the output folder; return ``settings.json``'s data.

    Ctrl-C saves a resumable checkpoint (the model and its ``VecNormalize``
    statistics, under ``checkpoints/``) and raises
    :class:`~rocketroll_common.errors.Interrupted` naming it; ``--resume`` it
    to go on.  No ``model.zip`` is written unless training finished.

    Raises
    ------
    UsageError
        A bad argument or hyperparameter (named).
    """
    started = time.perf_counter()
    algo = args.ALGO
    hp = load_hyperparameters(args.hyperparams, args.env_id, algo)
    settings, episode_note = fitted_settings(args.env_id, args.settings, args.recording, args.db)
    if episode_note:
        print(episode_note)
    if settings:  # the replay and options of --set, over the entry's env_kwargs
        options_config(args.env_id, settings, "train")  # a bad one is named as --set
        hp = dataclasses.replace(hp, env_kwargs={**hp.env_kwargs, **settings})
    n_envs = args.envs if args.envs is not None else hp.n_envs
    timesteps = args.timesteps if args.timesteps is not None else hp.n_timesteps
    if timesteps is None:
        raise UsageError(f"--timesteps is needed: {hp.source}, {hp.env_id} has no n_timesteps")
    algo_kwargs = algorithm_arguments(hp)
    algo_kwargs.setdefault("device", "cpu")
    planned = _planned(args, hp, algo, n_envs, timesteps, algo_kwargs)
    _check_size(args, hp, algo, n_envs, planned, algo_kwargs)
    out = (
        args.out if args.out is not None else Path("runs") / algo / args.env_id / f"seed{args.seed}"
    )
    out = Path(out)
    # Every file the run writes into the folder, before the work: one the user put there
    # is refused, unless --force (a resumed run's checkpoints: once its steps are read).
    results, library = _run_files(out, args, hp, n_envs, 0, planned)
    check_folder_files(out, results + (library if args.resume is None else []), "--out")

    import torch

    # Seeding: torch and SB3 (python, numpy, torch, the action space, the env) and the
    # adapters' generators; PPO(seed=...) reseeds the training adapter before its first reset.
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)

    adapter, train_env, normalize = make_env(hp, n_envs, args.seed, split="train", db=args.db)
    eval_adapter, eval_env, _ = make_env(
        hp, args.eval_episodes, args.eval_seed, split="test", db=args.db, training=False
    )

    rows = _setting_rows(args, hp, out, n_envs, planned, timesteps, adapter.bank.description)
    print(f"{ALGORITHMS[algo]} on {args.env_id}")
    _print_table(rows)

    if args.resume is not None:  # refused before the output folder is made
        model = resume_model(args.resume, train_env, normalize, algo_kwargs["device"], algo)
    out.mkdir(parents=True, exist_ok=True)
    (out / "eval").mkdir(exist_ok=True)
    if args.resume is None:
        model = _new_model(args, hp, algo, train_env, algo_kwargs)
    start_steps = int(model.num_timesteps)
    if args.resume is not None:
        _, library = _run_files(out, args, hp, n_envs, start_steps, planned - start_steps)
        check_folder_files(out, library, "--out")
    model.set_logger(_logger(out, args, algo_kwargs.get("tensorboard_log"), start_steps))
    held_out, callbacks = _callbacks(args, algo, out, n_envs, eval_env, eval_adapter, normalize)
    if args.resume is not None:
        held_out.continue_from(start_steps)
    learn_started = time.perf_counter()
    _learn(model, args, algo, out, timesteps, callbacks, normalize, library)
    train_s = time.perf_counter() - learn_started
    trained = int(model.num_timesteps) - start_steps  # by this run (a resumed one: since then)

    # The result: the final model and its observation statistics (as JSON, and as SB3's
    # VecNormalize pickle for `VecNormalize.load`).
    # Written at the end, all or nothing, with the folder's manifest.
    saved_model = io.BytesIO()
    model.save(saved_model)
    norm_record = normalization_record(normalize, hp.layout)
    outputs: dict[str | os.PathLike[str], str | bytes] = {
        out / "model.zip": saved_model.getvalue(),
        out / "normalize.json": json.dumps(norm_record, indent=2) + "\n",
    }
    if normalize is not None:
        from stable_baselines3.common.vec_env import sync_envs_normalization

        outputs[out / VECNORMALIZE_FILE] = pickle.dumps(normalize)  # as VecNormalize.save
        sync_envs_normalization(train_env, eval_env)
    final = evaluate_held_out(model, eval_env, eval_adapter, args.eval_seed)
    wall_s = time.perf_counter() - started
    settings = {
        **_record(args, hp, algo, n_envs, timesteps, adapter.config, adapter.bank.description),
        "command_line": shlex.join(sys.argv if command_line is None else command_line),
        "equivalent_command": command_of(args),
        "versions": _versions(),
        "torch_threads": args.torch_threads,
        "env_steps": int(model.num_timesteps),
        "resumed_at_env_steps": start_steps if args.resume is not None else None,
        "train_time_s": round(train_s, 3),
        "wall_time_s": round(wall_s, 3),
        "env_steps_per_s": round(trained / train_s, 1),
        "final_test_eval": {
            "episodes": int(final["episodes"]),
            "seed": args.eval_seed,
            "mean_reward": final["mean_reward"],
            "rms_tracking_error": final["rms_tracking_error"],
            "unit": "deg" if adapter.config.task == "angle" else "deg/s",
        },
    }
    outputs[out / "settings.json"] = json.dumps(settings, indent=2) + "\n"
    model.logger.close()
    write_all_atomic(outputs, folder=out)
    record_outputs(out, library)
    train_env.close()
    eval_env.close()
    _print_done(settings, out, normalize is not None, train_s, wall_s)
    return settings


def _new_model(
    args: Args, hp: Hyperparameters, algo: str, train_env: Any, algo_kwargs: dict[str, Any]
) -> Any:
    """The algorithm's model on the training stack, seeded (and its action noise, where the
    entry asks for one)."""
    if hp.noise is not None:
        from stable_baselines3.common.noise import NormalActionNoise

        dims = int(np.prod(train_env.action_space.shape))
        algo_kwargs["action_noise"] = NormalActionNoise(np.zeros(dims), np.full(dims, hp.noise[1]))
    return algorithm_class(algo)(
        hp.policy, train_env, seed=args.seed, verbose=args.verbose, **algo_kwargs
    )


def _print_done(
    settings: dict[str, Any], out: Path, vecnormalize: bool, train_s: float, wall_s: float
) -> None:
    """What a finished run says: its steps and speed (``train_s`` learning, ``wall_s`` in
    all), its final test, what it wrote."""
    trained = settings["env_steps"] - (settings["resumed_at_env_steps"] or 0)
    resumed = ""
    if settings["resumed_at_env_steps"] is not None:
        resumed = (
            f" (resumed at {settings['resumed_at_env_steps']:,}: {settings['env_steps']:,} in all)"
        )
    final = settings["final_test_eval"]
    print(
        f"\ntrained {trained:,} env-steps{resumed} in {train_s:.1f} s "
        f"({trained / train_s:,.0f} env-steps/s); wall time {wall_s:.1f} s"
    )
    print(
        f"final model on {int(final['episodes'])} test-split episodes: mean return "
        f"{final['mean_reward']:.1f}, RMS tracking error {final['rms_tracking_error']:.3f}"
    )
    written = ["model.zip", "normalize.json", "settings.json"]
    if vecnormalize:
        written.insert(2, VECNORMALIZE_FILE)
    print(f"wrote {out}/{', '.join(written)}")


def _logger(out: Path, args: Args, tensorboard_log: str | None, start_steps: int = 0) -> Any:
    """SB3's logger: CSV under ``out/logs``, stdout when verbose, TensorBoard when asked.

    A resumed run logs to ``progress_from_N.csv`` when ``progress.csv`` exists
    (SB3's CSV writer would start that file afresh).
    """
    from stable_baselines3.common.logger import Logger, make_output_format

    suffix = f"_from_{start_steps}" if (out / "logs" / "progress.csv").exists() else ""
    formats = [make_output_format("csv", str(out / "logs"), suffix)]
    if args.verbose:
        formats.append(make_output_format("stdout", str(out / "logs")))
    if tensorboard_log is not None:
        run = f"{ALGORITHMS[args.ALGO]}_{args.env_id}_seed{args.seed}"
        formats.append(make_output_format("tensorboard", str(Path(tensorboard_log) / run)))
    return Logger(folder=str(out / "logs"), output_formats=formats)


def quiet_logger() -> Any:
    """SB3's logger with no output and no folder, for a model trained outside
    :func:`train` (a benchmark's, a test's): SB3's default logger makes an empty
    ``tempdir/SB3-<time>`` folder for each model it trains, and leaves it."""
    from stable_baselines3.common.logger import Logger

    return Logger(folder=None, output_formats=[])


@dataclass(frozen=True)
class SACArgs(Args):
    """Arguments of a training run (``rocketroll train sac --help``)."""

    ALGO: ClassVar[str] = "sac"
    hyperparams: Path = setting(
        HYPERPARAMS_DIR / "sac-history.yml", "YAML file of hyperparameters keyed by environment id"
    )


@dataclass(frozen=True)
class TD3Args(Args):
    """Arguments of a training run (``rocketroll train td3 --help``)."""

    ALGO: ClassVar[str] = "td3"
    hyperparams: Path = setting(
        HYPERPARAMS_DIR / "td3-history.yml", "YAML file of hyperparameters keyed by environment id"
    )


#: The arguments class of each algorithm (``rocketroll sweep`` trains through these).
TRAIN_ARGS: dict[str, type[Args]] = {"ppo": Args, "sac": SACArgs, "td3": TD3Args}
