"""Evaluation episodes out as Minari datasets (``rocketroll eval --minari PREFIX``)."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

from rocketroll.cli import command
from rocketroll_common.settings import run_command

minari = pytest.importorskip(
    "minari",
    reason="Minari is an optional extra (pip install 'rocketroll[minari]'); make test has it",
)


def _eval(argv: list[str]) -> tuple[int, str, str]:
    with (
        contextlib.redirect_stdout(io.StringIO()) as out,
        contextlib.redirect_stderr(io.StringIO()) as err,
    ):
        code = run_command(command("eval"), argv, "rocketroll eval")
    return code, out.getvalue(), err.getvalue()


def test_evaluation_episodes_load_back_with_minari(tmp_path, monkeypatch, default_db):
    """PID and observer on 2 protocol episodes: one dataset each, loaded back with
    minari.load_dataset holding exactly the observations, actions and rewards of the same
    episodes run again; the recovered environment is the evaluated one."""
    from agents.evaluate import evaluate, protocol_episodes
    from agents.registry import make_controller
    from rollenv.bank import load_bank, variant_config

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    argv = ["--episodes", "2", "--policy", "pid", "--policy", "observer"]
    code, printed, _ = _eval([*argv, "--minari", "rocketroll/test"])
    assert code == 0, printed
    assert "rocketroll/test-pid-v0, rocketroll/test-observer-v0" in printed
    config = variant_config("RocketRoll-v0", {"split": "test"})
    bank = load_bank(config, None)
    specs = protocol_episodes(config, 2, 0, bank=bank)
    for name, dataset_id in (
        ("pid", "rocketroll/test-pid-v0"),
        ("observer", "rocketroll/test-observer-v0"),
    ):
        dataset = minari.load_dataset(dataset_id)
        assert dataset.total_episodes == 2
        again: list[dict] = []
        evaluate(
            config,
            make_controller(name, config, "RocketRoll-v0"),
            specs,
            bank=bank,
            transitions=again,
        )
        for episode, expected in zip(dataset.iterate_episodes(), again, strict=True):
            assert episode.observations.shape == (601, 4) and episode.actions.shape == (600, 1)
            np.testing.assert_array_equal(episode.observations, np.array(expected["observations"]))
            np.testing.assert_array_equal(episode.actions, np.array(expected["actions"]))
            np.testing.assert_allclose(episode.rewards, expected["rewards"], rtol=0, atol=0)
            assert episode.truncations[-1] and not episode.terminations.any()
        env = dataset.recover_environment()
        assert env.spec.id == "RocketRoll-v0" and env.spec.kwargs["split"] == "test"
    # The same prefix again: refused before any work, nothing changed.
    code, _, errors = _eval([*argv, "--minari", "rocketroll/test"])
    assert code == 2 and "exists already" in errors and "rocketroll/test-" in errors
    code, _, errors = _eval([*argv, "--minari", "bad prefix"])
    assert code == 2 and "a dataset name" in errors
