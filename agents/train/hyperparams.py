"""The hyperparameter file of a training run: one entry per environment id, rl-baselines3-zoo's
layout, checked key by key into :class:`Hyperparameters`, and the algorithm's keywords made
from it."""

from __future__ import annotations

import inspect
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, RootModel, field_validator, model_validator

from agents.memory import PolicyLayout
from rocketroll_common.errors import UsageError
from rocketroll_common.specs import Count, Whole, load_yaml, place, validated

#: The hyperparameter files shipped with the package, one per algorithm.
HYPERPARAMS_DIR = Path(__file__).resolve().parents[1] / "hyperparams"
#: PPO's (``rocketroll train ppo``'s default).
DEFAULT_HYPERPARAMS = HYPERPARAMS_DIR / "ppo.yml"


def shipped_recipes() -> tuple[str, ...]:
    """The names of the hyperparameter files shipped with the package (``ppo-history`` for
    ``agents/hyperparams/ppo-history.yml``), sorted."""
    return tuple(sorted(p.stem for p in HYPERPARAMS_DIR.glob("*.yml")))


def recipe_path(given: str | os.PathLike[str]) -> Path:
    """The hyperparameter file ``given`` names: a shipped recipe's name (``ppo-history``:
    the package's ``agents/hyperparams/ppo-history.yml``, wherever it is installed), or a
    path (a relative ``agents/hyperparams/...`` that is not there is the package's, as the
    docs write it from the repository).

    Raises
    ------
    UsageError
        A name (no folder, no ``.yml``) that is no shipped recipe: the line lists them.
    """
    path = Path(given)
    if path.suffix.lower() in (".yml", ".yaml") or len(path.parts) != 1 or path.exists():
        if not path.exists() and not path.is_absolute():
            installed = HYPERPARAMS_DIR.parents[1] / path
            if installed.is_file():
                return installed
        return path
    shipped = HYPERPARAMS_DIR / f"{path.name}.yml"
    if not shipped.is_file():
        raise UsageError(
            f"--hyperparams {given}: no such file, nor a shipped recipe (those are: "
            f"{', '.join(shipped_recipes())})"
        )
    return shipped


#: ``rocketroll train ALGO`` → the Stable-Baselines3 class.
ALGORITHMS = {"ppo": "PPO", "sac": "SAC", "td3": "TD3"}

#: Keys of a YAML entry that are not keywords of the algorithm: ``history`` (steps of
#: past observations and actions in the observation, :mod:`agents.memory`), ``observer``
#: (true: the observer's estimate ``[v̂, ψ̂, û_d]`` in the observation,
#: :class:`agents.observer.ObserverFeatures`, designed on the train split), ``residual``
#: (a scale in (0, 1]: the action is a residual added to the observer controller's command,
#: × the scale; implies ``observer``), ``incremental`` (a scale in (0, 1]: the action is
#: a change of the last fin command, × the scale, :class:`agents.memory.PolicyObservation`),
#: ``flight_clock`` (true, on a flight variant: the
#: flight's gain and damping multipliers at the coming control step in the observation,
#: :class:`agents.memory.FlightClock`), ``integral`` (a time constant, s: the leaky
#: integral of the observed error in the observation, :class:`agents.memory.ErrorIntegral`,
#: its integrand clipped at ``integral_clip``), and for the off-policy algorithms the exploration
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
    "incremental",
    "flight_clock",
    "integral",
    "integral_clip",
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


