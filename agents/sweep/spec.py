"""A sweep's spec (YAML): tasks, controllers with the settings to search, disturbance sets and
training seeds, checked key by key into :class:`SweepSpec`."""

from __future__ import annotations

import itertools
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.replay import (
    FIXED_OPTIONS,
    check_options,
    options_config,
)
from rocketroll_common.errors import UsageError

#: Algorithms a controller of a spec may train.
TRAINABLE = ("ppo", "sac", "td3")


# ----------------------------------------------------------------------------- the spec
@dataclass(frozen=True)
class ControllerSpec:
    """One controller of a spec: a ``--policy`` (``policy``) or a training recipe
    (``train`` + ``hyperparams``, optional ``timesteps``), with the grid searched over."""

    name: str
    policy: str | None = None
    train: str | None = None
    hyperparams: str | None = None
    timesteps: int | None = None
    grid: dict[str, list[Any]] = field(default_factory=dict)

    @property
    def learned(self) -> bool:
        return self.train is not None


@dataclass(frozen=True)
class SweepSpec:
    """A checked sweep spec (module docstring)."""

    name: str
    env_ids: list[str]
    controllers: list[ControllerSpec]
    seeds: list[int] = field(default_factory=lambda: [0])
    episodes: int = 20
    eval_seed: int = 0
    settings: dict[str, list[Any]] = field(default_factory=dict)
    kind: str = "grid"
    trials: int | None = None
    search_seed: int = 0
    source: str = "<spec>"


#: The sweep specs shipped with the package: ``rocketroll sweep run NAME`` finds them.
SHIPPED = Path(__file__).resolve().parents[1] / "sweeps"
#: What a sweep's name may be: it names its folder under runs/sweeps/.
_SWEEP_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")
_TOP_KEYS = ("name", "env_ids", "controllers", "seeds", "episodes", "eval_seed", "settings")
_CONTROLLER_KEYS = ("name", "policy", "train", "hyperparams", "timesteps", "grid")


def _values(value: Any, where: str) -> list[Any]:
    """A search axis: a list of one or more values (a scalar is a list of one)."""
    values = value if isinstance(value, list) else [value]
    if not values:
        raise UsageError(f"{where}: an empty list; give at least one value")
    return values


