"""Train Stable-Baselines3 PPO on RocketRoll-v0 / RocketRollRate-v0.

Read top to bottom, as CleanRL's ``ppo_continuous_action.py``: the arguments
(a dataclass, help and bounds on each field), the hyperparameters of the YAML file
keyed by environment id (rl-baselines3-zoo's layout), then the work:

1. seed everything (SB3's ``seed=``, ``torch.manual_seed``, the adapter's
   generator) and set torch's threads;
2. the training envs: ``VecNormalize(VecMonitor(RollVecEnv(split="train")))``
   -- the monitor inside, so it logs the raw returns whatever
   ``VecNormalize`` does to the rewards;
3. the held-out evaluation: the same stack over ``split="test"`` (observation
   statistics synced from training, frozen, raw rewards), the same seeded
   episodes at every evaluation, deterministic actions; it logs the mean
   return and the RMS true tracking error;
4. ``PPO.learn`` with checkpoints and a progress bar;
5. the **final** model is the result (``model.zip``).  It is *not* the best
   model by the test split: the test split is the held-out set, and choosing
   a model on it would leak it into the result.

Output directory::

    model.zip         the final PPO model
    normalize.json    observation normalisation (mean, var, clip, epsilon), portable
    vecnormalize.pkl  the same as SB3's VecNormalize.load(path, venv) reads it
    settings.json     arguments, resolved hyperparameters, command line, versions,
                      wall time, env-steps/s, the final model's test-split evaluation
    checkpoints/      periodic models and VecNormalize pickles (and the one Ctrl-C
                      saves; continue with --resume checkpoints/ppo_N_steps.zip)
    eval/             evaluations.npz (SB3) and tracking_error.csv
    logs/             SB3's progress.csv

Run::

    rocketroll train ppo --env-id RocketRoll-v0 --seed 0 --out runs/ppo-angle
    python -m agents.train --env-id RocketRollRate-v0 --timesteps 2000000   # the same
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import os
import platform
import shlex
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from agents.replay import (
    check_options,
    db_setting,
    env_options_setting,
    fitted_settings,
    options_config,
    recording_setting,
)
from rocketroll_common.errors import Interrupted, SettingError, UsageError
from rocketroll_common.settings import Command, check, parse, run_command, setting, to_argv

__all__ = [
    "COMMAND",
    "DEFAULT_HYPERPARAMS",
    "VECNORMALIZE_FILE",
    "Args",
    "Hyperparameters",
    "command_of",
    "load_hyperparameters",
    "make_env",
    "parse_args",
    "ppo_arguments",
    "ppo_keywords",
    "train",
]

#: The hyperparameter files shipped with the package, one per algorithm.
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
#: PPO's (``rocketroll train ppo``'s default).
DEFAULT_HYPERPARAMS = HYPERPARAMS_DIR / "ppo.yml"

#: ``rocketroll train ALGO`` → the Stable-Baselines3 class.
ALGORITHMS = {"ppo": "PPO", "sac": "SAC", "td3": "TD3"}

#: Keys of a YAML entry that are not keywords of the algorithm: ``history`` (steps of
#: past observations and actions in the observation, :mod:`agents.memory`), ``observer``
#: (true: the observer's estimate ``[v̂, ψ̂, û_d]`` in the observation,
#: :class:`agents.observer.ObserverFeatures`, designed on the train split), ``residual``
#: (a scale in (0, 1]: the action is a residual added to the observer controller's command,
#: × the scale; implies ``observer``), ``flight_clock`` (true, on a flight variant: the
#: flight's gain and damping multipliers at the coming control step in the observation,
#: :class:`agents.memory.FlightClock`), and for the off-policy algorithms the exploration
#: noise (``noise_type: normal``, ``noise_std``) as
#: rl-baselines3-zoo writes it.
SCRIPT_KEYS = (
    "n_envs",
    "n_timesteps",
    "policy",
    "normalize",
    "env_kwargs",
    "history",
    "observer",
    "residual",
    "flight_clock",
    "noise_type",
    "noise_std",
)
#: Environment settings the observer's design depends on (its bank, sensors, servo): an
#: entry with ``observer: true`` may not change them in ``env_kwargs``, since the acting
#: controller designs its observer on the evaluated environment's train split.
OBSERVER_DESIGN = (
    "method",
    "disturbance",
    "model",
    "recording",
    "dt_s",
    "substep_s",
    "rate_limit_dps",
    "fin_range_deg",
    "sensors",
    "encoder_counts",
    "gyro_noise_pct",
    "gyro_range_dps",
    "episode_s",
)
#: Keywords the script sets itself (from the command line), not the YAML file.
SCRIPT_SET = ("seed", "verbose")


def algorithm_class(algo: str) -> Any:
    """The Stable-Baselines3 class of ``algo`` (``"ppo"``, ``"sac"``, ``"td3"``)."""
    import stable_baselines3

    return getattr(stable_baselines3, ALGORITHMS[algo])


def algorithm_keywords(algo: str = "ppo") -> tuple[str, ...]:
    """Every keyword of the SB3 class of ``algo`` a YAML entry may set (its signature,
    less what the script sets: ``seed``, ``verbose``, ``env``)."""
    names = inspect.signature(algorithm_class(algo).__init__).parameters
    given = ("self", "policy", "env", "_init_setup_model", *SCRIPT_SET)  # policy: a script key
    return tuple(n for n in names if n not in given)


def ppo_keywords() -> tuple[str, ...]:
    """:func:`algorithm_keywords` of PPO."""
    return algorithm_keywords("ppo")


#: ``VecNormalize`` arguments a YAML ``normalize`` mapping may set.
NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")
#: ``policy_kwargs.activation_fn`` names.
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")


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
        "environment steps to train for (default: n_timesteps of the hyperparameter file)",
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
        None, "output folder (default: runs/<algorithm>/<env-id>/seed<seed>)", output="folder"
    )
    db: str | None = db_setting()
    hyperparams: Path = setting(
        DEFAULT_HYPERPARAMS, "YAML file of hyperparameters keyed by environment id", input=True
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
        if self.resume is not None and not Path(self.resume).is_file():
            raise SettingError("resume", f"{self.resume}: no such file")


@dataclass(frozen=True)
class Hyperparameters:
    """One entry of the hyperparameter file, checked.

    Attributes
    ----------
    env_id : str
        The key it was read under.
    n_envs : int
        Environments stepped side by side (1 when the file does not say, as
        in rl-baselines3-zoo).
    n_timesteps : int or None
        Environment steps to train for (None: the file does not say;
        ``--timesteps`` must).
    policy : str
        SB3 policy name (default ``"MlpPolicy"``).
    normalize : dict or None
        ``VecNormalize`` arguments, None for no normalisation.
    env_kwargs : dict
        RocketRoll settings for the training and evaluation envs.
    ppo : dict
        The algorithm's keywords as written in the file (schedules as
        ``"lin_<x>"``, the activation as a name); the name is PPO's, the first.
    source : str
        The file.
    algo : str
        The algorithm the entry is for.
    history : int
        Steps of past observations and actions beside the observation (0: none).
    noise : tuple or None
        ``("normal", sd)``: Gaussian exploration noise on the action (SAC, TD3).
    observer : bool
        The observer's estimate in the observation.
    residual : float
        0, or the scale of the action as a residual on the observer controller's
        command (:class:`agents.observer.ObserverFeatures`).
    flight_clock : bool
        The flight's phase in the observation (:class:`agents.memory.FlightClock`).
    """

    env_id: str
    n_envs: int
    n_timesteps: int | None
    policy: str
    normalize: dict[str, Any] | None
    env_kwargs: dict[str, Any]
    ppo: dict[str, Any]
    source: str
    algo: str = "ppo"
    history: int = 0
    noise: tuple[str, float] | None = None
    observer: bool = False
    residual: float = 0.0
    flight_clock: bool = False


# ----------------------------------------------------------------------------- arguments
def parse_args(argv: Sequence[str], cls: type[Args] = Args) -> Args:
    """:class:`Args` (or ``cls``) from command-line words (as ``rocketroll train ALGO``
    reads them)."""
    args: Args = parse(cls, argv, prog=f"rocketroll train {cls.ALGO}")
    return args


def command_of(args: Args) -> str:
    """The ``rocketroll train ALGO`` command line that reproduces ``args``."""
    return shlex.join(["rocketroll", "train", args.ALGO, *to_argv(args)])


# ------------------------------------------------------------------------ hyperparameters
def load_hyperparameters(
    path: str | os.PathLike[str], env_id: str, algo: str = "ppo"
) -> Hyperparameters:
    """The entry ``env_id`` of the YAML file ``path`` for ``algo``, checked key by key.

    Raises
    ------
    UsageError
        The file is missing or not a mapping, has no entry for ``env_id``,
        lacks a required key, or has an unknown one (named, with the file).
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise UsageError(f"--hyperparams {path}: no such file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise UsageError(
            f"--hyperparams {path}: not UTF-8 text (byte {exc.start} is "
            f"0x{exc.object[exc.start]:02x})"
        ) from None
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise UsageError(
            f"--hyperparams {path}: not valid YAML ({exc})".replace("\n", " ")
        ) from None
    if not isinstance(document, dict):
        raise UsageError(f"--hyperparams {path}: expected a mapping keyed by environment id")
    if env_id not in document:
        raise UsageError(
            f"--hyperparams {path} has no entry for {env_id!r} (it has: "
            f"{', '.join(map(str, document)) or 'none'})"
        )
    entry = document[env_id]
    where = f"{path}, {env_id}"
    if not isinstance(entry, dict):
        raise UsageError(f"{where}: expected a mapping of hyperparameters")
    set_here = sorted(set(entry) & set(SCRIPT_SET))
    if set_here:
        raise UsageError(
            f"{where}: {set_here[0]!r} is set by the command line (--{set_here[0]}), not the "
            "hyperparameter file"
        )
    keywords = algorithm_keywords(algo)
    unknown = sorted(set(entry) - set(SCRIPT_KEYS) - set(keywords))
    if unknown:
        raise UsageError(
            f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; known: "
            f"{', '.join(SCRIPT_KEYS + keywords)}"
        )
    counts: dict[str, int | None] = {"n_envs": 1, "n_timesteps": None, "history": 0}
    for key in ("n_envs", "n_timesteps", "history"):
        if key not in entry:
            continue
        value = entry[key]
        if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
            raise UsageError(f"{where}: {key} must be a whole number, got {value!r}")
        if value < (0 if key == "history" else 1):
            raise UsageError(f"{where}: {key} must be positive, got {value!r}")
        counts[key] = int(value)
    noise = None
    if "noise_type" in entry or "noise_std" in entry:
        kind, sd = entry.get("noise_type"), entry.get("noise_std")
        if algo == "ppo":
            raise UsageError(f"{where}: noise_type/noise_std are for SAC and TD3, not PPO")
        if kind != "normal":
            raise UsageError(f"{where}: noise_type must be 'normal', got {kind!r}")
        if isinstance(sd, bool) or not isinstance(sd, int | float) or not 0 < sd < 10:
            raise UsageError(f"{where}: noise_std must be a number in (0, 10), got {sd!r}")
        noise = ("normal", float(sd))
    normalize = entry.get("normalize", False)
    if isinstance(normalize, str):  # rl-baselines3-zoo's "dict(norm_obs=True, ...)"
        normalize = zoo_mapping(normalize, f"{where}: normalize")
    if normalize is True:
        normalize = {}
    if normalize is False or normalize is None:
        normalize = None
    elif not isinstance(normalize, dict):
        raise UsageError(f"{where}: normalize must be true, false or a mapping, got {normalize!r}")
    else:
        bad = sorted(set(normalize) - set(NORMALIZE_KEYS))
        if bad:
            raise UsageError(
                f"{where}: unknown normalize key(s) {', '.join(map(repr, bad))}; known: "
                f"{', '.join(NORMALIZE_KEYS)}"
            )
    observer = entry.get("observer", False)
    if not isinstance(observer, bool):
        raise UsageError(f"{where}: observer must be true or false, got {observer!r}")
    residual = entry.get("residual", 0.0)
    if isinstance(residual, bool) or not isinstance(residual, int | float):
        raise UsageError(f"{where}: residual must be a number in (0, 1], got {residual!r}")
    if residual:
        if not 0 < residual <= 1:
            raise UsageError(f"{where}: residual must be a number in (0, 1], got {residual!r}")
        if "observer" in entry and not observer:
            raise UsageError(
                f"{where}: residual acts on the observer controller, whose estimate the policy "
                "reads: observer: false contradicts it"
            )
        observer = True
    redesign = sorted(set(entry.get("env_kwargs") or {}) & set(OBSERVER_DESIGN))
    if observer and redesign:
        raise UsageError(
            f"{where}: observer: true with env_kwargs {redesign[0]!r}: the observer is designed "
            "on the train split of the environment evaluated, which that setting changes"
        )
    env_kwargs = entry.get("env_kwargs") or {}
    if not isinstance(env_kwargs, dict):
        raise UsageError(f"{where}: env_kwargs must be a mapping, got {env_kwargs!r}")
    flight_clock = entry.get("flight_clock", False)
    if not isinstance(flight_clock, bool):
        raise UsageError(f"{where}: flight_clock must be true or false, got {flight_clock!r}")
    if flight_clock:
        from rollenv.variants import variant_options

        if variant_options(env_id).get("flight") is None and "flight" not in env_kwargs:
            raise UsageError(
                f"{where}: flight_clock is the phase of a flight; {env_id} is not a flight variant"
            )
    ppo = {key: entry[key] for key in keywords if key in entry}
    if isinstance(ppo.get("policy_kwargs"), str):  # rl-baselines3-zoo's "dict(...)"
        ppo["policy_kwargs"] = zoo_mapping(ppo["policy_kwargs"], f"{where}: policy_kwargs")
    _ppo_arguments(ppo, where)  # fail now on a bad schedule or activation
    return Hyperparameters(
        env_id=env_id,
        n_envs=counts["n_envs"] or 1,
        n_timesteps=counts["n_timesteps"],
        policy=str(entry.get("policy", "MlpPolicy")),
        normalize=normalize,
        env_kwargs=dict(env_kwargs),
        ppo=ppo,
        source=str(path),
        algo=algo,
        history=counts["history"] or 0,
        noise=noise,
        observer=observer,
        residual=float(residual),
        flight_clock=flight_clock,
    )


