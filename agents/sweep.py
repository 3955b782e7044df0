"""Experiments as data: ``rocketroll sweep run SPEC.yml`` trains and evaluates a grid or a
random sample of trials and keeps every result in one SQLite file.

A *spec* (YAML) names the tasks, the controllers with the settings to search,
the disturbance sets and the training seeds::

    name: pid-ppo-seeds
    env_ids: [RocketRoll-v0, RocketRollRate-v0]
    episodes: 20              # the evaluation protocol: test split, 20 episodes,
    eval_seed: 0              # episode seed 0 (agents.evaluate.protocol_episodes)
    seeds: [0, 1, 2, 3, 4]    # training seeds (a learned controller's trials)
    settings:                 # environment settings searched over (disturbance sets)
      method: [ml, paper]
    search: {kind: grid}      # or {kind: random, trials: 12, seed: 0}
    controllers:
      - {name: pid, policy: pid}             # any --policy of rocketroll eval
      - name: ppo
        train: ppo                           # ppo, sac or td3: trained per trial
        hyperparams: ../agents/hyperparams/ppo.yml   # relative to the spec (or the cwd)
        timesteps: 100000                    # optional, the entry's n_timesteps otherwise
        grid: {learning_rate: [0.0001, 0.0003]}   # hyperparameters searched over

A *trial* is one point: an env id, a controller with one value of each of its
grid's keys, one value of each ``settings`` key and (learned controllers) one
training seed.  ``kind: grid`` runs every point; ``kind: random`` draws
``trials`` of them without replacement (seeded).  Each trial trains (a
learned controller: ``agents.train.train`` into ``OUT/trials/ID/``, its
hyperparameter entry with the grid's values written to ``hyperparams.yml``
there) and is evaluated on the fixed test protocol
(:func:`agents.evaluate.evaluate`, the same episodes for every trial of an env
id and settings).

The *results store* is ``OUT/results.sqlite`` (:class:`ResultStore`): one row
per trial with its spec, seed, package version, git revision, status, error,
every metric's mean and the per-episode headline, wall time and artifact
paths, written in one transaction when the trial ends.  A trial's id is the
hash of its spec, so a sweep run again with the same ``--out`` skips the
trials already done (resume) and re-runs the ones that failed; a trial that
raises records its error and the sweep goes on.  ``--jobs N`` runs trials in
``N`` worker processes (``concurrent.futures``); the results do not depend on
``N``: every trial is seeded by its spec alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import io
import itertools
import json
import os
import re
import shutil
import sqlite3
import subprocess
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.replay import (
    FIXED_OPTIONS,
    check_options,
    db_setting,
    env_options_setting,
    fitted_settings,
    options_config,
    recording_setting,
    replay_options,
)
from rocketroll_common import __version__
from rocketroll_common.arrays import nan_to_none
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, setting

__all__ = [
    "COMMAND",
    "ControllerSpec",
    "ResultStore",
    "SweepSpec",
    "Trial",
    "expand",
    "load_spec",
    "run_sweep",
    "run_trial",
]

#: Algorithms a controller of a spec may train.
TRAINABLE = ("ppo", "sac", "td3")
#: The results store's schema version (``PRAGMA user_version``).
SCHEMA_VERSION = 1
_SCHEMA = """
CREATE TABLE IF NOT EXISTS trials (
    id TEXT PRIMARY KEY,
    sweep TEXT NOT NULL,
    env_id TEXT NOT NULL,
    controller TEXT NOT NULL,
    seed INTEGER,
    spec TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('done', 'failed')),
    error TEXT,
    headline TEXT,
    headline_mean REAL,
    metrics TEXT,
    episode_headline TEXT,
    wall_s REAL NOT NULL,
    train_s REAL,
    env_steps_per_s REAL,
    artifacts TEXT,
    version TEXT NOT NULL,
    git_revision TEXT,
    finished_at TEXT NOT NULL
);
"""


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
SHIPPED = Path(__file__).resolve().parent / "sweeps"
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
        for point in _points(settings):
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
            for point in _points(grid):
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


# ----------------------------------------------------------------------------- trials
@dataclass(frozen=True)
class Trial:
    """One point of a sweep: everything that decides its result (and so its id)."""

    sweep: str
    env_id: str
    controller: ControllerSpec
    params: dict[str, Any]
    settings: dict[str, Any]
    seed: int | None
    episodes: int
    eval_seed: int
    #: A learned controller's effective hyperparameter entry (its file's, with the grid's
    #: values and the settings as env_kwargs): what the id hashes, not the file's path.
    recipe: dict[str, Any] | None = None

    def spec(self) -> dict[str, Any]:
        """The trial as plain data (what the store keeps and the id hashes)."""
        c = self.controller
        return {
            "env_id": self.env_id,
            "controller": c.name,
            "policy": c.policy,
            "train": c.train,
            "hyperparams": c.hyperparams,
            "timesteps": c.timesteps,
            "params": self.params,
            "settings": self.settings,
            "seed": self.seed,
            "episodes": self.episodes,
            "eval_seed": self.eval_seed,
            "recipe": self.recipe,
        }

    @property
    def id(self) -> str:
        """16 hex digits of the SHA-256 of :meth:`spec` without the recipe file's path (its
        content is in ``recipe``: an edited file makes new trials, a moved one does not; the
        sweep's name is not in it either: the same trial in two sweeps is one experiment)."""
        spec = self.spec()
        del spec["hyperparams"]
        text = json.dumps(spec, sort_keys=True, default=str)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]

    @property
    def label(self) -> str:
        """``controller`` with its searched values, for tables (``ppo lr=0.0003``)."""
        parts = [self.controller.name]
        parts += [f"{k}={v}" for k, v in sorted(self.params.items())]
        parts += [f"{k}={v}" for k, v in sorted(self.settings.items())]
        return " ".join(parts)


