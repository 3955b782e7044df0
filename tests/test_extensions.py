"""One seam per extension: a method and a controller written outside the packages join
everything by one ``register`` call each.

A toy identification method and a toy controller are defined here, in a test
module, and registered; then the command line stores the method's results in a
database, lists them, the environment replays its traces with its parameters,
and the evaluation protocol runs the controller on them -- with no change to any
package.  A plugin module named by ``ROCKETROLL_PLUGINS`` is picked up the same
way in another process.
"""

from __future__ import annotations

import dataclasses
import json
import os
import textwrap
from collections.abc import Iterator, Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rollenv  # registers the environments (and register_variant below)
from agents.base import Design
from agents.registry import CONTROLLERS, register_controller
from disturbances.db import DisturbanceDB
from disturbances.default import build_database, fingerprint
from disturbances.stores import check_filters, store_rows
from identification.instruments.bundled import bundled_path
from identification.methods import (
    METHODS,
    Context,
    ModelFit,
    default_methods,
    register_method,
    resimulation_metrics,
    trace_settings,
)
from identification.methods.pipeline import IdentifyOptions
from rocketroll.cli import main as rocketroll
from rollenv.env import RocketRollEnv
from rollenv.layout import Obs
from tests.cli import python

REPO = Path(__file__).resolve().parents[1]
FAST = IdentifyOptions(noise_runs=0)


def toy_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """The paper's rocket with α rounded to two decimals, and the u_d that goes with it."""
    fits = []
    for model in models:
        params = context.paper.model(model)
        params = dataclasses.replace(params, alpha=round(params.alpha, 2))
        dist, resim = context.disturbance(params, model)
        metrics = {"rounded": True, **resimulation_metrics(resim)}
        fits.append(ModelFit("toy", model, params, dist, metrics, trace_settings(dist)))
    return fits


class ToyController:
    """Fins against the measured error, saturated: a P controller without a model."""

    name = "toy"

    def reset(self, env: RocketRollEnv) -> None:
        """Nothing to forget."""

    def act(self, obs: np.ndarray, env: RocketRollEnv) -> np.ndarray:
        return np.array([np.clip(0.2 * obs[Obs.ERROR], -1.0, 1.0)], dtype=np.float32)


def make_toy(design: Design) -> ToyController:
    design.no_argument("toy")
    return ToyController()


@pytest.fixture(scope="module")
def registered() -> Iterator[None]:
    register_method("toy", toy_method, summary="the paper's rocket, α rounded")
    register_controller("toy", make_toy, summary="a P controller without a model")
    try:
        yield
    finally:
        METHODS.unregister("toy")
        CONTROLLERS.unregister("toy")


