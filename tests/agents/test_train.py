"""``agents.train`` (a tiny PPO run end to end) and ``agents.learned.LearnedController`` on
its output."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import re
import shlex
import shutil
import sys
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import pytest
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecNormalize

from agents.actor import ActorChain
from agents.base import FlightView
from agents.cli import TRAIN_COMMAND as COMMAND
from agents.learned import LearnedController, ObservationNormalizer
from agents.memory import PolicyLayout
from agents.train import (
    DEFAULT_HYPERPARAMS,
    VECNORMALIZE_FILE,
    Args,
    load_hyperparameters,
    make_env,
    parse_args,
    train,
)
from agents.vecenv import RollVecEnv
from disturbances.default import build_database
from identification.instruments.bundled import bundled_path
from identification.methods.pipeline import IdentifyOptions
from rocketroll.cli import command
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import flags, run_command
from rollenv.env import RocketRollEnv
from rollenv.layout import Obs
from tests.rollenv.conftest import array_bank

TINY = """\
RocketRoll-v0:
  n_envs: 2
  n_timesteps: 256
  policy: MlpPolicy
  normalize: {norm_obs: true, norm_reward: true}
  n_steps: 32
  batch_size: 32
  n_epochs: 2
  learning_rate: lin_3e-4
  policy_kwargs: {net_arch: [16, 16], activation_fn: tanh, log_std_init: -1.0}
"""


def _use_statistics(normalize: Any, run: Path) -> None:
    """Give a held-out stack's frozen ``VecNormalize`` the observation statistics the run
    ``run`` ended with (its ``normalize.json``): what the policy saw in training."""
    stored = json.loads((run / "normalize.json").read_text())
    normalize.obs_rms.mean = np.array(stored["mean"])
    normalize.obs_rms.var = np.array(stored["var"])


def main(argv: list[str]) -> int:
    """``python -m agents.train ARGV`` in this process."""
    with mock.patch.object(sys, "argv", ["python -m agents.train", *argv]):
        return run_command(COMMAND, argv, "python -m agents.train")


@pytest.fixture(scope="module")
def small_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A database of one bundled recording per split (seed 0: train, seed 4: test), of the
    method the environments replay by default (``ml``, its posterior draws) alone."""
    path = tmp_path_factory.mktemp("agents-db") / "small.sqlite"
    recordings = [bundled_path(n) for n in ("tunnel-paper-seed0", "tunnel-paper-seed4")]
    options = IdentifyOptions(noise_runs=0)
    build_database(path, recordings, options=options, surrogates=0, methods=("ml",))
    return path


