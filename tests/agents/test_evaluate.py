"""The evaluation protocol: fixed episodes, reproducible numbers, correct metrics, outputs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from agents.base import Evaluation
from agents.evaluate import (
    COMMAND,
    HEADLINE,
    METRICS,
    aggregate,
    env_on,
    evaluate,
    markdown_table,
    metrics,
    paired_difference,
    protocol_episodes,
    settling,
)
from agents.registry import make_controller
from rocketroll.cli import main as rocketroll
from rocketroll_common.settings import run_command
from rollenv.bank import load_bank, make_config, variant_config
from rollenv.history import EpisodeHistory


def main(argv: list[str]) -> int:
    """``python -m agents.evaluate ARGV`` in this process."""
    return run_command(COMMAND, argv, "python -m agents.evaluate")


@pytest.fixture(scope="module")
def angle_config(default_db):
    return make_config("RocketRoll-v0", {"split": "test"})


def test_protocol_episodes_are_fixed_by_the_seed(angle_config):
    first = protocol_episodes(angle_config, 5, seed=4)
    assert protocol_episodes(angle_config, 5, seed=4) == first
    other = protocol_episodes(angle_config, 5, seed=5)
    assert [e.seed for e in other] != [e.seed for e in first]
    test_uids = {t.uid for t in load_bank(angle_config, None).traces}
    for spec in first:
        assert spec.trace in test_uids  # held-out traces only
        assert len(spec.setpoints) == 6 and spec.setpoints[0] == 0.0
        assert all(abs(s) <= 90.0 for s in spec.setpoints)
    # The environment's own draws, not a distribution of the protocol's.
    env = env_on(angle_config, load_bank(angle_config, None))
    for spec in first:
        env.reset(seed=spec.seed)
        assert env.replay_options() == spec.options()


def test_every_controller_meets_the_same_episodes(angle_config):
    specs = protocol_episodes(angle_config, 2, seed=8)
    runs = [
        evaluate(angle_config, make_controller(p, angle_config, "RocketRoll-v0"), specs).rollouts
        for p in ("trim", "pid", "oracle")
    ]
    for other in runs[1:]:
        for a, b in zip(runs[0], other, strict=True):
            np.testing.assert_array_equal(a.u_d_deg, b.u_d_deg)
            np.testing.assert_array_equal(a.setpoint, b.setpoint)
            assert not np.array_equal(a.fin_deg, b.fin_deg)


@pytest.mark.parametrize("policy", ["pid", "oracle"])
def test_the_same_seed_gives_identical_numbers(policy, angle_config):
    specs = protocol_episodes(angle_config, 3, seed=1)
    runs = [
        evaluate(
            angle_config, make_controller(policy, angle_config, "RocketRoll-v0"), specs
        ).episodes
        for _ in range(2)
    ]
    assert runs[0] == runs[1]
    again = protocol_episodes(angle_config, 3, seed=1)
    third = evaluate(
        angle_config, make_controller(policy, angle_config, "RocketRoll-v0"), again
    ).episodes
    assert third == runs[0]
    different = evaluate(
        angle_config,
        make_controller(policy, angle_config, "RocketRoll-v0"),
        protocol_episodes(angle_config, 3, seed=2),
    ).episodes
    assert different != runs[0]


def test_metrics_of_a_hand_made_episode(angle_config):
    # 4 steps of 0.1 s; the fin moves 0 → 15 → 15 → 25 → 40 (at most 15° a step).
    n = 5
    rollout = EpisodeHistory(
        time_s=np.linspace(0.0, 0.4, n),
        angle_deg=np.zeros(n),
        rate_dps=np.zeros(n),
        fin_deg=np.array([0.0, 15.0, 15.0, 25.0, 40.0]),
        command_deg=np.array([0.0, 40.0, 15.0, 25.0, 40.0]),
        u_d_deg=np.zeros(n),
        setpoint=np.zeros(n),
        error=np.array([9.0, 3.0, -4.0, 5.0, 12.0]),
        reward=np.array([0.0, -1.0, -2.0, -3.0, -4.0]),
        task="angle",
    )
    cfg = make_config("RocketRoll-v0", {"setpoint_period_s": 0.4})  # 4 steps per period
    m = metrics(rollout, cfg)
    assert m["rms_error"] == pytest.approx(math.sqrt((9 + 16 + 25 + 144) / 4))
    assert m["max_error"] == 12.0
    assert m["settled_rms_error"] == 5.0  # step 3 is the period's last quarter
    # The headline: samples at least 3 steps (3/4 of a period) after the start, and the
    # setpoint never changes: steps 3 and 4.
    assert m["regulation_rms_error"] == pytest.approx(math.sqrt((25 + 144) / 2))
    assert math.isnan(m["settle_time_s"])  # the setpoint never changes
    assert m["fin_travel_dps"] == pytest.approx(40.0 / 0.4)
    # Moving at 150 °/s: 0.1 s (40° asked), 0, 10°/150 °/s, 0.1 s -- of 0.4 s.
    assert m["rate_limit_pct"] == pytest.approx(100 * (0.1 + 10 / 150 + 0.1) / 0.4)
    assert m["range_limit_pct"] == 25.0
    assert m["return"] == -10.0
    assert set(m) == {*METRICS, "setpoint_steps", "unsettled_steps"}
    assert m["setpoint_steps"] == m["unsettled_steps"] == 0


def _step_episode(error: list[float], setpoint: list[float]) -> EpisodeHistory:
    n = len(error)
    return EpisodeHistory(
        time_s=0.1 * np.arange(n),
        angle_deg=np.zeros(n),
        rate_dps=np.zeros(n),
        fin_deg=np.zeros(n),
        command_deg=np.zeros(n),
        u_d_deg=np.zeros(n),
        setpoint=np.array(setpoint, dtype=float),
        error=np.array(error, dtype=float),
        reward=np.zeros(n),
        task="angle",
    )


def test_settle_time_and_regulation_window_of_a_hand_made_episode():
    # 20-step periods (2 s); the setpoint changes at samples 20 and 40.  After the first
    # change the error is in the 2° band from sample 23 on: 0.3 s.  After the second it
    # enters at 42, leaves at 45 and is back from 46 on, for 14 samples (the hold is
    # 10 samples, 1 s): 0.6 s.
    cfg = make_config("RocketRoll-v0", {"setpoint_period_s": 2.0})
    error = [0.0] * 20 + [50, 20, 5] + [1] * 17 + [40, 10, 1, 1, 1, 3] + [1] * 14
    setpoint = [0.0] * 20 + [30.0] * 20 + [-10.0] * 20
    rollout = _step_episode(error, setpoint)
    assert settling(rollout, cfg)[0].tolist() == pytest.approx([0.3, 0.6])
    assert settling(rollout, cfg)[1].tolist() == [True, True]
    m = metrics(rollout, cfg)
    assert m["settle_time_s"] == pytest.approx(0.45)
    # The headline counts samples >= 15 (3/4 of the 20-step period, below 7.5 s) after
    # each change or the start: samples 15-19 (error 0), 35-39 and 55-59 (error 1).
    assert m["regulation_rms_error"] == pytest.approx(math.sqrt(10 / 15))
    # A step that never settles counts the whole time it had; one that settles only as the
    # next change comes too (its hold is cut short).
    never = _step_episode([0.0] * 20 + [9.0] * 11 + [0.0] * 9, [0.0] * 20 + [30.0] * 20)
    assert settling(never, cfg)[0].tolist() == pytest.approx([2.0])
    assert settling(never, cfg)[1].tolist() == [False]  # censored
    assert (m["setpoint_steps"], m["unsettled_steps"]) == (2, 0)
    censored = metrics(never, cfg)
    assert (censored["setpoint_steps"], censored["unsettled_steps"]) == (1, 1)


def test_the_table_says_how_many_steps_never_settled():
    """A time to settle that counts steps that never settled (each as the whole time it had)
    is a lower bound: a line under the table says so, with each such controller's count."""
    cfg = make_config("RocketRoll-v0", {"setpoint_period_s": 2.0})
    settles = _step_episode([0.0] * 20 + [1.0] * 20, [0.0] * 20 + [30.0] * 20)
    never = _step_episode([0.0] * 20 + [9.0] * 11 + [0.0] * 9, [0.0] * 20 + [30.0] * 20)

    def result(name, rollouts):
        episodes = [{"episode": i, **metrics(r, cfg)} for i, r in enumerate(rollouts)]
        return Evaluation(name, episodes, aggregate(episodes), rollouts)

    pid, trim = result("PID", [settles, settles]), result("trim", [never, settles])
    lines = markdown_table([trim, pid], cfg).splitlines()
    assert lines[2].startswith("| trim | ") and lines[3].startswith("| PID | ")
    assert lines[4:] == [
        "",
        "Setpoint steps that never settled, each counted in the time to settle as the whole "
        "time it had (the mean is then a lower bound): trim 1 of 2.",
    ]
    assert markdown_table([pid], cfg).count("\n") == 3  # every step settled: no such line