def _whole(value: Any, where: str, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
        raise UsageError(f"{where}: must be a whole number, got {value!r}")
    if value < low:
        raise UsageError(f"{where}: must be >= {low}, got {value!r}")
    return int(value)


def load_spec(path: str | os.PathLike[str], options: Mapping[str, Any] | None = None) -> SweepSpec:
    """The spec in the YAML file ``path``, checked key by key; ``options`` (``sweep run
    --set``) are environment options of every trial, over the spec's ``settings``.

    Raises
    ------
    UsageError
        Naming the file and the key: a missing file, bad YAML, an unknown or
        missing key, a value of the wrong kind, an unknown env id, algorithm
        or policy, a hyperparameter file without the env id's entry.
    """
    import yaml

    from agents.registry import CONTROLLERS
    from rollenv.variants import variant_ids

    path = Path(path)
    if not path.is_file() and path.parent == Path() and (SHIPPED / f"{path}.yml").is_file():
        path = SHIPPED / f"{path}.yml"  # a shipped spec by name
    if not path.is_file():
        shipped = ", ".join(sorted(p.stem for p in SHIPPED.glob("*.yml")))
        raise UsageError(f"{path}: no such sweep spec (shipped, by name: {shipped})")
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise UsageError(f"{path}: not a YAML file ({exc})".replace("\n", " ")) from None
    if not isinstance(document, dict):
        raise UsageError(f"{path}: expected a mapping (name, env_ids, controllers, ...)")
    unknown = sorted(set(document) - {*_TOP_KEYS, "search"})
    if unknown:
        raise UsageError(
            f"{path}: unknown key {unknown[0]!r}; known: {', '.join((*_TOP_KEYS, 'search'))}"
        )
    for key in ("name", "env_ids", "controllers"):
        if key not in document:
            raise UsageError(f"{path}: {key!r} is missing")
    name = document["name"]
    if not isinstance(name, str) or not _SWEEP_NAME.fullmatch(name):
        raise UsageError(
            f"{path}: name must be one word of letters, digits, '.', '_' and '-' (it names the "
            f"sweep's folder, which it must not leave), got {name!r}"
        )
    env_ids = [str(e) for e in _values(document["env_ids"], f"{path}: env_ids")]
    for env_id in env_ids:
        if env_id not in variant_ids():
            raise UsageError(
                f"{path}: env_ids: unknown {env_id!r}; one of {', '.join(variant_ids())}"
            )
    seeds = [_whole(s, f"{path}: seeds") for s in _values(document.get("seeds", [0]), "seeds")]
    episodes = _whole(document.get("episodes", 20), f"{path}: episodes", low=2)
    eval_seed = _whole(document.get("eval_seed", 0), f"{path}: eval_seed")
    settings_in = document.get("settings") or {}
    if not isinstance(settings_in, dict):
        raise UsageError(f"{path}: settings must be a mapping of setting -> values")
    settings = {str(k): _values(v, f"{path}: settings.{k}") for k, v in settings_in.items()}
    fixed = sorted(set(FIXED_OPTIONS) & set(settings))
    if fixed:
        raise UsageError(
            f"{path}: settings.{fixed[0]}: not a setting to search (the task follows env_ids, "
            "the evaluation's split is the test split)"
        )
    check_options(options or {})
    settings.update({k: [v] for k, v in (options or {}).items()})
    for env_id in env_ids:
        for point in points(settings):
            options_config(env_id, point, "test", flag=f"{path}: settings {point} on {env_id}")
    search = document.get("search") or {"kind": "grid"}
    if not isinstance(search, dict) or search.get("kind") not in ("grid", "random"):
        raise UsageError(f"{path}: search must be {{kind: grid}} or {{kind: random, trials: N}}")
    bad = sorted(set(search) - {"kind", "trials", "seed"})
    if bad:
        raise UsageError(f"{path}: search: unknown key {bad[0]!r}; known: kind, trials, seed")
    trials = None
    if search["kind"] == "random":
        if "trials" not in search:
            raise UsageError(f"{path}: search: kind random needs trials: N")
        trials = _whole(search["trials"], f"{path}: search.trials", low=1)
    controllers_in = document["controllers"]
    if not isinstance(controllers_in, list) or not controllers_in:
        raise UsageError(f"{path}: controllers must be a list of one or more controllers")
    controllers = []
    for i, entry in enumerate(controllers_in):
        where = f"{path}: controllers[{i}]"
        if not isinstance(entry, dict):
            raise UsageError(f"{where}: expected a mapping (name, policy or train, ...)")
        bad = sorted(set(entry) - set(_CONTROLLER_KEYS))
        if bad:
            raise UsageError(
                f"{where}: unknown key {bad[0]!r}; known: {', '.join(_CONTROLLER_KEYS)}"
            )
        cname = entry.get("name")
        if not isinstance(cname, str) or not cname:
            raise UsageError(f"{where}: name must be a non-empty text")
        where = f"{path}: controller {cname!r}"
        if ("policy" in entry) == ("train" in entry):
            raise UsageError(f"{where}: give exactly one of policy (evaluate) or train (learn)")
        grid_in = entry.get("grid") or {}
        if not isinstance(grid_in, dict):
            raise UsageError(f"{where}: grid must be a mapping of hyperparameter -> values")
        grid = {str(k): _values(v, f"{where}: grid.{k}") for k, v in grid_in.items()}
        if "policy" in entry:
            policy = str(entry["policy"])
            kind, sep, arg = policy.partition(":")
            if sep and arg and not Path(arg).is_absolute():  # a run's folder: made absolute,
                for base in (path.parent, Path.cwd()):  # so workers anywhere find it
                    if (base / arg).exists():
                        policy = f"{kind}:{(base / arg).resolve()}"
                        break
            if policy.split(":", 1)[0] not in CONTROLLERS.names():
                raise UsageError(
                    f"{where}: unknown policy {policy!r}; one of {', '.join(CONTROLLERS.names())}"
                )
            for key in ("hyperparams", "timesteps"):
                if key in entry:
                    raise UsageError(f"{where}: {key} is for a trained controller (train: ALGO)")
            if grid:
                raise UsageError(f"{where}: grid is for a trained controller's hyperparameters")
            controllers.append(ControllerSpec(cname, policy=policy))
            continue
        algo = entry["train"]
        if algo not in TRAINABLE:
            raise UsageError(f"{where}: train must be one of {', '.join(TRAINABLE)}, got {algo!r}")
        if "hyperparams" not in entry:
            raise UsageError(f"{where}: hyperparams (the YAML file of the recipe) is missing")
        hyperparams = Path(str(entry["hyperparams"]))
        if not hyperparams.is_absolute() and (path.parent / hyperparams).is_file():
            hyperparams = path.parent / hyperparams  # relative to the spec, else to the cwd
        if not hyperparams.is_file():
            raise UsageError(f"{where}: hyperparams {entry['hyperparams']}: no such file")
        timesteps = entry.get("timesteps")
        if timesteps is not None:
            timesteps = _whole(timesteps, f"{where}: timesteps", low=1)
        for env_id in env_ids:  # fail now, not in the middle of the sweep
            for point in points(grid):
                try:
                    _entry_with(hyperparams, env_id, str(algo), point)
                except UsageError as exc:
                    raise UsageError(f"{where}: {exc}") from None
        controllers.append(
            ControllerSpec(
                cname,
                train=str(algo),
                hyperparams=str(hyperparams.resolve()),
                timesteps=timesteps,
                grid=grid,
            )
        )
    names = [c.name for c in controllers]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise UsageError(f"{path}: controller name {repeated[0]!r} is given twice")
    return SweepSpec(
        name=name,
        env_ids=env_ids,
        controllers=controllers,
        seeds=seeds,
        episodes=episodes,
        eval_seed=eval_seed,
        settings=settings,
        kind=str(search["kind"]),
        trials=trials,
        search_seed=_whole(search.get("seed", 0), f"{path}: search.seed"),
        source=str(path),
    )


def points(axes: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Every combination of one value per axis, keys in sorted order."""
    keys = sorted(axes)
    return [
        dict(zip(keys, values, strict=True))
        for values in itertools.product(*(axes[k] for k in keys))
    ]


def _entry_with(
    hyperparams: Path, env_id: str, algo: str, overrides: dict[str, Any]
) -> dict[str, Any]:
    """The hyperparameter entry of ``env_id`` with ``overrides`` (dotted keys reach into
    mappings: ``policy_kwargs.net_arch``), checked as ``rocketroll train`` checks it."""
    import tempfile

    import yaml

    from agents.train import load_hyperparameters

    document = yaml.safe_load(hyperparams.read_text(encoding="utf-8"))
    if not isinstance(document, dict) or env_id not in document:
        raise UsageError(f"{hyperparams}: no entry for {env_id!r}")
    entry = json.loads(json.dumps(document[env_id]))  # a deep copy
    for key, value in overrides.items():
        *parents, last = key.split(".")
        node = entry
        for parent in parents:
            node = node.setdefault(parent, {})
            if not isinstance(node, dict):
                raise UsageError(f"{hyperparams}, {env_id}: grid key {key!r}: {parent} is no map")
        node[last] = value
    with tempfile.TemporaryDirectory() as tmp:
        trial_file = Path(tmp) / "hyperparams.yml"
        trial_file.write_text(yaml.safe_dump({env_id: entry}), encoding="utf-8")
        try:
            load_hyperparameters(trial_file, env_id, algo)
        except UsageError as exc:  # name the user's file, not the temporary one
            named = str(exc).replace(str(trial_file), f"{hyperparams} with {overrides}")
            raise UsageError(named) from None
    return dict(entry)