@pytest.fixture(scope="module")
def run(small_db: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A tiny training run's output directory and its printed output."""
    folder = tmp_path_factory.mktemp("train")
    hyperparams = folder / "tiny.yml"
    hyperparams.write_text(TINY, encoding="utf-8")
    out = folder / "run"
    argv = [
        "--hyperparams",
        str(hyperparams),
        "--db",
        str(small_db),
        "--out",
        str(out),
        "--seed",
        "3",
        "--eval-freq",
        "128",
        "--eval-episodes",
        "2",
        "--checkpoint-freq",
        "128",
        "--no-progress-bar",
    ]
    capture = folder / "stdout.txt"
    with capture.open("w", encoding="utf-8") as sink, contextlib.redirect_stdout(sink):
        assert main(argv) == 0
    return out, capture.read_text(encoding="utf-8")


def test_main_writes_the_model_statistics_settings_checkpoints_and_evaluations(run):
    out, printed = run
    for name in ("model.zip", "normalize.json", VECNORMALIZE_FILE, "settings.json"):
        assert (out / name).is_file(), name
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == [
        "ppo_128_steps.zip",
        "ppo_256_steps.zip",
        "ppo_vecnormalize_128_steps.pkl",
        "ppo_vecnormalize_256_steps.pkl",
    ]
    evaluations = np.load(out / "eval" / "evaluations.npz")
    assert evaluations["timesteps"].tolist() == [128, 256]
    assert evaluations["ep_lengths"].tolist() == [[600, 600], [600, 600]]
    rows = (out / "eval" / "tracking_error.csv").read_text().splitlines()
    assert rows[0] == "timesteps,mean_reward,rms_tracking_error" and len(rows) == 3
    assert all(float(r.split(",")[2]) > 0 for r in rows[1:])
    settings = json.loads((out / "settings.json").read_text())
    assert settings["env_id"] == "RocketRoll-v0"
    assert settings["args"]["seed"] == 3 and settings["env_steps"] == 256
    assert settings["hyperparameters"]["n_steps"] == 32
    assert settings["hyperparameters"]["learning_rate"] == "lin_3e-4"
    assert settings["env_settings"]["split"] == "train"
    assert "--seed 3" in settings["command_line"] and "agents.train" in settings["command_line"]
    # The echoed command is written by the code that parses it, and reads back the same.
    assert parse_args(shlex.split(settings["equivalent_command"])[3:]) == parse_args(
        shlex.split(settings["command_line"])[1:]
    )
    assert {"torch", "stable_baselines3", "gymnasium", "numpy"} <= set(settings["versions"])
    assert settings["env_steps_per_s"] > 0 and settings["wall_time_s"] > 0
    assert settings["final_test_eval"]["episodes"] == 2
    assert "final model" in settings["result"]
    # The settings are printed as a table first.
    assert printed.index("n_steps") < printed.index("trained 256 env-steps")
    assert "| 32" in printed


def test_normalize_json_is_the_training_statistics(run):
    out, _ = run
    record = json.loads((out / "normalize.json").read_text())
    assert record["norm_obs"] is True and len(record["mean"]) == len(record["var"]) == 4
    # vecnormalize.pkl (and the checkpoint at the last step) hold VecNormalize itself,
    # pickled by SB3, as SB3 users load it.
    venv = VecNormalize.load(str(out / VECNORMALIZE_FILE), RollVecEnv(1, bank=array_bank()))
    last = VecNormalize.load(
        str(out / "checkpoints" / "ppo_vecnormalize_256_steps.pkl"),
        RollVecEnv(1, bank=array_bank()),
    )
    assert isinstance(venv.obs_rms, RunningMeanStd) and isinstance(last.obs_rms, RunningMeanStd)
    np.testing.assert_array_equal(last.obs_rms.mean, venv.obs_rms.mean)
    np.testing.assert_array_equal(venv.obs_rms.mean, record["mean"])
    np.testing.assert_array_equal(venv.obs_rms.var, record["var"])
    normalizer = ObservationNormalizer(record)
    obs = np.random.default_rng(0).normal(0.0, 60.0, size=(200, 4)).astype(np.float32)
    obs[:3] = [[180.0, 250.0, 40.0, 40.0], [-180.0, -250.0, -40.0, -40.0], [0.0, 0.0, 0.0, 0.0]]
    expected = np.asarray(venv.normalize_obs(obs))
    assert expected.dtype == normalizer(obs).dtype == np.float32
    np.testing.assert_array_equal(normalizer(obs), expected)


def test_a_checkpoint_acts_as_the_model_of_its_step(run):
    """``LearnedController.load(run, checkpoint)`` (learning curves): the last checkpoint
    acts as the final model with the final statistics (here because the recipe's ``lin_``
    learning rate is 0 at the last update, which follows that checkpoint); an earlier one
    acts otherwise."""
    from agents.learned import LearnedController

    out, _ = run
    final = LearnedController.load(out)
    last = LearnedController.load(out, out / "checkpoints" / "ppo_256_steps.zip")
    early = LearnedController.load(out, out / "checkpoints" / "ppo_128_steps.zip")
    np.testing.assert_array_equal(last.normalizer.mean, final.normalizer.mean)
    obs = np.random.default_rng(1).normal(0.0, 20.0, size=(50, 4)).astype(np.float32)
    acted = [np.concatenate([c.predict(o) for o in obs]) for c in (final, last, early)]
    np.testing.assert_array_equal(acted[1], acted[0])
    assert not np.array_equal(acted[2], acted[0])
    with pytest.raises(FileNotFoundError, match=r"ppo_9_steps\.zip"):
        LearnedController.load(out, out / "checkpoints" / "ppo_9_steps.zip")
    # a checkpoint copied without its statistics is refused, not scored unnormalised
    alone = out.parent / "alone"
    alone.mkdir()
    shutil.copy(out / "settings.json", alone)
    shutil.copy(out / "checkpoints" / "ppo_128_steps.zip", alone)
    with pytest.raises(FileNotFoundError, match=r"ppo_vecnormalize_128_steps\.pkl"):
        LearnedController.load(alone, alone / "ppo_128_steps.zip")


def _resume(run_folder: Path, small_db: Path, checkpoint: str, timesteps: int, out: Path) -> str:
    hyperparams = run_folder.parent / "tiny.yml"
    argv = ["--hyperparams", str(hyperparams), "--db", str(small_db), "--out", str(out)]
    argv += ["--seed", "3", "--eval-freq", "128", "--eval-episodes", "2"]
    argv += ["--checkpoint-freq", "128", "--no-progress-bar"]
    argv += ["--resume", str(checkpoint), "--timesteps", str(timesteps)]
    capture = out.parent / f"resume-{timesteps}.txt"
    with capture.open("w", encoding="utf-8") as sink, contextlib.redirect_stdout(sink):
        assert main(argv) == 0
    return capture.read_text(encoding="utf-8")


def test_resuming_in_the_same_folder_keeps_the_logs_and_the_statistics(run, small_db, tmp_path):
    """A run resumed from its 128-step checkpoint goes on where it was: the evaluations up to
    then are kept, the CSV log is not overwritten, VecNormalize's statistics carry on."""
    out = tmp_path / "run"
    shutil.copytree(run[0], out)
    checkpoint = out / "checkpoints" / "ppo_128_steps.zip"
    printed = _resume(run[0], small_db, str(checkpoint), 384, out)
    assert "trained 256 env-steps (resumed at 128: 384 in all)" in printed
    evaluations = np.load(out / "eval" / "evaluations.npz")
    assert evaluations["timesteps"].tolist() == [128, 256, 384]
    first = np.load(run[0] / "eval" / "evaluations.npz")
    np.testing.assert_array_equal(evaluations["results"][0], first["results"][0])
    rows = (out / "eval" / "tracking_error.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["128", "256", "384"]
    assert (out / "logs" / "progress.csv").read_text() == (
        run[0] / "logs" / "progress.csv"
    ).read_text()
    assert (out / "logs" / "progress_from_128.csv").is_file()
    settings = json.loads((out / "settings.json").read_text())
    assert settings["env_steps"] == 384 and settings["resumed_at_env_steps"] == 128
    env = RollVecEnv(1, bank=array_bank())
    before = VecNormalize.load(str(checkpoint.parent / "ppo_vecnormalize_128_steps.pkl"), env)
    after = VecNormalize.load(str(out / VECNORMALIZE_FILE), env)
    # One count per observation row: 256 steps, plus the resumed
    # run's first reset (2 envs); a fresh VecNormalize would have counted 258.
    assert isinstance(after.obs_rms, RunningMeanStd) and isinstance(before.obs_rms, RunningMeanStd)
    assert after.obs_rms.count == pytest.approx(before.obs_rms.count + 256 + 2)


def test_a_finished_run_resumes_from_its_model_and_vecnormalize(run, small_db, tmp_path):
    printed = _resume(run[0], small_db, str(run[0] / "model.zip"), 320, tmp_path / "more")
    assert "trained 64 env-steps (resumed at 256: 320 in all)" in printed
    plain = tmp_path / "plain.yml"
    plain.write_text(TINY.replace("normalize: {norm_obs: true, norm_reward: true}", ""))
    args = Args(hyperparams=plain, db=str(small_db), resume=run[0] / "model.zip", out=tmp_path)
    with pytest.raises(UsageError, match=r"trained with VecNormalize .* normalize: false"):
        train(dataclasses.replace(args, out=tmp_path / "x", timesteps=320))
    assert not (tmp_path / "x").exists()  # nothing written
    other = tmp_path / "other.yml"
    other.write_text(TINY + "  history: 1\n  integral: 2.0\n", encoding="utf-8")
    args = dataclasses.replace(args, hyperparams=other, out=tmp_path / "y", timesteps=320)
    with pytest.raises(UsageError, match=r"trained on another observation or action than"):
        train(args)
    assert not (tmp_path / "y").exists()  # nothing written


def test_controller_acts_like_predict_within_the_action_space(run):
    out, _ = run
    controller = LearnedController.load(out)
    assert controller.name == "PPO" and controller.task == "angle"
    env = RocketRollEnv(bank=array_bank())
    obs, _ = env.reset(seed=0)
    view = FlightView(env)
    controller.reset(view)
    actions = []
    for _ in range(100):
        action = controller.act(obs, view)
        assert action.dtype == np.float32 and action.shape == (1,)
        # The same network as torch's, summed in float64: within float32 rounding.
        np.testing.assert_allclose(action, controller.predict(obs), rtol=0, atol=1e-6)
        actions.append(float(action[0]))
        obs, *_ = env.step(action)
    assert all(-1.0 <= a <= 1.0 for a in actions)
    assert len(set(actions)) > 10  # it reacts to the observation
    extreme = np.array([-180.0, 250.0, -40.0, 40.0], np.float32)
    np.testing.assert_allclose(
        controller.act(extreme, view), controller.predict(extreme), rtol=0, atol=1e-6
    )
    with pytest.raises(ValueError, match="'angle' task"):
        controller.reset(FlightView(RocketRollEnv(bank=array_bank(), task="rate")))


def test_load_refuses_a_folder_without_a_model(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"model\.zip"):
        LearnedController.load(tmp_path)


# ------------------------------------------------------------------------- arguments
def test_arguments_parse_into_the_dataclass_with_help_from_its_fields():
    assert parse_args([]) == Args()
    args = parse_args(["--env-id", "RocketRollRate-v0", "--timesteps", "5000", "--envs", "4"])
    assert (args.env_id, args.timesteps, args.envs) == ("RocketRollRate-v0", 5000, 4)
    assert parse_args(["--no-progress-bar"]).progress_bar is False
    assert parse_args(["--out", "x/y"]).out == Path("x/y")
    assert set(flags(Args)) == {f.name for f in dataclasses.fields(Args)}
    helptext = COMMAND.parser("rocketroll train ppo").format_help()
    assert "seed of torch" in helptext and "--resume" in helptext


def test_rocketroll_train_ppo_is_the_same_command():
    parser = command("train").parser("rocketroll train")
    ns = parser.parse_args(["ppo", "--env-id", "RocketRollRate-v0", "--seed", "7"])
    assert ns._command is COMMAND
    assert (ns.env_id, ns.seed, ns.timesteps, ns.progress_bar) == (
        "RocketRollRate-v0",
        7,
        None,
        True,
    )
    with pytest.raises(UsageError, match="--timesteps: must be an integer"):
        parser.parse_args(["ppo", "--timesteps", "many"])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--env-id", "CartPole-v1"], "argument --env-id: invalid choice: 'CartPole-v1'"),
        (["--timesteps", "0"], "--timesteps: must be in [1, 1000000000000], got 0"),
        (["--envs", "-2"], "--envs: must be in [1, 4096], got -2"),
        (["--envs", "100000"], "--envs: must be in [1, 4096], got 100000"),
        (["--eval-episodes", "0"], "--eval-episodes: must be in [1, 4096], got 0"),
        (["--torch-threads", "0"], "--torch-threads: must be in [1, 1024], got 0"),
        (["--checkpoint-freq", "-1"], "--checkpoint-freq: must be in [0, 1000000000000], got -1"),
        (["--db", "/nonexistent/db.sqlite"], "--db: /nonexistent/db.sqlite: no such file"),
        (["--hyperparams", "/nonexistent.yml"], "--hyperparams /nonexistent.yml: no such file"),
    ],
)
def test_bad_arguments_are_named_and_exit_2(argv, message, capsys):
    assert main([*argv, "--no-progress-bar"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m agents.train: error: ") and message in err


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("RocketRollRate-v0: {n_envs: 2}\n", "no entry for 'RocketRoll-v0'"),
        (TINY.replace("n_steps:", "nsteps:"), "unknown key(s) 'nsteps'"),
        (
            TINY.replace("n_envs: 2", "n_envs: 0"),
            "n_envs: Input should be greater than or equal to 1",
        ),
        (TINY.replace("lin_3e-4", "cosine"), "learning_rate must be a number or 'lin_<number>'"),
        (TINY.replace("activation_fn: tanh", "activation_fn: swish"), "activation_fn must be"),
        (TINY.replace("norm_reward: true", "norm_rewards: true"), "'norm_rewards'"),
        ("- a list\n", "expected a mapping keyed by environment id"),
    ],
)
def test_bad_hyperparameter_files_are_named(tmp_path, text, message):
    path = tmp_path / "hp.yml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(UsageError) as excinfo:
        load_hyperparameters(path, "RocketRoll-v0")
    assert message in str(excinfo.value) and str(path) in str(excinfo.value)


