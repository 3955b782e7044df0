"""A sweep's spec (YAML): tasks, controllers with the settings to search, disturbance sets and
training seeds; its structure a pydantic model (:class:`SweepDocument`, whose JSON Schema is
``docs/schemas/sweep.schema.json``), checked into :class:`SweepSpec`."""

from __future__ import annotations

import itertools
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from agents.replay import (
    FIXED_OPTIONS,
    check_options,
    options_config,
)
from rocketroll_common.errors import UsageError
from rocketroll_common.specs import Count, Whole, as_whole, load_yaml, place, validated

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


def _axis(value: Any) -> list[Any]:
    """A search axis: a list of one or more values (a scalar is a list of one)."""
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ValueError("an empty list; give at least one value")
    return values


#: What a sweep's name may be: it names its folder under runs/sweeps/.
SWEEP_NAME = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9._-]*$")


def _sweep_name(name: str) -> str:
    if not SWEEP_NAME.fullmatch(name):
        raise ValueError(
            "must be one word of letters, digits, '.', '_' and '-' (it names the sweep's "
            f"folder, which it must not leave), got {name!r}"
        )
    return name


#: One or more values searched over (a scalar is a list of one).
Axis = Annotated[list[Any], BeforeValidator(_axis, json_schema_input_type=list[Any] | Any)]