def _schedule(value: Any, key: str, where: str) -> float | Callable[[float], float]:
    """A float, or ``"lin_<x>"``: x at the start, decaying linearly to 0 at the end."""
    if isinstance(value, str):
        if value.startswith("lin_"):
            try:
                initial = float(value[4:])
            except ValueError:
                initial = math.nan
            if math.isfinite(initial) and initial > 0:
                return _LinearSchedule(initial)
        raise UsageError(f"{where}: {key} must be a number or 'lin_<number>', got {value!r}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise UsageError(f"{where}: {key} must be a number or 'lin_<number>', got {value!r}")
    return float(value)


@dataclass(frozen=True)
class _LinearSchedule:
    """SB3 schedule: ``initial`` times the fraction of training remaining."""

    initial: float

    def __call__(self, progress_remaining: float) -> float:
        return self.initial * progress_remaining


#: ``torch.nn`` activations as rl-baselines3-zoo's files name them -> :data:`ACTIVATIONS`.
ZOO_ACTIVATIONS = {"Tanh": "tanh", "ReLU": "relu", "ELU": "elu", "LeakyReLU": "leaky_relu"}


def zoo_mapping(text: str, where: str) -> dict[str, Any]:
    """A mapping written as rl-baselines3-zoo writes one in a YAML string, read without
    ``eval``: ``dict(net_arch=[64, 64], activation_fn=nn.Tanh)`` or ``{'norm_obs': True}``
    -- literals, nested ``dict(...)``, and the ``nn.X`` activations of
    :data:`ZOO_ACTIVATIONS` (as their names: ``nn.Tanh`` is ``tanh``)."""
    import ast

    def value(node: ast.expr) -> Any:
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "dict"
            and not node.args
        ):
            if any(k.arg is None for k in node.keywords):
                raise ValueError("dict(**...) is not read")
            return unique([(str(k.arg), value(k.value)) for k in node.keywords])
        if isinstance(node, ast.Dict):
            pairs = []
            for k, v in zip(node.keys, node.values, strict=True):
                if k is None:
                    raise ValueError("{**...} is not read")
                pairs.append((ast.literal_eval(k), value(v)))
            return unique(pairs)
        if isinstance(node, ast.List | ast.Tuple):
            return [value(item) for item in node.elts]
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.value.id == "nn" and node.attr in ZOO_ACTIVATIONS:
                return ZOO_ACTIVATIONS[node.attr]
            raise ValueError(
                f"{node.value.id}.{node.attr}: the activations read are "
                f"{', '.join('nn.' + a for a in ZOO_ACTIVATIONS)}"
            )
        literal = ast.literal_eval(node)
        if literal is not None and not isinstance(literal, bool | int | float | str):
            raise ValueError(f"{type(literal).__name__} values are not read")
        return literal

    def unique(pairs: list[tuple[Any, Any]]) -> dict[Any, Any]:
        keys = [k for k, _ in pairs]
        repeated = sorted({str(k) for k in keys if keys.count(k) > 1})
        if repeated:
            raise ValueError(f"{repeated[0]!r} is given twice")
        return dict(pairs)

    try:
        read = value(ast.parse(text.strip(), mode="eval").body)
    except (SyntaxError, ValueError, TypeError, RecursionError, MemoryError) as exc:
        raise UsageError(f"{where}: {text!r} is not a dict(...) of literals: {exc}") from None
    if not isinstance(read, dict):
        raise UsageError(f"{where}: {text!r} is not a mapping")
    return read