def test_a_file_without_counts_needs_them_on_the_command_line(tmp_path):
    """n_envs (1) and policy (MlpPolicy) default as in rl-baselines3-zoo; the length of
    training must come from the file or --timesteps."""
    path = tmp_path / "hp.yml"
    path.write_text("RocketRoll-v0: {n_steps: 64, batch_size: 64}\n", encoding="utf-8")
    hp = load_hyperparameters(path, "RocketRoll-v0")
    assert (hp.n_envs, hp.n_timesteps, hp.policy) == (1, None, "MlpPolicy")
    with pytest.raises(UsageError, match=r"--timesteps is needed: .*hp.yml, RocketRoll-v0 has no"):
        train(Args(hyperparams=path, out=tmp_path / "run"))
    assert not (tmp_path / "run").exists()


def test_batch_size_must_divide_the_rollout(tmp_path):
    path = tmp_path / "hp.yml"
    path.write_text(TINY.replace("batch_size: 32", "batch_size: 64"), encoding="utf-8")
    with pytest.raises(UsageError, match=r"--envs 3 x n_steps 32 = 96 .* batch_size 64"):
        train(Args(hyperparams=path, envs=3))


def test_the_shipped_hyperparameters_load_for_both_tasks():
    for env_id in ("RocketRoll-v0", "RocketRollRate-v0"):
        hp = load_hyperparameters(DEFAULT_HYPERPARAMS, env_id)
        assert hp.n_timesteps is not None, env_id
        assert hp.policy == "MlpPolicy" and hp.n_envs >= 1 and hp.n_timesteps >= 100_000
        assert (hp.algo_kwargs["n_steps"] * hp.n_envs) % hp.algo_kwargs["batch_size"] == 0