class _Document(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SearchDocument(_Document):
    """How the points are chosen: every one (``grid``) or a seeded random sample."""

    kind: Literal["grid", "random"] = Field("grid", description="every point, or a sample")
    trials: Count | None = Field(
        None, description="points drawn without replacement (kind: random)"
    )
    seed: Whole = Field(0, description="the sample's seed")

    @model_validator(mode="after")
    def _trials_for_random(self) -> SearchDocument:
        if self.kind == "random" and self.trials is None:
            raise ValueError("kind random needs trials: N")
        return self


class ControllerDocument(_Document):
    """One controller: a ``--policy`` of ``rocketroll eval`` (``policy``), or a recipe trained
    per trial (``train`` and ``hyperparams``, optional ``timesteps``, a ``grid`` of its
    hyperparameters searched over)."""

    name: str = Field(min_length=1, description="the controller's name in the tables")
    policy: str | None = Field(None, description="a --policy of rocketroll eval (NAME[:ARG])")
    train: Literal["ppo", "sac", "td3"] | None = Field(None, description="algorithm to train")
    hyperparams: str | None = Field(
        None, description="the recipe's YAML file, relative to the spec (or the cwd)"
    )
    timesteps: Count | None = Field(
        None, description="environment steps (default: the entry's n_timesteps)"
    )
    grid: dict[str, Axis] = Field(
        default_factory=dict, description="hyperparameters searched over (dotted keys reach in)"
    )

    @model_validator(mode="after")
    def _one_kind(self) -> ControllerDocument:
        if (self.policy is None) == (self.train is None):
            raise ValueError("give exactly one of policy (evaluate) or train (learn)")
        if self.policy is not None:
            for key in ("hyperparams", "timesteps"):
                if getattr(self, key) is not None:
                    raise ValueError(f"{key} is for a trained controller (train: ALGO)")
            if self.grid:
                raise ValueError("grid is for a trained controller's hyperparameters")
        elif self.hyperparams is None:
            raise ValueError("hyperparams (the YAML file of the recipe) is missing")
        return self


class SweepDocument(_Document):
    """A sweep spec as written (the package's docstring): the structure pydantic checks;
    :func:`load_spec` then checks what needs the toolkit (registered env ids and policies,
    the recipes' files and entries) and makes the :class:`SweepSpec`."""

    name: Annotated[str, AfterValidator(_sweep_name)] = Field(
        json_schema_extra={"pattern": SWEEP_NAME.pattern},
        description="one word of letters, digits, '.', '_' and '-': it names the sweep's "
        "folder, which it must not leave",
    )
    env_ids: Annotated[
        list[str], BeforeValidator(_axis, json_schema_input_type=list[str] | str)
    ] = Field(description="the tasks (registered environment ids)")
    controllers: list[ControllerDocument] = Field(min_length=1)
    seeds: Annotated[
        list[Whole], BeforeValidator(_axis, json_schema_input_type=list[int] | int)
    ] = Field(default_factory=lambda: [0], description="training seeds of the learned controllers")
    episodes: Annotated[int, Field(strict=True, ge=2), BeforeValidator(as_whole)] = Field(
        20, description="test-split episodes of the evaluation protocol"
    )
    eval_seed: Whole = Field(0, description="the evaluation episodes' seed")
    settings: dict[str, Axis] = Field(
        default_factory=dict, description="environment settings searched over"
    )
    search: SearchDocument = SearchDocument()


def load_spec(path: str | os.PathLike[str], options: Mapping[str, Any] | None = None) -> SweepSpec:
    """The spec in the YAML file ``path``, checked key by key; ``options`` (``sweep run
    --set``) are environment options of every trial, over the spec's ``settings``.

    Raises
    ------
    UsageError
        Naming the file, the line and the key: a missing file, bad YAML, an unknown or
        missing key, a value of the wrong kind (:class:`SweepDocument`), an unknown env id
        or policy, a hyperparameter file without the env id's entry.
    """
    from agents.registry import CONTROLLERS
    from rollenv.variants import variant_ids

    path = Path(path)
    if not path.is_file() and path.parent == Path() and (SHIPPED / f"{path}.yml").is_file():
        path = SHIPPED / f"{path}.yml"  # a shipped spec by name
    if not path.is_file():
        shipped = ", ".join(sorted(p.stem for p in SHIPPED.glob("*.yml")))
        raise UsageError(f"{path}: no such sweep spec (shipped, by name: {shipped})")
    document, lines = load_yaml(path)
    doc = validated(SweepDocument, document, str(path), lines)

    def at(*key: str | int) -> str:
        return place(str(path), lines, key)

    for i, env_id in enumerate(doc.env_ids):
        if env_id not in variant_ids():
            raise UsageError(
                f"{at('env_ids', i)}: env_ids: unknown {env_id!r}; "
                f"one of {', '.join(variant_ids())}"
            )
    settings = {str(k): list(v) for k, v in doc.settings.items()}
    fixed = sorted(set(FIXED_OPTIONS) & set(settings))
    if fixed:
        raise UsageError(
            f"{at('settings', fixed[0])}: settings.{fixed[0]}: not a setting to search (the "
            "task follows env_ids, the evaluation's split is the test split)"
        )
    check_options(options or {})
    settings.update({k: [v] for k, v in (options or {}).items()})
    for env_id in doc.env_ids:
        for point in points(settings):
            options_config(env_id, point, "test", flag=f"{path}: settings {point} on {env_id}")
    controllers = []
    for i, entry in enumerate(doc.controllers):
        where = f"{at('controllers', i)}: controller {entry.name!r}"
        grid = {str(k): list(v) for k, v in entry.grid.items()}
        if entry.policy is not None:
            policy = entry.policy
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
            controllers.append(ControllerSpec(entry.name, policy=policy))
            continue
        assert entry.train is not None and entry.hyperparams is not None  # the document's check
        hyperparams = Path(entry.hyperparams)
        if not hyperparams.is_absolute() and (path.parent / hyperparams).is_file():
            hyperparams = path.parent / hyperparams  # relative to the spec, else to the cwd
        if not hyperparams.is_file():
            raise UsageError(f"{where}: hyperparams {entry.hyperparams}: no such file")
        for env_id in doc.env_ids:  # fail now, not in the middle of the sweep
            for point in points(grid):
                try:
                    entry_with(hyperparams, env_id, entry.train, point)
                except UsageError as exc:
                    raise UsageError(f"{where}: {exc}") from None
        controllers.append(
            ControllerSpec(
                entry.name,
                train=entry.train,
                hyperparams=str(hyperparams.resolve()),
                timesteps=entry.timesteps,
                grid=grid,
            )
        )
    names = [c.name for c in controllers]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise UsageError(f"{path}: controller name {repeated[0]!r} is given twice")
    return SweepSpec(
        name=doc.name,
        env_ids=list(doc.env_ids),
        controllers=controllers,
        seeds=list(doc.seeds),
        episodes=doc.episodes,
        eval_seed=doc.eval_seed,
        settings=settings,
        kind=doc.search.kind,
        trials=doc.search.trials,
        search_seed=doc.search.seed,
        source=str(path),
    )


def points(axes: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Every combination of one value per axis, keys in sorted order."""
    keys = sorted(axes)
    return [
        dict(zip(keys, values, strict=True))
        for values in itertools.product(*(axes[k] for k in keys))
    ]


def entry_with(
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