def _ppo_arguments(ppo: dict[str, Any], where: str) -> dict[str, Any]:
    """PPO keywords from a YAML entry: schedules and the activation resolved."""
    import torch

    out = dict(ppo)
    for key in ("learning_rate", "clip_range"):
        if key in out:
            out[key] = _schedule(out[key], key, where)
    policy_kwargs = dict(out.get("policy_kwargs") or {})
    activation = policy_kwargs.get("activation_fn")
    if activation is not None:
        table = {
            "tanh": torch.nn.Tanh,
            "relu": torch.nn.ReLU,
            "elu": torch.nn.ELU,
            "leaky_relu": torch.nn.LeakyReLU,
        }
        if activation not in table:
            raise UsageError(
                f"{where}: policy_kwargs.activation_fn must be one of {', '.join(ACTIVATIONS)}, "
                f"got {activation!r}"
            )
        policy_kwargs["activation_fn"] = table[activation]
    if "policy_kwargs" in out:
        out["policy_kwargs"] = policy_kwargs
    if out.get("tensorboard_log") is not None:
        import importlib.util

        if importlib.util.find_spec("tensorboard") is None:
            raise UsageError(
                f"{where}: tensorboard_log needs the tensorboard package (pip install tensorboard)"
            )
        out["tensorboard_log"] = str(out["tensorboard_log"])
    return out