@pytest.fixture(scope="module")
def toy_db(registered: None, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two bundled recordings (seed 0: train, seed 4: test) with the paper's method and the toy."""
    path = tmp_path_factory.mktemp("toy") / "toy.sqlite"
    for name in ("tunnel-paper-seed0", "tunnel-paper-seed4"):
        argv = ["db", "add", str(bundled_path(name)), "--db", str(path), "--mc-runs", "0"]
        code = rocketroll([*argv, "--method", "paper", "--method", "toy"])
        assert code == 0
    return path


def test_the_method_is_stored_and_listed(toy_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert rocketroll(["db", "list", "--db", str(toy_db), "--method", "toy", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert sorted(r["uid"].split("-", 1)[1] for r in listed) == [
        "toy-constant",
        "toy-constant",
        "toy-theta",
        "toy-theta",
    ]
    with DisturbanceDB(toy_db, create=False) as db:
        (paper,) = db.identifications(recording="tunnel-paper-seed4", method="paper", model="theta")
        (toy,) = db.identifications(recording="tunnel-paper-seed4", method="toy", model="theta")
        assert toy.params.alpha == round(paper.params.alpha, 2) != paper.params.alpha
        assert toy.metrics["rounded"] is True and "resim_angle_mae_deg" in toy.metrics


def test_the_environment_replays_the_methods_traces(toy_db: Path) -> None:
    env = gym.make("RocketRoll-v0", db=str(toy_db), method="toy", split="test")
    _, info = env.reset(seed=0)
    assert info["trace"].endswith("-toy-theta")
    core = env.unwrapped.core  # type: ignore[attr-defined]
    with DisturbanceDB(toy_db, create=False) as db:
        stored = db.trace(info["trace"])
    assert core.roll_params(0) == stored.params
    env.step(env.action_space.sample())
    env.close()


def test_the_controller_is_evaluated_on_the_methods_traces(
    toy_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "eval"
    argv = ["eval", "--db", str(toy_db), "--policy", "toy", "--policy", "pid"]
    argv += ["--set", "method=toy", "--episodes", "2", "--out", str(out)]
    assert rocketroll(argv) == 0
    printed = capsys.readouterr().out
    assert "| toy |" in printed and "| PID |" in printed
    results = json.loads((out / "results.json").read_text())
    assert set(results["controllers"]) == {"toy", "PID"}
    assert all("-toy-theta" in e["trace"] for e in results["protocol"]["episodes"])


def test_help_and_identify_list_what_is_registered(
    registered: None, capsys: pytest.CaptureFixture[str]
) -> None:
    from rocketroll.cli import command

    shown = " ".join(command("eval").parser("x").format_help().split())  # argparse wraps lines
    assert "toy: a P controller without a model" in shown
    rec = bundled_path("tunnel-paper-seed0")
    assert rocketroll(["identify", str(rec), "--mc-runs", "0", "--method", "toy"]) == 0
    printed = capsys.readouterr().out
    assert "toy" in printed and "θ-dependent truth" not in printed  # no paper table asked for


def test_a_default_method_joins_the_default_recipe(registered: None, tmp_path: Path) -> None:
    files = [bundled_path("tunnel-paper-seed0")]
    before = fingerprint(files, FAST, 0, ("iaaft",))
    register_method("toy", toy_method, summary="now a default", default=True, replace=True)
    try:
        assert "toy" in default_methods()
        assert fingerprint(files, FAST, 0, ("iaaft",)) != before
        path = build_database(tmp_path / "db.sqlite", files, options=FAST, surrogates=0)
        with DisturbanceDB(path, create=False) as db:
            assert [m for m in db.methods() if m == "toy"] == ["toy"]
    finally:
        register_method("toy", toy_method, summary="the paper's rocket, α rounded", replace=True)


def test_an_unregistered_method_is_refused_by_name(toy_db: Path, tmp_path: Path) -> None:
    """Names are checked in Python above the store (no CHECK constraint, no registry in
    the store), and so do the env options."""
    with DisturbanceDB(toy_db, create=False) as db:
        (ident,) = db.identifications(recording="tunnel-paper-seed0", method="toy", model="theta")
    copy = tmp_path / "copy.sqlite"
    copy.write_bytes(toy_db.read_bytes())
    stray = dataclasses.replace(ident, method="no-such", id=None)
    with DisturbanceDB(copy, create=False) as db:
        with pytest.raises(ValueError, match="unknown identification method 'no-such'"):
            store_rows(db, identifications=[stray])
        assert "no-such" not in db.methods()
        with pytest.raises(ValueError, match="filter method='no-such': must be one of paper"):
            check_filters(db, {"method": "no-such"})
        check_filters(db, {"method": ["toy", "ml"]})  # stored, and registered but not stored
        assert db.traces(method="ml") == []
    with pytest.raises(ValueError, match="unknown identification method 'no-such'"):
        RocketRollEnv(method="no-such")
    # The store itself only stores: a name it is handed is kept, and found again.
    with DisturbanceDB(copy, create=False) as db:
        assert db.store(identifications=[stray]).identifications == 1
        assert db.identifications(method="no-such")[0].params == ident.params


@pytest.fixture
def toy_variant(registered: None) -> Iterator[str]:
    """A variant that replays the toy method's traces."""

    rollenv.register_variant("RocketRollToy-v0", task="angle", method="toy", summary="toy traces")
    try:
        yield "RocketRollToy-v0"
    finally:
        rollenv.unregister_variant("RocketRollToy-v0")


def test_a_variants_options_reach_training_tuning_and_evaluation(
    toy_db: Path, toy_variant: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from agents.vecenv import RollVecEnv
    from rollenv.bank import variant_config

    assert variant_config(toy_variant).method == "toy"
    assert variant_config(toy_variant, {"method": "paper"}).method == "paper"  # as gym.make
    with pytest.raises(ValueError, match="is the 'angle' task; task='rate' conflicts"):
        variant_config(toy_variant, {"task": "rate"})
    env = gym.make(toy_variant, db=str(toy_db))
    assert env.unwrapped.config.method == "toy"  # type: ignore[attr-defined]
    venv = RollVecEnv(2, toy_variant, db=str(toy_db))
    assert venv.config.method == "toy"
    venv.reset()
    assert all(info["trace"].endswith("-toy-theta") for info in venv.reset_infos)
    capsys.readouterr()
    argv = ["tune", "pid", "--env-id", toy_variant, "--db", str(toy_db), "--episodes", "1"]
    assert rocketroll([*argv, "--omegas", "2"]) == 0
    assert "α = 0.68," in capsys.readouterr().out  # the toy method's rounded α, not 0.6777
    out = tmp_path / "eval"
    argv = ["eval", "--env-id", toy_variant, "--db", str(toy_db), "--policy", "trim"]
    assert rocketroll([*argv, "--episodes", "2", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    assert all(e["trace"].endswith("-toy-theta") for e in results["protocol"]["episodes"])


def test_a_plugin_that_cannot_be_imported_is_one_error_naming_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from rocketroll_common import registry
    from rocketroll_common.errors import UsageError

    monkeypatch.setenv("ROCKETROLL_PLUGINS", "no_such_plugin_module")
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    with pytest.raises(UsageError, match="module 'no_such_plugin_module' cannot be loaded"):
        METHODS.names()
    monkeypatch.delenv("ROCKETROLL_PLUGINS")
    assert "paper" in METHODS.names()  # tried again once the cause is gone


def test_a_plugin_module_registers_in_another_process(tmp_path: Path) -> None:
    """``ROCKETROLL_PLUGINS`` (or a ``rocketroll.plugins`` entry point) imports a module
    that registers; the command line of a new process then offers its entries."""
    (tmp_path / "my_plugin.py").write_text(
        textwrap.dedent(
            """
            from agents.registry import register_controller
            from identification.methods import register_method

            register_controller("plug", "my_plugin:make", summary="from a plugin")
            register_method("plug-method", "my_plugin:fit", summary="from a plugin too")
            """
        ),
        encoding="utf-8",
    )
    env = {
        **os.environ,
        "ROCKETROLL_PLUGINS": "my_plugin",
        "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO)]),
    }
    for argv, wanted in (
        (["eval", "--help"], "plug: from a plugin"),
        (["db", "add", "--help"], "plug-method"),
    ):
        done = python(["-m", "rocketroll", *argv], tmp_path, env)
        assert done.returncode == 0, done.stderr
        # argparse wraps the help at any width and breaks words at hyphens: compare
        # without the whitespace.
        assert "".join(wanted.split()) in "".join(done.stdout.split()), done.stdout