def _points(axes: dict[str, list[Any]]) -> list[dict[str, Any]]:
    keys = sorted(axes)
    return [
        dict(zip(keys, values, strict=True))
        for values in itertools.product(*(axes[k] for k in keys))
    ]


def expand(spec: SweepSpec) -> list[Trial]:
    """The trials of ``spec``: the full grid, or (``kind: random``) ``trials`` of its
    points drawn without replacement with ``search_seed``, in grid order.  A random
    sample of ``k`` points is the first ``k`` of one seeded permutation, so a larger
    sample contains a smaller one.  Repeated points (a value listed twice) are one trial."""
    trials: dict[str, Trial] = {}
    for env_id in spec.env_ids:
        for settings in _points(spec.settings):
            for controller in spec.controllers:
                seeds: Sequence[int | None] = spec.seeds if controller.learned else [None]
                for params in _points(controller.grid):
                    recipe = None
                    if controller.learned:
                        assert controller.hyperparams is not None and controller.train
                        # The disturbance set is trained on too (checked with the entry,
                        # before any trial); training reads the whole train split, so a
                        # recording chooses only what is evaluated.
                        trained_on = {
                            f"env_kwargs.{k}": v for k, v in settings.items() if k != "recording"
                        }
                        recipe = _entry_with(
                            Path(controller.hyperparams),
                            env_id,
                            controller.train,
                            {**params, **trained_on},
                        )
                    for seed in seeds:
                        trial = Trial(
                            spec.name,
                            env_id,
                            controller,
                            params,
                            settings,
                            seed,
                            spec.episodes,
                            spec.eval_seed,
                            recipe,
                        )
                        trials.setdefault(trial.id, trial)
    found = list(trials.values())
    if spec.kind == "random" and spec.trials is not None and spec.trials < len(found):
        order = np.random.default_rng(spec.search_seed).permutation(len(found))
        found = [found[i] for i in np.sort(order[: spec.trials])]
    return found