def test_a_policys_layout_is_read_back_as_it_was_recorded(tmp_path):
    """What training records of a policy's layout (`settings.json`'s hyperparameters) is what
    the controller reads back; keys absent from an older run's settings mean "not used", and
    a residual implies the observer's estimate."""
    layouts = [
        PolicyLayout(),
        PolicyLayout(history=2, incremental=0.1),
        PolicyLayout(history=4, observer=True, residual=0.25),
        PolicyLayout(flight_clock=True, integral=10.0, integral_clip=3.0),
    ]
    for layout in layouts:
        recorded = json.loads(json.dumps({"hyperparameters": {"n_envs": 4, **layout.record()}}))
        assert PolicyLayout.from_settings(recorded) == layout
    assert PolicyLayout().record() == {}
    assert PolicyLayout.from_settings({}) == PolicyLayout()
    assert PolicyLayout.from_settings({"hyperparameters": {"residual": 0.5}}).observer
    assert PolicyLayout(residual=0.25) == PolicyLayout(residual=0.25, observer=True)
    path = tmp_path / "hp.yml"
    path.write_text(
        TINY.replace("  n_steps: 32", "  history: 2\n  integral: 5\n  n_steps: 32"),
        encoding="utf-8",
    )
    hp = load_hyperparameters(path, "RocketRoll-v0")
    assert hp.layout == PolicyLayout(history=2, integral=5.0)


# ------------------------------------------------------------------ SAC, TD3, memory
TINY_OFF_POLICY = """\
RocketRoll-v0:
  n_envs: 2
  n_timesteps: 240
  policy: MlpPolicy
  normalize: {norm_obs: true, norm_reward: true}
  history: 3
  learning_starts: 100
  batch_size: 32
  buffer_size: 1000
  policy_kwargs: {net_arch: [16, 16]}
"""


