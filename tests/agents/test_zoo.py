"""rl-baselines3-zoo runs the project's zoo-format hyperparameter files as they are."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from agents.train import load_hyperparameters, zoo_mapping
from rocketroll_common.errors import UsageError

REPO = Path(__file__).resolve().parents[2]
HYPERPARAMS = REPO / "agents" / "hyperparams"


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_rl_zoo3_trains_on_the_zoo_format_file(algo: str, tmp_path: Path, default_db: Path) -> None:
    pytest.importorskip("rl_zoo3", reason="rl-baselines3-zoo is in the dev extra")
    argv = [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", "RocketRoll-v0"]
    argv += ["--gym-packages", "rollenv", "-conf", str(HYPERPARAMS / f"{algo}.yml")]
    argv += ["-n", "1000", "-f", str(tmp_path / "logs"), "--seed", "0", "--eval-freq", "-1"]
    env = {**os.environ, "ROCKETROLL_DB": str(default_db), "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    (saved,) = (tmp_path / "logs" / algo).glob("RocketRoll-v0_*/RocketRoll-v0.zip")
    assert saved.stat().st_size > 0


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_the_project_reads_the_zoo_format_files_as_the_zoo_does(algo: str) -> None:
    hp = load_hyperparameters(HYPERPARAMS / f"{algo}.yml", "RocketRoll-v0", algo)
    assert not hp.layout.history and not hp.layout.observer  # the project's own keys live elsewhere
    if algo == "ppo":
        assert hp.algo_kwargs["policy_kwargs"] == {
            "net_arch": [64, 64],
            "log_std_init": -1.0,
            "activation_fn": "tanh",
        }
    mine = load_hyperparameters(HYPERPARAMS / f"{algo}-history.yml", "RocketRoll-v0", algo)
    if algo != "ppo":
        assert mine.layout.history == 4 and mine.algo_kwargs == hp.algo_kwargs


def test_a_zoo_string_is_read_without_eval() -> None:
    assert zoo_mapping("dict(pi=[64], vf=dict(a=(1, 2)), act=nn.ReLU)", "x") == {
        "pi": [64],
        "vf": {"a": [1, 2]},
        "act": "relu",
    }
    assert zoo_mapping("{'norm_obs': True, 'norm_reward': False}", "x") == {
        "norm_obs": True,
        "norm_reward": False,
    }
    for bad, said in (
        ("dict(a=__import__('os').system('true'))", "not a dict(...) of literals"),
        ("dict(act=torch.nn.Tanh)", "not a dict(...) of literals"),
        ("dict(act=nn.Sigmoid)", "nn.Sigmoid: the activations read are"),
        ("[1, 2]", "is not a mapping"),
        ("dict(**x)", "dict(**...) is not read"),
        ("dict(a=1, a=2)", "'a' is given twice"),
        ("{'a': {1, 2}}", "set values are not read"),
        ("dict(a=" + "1+" * 100_000 + "1)", "not a dict(...) of literals"),
    ):
        with pytest.raises(UsageError, match=re.escape(said)):
            zoo_mapping(bad, "ppo.yml, RocketRoll-v0: policy_kwargs")


def test_a_shipped_recipe_is_named_and_a_path_still_works(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from agents.train import recipe_path, shipped_recipes

    monkeypatch.chdir(tmp_path)  # another folder than the repository, as a pip user's
    assert recipe_path("ppo-history") == HYPERPARAMS / "ppo-history.yml"
    assert recipe_path("agents/hyperparams/ppo.yml") == HYPERPARAMS / "ppo.yml"
    mine = tmp_path / "ppo-history.yml"
    mine.write_text("RocketRoll-v0: {n_envs: 2}\n", encoding="utf-8")
    assert recipe_path(mine) == mine  # a path is a path, even with a shipped name
    assert load_hyperparameters("ppo-history", "RocketRoll-v0").layout.history == 2
    assert {"ppo", "ppo-history", "sac-history", "td3"} <= set(shipped_recipes())
    with pytest.raises(UsageError, match=r"ppo-histroy: no such file, nor a shipped recipe"):
        recipe_path("ppo-histroy")
