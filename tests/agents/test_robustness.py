"""The robustness table: controllers designed once on the default env, run under conditions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.evaluate import HEADLINE, evaluate, protocol_episodes
from agents.pid import PIDController
from agents.registry import make_controller
from agents.robustness import COMMAND, CONDITIONS
from rocketroll.cli import main as rocketroll
from rocketroll_common.settings import run_command
from rollenv.bank import load_bank, variant_config


def test_each_condition_runs_the_default_design_on_its_own_episodes(tmp_path, default_db, capsys):
    out = tmp_path / "rob"
    argv = ["robustness", "--policy", "pid", "--policy", "observer", "--episodes", "2"]
    argv += ["--condition", "default", "--condition", "paper replay", "--out", str(out)]
    assert rocketroll(argv) == 0
    printed = capsys.readouterr().out
    assert "| controller | default (°) | paper replay (°) |" in printed
    record = json.loads((out / "robustness.json").read_text())
    assert set(record["scores"]) == {"PID", "observer"}
    # The paper-replay column is the PID designed on the default env's train split (ml's
    # rockets), run on the paper replay's test episodes -- not a PID re-designed there.
    default_cfg = variant_config("RocketRoll-v0", {"split": "test"})
    paper_cfg = variant_config("RocketRoll-v0", {**CONDITIONS["paper replay"], "split": "test"})
    bank = load_bank(paper_cfg, None)
    pid = make_controller("pid", default_cfg, "RocketRoll-v0")
    redesigned = make_controller("pid", paper_cfg, "RocketRoll-v0")
    assert isinstance(pid, PIDController) and isinstance(redesigned, PIDController)
    assert pid.gains != redesigned.gains  # the two designs differ, so the check can fail
    specs = protocol_episodes(paper_cfg, 2, 0, bank=bank)
    expected = [e[HEADLINE] for e in evaluate(paper_cfg, pid, specs, bank=bank).episodes]
    np.testing.assert_allclose(record["scores"]["PID"]["paper replay"], expected)
    assert (out / "robustness.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "robustness.md").read_text().count("\n") == 4


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--condition", "windy"], "--condition 'windy': unknown"),
        (["--condition", "default", "--condition", "default"], "--condition default is given"),
        (["--episodes", "1"], "--episodes: must be in [2, 100000], got 1"),
        (["--policy", "mpc", "--policy", "mpc:20"], "two --policy values give controllers"),
    ],
)
def test_bad_arguments_exit_2_and_write_nothing(argv, message, tmp_path, capsys, default_db):
    out = tmp_path / "rob"
    assert run_command(COMMAND, [*argv, "--out", str(out)], "python -m agents.robustness") == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