@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_runs_with_history_and_observer_act_as_they_were_trained(algo, small_db, tmp_path):
    """A tiny SAC/TD3 run with 3 steps of history (PPO: 3 steps and the observer's
    estimate): settings.json records them, and the controller, which keeps its own history
    and observer, acts on an episode exactly as the model's predict() on the training
    stack's observation (VecPolicyObservation, VecNormalize)."""
    from agents.cli import SAC_COMMAND, TD3_COMMAND
    from agents.train import load_hyperparameters, make_env
    from rollenv.bank import load_bank, variant_config

    text = {
        "sac": TINY_OFF_POLICY,
        "td3": TINY_OFF_POLICY + "  noise_type: normal\n  noise_std: 0.2\n",
        "ppo": TINY.replace("  n_timesteps: 256\n", "  n_timesteps: 128\n")
        + "  history: 3\n  observer: true\n",
    }[algo]
    hyperparams = tmp_path / f"{algo}.yml"
    hyperparams.write_text(text, encoding="utf-8")
    out = tmp_path / "run"
    argv = ["--hyperparams", str(hyperparams), "--db", str(small_db), "--out", str(out)]
    argv += ["--eval-freq", "0", "--eval-episodes", "2", "--checkpoint-freq", "0"]
    argv += ["--no-progress-bar"]
    command = {"sac": SAC_COMMAND, "td3": TD3_COMMAND, "ppo": COMMAND}[algo]
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        assert run_command(command, argv, f"rocketroll train {algo}") == 0
    assert f"{algo.upper()} on RocketRoll-v0" in printed.getvalue()
    assert "history" in printed.getvalue()
    settings = json.loads((out / "settings.json").read_text())
    assert settings["algorithm"] == algo and settings["hyperparameters"]["history"] == 3
    assert settings["equivalent_command"].startswith(f"rocketroll train {algo} ")
    if algo == "td3":
        assert settings["hyperparameters"]["noise_std"] == 0.2
    observer = algo == "ppo"
    assert settings["hyperparameters"].get("observer", False) is observer
    controller = LearnedController.load(out)
    assert controller.name == algo.upper() and controller.layout.history == 3
    assert controller.needs_observer is observer
    if observer:
        train_config = variant_config("RocketRoll-v0", {"split": "train"})
        controller.attach_observer(train_config, load_bank(train_config, small_db))
    # The training stack, one env, frozen statistics: what the policy saw in training.
    hp = load_hyperparameters(hyperparams, "RocketRoll-v0", algo)
    _, stack, normalize = make_env(hp, 1, 5, split="test", db=small_db, training=False)
    _use_statistics(normalize, out)
    seen = stack.reset()
    width = 4 + (3 if observer else 0)  # the observation (and the observer's estimate)
    assert seen.shape == (1, width * 4 + 3)  # it, 3 past ones, 3 past actions
    raw = stack.unnormalize_obs(seen)[0, :4]
    view = FlightView(RocketRollEnv(bank=array_bank()))
    controller.reset(view)
    for _ in range(30):
        expected, _ = controller.model.predict(seen, deterministic=True)
        action = controller.act(raw, view)
        np.testing.assert_allclose(action, expected.reshape(1), rtol=0, atol=1e-6)
        seen, _, _, _ = stack.step(action.reshape(1, 1))
        raw = stack.unnormalize_obs(seen)[0, :4]


def test_an_incremental_policy_moves_the_fin_from_its_last_command(small_db, tmp_path):
    """``incremental: S``: the env gets the last command plus S × the policy's action; the
    acting controller sends, step by step, the command the training stack applied."""
    from agents.memory import incremental_commands
    from agents.train import load_hyperparameters, make_env
    from rollenv.layout import Obs

    hyperparams = tmp_path / "inc.yml"
    text = TINY.replace("  n_timesteps: 256\n", "  n_timesteps: 128\n")
    hyperparams.write_text(text + "  history: 2\n  incremental: 0.375\n", encoding="utf-8")
    out = tmp_path / "run"
    argv = ["--hyperparams", str(hyperparams), "--db", str(small_db), "--out", str(out)]
    argv += ["--eval-freq", "0", "--eval-episodes", "1", "--checkpoint-freq", "0"]
    with contextlib.redirect_stdout(io.StringIO()):
        assert run_command(COMMAND, [*argv, "--no-progress-bar"], "rocketroll train ppo") == 0
    controller = LearnedController.load(out)
    assert controller.layout.incremental == 0.375
    hp = load_hyperparameters(hyperparams, "RocketRoll-v0")
    _, stack, normalize = make_env(hp, 1, 5, split="test", db=small_db, training=False)
    _use_statistics(normalize, out)
    seen = stack.reset()
    raw = stack.unnormalize_obs(seen)[0, :4]
    view = FlightView(RocketRollEnv(bank=array_bank()))
    controller.reset(view)
    moved = []
    for _ in range(30):
        action, _ = controller.model.predict(seen, deterministic=True)
        expected = np.clip(raw[Obs.COMMAND] / 40.0 + 0.375 * action.reshape(1), -1, 1)
        sent = controller.act(raw, view)
        np.testing.assert_allclose(sent, expected, rtol=0, atol=1e-6)
        seen, _, _, _ = stack.step(action.reshape(1, 1))
        raw = stack.unnormalize_obs(seen)[0, :4]
        np.testing.assert_allclose(raw[Obs.COMMAND], 40.0 * sent[0], atol=1e-3)  # applied
        moved.append(abs(float(sent[0]) - float(expected[0] - 0.375 * action.reshape(1)[0])))
    assert max(moved) > 0  # the actions moved the fin
    np.testing.assert_array_equal(
        incremental_commands(np.array([0.9, -0.5]), np.array([[1.0], [0.2]]), 0.375),
        np.array([[1.0], [-0.425]], dtype=np.float32),
    )


