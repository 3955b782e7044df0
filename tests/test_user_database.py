"""A user's own database works with every command: what it lacks is said in one line with
the option that replays what it holds or the command that adds what is missing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from disturbances.bank import TraceBank
from identification.instruments.bundled import bundled_path
from identification.recordings.recording import load_recording
from rocketroll.cli import main as rocketroll
from rocketroll_physics.flown import interval_means
from tests.cli import ok, refused

#: Fast identification: no Monte Carlo noise study.
FAST = ["--mc-runs", "0"]
#: The paper's replay (the default replays ml's posterior draws).
PAPER = ["--set", "method=paper", "--set", "disturbance=replay"]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two 10-Hz tunnel runs and one at 100 Hz."""
    folder = tmp_path_factory.mktemp("recordings")
    made = {}
    for name, extra in (("a", ["--seed", "5"]), ("b", ["--seed", "8"])):
        made[name] = folder / f"{name}.csv"
        assert rocketroll(["tunnel", *extra, "--out", str(made[name])]) == 0
    made["fast"] = folder / "fast.csv"
    assert (
        rocketroll(["tunnel", "--seed", "7", "--log-dt", "0.01", "--out", str(made["fast"])]) == 0
    )
    return made


def test_a_database_without_the_default_replay_says_what_it_holds(
    recordings: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`tune pid --db my.sqlite` on paper and output-error fits was a traceback."""
    db = str(tmp_path / "my.sqlite")
    add = ["db", "add", str(recordings["a"]), "--db", db, "--method", "paper", *FAST]
    ok(capsys, [*add, "--method", "output-error", "--split", "train"])
    refused(
        capsys,
        ["tune", "pid", "--db", db, "--episodes", "2"],
        "no posterior traces of ml's theta model in the train split",
        "its train split holds 1 identified of output-error, 1 identified of paper",
        "(--set method=output-error --set disturbance=replay)",
        f"rocketroll db add RECORDING --db {db} --method ml --posterior 8",
    )
    out = ok(capsys, ["tune", "pid", "--db", db, "--episodes", "2", "--omegas", "2,3", *PAPER])
    assert "best ω by regulation_rms_error" in out
    # No recording in the test split: eval says so and how to add one.
    refused(
        capsys,
        ["eval", "--db", db, "--policy", "pid", *PAPER, "--episodes", "2"],
        "none of its recordings is in the test split (it has train)",
        "--split test",
    )
    ok(capsys, ["db", "add", str(recordings["b"]), "--db", db, "--method", "paper", *FAST,
                "--split", "test"])  # fmt: skip
    out = ok(capsys, ["eval", "--db", db, "--policy", "pid", *PAPER, "--episodes", "2"])
    assert "| PID |" in out


def test_import_csv_and_db_add_take_the_split(
    recordings: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = load_recording(recordings["a"])
    assert rec.fin_cmd_deg is not None and rec.roll_deg is not None
    log = tmp_path / "log.csv"
    np.savetxt(log, np.column_stack([rec.time_s, rec.fin_cmd_deg, rec.roll_deg]), delimiter=",")
    out = tmp_path / "rec.csv"
    argv = ["import-csv", str(log), "--out", str(out), "--columns", "time,fin_cmd,roll"]
    ok(capsys, [*argv, "--no-header", "--split", "test"])
    assert load_recording(out).metadata["split"] == "test"


def test_traces_of_another_sampling_interval_are_averaged_onto_the_control_steps(
    recordings: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """After a 100-Hz import, `db add --method ml` and eval: 'all traces of a bank must
    share one Δt' (traceback)."""
    db = str(tmp_path / "mixed.sqlite")
    for name, split in (("a", "train"), ("b", "test"), ("fast", "test")):
        argv = ["db", "add", str(recordings[name]), "--db", db, "--method", "paper", *FAST]
        ok(capsys, [*argv, "--split", split])
    out = ok(capsys, ["eval", "--db", db, "--policy", "pid", *PAPER, "--episodes", "4"])
    assert "| PID |" in out


def test_averaging_a_held_trace_is_exact() -> None:
    u = np.random.default_rng(0).normal(0.0, 10.0, 1000)  # 100 Hz, 10 s
    edges = np.arange(101, dtype=np.float64) * 0.1
    means = interval_means(u, 0.01, edges)
    np.testing.assert_allclose(means, u.reshape(100, 10).mean(axis=1), rtol=0, atol=1e-12)
    fine, coarse = TraceBank.from_arrays([u], 0.01), TraceBank.from_arrays([u[:500]], 0.1)
    mixed = TraceBank([*fine.traces, *coarse.traces]).on_grid(0.1, 0.01)
    assert [(t.dt_s, t.n_samples) for t in mixed.traces] == [(0.1, 100), (0.1, 500)]
    assert mixed.traces[0].uid == fine.traces[0].uid  # the same turbulence, another grid
    off = TraceBank.from_arrays([u], 0.015).on_grid(0.1, 0.01)  # not whole substeps
    assert [(t.dt_s, t.n_samples) for t in off.traces] == [(0.1, 150)]
    assert fine.on_grid(0.1, 0.01) is fine  # one Δt of whole substeps: replayed as it is


def test_an_episode_longer_than_every_trace_is_one_line(
    default_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    refused(
        capsys,
        ["eval", "--policy", "pid", "--episodes", "1", "--set", "episode_s=3000"],
        "an episode is 3000 s, and the longest trace of",
        "--set episode_s=",
    )


def test_surrogates_of_a_recording_too_short_to_check_them_are_refused_first(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`db add REC --surrogates 2` on a 15-s recording was a traceback after the work."""
    short = tmp_path / "short.csv"
    argv = ["tunnel", "--schedule", "staircase", "--steps", "2", "--dwell-min", "6"]
    ok(capsys, [*argv, "--dwell-max", "8", "--seed", "1", "--out", str(short)])
    db = tmp_path / "s.sqlite"
    refused(
        capsys,
        ["db", "add", str(short), "--db", str(db), "--method", "paper", "--surrogates", "2"],
        "a checked surrogate needs 512 (51.2 s)",
        "--surrogates 0",
    )
    assert not db.exists()
    assert bundled_path("tunnel-paper-seed0").exists()


TINY_PPO = """\
RocketRoll-v0:
  n_envs: 1
  n_timesteps: 64
  n_steps: 32
  batch_size: 32
  n_epochs: 1
  policy_kwargs: {net_arch: [8], activation_fn: tanh}
"""


@pytest.fixture(scope="module")
def paper_db(recordings: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Paper fits only: a train recording and two test recordings."""
    db = tmp_path_factory.mktemp("paper") / "paper.sqlite"
    for name, split in (("a", "train"), ("b", "test"), ("fast", "test")):
        argv = ["db", "add", str(recordings[name]), "--db", str(db), "--method", "paper"]
        assert rocketroll([*argv, *FAST, "--split", split]) == 0
    return db


def test_a_recording_is_chosen_by_name_and_a_wrong_name_is_one_line(
    paper_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from agents.replay import options_config
    from rollenv.bank import load_bank

    capsys.readouterr()
    b, fast = "tunnel-paper-seed8", "tunnel-paper-seed7"  # the tunnel's names of b and fast
    config = options_config("RocketRoll-v0", {"method": "paper", "recording": b}, "test")
    assert {t.recording for t in load_bank(config, paper_db).traces} == {b}
    everything = options_config("RocketRoll-v0", {"method": "paper"}, "test")
    assert {t.recording for t in load_bank(everything, paper_db).traces} == {b, fast}
    db = str(paper_db)
    base = ["eval", "--db", db, "--policy", "pid", "--episodes", "2", *PAPER]
    assert "| PID |" in ok(capsys, [*base, "--set", f"recording={fast}"])
    refused(
        capsys,
        [*base, "--set", "recording=nope"],
        "no recording named 'nope'",
        f"its test split holds {fast}, {b}",
    )
    train = "tunnel-paper-seed5"
    refused(
        capsys,
        [*base, "--set", f"recording={train}"],
        f"recording '{train}' is in the train split, not test",
    )


def test_every_command_that_runs_episodes_replays_what_set_selects(
    paper_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """tune, eval, train, seeds, robustness and sweep run take --set and read it through
    one function: on a database of paper fits each runs on the paper replay and each
    says in one line what it lacks without it."""
    db = str(paper_db)
    runs = Path(__file__).resolve().parents[1] / "agents" / "policies" / "seeds" / "RocketRoll-v0"
    seeds = ["seeds", "--run", f"ppo:{runs / 'ppo' / 'seed1'}", "--run"]
    seeds += [f"ppo:{runs / 'ppo' / 'seed2'}", "--reference", "pid"]
    hyperparams = tmp_path / "tiny.yml"
    hyperparams.write_text(TINY_PPO, encoding="utf-8")
    spec = tmp_path / "spec.yml"
    spec.write_text(
        "name: mine\nenv_ids: [RocketRoll-v0]\nepisodes: 2\ncontrollers:\n"
        "  - {name: pid, policy: pid}\n",
        encoding="utf-8",
    )
    train = ["train", "ppo", "--hyperparams", str(hyperparams), "--eval-freq", "0"]
    train += ["--eval-episodes", "1", "--checkpoint-freq", "0", "--no-progress-bar"]
    commands = {
        "tune": ["tune", "pid", "--omegas", "2,3"],
        "eval": ["eval", "--policy", "pid"],
        "robustness": ["robustness", "--policy", "pid", "--condition", "default"],
        "seeds": seeds,
        "sweep": ["sweep", "run", str(spec), "--out", str(tmp_path / "sweep"), "--no-progress"],
        "train": [*train, "--out", str(tmp_path / "run"), "--timesteps", "32"],
    }
    episodes = {"tune": ["--episodes", "2"], "eval": ["--episodes", "2"]}
    episodes.update(robustness=["--episodes", "2"], seeds=["--episodes", "2"])
    for name, argv in commands.items():
        lacking = "no posterior traces of ml's theta model in the"
        refused(capsys, [*argv, *episodes.get(name, []), "--db", db], lacking, "--set method=")
        ok(capsys, [*argv, *episodes.get(name, []), "--db", db, *PAPER])
    import json

    trained = json.loads((tmp_path / "run" / "settings.json").read_text(encoding="utf-8"))
    assert trained["env_settings"]["method"] == "paper"
    assert trained["env_settings"]["disturbance"] == "replay"


def test_a_policy_reading_an_observer_is_evaluated_on_the_replay_it_was_trained_on(
    default_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    residual = "agents/policies/seeds/RocketRoll-v0/ppo-residual/seed0"
    refused(
        capsys,
        ["eval", "--policy", f"ppo:{residual}", "--episodes", "1", *PAPER],
        "its policy reads an observer designed with method='ml'",
        "give the same --set method=... as training did",
    )


def test_one_recording_is_replayed_but_designs_read_the_whole_train_split(
    paper_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """tune's nominal rocket is eval's (the whole train split); its hint leaves the
    recording out (eval's episodes come from the test split)."""
    db = str(paper_db)
    base = ["tune", "pid", "--db", db, "--episodes", "1", "--omegas", "3", *PAPER]
    whole = ok(capsys, base)
    one = ok(capsys, [*base, "--set", "recording=tunnel-paper-seed5"])
    nominal = [line for line in whole.splitlines() if line.startswith("  a = ")]
    assert nominal and nominal == [line for line in one.splitlines() if line.startswith("  a = ")]
    hint = one.splitlines()[-1]
    assert hint.startswith("use it with: rocketroll eval") and "recording" not in hint


def test_set_errors_name_set_and_conditions_take_their_own_disturbance(
    default_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    refused(
        capsys,
        ["train", "ppo", "--set", "gyro_nois=1", "--out", str(tmp_path / "run")],
        "--set: RocketRoll-v0: unknown option 'gyro_nois' (did you mean 'gyro_noise_pct'?)",
    )
    refused(capsys, ["sweep", "run", "pid-ppo-seeds", "--set", "split=test"], "--set split=")
    # --set disturbance=posterior is ml's; the paper-replay condition replays the paper's own
    argv = ["robustness", "--policy", "pid", "--condition", "default", "--condition"]
    out = ok(capsys, [*argv, "paper replay", "--episodes", "2", "--set", "disturbance=posterior"])
    assert "paper replay" in out


def test_a_sweep_refuses_an_observer_recipe_on_another_replay_before_any_trial(
    tmp_path: Path,
) -> None:
    from agents.sweep import expand, load_spec
    from rocketroll_common.errors import UsageError

    spec = tmp_path / "spec.yml"
    spec.write_text(
        "name: obs\nenv_ids: [RocketRoll-v0]\nepisodes: 2\ncontrollers:\n"
        "  - {name: res, train: ppo, hyperparams: ppo-residual.yml}\n"
        "settings: {method: [paper]}\n",
        encoding="utf-8",
    )
    (tmp_path / "ppo-residual.yml").write_bytes(
        (Path(__file__).resolve().parents[1] / "agents/hyperparams/ppo-residual.yml").read_bytes()
    )
    with pytest.raises(UsageError, match="observer: true with env_kwargs 'method'"):
        expand(load_spec(spec))