@functools.cache  # once per process: every trial of a run comes from the same checkout
def _git_revision() -> str | None:
    """The checkout's commit (with ``-dirty`` for uncommitted changes), None outside git."""
    root = Path(__file__).resolve().parent.parent
    try:
        rev = subprocess.run(
            ["git", "-C", str(root), "describe", "--always", "--dirty", "--abbrev=40"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return rev or None


def _record(trial: Trial) -> dict[str, Any]:
    """A trial's record before its result: what it is and what ran it."""
    return {
        "id": trial.id,
        "sweep": trial.sweep,
        "env_id": trial.env_id,
        "controller": trial.label,
        "seed": trial.seed,
        "spec": trial.spec(),
        "version": __version__,
        "git_revision": _git_revision(),
    }


def failed_record(trial: Trial, error: str, wall_s: float = 0.0) -> dict[str, Any]:
    """The record of a trial that gave no result of its own (its worker died)."""
    return {**_record(trial), "status": "failed", "error": error, "wall_s": wall_s}


def run_trial(trial: Trial, root: str | os.PathLike[str], db: str | None = None) -> dict[str, Any]:
    """Train (a learned controller) and evaluate one trial; its store record.

    Never raises for the trial's own failure: the record then has status
    ``failed`` and the error (its last traceback lines).  Output of training
    and evaluation is captured, not printed (trials may run side by side).
    """
    began = time.perf_counter()
    record = _record(trial)
    folder = Path(root) / "trials" / trial.id
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            record.update(_train_and_evaluate(trial, folder, db))
        record["status"] = "done"
    except Exception as exc:  # a failed trial is a result, not a crash
        lines = traceback.format_exception(exc)
        record["status"] = "failed"
        record["error"] = f"{type(exc).__name__}: {exc}\n" + "".join(lines[-6:])
    record["wall_s"] = time.perf_counter() - began
    return record


def _train_and_evaluate(trial: Trial, folder: Path, db: str | None) -> dict[str, Any]:
    import yaml

    from agents.evaluate import HEADLINE, evaluate, headline_scores, protocol_episodes
    from agents.registry import make_controller
    from rollenv.bank import load_bank

    c = trial.controller
    artifacts: dict[str, str] = {}
    out: dict[str, Any] = {}
    policy = c.policy
    if c.learned:
        from agents.train import TRAIN_ARGS, train

        assert trial.recipe is not None and c.train is not None
        entry = trial.recipe
        shutil.rmtree(folder, ignore_errors=True)  # a retried trial starts afresh
        folder.mkdir(parents=True)
        hyperparams = folder / "hyperparams.yml"
        hyperparams.write_text(yaml.safe_dump({trial.env_id: entry}), encoding="utf-8")
        run = folder / "run"
        args = TRAIN_ARGS[c.train](
            env_id=trial.env_id,
            hyperparams=hyperparams,
            out=run,
            seed=int(trial.seed or 0),
            timesteps=c.timesteps,
            db=db,
            eval_freq=0,
            checkpoint_freq=0,
            progress_bar=False,
        )
        settings = train(args)
        out["train_s"] = float(settings["train_time_s"])
        out["env_steps_per_s"] = float(settings["env_steps_per_s"])
        artifacts.update(run=str(run), model=str(run / "model.zip"), hyperparams=str(hyperparams))
        policy = f"{c.train}:{run}"
    assert policy is not None
    config = options_config(trial.env_id, trial.settings, "test")
    controller = make_controller(policy, config, trial.env_id, db=db)
    bank = load_bank(config, db)
    specs = protocol_episodes(config, trial.episodes, trial.eval_seed, bank=bank)
    result = evaluate(config, controller, specs, bank=bank)
    scores = headline_scores(result)
    out.update(
        headline=HEADLINE,
        headline_mean=float(np.nanmean(scores)) if np.isfinite(scores).any() else None,
        metrics={k: v["mean"] for k, v in result.aggregate.items()},
        episode_headline=scores.tolist(),
        artifacts=artifacts,
    )
    return out


# ----------------------------------------------------------------------------- the store
class ResultStore:
    """The sweep's results: ``trials`` in one SQLite file (schema :data:`_SCHEMA`).

    Each record is written in one transaction (``INSERT OR REPLACE``: a
    failed trial run again replaces its failure).  Query it with any SQLite
    client, :meth:`rows`, or :meth:`export_parquet`.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(self.path)
        version = self._db.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:
            raise UsageError(
                f"{self.path}: results store of schema {version}, newer than this rocketroll's "
                f"{SCHEMA_VERSION}"
            )
        with self._db:
            self._db.executescript(_SCHEMA)
            self._db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def done(self) -> set[str]:
        """Ids of the trials finished without error."""
        return {r[0] for r in self._db.execute("SELECT id FROM trials WHERE status = 'done'")}

    def record(self, record: dict[str, Any]) -> None:
        """Store one trial's record (one transaction)."""

        def text(key: str) -> str | None:
            value = record.get(key)
            return None if value is None else json.dumps(nan_to_none(value), allow_nan=False)

        row = (
            record["id"],
            record["sweep"],
            record["env_id"],
            record["controller"],
            record.get("seed"),
            json.dumps(record["spec"], sort_keys=True, default=str),
            record["status"],
            record.get("error"),
            record.get("headline"),
            record.get("headline_mean"),
            text("metrics"),
            text("episode_headline"),
            float(record["wall_s"]),
            record.get("train_s"),
            record.get("env_steps_per_s"),
            text("artifacts"),
            record["version"],
            record.get("git_revision"),
            time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        )
        with self._db:
            self._db.execute(f"INSERT OR REPLACE INTO trials VALUES ({', '.join('?' * 19)})", row)

    def rows(self, sweep: str | None = None) -> list[dict[str, Any]]:
        """Every trial (of ``sweep``) as a dict, JSON columns decoded, in id order."""
        self._db.row_factory = sqlite3.Row
        try:
            query = "SELECT * FROM trials" + (" WHERE sweep = ?" if sweep else "") + " ORDER BY id"
            found = self._db.execute(query, (sweep,) if sweep else ()).fetchall()
        finally:
            self._db.row_factory = None
        rows = []
        for r in found:
            row = dict(r)
            for key in ("spec", "metrics", "episode_headline", "artifacts"):
                if row[key] is not None:
                    row[key] = json.loads(row[key])
            rows.append(row)
        return rows

    def export_parquet(self, path: str | os.PathLike[str]) -> Path:
        """Every row into a Parquet file (needs pyarrow: ``pip install 'rocketroll[parquet]'``);
        the JSON columns stay JSON text."""
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise UsageError(
                "Parquet export needs pyarrow: pip install 'rocketroll[parquet]'"
            ) from exc
        cursor = self._db.execute("SELECT * FROM trials ORDER BY id")
        names = [d[0] for d in cursor.description]
        found = cursor.fetchall()
        table = pa.table({n: [row[i] for row in found] for i, n in enumerate(names)})
        target = Path(path)
        pq.write_table(table, target)
        return target


# ----------------------------------------------------------------------------- running
def run_sweep(
    spec: SweepSpec,
    out: str | os.PathLike[str],
    *,
    jobs: int = 1,
    db: str | None = None,
    progress: bool = True,
    ray: str | None = None,
    trials: Sequence[Trial] | None = None,
) -> list[dict[str, Any]]:
    """Run every trial of ``spec`` (``trials``: its :func:`expand`, if already made) not yet
    done in ``OUT/results.sqlite``; the records of this run (finished and failed), in the
    order they ended.

    ``ray``: run the trials as Ray Tune trials on the cluster at that address
    (``"auto"``: the running cluster this machine belongs to, or a local
    instance; an already initialised Ray is used as it is), one CPU each,
    instead of ``jobs`` local processes.  Each record reaches the store in
    this process as its trial ends, as in-process; ``OUT`` and the database
    must be on a file system every node sees.
    """
    root = Path(out).resolve()
    if db is None:  # name it for the workers, whose environment may differ
        from disturbances.default import default_path

        db = str(default_path())
    db = str(Path(db).resolve())  # Ray runs each trial in a folder of its own
    if ray:
        _ray_module(ray)  # refused before anything is made
    if trials is None:
        trials = expand(spec)
    with ResultStore(root / "results.sqlite") as store:
        done = store.done()
        todo = [t for t in trials if t.id not in done]
        records: list[dict[str, Any]] = []
        bar = _bar(len(todo), f"sweep {spec.name}", progress)

        def take(record: dict[str, Any]) -> None:
            store.record(record)
            records.append(record)
            bar.update(1)
            if record["status"] == "failed":
                bar.write(
                    f"trial {record['id']} ({record['controller']}) failed: "
                    f"{record['error'].splitlines()[0]}"
                )

        errors: dict[str, str] = {}
        if ray:
            errors = _on_ray(todo, root, db, ray, take)
        else:
            for record in _execute(todo, root, db, jobs):
                take(record)
        seen = {r["id"] for r in records}
        for trial in todo:  # a worker that died: its trial failed, to be retried
            if trial.id not in seen:
                take(failed_record(trial, errors.get(trial.id, "no result came back")))
        bar.close()
    return records


def _bar(total: int, desc: str, enabled: bool) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="trial", disable=not enabled)


def _execute(
    trials: Sequence[Trial], root: Path, db: str | None, jobs: int
) -> Iterator[dict[str, Any]]:
    if jobs <= 1 or len(trials) <= 1:
        for trial in trials:
            yield run_trial(trial, root, db)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(run_trial, t, root, db): t for t in trials}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:  # the worker died (memory, a signal): the trial failed
                yield failed_record(futures[future], f"{type(exc).__name__}: {exc}")