def test_an_integral_policy_reads_the_leaky_integral_of_its_observed_error(small_db, tmp_path):
    """``integral: τ`` (``integral_clip: c``): the observation carries
    ``I_t = exp(-dt/τ) I_{t-1} + dt clip(e_t, ±c)``; the acting controller rebuilds it from
    the observations alone, step by step, and acts as model.predict does on the training
    stack, across the end of an episode."""
    import math

    from agents.train import load_hyperparameters, make_env

    hyperparams = tmp_path / "int.yml"
    text = TINY.replace("  n_timesteps: 256\n", "  n_timesteps: 128\n")
    extra = "  history: 1\n  integral: 2.0\n  integral_clip: 3.0\n"
    hyperparams.write_text(text + extra, encoding="utf-8")
    out = tmp_path / "run"
    argv = ["--hyperparams", str(hyperparams), "--db", str(small_db), "--out", str(out)]
    argv += ["--eval-freq", "0", "--eval-episodes", "1", "--checkpoint-freq", "0"]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert run_command(COMMAND, [*argv, "--no-progress-bar"], "rocketroll train ppo") == 0
    assert "in the observation, time constant 2 s, integrand clipped at 3" in printed.getvalue()
    assert "1 test-split episodes at the end" in printed.getvalue()  # --eval-freq 0
    settings = json.loads((out / "settings.json").read_text())
    assert settings["hyperparameters"]["integral"] == 2.0
    assert settings["hyperparameters"]["integral_clip"] == 3.0
    names = json.loads((out / "normalize.json").read_text())["observation_names"]
    assert names[4] == "error_integral" and names[9] == "error_integral@t-1"
    controller = LearnedController.load(out)
    assert (controller.layout.integral, controller.layout.integral_clip) == (2.0, 3.0)
    hp = load_hyperparameters(hyperparams, "RocketRoll-v0")
    options = {"episode_s": 2.0}  # 20 steps: the loop crosses into a second episode
    hp = dataclasses.replace(hp, env_kwargs={**hp.env_kwargs, **options})
    adapter, stack, normalize = make_env(hp, 1, 5, split="test", db=small_db, training=False)
    _use_statistics(normalize, out)
    dt = adapter.config.dt_s
    seen = stack.reset()
    env = RocketRollEnv(bank=array_bank(), episode_s=2.0)
    view = FlightView(env)
    controller.reset(view)
    integral, clipped, ends = 0.0, 0, 0
    for _ in range(30):
        raw_all = stack.unnormalize_obs(seen)[0]
        error = float(raw_all[Obs.ERROR])
        clipped += abs(error) > 3.0
        integral = math.exp(-dt / 2.0) * integral + dt * float(np.clip(error, -3.0, 3.0))
        np.testing.assert_allclose(raw_all[4], integral, rtol=1e-5, atol=1e-5)
        expected, _ = controller.model.predict(seen, deterministic=True)
        action = controller.act(raw_all[:4], view)
        np.testing.assert_allclose(action, expected.reshape(1), rtol=0, atol=1e-6)
        seen, _, dones, _ = stack.step(action.reshape(1, 1))
        if dones[0]:  # a new episode: the integral and the controller start afresh
            ends += 1
            integral = 0.0
            controller.reset(view)
    assert ends == 1 and clipped > 0  # both the reset and the clip were exercised


def test_a_policy_is_loaded_only_under_its_own_algorithm(run, tmp_path, default_db):
    from agents.registry import make_controller
    from rollenv.bank import variant_config

    cfg = variant_config("RocketRoll-v0", {"split": "test"})
    with pytest.raises(ValueError, match=r"that run trained PPO, not SAC"):
        make_controller(f"sac:{run[0]}", cfg, "RocketRoll-v0")
    with pytest.raises(ValueError, match=r"--policy td3:DIR needs the folder"):
        make_controller("td3", cfg, "RocketRoll-v0")


@pytest.mark.parametrize(
    ("extra", "algo", "message"),
    [
        ("  noise_type: normal\n  noise_std: 0.1\n", "ppo", "are for SAC and TD3, not PPO"),
        (
            "  noise_type: ou\n  noise_std: 0.1\n",
            "sac",
            "noise_type: Input should be 'normal', got 'ou'",
        ),
        ("  history: -1\n", "ppo", "history: Input should be greater than or equal to 0"),
        ("  n_epochs: 3\n", "sac", "unknown key(s) 'n_epochs'"),
    ],
)
def test_bad_algorithm_settings_are_named(extra, algo, message, tmp_path):
    path = tmp_path / "hp.yml"
    base = TINY if algo == "ppo" else TINY_OFF_POLICY.replace("  history: 3\n", "")
    path.write_text(base + extra, encoding="utf-8")
    with pytest.raises(UsageError, match=re.escape(message)):
        load_hyperparameters(path, "RocketRoll-v0", algo)


def test_the_shipped_off_policy_and_memory_hyperparameters_load():
    from agents.train import HYPERPARAMS_DIR

    for env_id in ("RocketRoll-v0", "RocketRollRate-v0"):
        for name, algo in [
            ("sac-history", "sac"),
            ("td3-history", "td3"),
            ("ppo-history", "ppo"),
            ("ppo-observer", "ppo"),
        ]:
            hp = load_hyperparameters(HYPERPARAMS_DIR / f"{name}.yml", env_id, algo)
            assert hp.layout.history >= 1 and hp.n_timesteps is not None, (name, env_id)
    zero = load_hyperparameters(HYPERPARAMS_DIR / "ppo-zero.yml", "RocketRoll-v0")
    assert zero.env_kwargs == {"setpoint": "zero"}
    plain = load_hyperparameters(DEFAULT_HYPERPARAMS, "RocketRoll-v0")
    assert (zero.algo_kwargs, zero.n_envs, zero.n_timesteps) == (
        plain.algo_kwargs,
        plain.n_envs,
        plain.n_timesteps,
    )
    residual = load_hyperparameters(HYPERPARAMS_DIR / "ppo-residual.yml", "RocketRoll-v0")
    assert residual.layout.residual == 0.25 and residual.layout.observer
    assert residual.env_kwargs == {"setpoint": "zero"}