def test_paired_difference_is_over_common_episodes():
    def result(name, values):
        episodes = [{"episode": i, HEADLINE: v} for i, v in enumerate(values)]
        return Evaluation(name, episodes, {}, [])

    a, b = result("a", [1.0, 2.0, 3.0]), result("b", [0.5, 1.0, 2.5])
    mean, sem = paired_difference(a, b)
    diff = np.array([0.5, 1.0, 0.5])
    assert mean == pytest.approx(diff.mean())
    assert sem == pytest.approx(diff.std(ddof=1) / math.sqrt(3))


def test_the_table_counts_sems_only_where_the_sem_shows():
    """Episodes that are copies of one another (a recording with room for one window) give a
    paired SEM of rounding noise: the table shows ``± 0.00`` and no count of SEMs."""
    cfg = make_config("RocketRoll-v0", {"split": "test"})
    names = [HEADLINE, "settle_time_s", "settled_rms_error", "rms_error", "max_error"]
    names += ["fin_travel_dps", "rate_limit_pct", "range_limit_pct", "return"]

    def result(name, values):
        episodes = [{"episode": i, HEADLINE: v} for i, v in enumerate(values)]
        nan = {"mean": math.nan, "sd": math.nan, "worst": math.nan}
        return Evaluation(name, episodes, dict.fromkeys(names, nan), [])

    pid = result("PID", [0.11 + 1e-12 * k for k in range(20)])
    copies = result("trim", [0.02] * 20)
    spread = result("observer", [0.0, 0.1] * 10)
    rows = markdown_table([pid, copies, spread], cfg).splitlines()
    assert rows[3].startswith("| trim | – | -0.09 ± 0.00 | – |"), rows[3]
    assert rows[4].startswith("| observer | – | -0.06 ± 0.01 (5.2 SEM) | – |"), rows[4]