def _on_ray(
    trials: Sequence[Trial],
    root: Path,
    db: str,
    address: str,
    take: Callable[[dict[str, Any]], None],
) -> dict[str, str]:
    """The trials as Ray Tune trials (one CPU each); ``take`` gets each record as its trial
    ends (:mod:`agents.sweep_ray`); the errors of trials that gave none, by trial id."""
    sweep_ray = _ray_module(address)
    if not trials:
        return {}
    return sweep_ray.run(trials, run_trial, root, db, address, take)


def _ray_module(address: str) -> Any:
    """:mod:`agents.sweep_ray`, or a ``UsageError`` when Ray Tune is missing or ``address``
    cannot hold the results store (before anything is made)."""
    try:
        from agents import sweep_ray
    except ImportError as exc:
        raise UsageError(
            "--ray needs Ray Tune, an optional extra: pip install 'rocketroll[ray]'"
        ) from exc
    if address.startswith("ray://"):
        raise UsageError(
            f"--ray {address}: Ray Client runs Tune away from this process, where the results "
            "store is; run the sweep on the cluster's head node (--ray auto) instead"
        )
    return sweep_ray


# ----------------------------------------------------------------------------- command
@dataclass(frozen=True)
class RunArgs:
    """``rocketroll sweep run``."""

    spec: Path = setting(help="the sweep spec (YAML)", positional=True, metavar="SPEC", input=True)
    out: Path | None = setting(
        None,
        "folder of the results store and trial outputs (default: runs/sweeps/NAME)",
        output="folder",
    )
    jobs: int = setting(1, "trials run side by side (worker processes)", ge=1, le=256)
    db: str | None = db_setting()
    progress: bool = setting(True, "show the progress bar")
    ray: str | None = setting(
        None,
        "run the trials on Ray Tune: 'auto' (this machine's cluster, or a local instance) or "
        "a cluster's ADDRESS (HOST:6379); the optional extra rocketroll[ray]",
        metavar="ADDRESS",
    )
    settings: dict[str, Any] = env_options_setting()
    recording: str | None = recording_setting()

    def __post_init__(self) -> None:
        check(self)
        check_options(self.settings)