def ppo_arguments(hp: Hyperparameters) -> dict[str, Any]:
    """The PPO keywords of ``hp``: ``"lin_<x>"`` schedules and the activation name resolved."""
    return _ppo_arguments(hp.ppo, f"{hp.source}, {hp.env_id}")


def make_env(
    hp: Hyperparameters,
    n_envs: int,
    seed: int,
    *,
    split: str,
    db: str | os.PathLike[str] | None = None,
    training: bool = True,
) -> tuple[Any, Any, Any]:
    """The vector env stack of a run: ``VecNormalize(VecMonitor(RollVecEnv))``, with
    ``VecObserver`` and ``VecHistory`` over the adapter when the entry asks for
    ``observer`` and ``history``.

    The monitor is inside, so it records the raw returns whatever
    ``VecNormalize`` does to rewards.  ``training=False`` (evaluation):
    frozen statistics (synced from training by the caller), raw rewards, and
    every recording of the split (a ``recording`` option chooses what is
    trained on, not the held-out set).

    Returns
    -------
    adapter : RollVecEnv
        The adapter at the bottom (for seeding).
    env : VecEnv
        The top of the stack.
    normalize : VecNormalize or None
        The normalisation wrapper, None when ``hp.normalize`` is None.
    """
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.vecenv import RollVecEnv

    for forbidden in ("split", "task"):
        if forbidden in hp.env_kwargs:
            raise UsageError(f"{hp.source}, {hp.env_id}: env_kwargs may not set {forbidden!r}")
    options = dict(hp.env_kwargs)
    if not training:  # the held-out check replays the whole test split
        options.pop("recording", None)
    try:
        adapter = RollVecEnv(n_envs, hp.env_id, db=db, seed=seed, split=split, **options)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{hp.source}, {hp.env_id}: env_kwargs: {exc}") from exc
    env: Any = adapter
    if hp.observer:
        from agents.base import design_bank
        from agents.observer import ObserverFeatures
        from agents.vecenv import VecObserver

        train_bank = adapter.bank
        if (
            split != "train"
            or adapter.config.flight_schedule is not None
            or adapter.config.recording is not None
        ):
            # the observer is designed on the train split (the replayed recording's part
            # there, where it has one), as --policy designs it when the policy is
            # evaluated; in flight on its tunnel traces
            train_bank = design_bank(adapter.config, db)
        features = ObserverFeatures.from_bank(adapter.config, train_bank, n_envs, hp.residual)
        env = VecObserver(env, features)
    if hp.flight_clock:
        from agents.vecenv import VecFlightClock

        schedule = adapter.config.flight_schedule
        if schedule is None:
            raise UsageError(f"{hp.source}, {hp.env_id}: flight_clock needs a flight")
        env = VecFlightClock(env, schedule.scales[: adapter.config.max_episode_steps])
    if hp.history:
        from agents.vecenv import VecHistory

        env = VecHistory(env, hp.history)
    env = VecMonitor(env)
    normalize = None
    if hp.normalize is not None:
        norm = dict(hp.normalize)
        norm.setdefault("gamma", float(hp.ppo.get("gamma", 0.99)))
        if not training:
            norm.update(training=False, norm_reward=False)
        normalize = VecNormalize(env, **norm)
        env = normalize
    return adapter, env, normalize