#: ``VecNormalize`` arguments a YAML ``normalize`` mapping may set.
NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")
#: ``policy_kwargs.activation_fn`` names.
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")


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
    algo_kwargs : dict
        The algorithm's keywords as written in the file (schedules as
        ``"lin_<x>"``, the activation as a name).
    source : str
        The file.
    algo : str
        The algorithm the entry is for.
    noise : tuple or None
        ``("normal", sd)``: Gaussian exploration noise on the action (SAC, TD3).
    layout : PolicyLayout
        What the policy reads and sends beyond the env's observation and action: history,
        the observer's estimate, a residual or incremental action, the flight's phase, the
        error's integral; ``settings.json`` records it (:meth:`PolicyLayout.record`).
    """

    env_id: str
    n_envs: int
    n_timesteps: int | None
    policy: str
    normalize: dict[str, Any] | None
    env_kwargs: dict[str, Any]
    algo_kwargs: dict[str, Any]
    source: str
    algo: str = "ppo"
    noise: tuple[str, float] | None = None
    layout: PolicyLayout = field(default_factory=PolicyLayout)


# ------------------------------------------------------------------------ hyperparameters
class HyperparameterEntry(BaseModel):
    """One entry of a hyperparameter file as written (rl-baselines3-zoo's layout): the keys
    the script reads, typed; any other key is a keyword of the algorithm's Stable-Baselines3
    class, which :func:`load_hyperparameters` checks against its signature.  The JSON Schema
    of a whole file (entries keyed by environment id) is
    ``docs/schemas/hyperparams.schema.json``."""

    model_config = ConfigDict(extra="allow", frozen=True)

    n_envs: Count = Field(1, description="environments stepped side by side")
    n_timesteps: Count | None = Field(
        None, description="environment steps to train for (else --timesteps)"
    )
    policy: str = Field("MlpPolicy", description="SB3 policy name")
    normalize: bool | dict[str, Any] | str | None = Field(
        False,
        description="VecNormalize: true, false, a mapping of its arguments, or the zoo's "
        '"dict(...)" string',
    )
    env_kwargs: dict[str, Any] = Field(
        default_factory=dict, description="RocketRoll settings of the training and evaluation envs"
    )
    history: Whole = Field(
        0, description="steps of past observations and actions beside the observation"
    )
    observer: Annotated[bool, Field(strict=True)] | None = Field(
        None, description="the observer's estimate in the observation"
    )
    residual: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = Field(
        0.0, description="0, or the scale of the action as a residual on the observer controller"
    )
    incremental: Annotated[float, Field(strict=True, ge=0.0, le=1.0)] = Field(
        0.0, description="0, or the scale of the action as a change of the last fin command"
    )
    flight_clock: Annotated[bool, Field(strict=True)] = Field(
        False, description="the flight's phase in the observation (a flight variant)"
    )
    integral: Annotated[float, Field(strict=True, ge=0.0, allow_inf_nan=False)] = Field(
        0.0,
        description="0, or the time constant (s) of the observed error's leaky integral in "
        "the observation",
    )
    integral_clip: Annotated[float, Field(strict=True, gt=0.0, allow_inf_nan=False)] | None = Field(
        None, description="the largest error magnitude the integral integrates (none: no clip)"
    )
    noise_type: Literal["normal"] | None = Field(
        None, description="exploration noise of SAC and TD3"
    )
    noise_std: Annotated[float, Field(strict=True, gt=0.0, lt=10.0)] | None = Field(
        None, description="its standard deviation (a fraction of the action range)"
    )

    @field_validator(
        "residual", "incremental", "integral", "integral_clip", "noise_std", mode="before"
    )
    @classmethod
    def _a_number(cls, value: Any) -> Any:
        if isinstance(value, int) and not isinstance(value, bool):
            return float(value)  # a whole number is a number (strict floats refuse it)
        return value

    @model_validator(mode="after")
    def _consistent(self) -> HyperparameterEntry:
        if self.residual and self.observer is False:
            raise ValueError(
                "residual acts on the observer controller, whose estimate the policy reads: "
                "observer: false contradicts it"
            )
        if self.incremental and (self.residual or self.observer):
            raise ValueError(
                "incremental moves the fin from its last command; with the observer's "
                "estimate or a residual on its controller it is not supported"
            )
        if self.integral_clip is not None and not self.integral:
            raise ValueError("integral_clip clips the error the integral sums: give integral too")
        return self


def load_hyperparameters(
    path: str | os.PathLike[str], env_id: str, algo: str = "ppo"
) -> Hyperparameters:
    """The entry ``env_id`` of the YAML file ``path`` for ``algo``, checked key by key
    (:class:`HyperparameterEntry`, then the algorithm's keywords and what needs the
    toolkit).

    Raises
    ------
    UsageError
        The file is missing or not a mapping, has no entry for ``env_id``, or a key that is
        unknown, missing or of the wrong kind (named, with the file and its line).
    """
    path = recipe_path(path)
    if not path.is_file():
        raise UsageError(f"--hyperparams {path}: no such file")
    document, lines = load_yaml(path)
    if not isinstance(document, dict):
        raise UsageError(f"--hyperparams {path}: expected a mapping keyed by environment id")
    if env_id not in document:
        raise UsageError(
            f"--hyperparams {path} has no entry for {env_id!r} (it has: "
            f"{', '.join(map(str, document)) or 'none'})"
        )
    raw = document[env_id]
    where = f"{place(str(path), lines, (env_id,))}: {env_id}"
    set_here = sorted(set(raw) & set(SCRIPT_SET)) if isinstance(raw, dict) else []
    if set_here:
        raise UsageError(
            f"{where}: {set_here[0]!r} is set by the command line (--{set_here[0]}), not the "
            "hyperparameter file"
        )
    keywords = algorithm_keywords(algo)
    unknown = sorted(set(raw) - set(SCRIPT_KEYS) - set(keywords)) if isinstance(raw, dict) else []
    if unknown:
        raise UsageError(
            f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; known: "
            f"{', '.join(SCRIPT_KEYS + keywords)}"
        )
    entry = validated(HyperparameterEntry, raw, str(path), lines, at=(env_id,))
    noise = None
    if entry.noise_type is not None or entry.noise_std is not None:
        if algo == "ppo":
            raise UsageError(f"{where}: noise_type/noise_std are for SAC and TD3, not PPO")
        if entry.noise_type is None or entry.noise_std is None:
            raise UsageError(f"{where}: give both noise_type: normal and noise_std")
        noise = ("normal", float(entry.noise_std))
    normalize = entry.normalize
    if isinstance(normalize, str):  # rl-baselines3-zoo's "dict(norm_obs=True, ...)"
        normalize = zoo_mapping(normalize, f"{where}: normalize")
    if normalize is True:
        normalize = {}
    if normalize is False or normalize is None:
        normalize = None
    else:
        bad = sorted(set(normalize) - set(NORMALIZE_KEYS))
        if bad:
            raise UsageError(
                f"{where}: unknown normalize key(s) {', '.join(map(repr, bad))}; known: "
                f"{', '.join(NORMALIZE_KEYS)}"
            )
    layout = PolicyLayout(  # a residual implies the observer's estimate
        history=entry.history,
        observer=bool(entry.observer),
        residual=float(entry.residual),
        incremental=float(entry.incremental),
        flight_clock=entry.flight_clock,
        integral=float(entry.integral),
        integral_clip=None if entry.integral_clip is None else float(entry.integral_clip),
    )
    redesign = sorted(set(entry.env_kwargs) & set(OBSERVER_DESIGN))
    if layout.observer and redesign:
        raise UsageError(
            f"{where}: observer: true with env_kwargs {redesign[0]!r}: the observer is designed "
            "on the train split of the environment evaluated, which that setting changes"
        )
    if entry.flight_clock:
        from rollenv.variants import variant_options

        if variant_options(env_id).get("flight") is None and "flight" not in entry.env_kwargs:
            raise UsageError(
                f"{where}: flight_clock is the phase of a flight; {env_id} is not a flight variant"
            )
    algo_kwargs = {key: raw[key] for key in keywords if key in raw}
    if isinstance(algo_kwargs.get("policy_kwargs"), str):  # rl-baselines3-zoo's "dict(...)"
        algo_kwargs["policy_kwargs"] = zoo_mapping(
            algo_kwargs["policy_kwargs"], f"{where}: policy_kwargs"
        )
    _algorithm_arguments(algo_kwargs, where)  # fail now on a bad schedule or activation
    return Hyperparameters(
        env_id=env_id,
        n_envs=entry.n_envs,
        n_timesteps=entry.n_timesteps,
        policy=entry.policy,
        normalize=normalize,
        env_kwargs=dict(entry.env_kwargs),
        algo_kwargs=algo_kwargs,
        source=str(path),
        algo=algo,
        noise=noise,
        layout=layout,
    )


#: A hyperparameter file as an editor checks it: entries keyed by environment id.
HyperparameterFile = RootModel[dict[str, HyperparameterEntry]]


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


def _algorithm_arguments(algo_kwargs: dict[str, Any], where: str) -> dict[str, Any]:
    """The algorithm's keywords from a YAML entry: schedules and the activation resolved."""
    import torch

    out = dict(algo_kwargs)
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


def algorithm_arguments(hp: Hyperparameters) -> dict[str, Any]:
    """The algorithm's keywords of ``hp``: ``"lin_<x>"`` schedules and the activation name
    resolved (SB3's ``PPO``, ``SAC`` or ``TD3`` takes them)."""
    return _algorithm_arguments(hp.algo_kwargs, f"{hp.source}, {hp.env_id}")