def _run(args: RunArgs) -> int:
    settings = replay_options(args.settings, args.recording)
    if args.recording is not None:
        spec = load_spec(args.spec, settings)
        for env_id in spec.env_ids:
            settings, note = fitted_settings(env_id, settings, None, args.db)
            if note:
                print(note)
    spec = load_spec(args.spec, settings)
    if args.ray:
        _ray_module(args.ray)  # refused before anything is made or printed
    _check_replays(spec, args.db)
    out = args.out if args.out is not None else Path("runs") / "sweeps" / spec.name
    trials = expand(spec)
    print(f"rocketroll sweep: {spec.name} ({spec.source}), {len(trials)} trials, out {out}")
    with ResultStore(out / "results.sqlite") as store:
        skipped = len({t.id for t in trials} & store.done())
    records = run_sweep(
        spec, out, jobs=args.jobs, db=args.db, progress=args.progress, ray=args.ray, trials=trials
    )
    failed = [r for r in records if r["status"] == "failed"]
    print(
        f"ran {len(records)} trials ({len(failed)} failed), skipped {skipped} already done; "
        f"results in {out / 'results.sqlite'}"
    )
    return 1 if failed else 0


def _check_replays(spec: SweepSpec, db: str | None) -> None:
    """Refuse (:class:`disturbances.bank.BankError`, one line) a sweep whose database lacks
    a replay it asks for, before any trial: every trial would fail on it.  The designs
    read the train split (all its recordings), the evaluation the test split."""
    from rollenv.bank import load_bank

    for env_id in spec.env_ids:
        for point in _points(spec.settings):
            evaluated = options_config(env_id, point, "test")
            load_bank(evaluated, db)
            load_bank(dataclasses.replace(evaluated, split="train", recording=None), db)