def test_the_cli_writes_table_json_and_plots(tmp_path, default_db, capsys):
    out = tmp_path / "eval"
    code = rocketroll(
        ["eval", "--policy", "trim", "--policy", "pid:3", "--episodes", "3", "--out", str(out)]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "| trim |" in printed and "| PID ω=3 |" in printed
    table = (out / "table.md").read_text()
    rows = [line for line in table.splitlines() if line.startswith("|")]
    assert len(rows) == 4 and "RMS error (°)" in table
    # trim holds the fins: most setpoint steps never settle, as the line under the table says
    assert table.splitlines()[-1].startswith("Setpoint steps that never settled")
    assert ": trim " in table.splitlines()[-1] and table.splitlines()[-1] in printed
    results = json.loads((out / "results.json").read_text())
    assert results["protocol"]["split"] == "test"
    assert results["protocol"]["command"].startswith(
        "rocketroll eval --env-id RocketRoll-v0 --policy trim --policy pid:3"
    )
    assert len(results["protocol"]["episodes"]) == 3
    assert set(results["controllers"]) == {"trim", "PID ω=3"}
    pid = results["controllers"]["PID ω=3"]
    assert len(pid["episodes"]) == 3
    rms = [e["rms_error"] for e in pid["episodes"]]
    assert pid["aggregate"]["rms_error"]["mean"] == pytest.approx(np.mean(rms))
    assert pid["aggregate"]["rms_error"]["worst"] == max(rms)
    for png in ("episode.png", "errors.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out.iterdir()) == [
        ".rocketroll-outputs.json",  # what rocketroll wrote there, for the next run
        "episode.png",
        "errors.png",
        "results.json",
        "table.md",
    ]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--policy", "lqr"], "--policy lqr: unknown controller 'lqr'"),
        (["--policy", "pid:fast"], "pid:OMEGA needs a number"),
        (["--policy", "trim:1"], "takes no argument"),
        (["--policy", "mpc:0"], "mpc:HORIZON must be 1 to 100 steps (10 s ahead), got 0"),
        (["--policy", "mpc:100000"], "mpc:HORIZON must be 1 to 100 steps (10 s ahead), got 100000"),
        (["--episodes", "0"], "--episodes: must be in [1, 100000], got 0"),
        (["--env-id", "CartPole-v1"], "--env-id"),
        (["--set", "split=train"], "--set split=... is not allowed"),
        (["--set", "setpiont=zero"], "did you mean 'setpoint'"),
        (["--policy", "ppo:/nonexistent/run"], "/nonexistent/run"),
        (["--policy", "pid", "--policy", "pid"], "--policy pid is given twice"),
        (["--policy", "pid:2.5", "--policy", "pid:2.50"], "one name"),
        (["--seed", "-1"], "--seed: must be in [0, 2147483647], got -1"),
        (["--policy", "ppo:agents/policies/RocketRollRate-v0"], "trained on the 'rate' task"),
    ],
)
def test_bad_arguments_exit_2_and_write_nothing(argv, message, tmp_path, capsys, default_db):
    out = tmp_path / "eval"
    assert main([*argv, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_the_table_marks_the_units_of_the_rate_task(default_db):
    cfg = make_config("RocketRollRate-v0", {"task": "rate", "split": "test"})
    result = evaluate(
        cfg, make_controller("trim", cfg, "RocketRollRate-v0"), protocol_episodes(cfg, 2)
    )
    table = markdown_table([result], cfg)
    assert "RMS error (°/s)" in table and "| trim |" in table


def test_set_passes_environment_options_to_every_episode(tmp_path, default_db):
    out = tmp_path / "zero"
    assert (
        main(["--policy", "pid", "--episodes", "2", "--set", "setpoint=zero", "--out", str(out)])
        == 0
    )
    results = json.loads((out / "results.json").read_text())
    assert results["protocol"]["settings"] == {"setpoint": "zero"}
    assert results["protocol"]["config"]["setpoint"] == "zero"
    assert all(set(e["setpoints"]) == {0.0} for e in results["protocol"]["episodes"])


@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
def test_the_headline_tells_pid_ppo_and_the_oracle_apart(env_id, default_db):
    """The issue's requirement: on the protocol (20 test episodes, seed 0) the headline of
    the PID, the committed PPO and the oracle differ pairwise by more than 3 SEM."""
    cfg = variant_config(env_id, {"split": "test"})
    bank = load_bank(cfg, None)
    specs = protocol_episodes(cfg, 20, seed=0, bank=bank)
    results = {
        p: evaluate(cfg, make_controller(p, cfg, env_id), specs, bank=bank)
        for p in ("pid", "ppo", "oracle")
    }
    for a, b in [("pid", "ppo"), ("pid", "oracle"), ("ppo", "oracle")]:
        mean, sem = paired_difference(results[a], results[b])
        assert abs(mean) > 3 * sem, (a, b, mean, sem)
    # and the whole-episode RMS does not (what the headline replaced): within 1 %
    rms = [r.aggregate["rms_error"]["mean"] for r in results.values()]
    if env_id == "RocketRoll-v0":
        assert max(rms) < 1.01 * min(rms)