def test_sac_resumes_from_a_checkpoint_with_its_replay_buffer(small_db, tmp_path):
    from agents.train import SACArgs

    hyperparams = tmp_path / "sac.yml"
    hyperparams.write_text(TINY_OFF_POLICY, encoding="utf-8")
    args = SACArgs(
        hyperparams=hyperparams,
        db=str(small_db),
        out=tmp_path / "run",
        eval_freq=0,
        eval_episodes=1,
        checkpoint_freq=120,
        progress_bar=False,
    )
    with contextlib.redirect_stdout(io.StringIO()):
        train(args)
    checkpoint = tmp_path / "run" / "checkpoints" / "sac_120_steps.zip"
    assert (checkpoint.parent / "sac_replay_buffer_120_steps.pkl").is_file()
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        train(dataclasses.replace(args, resume=checkpoint, out=tmp_path / "more", timesteps=280))
    assert "resumed at 120" in printed.getvalue()
    with pytest.raises(UsageError, match=r"replay buffer beside it .* model\.zip has none"):
        train(dataclasses.replace(args, resume=tmp_path / "run" / "model.zip", timesteps=300))


def test_the_observer_refuses_env_kwargs_that_change_its_design(tmp_path):
    path = tmp_path / "hp.yml"
    path.write_text(TINY + "  observer: true\n  env_kwargs: {method: paper}\n", encoding="utf-8")
    with pytest.raises(UsageError, match="observer: true with env_kwargs 'method'"):
        load_hyperparameters(path, "RocketRoll-v0")
    path.write_text(TINY + "  observer: true\n  env_kwargs: {setpoint_range: 20}\n", "utf-8")
    assert load_hyperparameters(path, "RocketRoll-v0").layout.observer


# ------------------------------------------------------------------ residual on the observer
@pytest.fixture(scope="module")
def residual_run(small_db: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A tiny PPO run whose action is a residual (× 0.25) on the observer controller's."""
    folder = tmp_path_factory.mktemp("residual")
    hyperparams = folder / "residual.yml"
    hyperparams.write_text(TINY + "  residual: 0.25\n", encoding="utf-8")
    out = folder / "run"
    argv = ["--hyperparams", str(hyperparams), "--db", str(small_db), "--out", str(out)]
    argv += ["--eval-freq", "0", "--eval-episodes", "2", "--checkpoint-freq", "0"]
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        assert run_command(COMMAND, [*argv, "--no-progress-bar"], "rocketroll train ppo") == 0
    assert "x 0.25 on the observer's command" in printed.getvalue()
    return out, hyperparams


def _observer_on_train(small_db: Path) -> tuple[Any, Any]:
    from agents.nominal import NominalModel
    from agents.observer import ObserverController, TurbulenceModel
    from rollenv.bank import load_bank, variant_config

    train_config = variant_config("RocketRoll-v0", {"split": "train"})
    bank = load_bank(train_config, small_db)
    nominal = NominalModel.from_bank(bank)
    turbulence = TurbulenceModel.from_bank(bank, train_config.dt_s, nominal)
    return ObserverController(train_config, nominal, turbulence), (train_config, bank)


def test_a_residual_policy_adds_its_action_to_the_observer_controllers(residual_run, small_db):
    """The learned controller of a residual run applies the observer controller's command
    plus 0.25 × the model's predict() on the training stack's observation, step by step;
    the stack below applies the same (else the observations would part)."""
    from agents.observer import ObserverFeatures

    out, hyperparams = residual_run
    settings = json.loads((out / "settings.json").read_text())
    assert settings["hyperparameters"]["residual"] == 0.25
    controller = LearnedController.load(out)
    assert controller.layout.residual == 0.25 and controller.needs_observer
    reference, (train_config, bank) = _observer_on_train(small_db)
    controller.attach_observer(train_config, bank)
    hp = load_hyperparameters(hyperparams, "RocketRoll-v0")
    assert hp.layout.observer and hp.layout.residual == 0.25
    _, stack, normalize = make_env(hp, 1, 5, split="test", db=small_db, training=False)
    assert isinstance(stack.venv.venv.stack.features, ObserverFeatures)
    _use_statistics(normalize, out)
    seen = stack.reset()
    assert seen.shape == (1, 7)
    raw = stack.unnormalize_obs(seen)[0, :4].astype(np.float32)
    view = FlightView(RocketRollEnv(bank=array_bank()))
    controller.reset(view)
    reference.reset()
    limit = reference.config.fin_range_deg
    moved = 0.0
    for step in range(40):
        residual, _ = controller.model.predict(seen, deterministic=True)
        state, shift = reference.design_state(raw)
        base = reference.command(state, shift, float(raw[Obs.FIN])) / limit
        expected = np.clip(base + 0.25 * float(residual[0, 0]), -1.0, 1.0)
        action = controller.act(raw, view)
        np.testing.assert_allclose(action, [expected], rtol=0, atol=1e-6, err_msg=f"step {step}")
        moved = max(moved, abs(float(residual[0, 0])))
        reference._last = (float(raw[Obs.FIN]), float(action[0]) * limit)
        seen, _, _, _ = stack.step(residual.reshape(1, 1))
        raw = stack.unnormalize_obs(seen)[0, :4].astype(np.float32)
    assert moved > 1e-4  # the residual was not nothing


def test_a_residual_policy_of_zero_is_the_observer_controller(residual_run, small_db):
    """With its action net zeroed, a residual policy flies an episode exactly as the
    observer controller does."""
    import torch

    out, _ = residual_run
    controller = LearnedController.load(out)
    with torch.no_grad():
        controller.model.policy.action_net.weight.zero_()
        controller.model.policy.action_net.bias.zero_()
    controller.chain = ActorChain.from_policy(controller.model.policy)  # the weights changed
    reference, (train_config, bank) = _observer_on_train(small_db)
    controller.attach_observer(train_config, bank)
    actions = []
    for agent in (controller, reference):
        env = RocketRollEnv(bank=array_bank())
        obs, _ = env.reset(seed=3)
        agent.reset(FlightView(env))
        taken = []
        for _ in range(150):
            action = agent.act(obs, FlightView(env))
            taken.append(float(action[0]))
            obs, *_ = env.step(action)
        actions.append(taken)
    np.testing.assert_array_equal(actions[0], actions[1])
    assert np.ptp(actions[1]) > 0.05  # the observer did steer


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("  residual: 1.5\n", "residual: Input should be less than or equal to 1"),
        ("  residual: yes\n", "residual: Input should be a valid number, got True"),
        ("  residual: 0.2\n  observer: false\n", "observer: false contradicts it"),
        ("  incremental: 2\n", "incremental: Input should be less than or equal to 1"),
        ("  incremental: 0.3\n  observer: true\n", "incremental moves the fin from its last"),
        ("  integral_clip: 3\n", "integral_clip clips the error the integral sums: give integral"),
        ("  integral: -1\n", "integral: Input should be greater than or equal to 0"),
        ("  integral: .inf\n", "integral: Input should be a finite number"),
    ],
)
def test_bad_residual_settings_are_named(extra, message, tmp_path):
    path = tmp_path / "hp.yml"
    path.write_text(TINY + extra, encoding="utf-8")
    with pytest.raises(UsageError, match=re.escape(message)):
        load_hyperparameters(path, "RocketRoll-v0")