@dataclass(frozen=True)
class ReportArgs:
    """``rocketroll sweep report``."""

    sweep_dir: Path = setting(
        help="the sweep's folder (holding results.sqlite)", positional=True, metavar="DIR"
    )
    name: str | None = setting(None, "only the trials of this sweep name (default: all)")
    out: Path | None = setting(
        None,
        "folder for report.md and one report-N.png per table (default: DIR)",
        output="folder",
    )
    seed: int = setting(0, "seed of the bootstrap", ge=0, le=2**31 - 1)

    def __post_init__(self) -> None:
        check(self)


def report(rows: Sequence[dict[str, Any]], seed: int = 0) -> list[dict[str, Any]]:
    """The sweep's statistics: one table per env id and settings point.

    In each, a learned controller's trials of one label (its name and grid
    values) are one learner's runs, one per training seed, summarised as
    ``rocketroll seeds`` does (:func:`agents.seeds.learner_stats`: mean, IQM,
    95 % stratified-bootstrap intervals, P(beats PID) against the table's
    ``pid`` trial); every other controller is a reference row.  Failed trials
    are counted, not scored.  Per learned controller, ``best`` is the label
    of the lowest mean headline.
    """
    from agents.base import Evaluation
    from agents.evaluate import HEADLINE
    from agents.seeds import learner_stats

    tables: dict[tuple[str, str, int, int], dict[str, Any]] = {}
    for row in rows:
        spec = row["spec"]
        # one table per protocol: the same episodes for every row in it
        key = (
            row["env_id"],
            json.dumps(spec["settings"], sort_keys=True),
            int(spec["episodes"]),
            int(spec["eval_seed"]),
        )
        table = tables.setdefault(
            key,
            {
                "env_id": row["env_id"],
                "episodes": key[2],
                "eval_seed": key[3],
                "settings": spec["settings"],
                "learned": {},
                "references": [],
                "failed": [],
            },
        )
        if row["status"] != "done":
            table["failed"].append(row["controller"])
        elif spec["train"]:  # one learner: one recipe (label and content), its seeds
            recipe = {k: v for k, v in spec.items() if k not in ("seed", "hyperparams")}
            version = hashlib.sha256(
                json.dumps(recipe, sort_keys=True, default=str).encode("utf-8")
            ).hexdigest()[:6]
            table["learned"].setdefault((row["controller"], version), []).append(row)
        else:
            table["references"].append(row)
    out = []
    for _, table in sorted(tables.items()):
        refs = [
            Evaluation(
                r["controller"],
                [{"episode": i, HEADLINE: v} for i, v in enumerate(r["episode_headline"])],
                {},
                [],
            )
            for r in table["references"]
        ]
        pids = [r for r in table["references"] if (r["spec"]["policy"] or "").startswith("pid")]
        pid = min(pids, key=lambda r: (r["spec"]["policy"] != "pid", r["id"]), default=None)
        labels = [label for label, _ in table["learned"]]
        learners = []
        controller_of: dict[str, str] = {}  # learner's label -> its spec's controller
        for (label, version), runs in sorted(table["learned"].items()):
            runs = sorted(runs, key=lambda r: r["seed"])
            if labels.count(label) > 1:  # the same label from two versions of a recipe
                label = f"{label} [{version}]"
            controller_of[label] = runs[0]["spec"]["controller"]
            scores = np.array([r["episode_headline"] for r in runs], dtype=float)
            reference = None if pid is None else np.array(pid["episode_headline"], dtype=float)
            learners.append(
                learner_stats(
                    label,
                    [f"seed {r['seed']}" for r in runs],
                    scores,
                    reference,
                    seed=seed,
                    train_seconds=[r["train_s"] for r in runs],
                    env_steps_per_s=[r["env_steps_per_s"] for r in runs],
                )
            )
        best: dict[str, str] = {}
        for stats in sorted(learners, key=lambda s: s.mean):
            best.setdefault(controller_of[stats.name], stats.name)
        out.append({**table, "learners": learners, "reference_results": refs, "best": best})
    return out


