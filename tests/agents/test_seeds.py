"""Statistics over training seeds (rocketroll seeds): the numbers and the command."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from agents.seeds import COMMAND, learner_stats
from rocketroll.cli import main as rocketroll
from rocketroll_common.settings import run_command


def test_mean_iqm_and_probability_of_improvement_by_hand():
    scores = np.array([[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]])
    pid = np.array([2.0, 2.0, 9.0, 0.5])
    s = learner_stats("x", ["a", "b"], scores, pid)
    assert s.mean == pytest.approx(4.5)
    assert s.iqm == pytest.approx(np.mean([3.0, 4.0, 5.0, 6.0]))  # the middle 4 of 8
    # below the PID's score on the same episode, ties half: episode 0: 1 of 2, episode 1:
    # a tie (0.5), episode 2: 2 of 2, episode 3: 0 -> (0.5 + 0.25 + 1 + 0) / 4
    assert s.p_beats == pytest.approx((0.5 + 0.25 + 1.0 + 0.0) / 4)
    assert s.p_beats is not None and s.p_beats_ci is not None
    assert s.run_means.tolist() == [2.5, 6.5]
    checks = [(s.mean, s.mean_ci), (s.iqm, s.iqm_ci), (s.p_beats, s.p_beats_ci)]
    for value, (low, high) in checks:
        assert low <= value <= high


def test_the_bootstrap_resamples_runs_not_episodes():
    """Runs that agree on every episode leave nothing to resample: the interval is a
    point, however different the episodes are.  (A bootstrap over all run x episode
    cells would give an interval of about ±1.8 here.)"""
    scores = np.tile(np.arange(1.0, 11.0), (4, 1))
    s = learner_stats("x", list("abcd"), scores, None)
    assert s.mean_ci == pytest.approx((5.5, 5.5)) and s.iqm_ci == pytest.approx((5.5, 5.5))
    assert s.p_beats is None


def test_the_interval_covers_the_truth_about_as_often_as_it_says():
    """Runs with a persistent seed effect (SD 1, shared by all of a run's episodes) and
    episode noise around a known mean: the 95 % interval of the mean covers it in most of
    40 repetitions.  The percentile bootstrap of 5 runs under-covers (its interval has
    the width of a 1.96-SD normal interval without the small-sample t factor: ~85 %
    for 5 runs); a bootstrap with episodes as strata covered it 7 times of 40."""
    rng = np.random.default_rng(7)
    covered = 0
    for _ in range(40):
        scores = 3.0 + rng.normal(0.0, 1.0, (5, 1)) + rng.normal(0.0, 0.3, (5, 20))
        low, high = learner_stats("x", list("abcde"), scores, None).mean_ci
        covered += low <= 3.0 <= high
    assert covered >= 29, covered  # 31 measured; 84 % of 200 with another seed


def test_bad_matrices_are_refused():
    with pytest.raises(ValueError, match="matrix"):
        learner_stats("x", ["a"], np.ones(3), None)
    with pytest.raises(ValueError, match="one reference score per episode"):
        learner_stats("x", ["a", "b"], np.ones((2, 3)), np.ones(2))


def test_the_command_writes_table_json_and_plot(tmp_path, default_db, capsys):
    committed = "agents/policies/RocketRoll-v0"
    copy = tmp_path / "seed-copy"
    shutil.copytree(committed, copy)
    out = tmp_path / "seeds"
    argv = ["seeds", "--run", f"ppo:{committed}", "--run", f"ppo:{copy}"]
    argv += ["--reference", "pid", "--episodes", "3", "--out", str(out)]
    assert rocketroll(argv) == 0
    printed = capsys.readouterr().out
    assert "| ppo | 2 |" in printed and "| PID | 1 |" in printed
    record = json.loads((out / "seeds.json").read_text())
    ppo = record["learners"]["ppo"]
    scores = np.array(ppo["scores"])
    assert scores.shape == (2, 3)
    np.testing.assert_array_equal(scores[0], scores[1])  # the same policy twice
    assert ppo["mean"] == pytest.approx(scores.mean())
    assert ppo["train_seconds"][0] is not None  # from the run's settings.json
    assert (out / "seeds.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "--run: give the trained runs"),
        (["--run", "ppo:agents/policies/RocketRoll-v0"], "learner 'ppo' has 1 run"),
        (["--run", "ppo:x", "--run", "ppo:x"], "--run ppo:x is given twice"),
        (["--run", "ppo:/nonexistent/a", "--run", "ppo:/nonexistent/b"], "/nonexistent/a"),
    ],
)
def test_bad_arguments_exit_2_and_write_nothing(argv, message, tmp_path, capsys, default_db):
    out = tmp_path / "seeds"
    code = run_command(COMMAND, [*argv, "--out", str(out)], "python -m agents.seeds")
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