# ----------------------------------------------------------------------------- evaluation
def _make_eval_callback_class() -> type:
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


# ----------------------------------------------------------------------------- outputs
def observation_names(
    history: int = 0, observer: bool = False, flight_clock: bool = False
) -> list[str]:
    """The names of the policy's observation: the env's, the observer's estimate, the
    flight's phase, then the history (``name@t-k``, and ``action@t-k``).

    Examples
    --------
    >>> observation_names(1)[4:]
    ['tracking_error@t-1', 'roll_rate_dps@t-1', 'fin_deg@t-1', 'fin_cmd_deg@t-1', 'action@t-1']
    >>> len(observation_names(2, observer=True))  # (4 + 3) x 3 + 2
    23
    """
    from agents.memory import FlightClock
    from rollenv.layout import OBSERVATION_NAMES

    now = [*OBSERVATION_NAMES, *(("v_hat_dps", "psi_hat_deg", "u_d_hat_deg") if observer else ())]
    now += list(FlightClock.NAMES) if flight_clock else []
    past = [f"{name}@t-{k}" for k in range(1, history + 1) for name in now]
    return now + past + [f"action@t-{k}" for k in range(1, history + 1)]


def normalization_record(
    venv: Any, history: int = 0, observer: bool = False, flight_clock: bool = False
) -> dict[str, Any]:
    """The observation normalisation of a ``VecNormalize`` (or None) as plain JSON data."""
    names = observation_names(history, observer, flight_clock)
    if venv is None or not venv.norm_obs:
        return {"norm_obs": False, "observation_names": names}
    rms = venv.obs_rms
    return {
        "norm_obs": True,
        "observation_names": names,
        "mean": [float(x) for x in rms.mean],
        "var": [float(x) for x in rms.var],
        "count": float(rms.count),
        "clip_obs": float(venv.clip_obs),
        "epsilon": float(venv.epsilon),
        "formula": "clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs) as float32",
    }


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
    print(f"{'setting':<{width}} | value")
    print(f"{'-' * width}-+-{'-' * 40}")
    for name, value in rows:
        print(f"{name:<{width}} | {value}")
    print()