def test_a_flight_policy_reads_the_flights_phase_as_in_training(tmp_path, default_db):
    """``flight_clock: true``: the flight's gain and damping multipliers of the coming control
    step beside the observation; the controller rebuilds them from the env's flight, step by
    step, and acts as model.predict does on the training stack."""
    import gymnasium as gym

    from agents.train import load_hyperparameters, make_env

    text = TINY.replace("RocketRoll-v0:", "RocketRollFlight-v0:") + "  flight_clock: true\n"
    hyperparams = tmp_path / "flight.yml"
    hyperparams.write_text(text, encoding="utf-8")
    out = tmp_path / "run"
    argv = ["--env-id", "RocketRollFlight-v0", "--hyperparams", str(hyperparams)]
    argv += ["--db", str(default_db), "--out", str(out), "--eval-freq", "0"]
    argv += ["--eval-episodes", "1", "--checkpoint-freq", "0", "--no-progress-bar"]
    with contextlib.redirect_stdout(io.StringIO()):
        assert run_command(COMMAND, argv, "rocketroll train ppo") == 0
    settings = json.loads((out / "settings.json").read_text())
    assert settings["hyperparameters"]["flight_clock"] is True
    names = json.loads((out / "normalize.json").read_text())["observation_names"]
    assert names[-2:] == ["flight_gain", "flight_damping"]
    controller = LearnedController.load(out)
    assert controller.needs_clock
    hp = load_hyperparameters(hyperparams, "RocketRollFlight-v0", "ppo")
    adapter, stack, normalize = make_env(hp, 1, 5, split="test", db=default_db, training=False)
    _use_statistics(normalize, out)
    schedule = adapter.config.flight_schedule
    seen = stack.reset()
    env = gym.make("RocketRollFlight-v0").unwrapped
    assert isinstance(env, RocketRollEnv)
    view = FlightView(env)
    controller.reset(view)
    for k in range(40):
        raw_all = stack.unnormalize_obs(seen)[0]
        np.testing.assert_allclose(raw_all[4:], schedule.scales[k], rtol=1e-6)  # the clock
        expected, _ = controller.model.predict(seen, deterministic=True)
        action = controller.act(raw_all[:4], view)
        np.testing.assert_allclose(action, expected.reshape(1), rtol=0, atol=1e-6)
        seen, _, _, _ = stack.step(action.reshape(1, 1))
    # In the tunnel there is no flight to read the phase of; the YAML is refused there too.
    with pytest.raises(ValueError, match="reads the flight's phase"):
        controller.reset(FlightView(RocketRollEnv(bank=array_bank())))
    tunnel = tmp_path / "tunnel.yml"
    tunnel.write_text(TINY + "  flight_clock: true\n", encoding="utf-8")
    with pytest.raises(UsageError, match="flight_clock is the phase of a flight"):
        load_hyperparameters(tunnel, "RocketRoll-v0", "ppo")
    # In flight a recipe's observer is the scheduled one, designed on the tunnel's traces.
    flown = tmp_path / "flown.yml"
    flown.write_text(TINY.replace("RocketRoll-v0", "RocketRollFlight-v0") + "  residual: 0.5\n")
    hp = load_hyperparameters(flown, "RocketRollFlight-v0", "ppo")
    _, stack, _ = make_env(hp, 2, 5, split="test", db=default_db, training=False)
    features = stack.venv.venv.stack.features
    assert all(c.schedule is not None for c in features.controllers)