def _report(args: ReportArgs) -> int:
    from agents.seeds import markdown_table, plot
    from rocketroll_common.files import write_all_atomic
    from rollenv.bank import variant_config

    store_path = args.sweep_dir / "results.sqlite"
    if not store_path.is_file():
        raise UsageError(f"{store_path}: no results store (run `rocketroll sweep run` first)")
    with ResultStore(store_path) as store:
        rows = store.rows(args.name)
    if not rows:
        raise UsageError(
            f"{store_path}: no trials{f' of sweep {args.name!r}' if args.name else ''}"
        )
    out = args.out if args.out is not None else args.sweep_dir
    text = [f"# Sweep report: {store_path}\n"]
    files: dict[str | os.PathLike[str], str | bytes] = {}
    for n, table in enumerate(report(rows, args.seed), start=1):
        task = variant_config(table["env_id"], table["settings"]).task
        unit = "°" if task == "angle" else "°/s"
        where = ", ".join(f"{k}={v}" for k, v in sorted(table["settings"].items()))
        title = f"{table['env_id']}" + (f" ({where})" if where else "")
        title += f", {table['episodes']} test episodes, seed {table['eval_seed']}"
        text.append(f"## {n}. {title}\n")
        text.append(markdown_table(table["learners"], table["reference_results"], unit))
        for name, label in sorted(table["best"].items()):
            text.append(f"best settings of {name}: {label}  ")
        if table["failed"]:
            text.append(f"failed trials (not scored): {', '.join(table['failed'])}  ")
        text.append("")
        if table["learners"]:
            png = out / f"report-{n}.png"
            files[png] = plot(table["learners"], table["reference_results"], unit, title)
            text.append(f"![{title}: learners over seeds and the references]({png.name})\n")
    document = "\n".join(text)
    print(document, end="")
    files[out / "report.md"] = document
    write_all_atomic(files)
    print(
        f"wrote {out / 'report.md'}"
        + (f" and {len(files) - 1} figure(s)" if len(files) > 1 else "")
    )
    return 0


COMMAND = Command(
    "sweep",
    "sweeps over controllers, settings, seeds and tasks, resumable, into a results store",
    description=__doc__ or "",
    subcommands=(
        Command("run", "run (or resume) a sweep spec", RunArgs, _run, __doc__ or ""),
        Command(
            "report",
            "tables and plots of a sweep: seeds' statistics, P(beats PID), best settings",
            ReportArgs,
            _report,
            (report.__doc__ or "").split("\n\n", 1)[-1],
        ),
    ),
)