# ----------------------------------------------------------------------------- training
def _memory_bytes() -> int | None:
    """This machine's physical memory, where the system tells it."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return None


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
    width = len(observation_names(hp.history, hp.observer, hp.flight_clock)) + 1
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
    ppo_kwargs = ppo_arguments(hp)
    ppo_kwargs.setdefault("device", "cpu")
    planned = timesteps
    if algo == "ppo":
        n_steps = int(ppo_kwargs.get("n_steps", 2048))
        batch_size = int(ppo_kwargs.get("batch_size", 64))
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
    _check_size(args, hp, algo, n_envs, planned, ppo_kwargs)
    out = (
        args.out if args.out is not None else Path("runs") / algo / args.env_id / f"seed{args.seed}"
    )
    out = Path(out)

    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    # Seeding: torch and SB3 (python, numpy, torch, the action space, the env) and the
    # adapters' generators; PPO(seed=...) reseeds the training adapter before its first reset.
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)

    adapter, train_env, normalize = make_env(hp, n_envs, args.seed, split="train", db=args.db)
    eval_adapter, eval_env, _ = make_env(
        hp, args.eval_episodes, args.eval_seed, split="test", db=args.db, training=False
    )

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
        ("eval", f"{args.eval_episodes} test-split episodes every {args.eval_freq:,} steps"),
        ("checkpoints", f"every {args.checkpoint_freq:,} steps" if args.checkpoint_freq else "off"),
        ("resume", args.resume if args.resume is not None else "-"),
        ("policy", hp.policy),
        ("normalize", hp.normalize if hp.normalize is not None else "off"),
        ("history", f"{hp.history} steps" if hp.history else "off"),
        ("observer estimate", "in the observation" if hp.observer else "off"),
        *((("residual", f"x {hp.residual:g} on the observer's command"),) if hp.residual else ()),
        *(
            (("flight clock", "the flight's gain and damping in the observation"),)
            if hp.flight_clock
            else ()
        ),
        *((("action noise", f"{hp.noise[0]}, sd {hp.noise[1]}"),) if hp.noise else ()),
        *((k, hp.ppo[k]) for k in hp.ppo),
        ("env_kwargs", hp.env_kwargs or "-"),
        ("database", adapter.bank.description),
    ]
    print(f"{ALGORITHMS[algo]} on {args.env_id}")
    _print_table(rows)

    out.mkdir(parents=True, exist_ok=True)
    (out / "eval").mkdir(exist_ok=True)
    if args.resume is not None:
        model = _resume(args.resume, train_env, normalize, ppo_kwargs["device"], algo)
    else:
        if hp.noise is not None:
            from stable_baselines3.common.noise import NormalActionNoise

            dims = int(np.prod(train_env.action_space.shape))
            ppo_kwargs["action_noise"] = NormalActionNoise(
                np.zeros(dims), np.full(dims, hp.noise[1])
            )
        model = algorithm_class(algo)(
            hp.policy, train_env, seed=args.seed, verbose=args.verbose, **ppo_kwargs
        )
    start_steps = int(model.num_timesteps)
    model.set_logger(_logger(out, args, ppo_kwargs.get("tensorboard_log"), start_steps))
    held_out = _make_eval_callback_class()(
        eval_env,
        eval_adapter,
        args.eval_seed,
        n_eval_episodes=args.eval_episodes,
        eval_freq=max(args.eval_freq // n_envs, 1) if args.eval_freq else 0,
        log_path=str(out / "eval"),
        deterministic=True,
        verbose=1,
    )
    if args.resume is not None:
        held_out.continue_from(start_steps)
    callbacks: list[Any] = [held_out]
    if args.checkpoint_freq:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(args.checkpoint_freq // n_envs, 1),
                save_path=str(out / "checkpoints"),
                name_prefix=algo,
                save_vecnormalize=normalize is not None,
                save_replay_buffer=algo != "ppo",  # SAC/TD3 go on with what they collected
            )
        )
    learn_started = time.perf_counter()
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
        saved = _checkpoint(model, normalize, out / "checkpoints", algo)
        again = to_argv(dataclasses.replace(args, resume=saved, out=out))
        raise Interrupted(
            f"after {model.num_timesteps:,} env-steps; saved the resumable checkpoint {saved} "
            f"(go on with: {shlex.join(['rocketroll', 'train', algo, *again])})"
        ) from None
    train_s = time.perf_counter() - learn_started
    trained = int(model.num_timesteps) - start_steps  # by this run (a resumed one: since then)

    # The result: the final model and its observation statistics (as JSON, and as SB3's
    # VecNormalize pickle for `VecNormalize.load`).
    model.save(out / "model.zip")
    norm_record = normalization_record(normalize, hp.history, hp.observer, hp.flight_clock)
    (out / "normalize.json").write_text(json.dumps(norm_record, indent=2) + "\n", "utf-8")
    if normalize is not None:
        from stable_baselines3.common.vec_env import sync_envs_normalization

        normalize.save(str(out / VECNORMALIZE_FILE))
        sync_envs_normalization(train_env, eval_env)
    final = evaluate_held_out(model, eval_env, eval_adapter, args.eval_seed)
    wall_s = time.perf_counter() - started
    settings = {
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
                **({"history": hp.history} if hp.history else {}),
                **({"observer": True} if hp.observer else {}),
                **({"residual": hp.residual} if hp.residual else {}),
                **({"flight_clock": True} if hp.flight_clock else {}),
                **({"noise_type": hp.noise[0], "noise_std": hp.noise[1]} if hp.noise else {}),
                **hp.ppo,
            }
        ),
        "hyperparameter_file": hp.source,
        "env_settings": _jsonable(dataclasses.asdict(adapter.config)),
        "database": adapter.bank.description,
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
    (out / "settings.json").write_text(json.dumps(settings, indent=2) + "\n", "utf-8")
    model.logger.close()
    train_env.close()
    eval_env.close()
    resumed = ""
    if args.resume is not None:
        resumed = f" (resumed at {start_steps:,}: {model.num_timesteps:,} in all)"
    print(
        f"\ntrained {trained:,} env-steps{resumed} in {train_s:.1f} s "
        f"({trained / train_s:,.0f} env-steps/s); wall time {wall_s:.1f} s"
    )
    print(
        f"final model on {int(final['episodes'])} test-split episodes: mean return "
        f"{final['mean_reward']:.1f}, RMS tracking error {final['rms_tracking_error']:.3f}"
    )
    written = ["model.zip", "normalize.json", "settings.json"]
    if normalize is not None:
        written.insert(2, VECNORMALIZE_FILE)
    print(f"wrote {out}/{', '.join(written)}")
    return settings


#: SB3's ``VecNormalize`` statistics of the final model (``VecNormalize.load(path, venv)``).
VECNORMALIZE_FILE = "vecnormalize.pkl"


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
    its ``VecNormalize`` statistics, and for SAC/TD3 the replay buffer)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{algo}_{model.num_timesteps}_steps.zip"
    model.save(path)
    if normalize is not None:
        normalize.save(str(_normalization_file(path, algo)))
    if algo != "ppo":
        model.save_replay_buffer(_replay_buffer_file(path, algo))
    return path


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
    stats = _normalization_file(checkpoint, algo)
    if not stats.is_file():
        stats = checkpoint.with_name(VECNORMALIZE_FILE)
    if normalize is None and stats.is_file():
        raise UsageError(
            f"--resume {checkpoint}: it was trained with VecNormalize ({stats.name} is beside "
            "it) but the hyperparameters say normalize: false"
        )
    model = algorithm_class(algo).load(checkpoint, env=train_env, device=device)
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


def _train(args: Args) -> int:
    train(args)
    return 0


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


#: ``rocketroll train ppo``.
COMMAND = Command(
    "ppo",
    "train PPO on a RocketRoll environment (Stable-Baselines3)",
    Args,
    _train,
    __doc__ or "",
)
#: ``rocketroll train sac`` and ``rocketroll train td3``: the same script, off-policy.
SAC_COMMAND = Command(
    "sac",
    "train SAC on a RocketRoll environment (Stable-Baselines3)",
    SACArgs,
    _train,
    __doc__ or "",
)
TD3_COMMAND = Command(
    "td3",
    "train TD3 on a RocketRoll environment (Stable-Baselines3)",
    TD3Args,
    _train,
    __doc__ or "",
)
#: The arguments class of each algorithm (``rocketroll sweep`` trains through these).
TRAIN_ARGS: dict[str, type[Args]] = {"ppo": Args, "sac": SACArgs, "td3": TD3Args}

if __name__ == "__main__":
    sys.exit(run_command(COMMAND, sys.argv[1:], "python -m agents.train"))
