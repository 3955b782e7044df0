"""``RocketRoll-v0`` / ``RocketRollRate-v0``: the single environment against its specification.

The specification is the docstring of :class:`rollenv.env.RocketRollEnv`.
Replays of recordings are in ``test_replay.py``, the vector environment in
``test_vector.py``.
"""

from __future__ import annotations

import math
import os
import pickle
import re
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import rollenv
from disturbances.bank import TraceBank
from disturbances.default import open_default
from identification.model import Servo, servo_path, simulate
from rollenv.bank import variant_config
from rollenv.env import RESET_OPTIONS, RocketRollEnv
from tests.cli import python
from tests.rollenv.conftest import array_bank, wrap

IDS = rollenv.variant_ids()
RENDER_MODES = (None, "rgb_array", "human")
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def no_display(monkeypatch):
    """No window can open: human mode must draw offscreen."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


def rollout(env, seed, steps, *, action_seed=0, reset_seed=True):
    """Observations, rewards, flags and infos of ``steps`` random actions after a reset."""
    obs, info = env.reset(seed=seed) if reset_seed else env.reset()
    rng = np.random.default_rng(action_seed)
    observations, rewards, flags, infos = [obs], [], [], [info]
    for _ in range(steps):
        action = rng.uniform(-1.2, 1.2, size=1).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        flags.append((terminated, truncated))
        infos.append(info)
    return np.array(observations), rewards, flags, infos


def assert_same_rollout(a, b):
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1] == b[1]
    assert a[2] == b[2]
    assert a[3] == b[3]


# ----------------------------------------------------------------- checkers (must show 1)
@pytest.mark.parametrize("render_mode", RENDER_MODES)
@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_and_sb3_checkers_pass_without_warnings(
    env_id, render_mode, default_db, no_display, capfd
):
    env = gym.make(env_id, render_mode=render_mode)
    assert isinstance(env.unwrapped, RocketRollEnv)
    assert env.unwrapped.config.task == rollenv.task_of(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # Gymnasium's checker wants the bare environment (it warns on wrappers).
        gym_check_env(env.unwrapped)
        sb3_check_env(env.unwrapped, warn=True, skip_render_check=False)
        env.close()
    said = [str(w.message) for w in caught]
    # Gymnasium's checker also makes the env in every render mode; "human" without a
    # display says so (once per env), and nothing else is ever warned about.
    assert [m for m in said if "no display" not in m] == []
    if render_mode == "human":
        assert any("no display" in m for m in said)
    out, err = capfd.readouterr()
    assert (out, err) == ("", "")


@pytest.mark.parametrize("render_mode", RENDER_MODES)
@pytest.mark.parametrize("env_id", IDS)
def test_made_environment_steps_through_its_wrappers(env_id, render_mode, bank, no_display, capfd):
    # gym.make adds the passive checker and order enforcing; with warnings as errors
    # their checks of reset, step and render pass too.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Without a display, human mode says so once (tests/rollenv/test_render.py).
        warnings.filterwarnings("ignore", message=".*no display", category=UserWarning)
        env = gym.make(env_id, bank=bank, render_mode=render_mode, episode_s=2.0)
        assert env.unwrapped.metadata["render_fps"] == pytest.approx(10.0)
        obs, _ = env.reset(seed=3)
        assert env.observation_space.contains(obs)
        for k in range(20):
            obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            assert env.observation_space.contains(obs)
            assert type(reward) is float  # a Python float, not a numpy scalar
            assert (terminated, truncated) == (False, k == 19)
        if render_mode is None:
            with pytest.warns(UserWarning, match="without a render_mode"):
                frame = env.render()
        else:
            frame = env.render()
        if render_mode == "rgb_array":
            assert isinstance(frame, np.ndarray)
            assert frame.dtype == np.uint8
            assert frame.ndim == 3 and frame.shape[2] == 3
            assert frame.std() > 0  # something is drawn
        else:
            assert frame is None
        env.close()
    if render_mode is None:
        return
    out, err = capfd.readouterr()
    assert (out, err) == ("", "")


def test_time_limit_wrapper_can_only_shorten_episodes(bank):
    env = gym.make("RocketRoll-v0", bank=bank, episode_s=2.0, max_episode_steps=5)
    env.reset(seed=0)
    flags = [env.step(np.zeros(1, np.float32))[3] for _ in range(5)]
    assert flags == [False] * 4 + [True]


# ---------------------------------------------------------------- determinism (must show 2)
@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_rollout_other_seed_another(env_id, default_db):
    # Two separate instances (no shared state), the database's traces, sensors on,
    # setpoint steps: every source of randomness is the seed.
    kwargs: dict[str, Any] = {"setpoint_period_s": 2.0, "initial_angle_deg": 30.0}
    steps = min(300, variant_config(env_id).max_episode_steps)  # a flight is 212 steps
    a = rollout(gym.make(env_id, **kwargs), seed=11, steps=steps)
    b = rollout(gym.make(env_id, **kwargs), seed=11, steps=steps)
    assert_same_rollout(a, b)
    c = rollout(gym.make(env_id, **kwargs), seed=12, steps=steps)
    assert not np.array_equal(a[0], c[0])
    assert a[1] != c[1]


def test_reset_with_the_same_seed_repeats_the_episode(default_db):
    env = RocketRollEnv(initial_angle_deg=90.0)
    a = rollout(env, seed=5, steps=50)
    b = rollout(env, seed=5, steps=50)
    assert_same_rollout(a, b)
    first = [env.reset(seed=s) for s in (7, 8, 7)]
    np.testing.assert_array_equal(first[0][0], first[2][0])
    assert first[0][1] == first[2][1]
    assert first[0][1] != first[1][1]


def test_reset_without_seed_continues_the_generator(default_db):
    # reset() without a seed starts a new, different episode; the sequence of
    # episodes is fixed by the first seed.
    def episodes(env):
        out = [rollout(env, seed=21, steps=20)]
        out += [rollout(env, seed=None, steps=20, reset_seed=False) for _ in range(2)]
        return out

    a, b = episodes(RocketRollEnv()), episodes(RocketRollEnv())
    for x, y in zip(a, b, strict=True):
        assert_same_rollout(x, y)
    assert a[1][3][0] != a[2][3][0]


# ------------------------------------------------------------------- bad use (must show 4)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_actions_are_refused(bank, bad):
    env = RocketRollEnv(bank=bank)
    env.reset(seed=0)
    for action in (np.array([bad], np.float32), np.array([bad]), [bad], bad):
        with pytest.raises(ValueError, match="finite"):
            env.step(action)  # type: ignore[arg-type]
    # Nothing was stepped.
    info = env.step(np.zeros(1, np.float32))[4]
    assert info["time_s"] == pytest.approx(0.1)


def test_out_of_range_actions_are_clipped(bank):
    rng = np.random.default_rng(4)
    raw = rng.choice([5.0, -3.0, 1.0, -1.0, 100.0, -1e30], size=80)
    clipped = np.clip(raw, -1.0, 1.0)
    results = []
    for actions in (raw, clipped, np.full(80, 0.5)):
        env = RocketRollEnv(bank=bank)
        env.reset(seed=9)
        steps = [env.step(np.array([a], np.float32)) for a in actions]
        results.append(steps)
    for s0, s1 in zip(results[0], results[1], strict=True):
        np.testing.assert_array_equal(s0[0], s1[0])
        assert s0[1:] == s1[1:]
    assert max(abs(s[4]["fin_cmd_deg"]) for s in results[0]) == 40.0
    assert results[0][-1][4] != results[2][-1][4]


@pytest.mark.parametrize(
    "action", [np.zeros(2), np.zeros((1, 2)), np.zeros(0), [[0.1], [0.2]], "up", None]
)
def test_actions_of_the_wrong_shape_or_type_are_refused(bank, action):
    env = RocketRollEnv(bank=bank)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must"):
        env.step(action)


def test_scalar_and_column_actions_are_accepted(bank):
    env = RocketRollEnv(bank=bank)
    env.reset(seed=0)
    for action in (0.25, [0.25], np.array([[0.25]]), np.float64(0.25)):
        info = env.step(action)[4]  # type: ignore[arg-type]
        assert info["fin_cmd_deg"] == 10.0


def test_a_bank_without_a_long_enough_trace_is_refused():
    short = TraceBank.from_arrays([np.zeros(100), np.zeros(250)], 0.1)
    longest = r"an episode is 60 s, and the longest trace of .* is 25 s: .*episode_s=25 or less"
    with pytest.raises(ValueError, match=longest):
        RocketRollEnv(bank=short)
    with pytest.raises(ValueError, match=longest):
        gym.make("RocketRoll-v0", bank=short)
    with pytest.raises(ValueError, match=longest):
        gym.make_vec("RocketRoll-v0", num_envs=2, bank=short)
    RocketRollEnv(bank=short, episode_s=25.0)  # exactly long enough


@pytest.mark.parametrize(
    ("name", "message"),
    [("foo", "unknown option 'foo'"), ("disturbence", "did you mean 'disturbance'")],
)
def test_unknown_options_are_named(name, message):
    for make in (gym.make, lambda i, **kw: gym.make_vec(i, num_envs=2, **kw)):
        with pytest.raises(ValueError, match=re.escape(message)):
            options: dict[str, Any] = {name: 1}
            make("RocketRoll-v0", **options)


@pytest.mark.parametrize(
    "option",
    [
        {"task": "yaw"},
        {"disturbance": "wind"},
        {"dt_s": 0.015},
        {"episode_s": -1},
        {"episode_s": 0.05},
        {"split": "val"},
        {"model": "linear"},
        {"setpoint": "ramp"},
        {"gyro_noise_pct": -1.0},
        {"disturbance_scale": math.nan},
        {"encoder_counts": -4},
        {"error_scale": 0.0},
    ],
)
def test_bad_option_values_are_named(option):
    (name,) = option
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        gym.make("RocketRoll-v0", **option)
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        RocketRollEnv(**option)


def test_bad_render_mode_is_refused(bank):
    with pytest.raises(ValueError, match="render_mode"):
        RocketRollEnv(bank=bank, render_mode="ansi")


def test_unknown_reset_option_is_named(bank):
    env = RocketRollEnv(bank=bank)
    with pytest.raises(ValueError, match="'seed'"):
        env.reset(options={"seed": 3})
    with pytest.raises(ValueError, match="'angle'"):
        env.reset(options={"angle": 3.0, "rate_dps": 1.0})


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"trace": 4}, "out of range"),
        ({"trace": -1}, "out of range"),
        ({"trace": "nope"}, "'nope'"),
        ({"trace": 1.0}, "index or a uid"),
        ({"trace": True}, "index or a uid"),
        ({"start": 3}, "needs a trace"),
        ({"trace": 0, "start": 101}, "does not fit"),
        ({"trace": 0, "start": -1}, "start"),
        ({"rate_dps": math.nan}, "rate_dps"),
        ({"angle_deg": "0"}, "angle_deg"),
        ({"fin_deg": True}, "fin_deg"),
        ({"setpoint": math.inf}, "setpoint"),
        ({"setpoints": [0.0] * 5}, "6 values"),
        ({"setpoints": [0.0] * 5 + [math.nan]}, "finite"),
        ({"setpoints": "abc"}, "numbers"),
        ({"setpoints": [0.0] * 6, "setpoint": 1.0}, "exclude each other"),
    ],
)
def test_bad_reset_option_values_are_refused(bank, options, message):
    # Trace 0 of the bank has 700 samples: a 60-s window fits at starts 0..100.
    env = RocketRollEnv(bank=bank)
    with pytest.raises(ValueError, match=re.escape(message)):
        env.reset(options=options)
    env.reset(options={"trace": 0, "start": 100})  # the last window that fits


def test_step_before_reset_and_after_the_end(bank):
    env = RocketRollEnv(bank=bank, episode_s=0.5)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(1, np.float32))
    with pytest.raises(gym.error.ResetNeeded):  # gym.make's order enforcing says it first
        gym.make("RocketRoll-v0", bank=bank).step(np.zeros(1, np.float32))
    env.reset(seed=0)
    flags = [env.step(np.zeros(1, np.float32))[2:4] for _ in range(5)]
    assert flags == [(False, False)] * 4 + [(False, True)]
    with pytest.raises(RuntimeError, match="truncated after 5 steps"):
        env.step(np.zeros(1, np.float32))
    env.reset()
    assert env.step(np.zeros(1, np.float32))[4]["time_s"] == pytest.approx(0.1)


def test_render_without_render_mode_warns(bank):
    env = RocketRollEnv(bank=bank)
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_rgb_array_frames_follow_the_episode(bank):
    env = RocketRollEnv(bank=bank, render_mode="rgb_array")
    env.reset(seed=1)
    first = env.render()
    for _ in range(30):
        env.step(np.ones(1, np.float32))
    later = env.render()
    assert first is not None and later is not None
    assert first.shape == later.shape
    assert not np.array_equal(first, later)
    env.close()
    env.close()  # twice is fine


# --------------------------------------------------------------- properties (must show 5)
#: Largest fin travel per second (eq. 23).
RATE_LIMIT = Servo().rate_limit_dps

OPTIONS = st.fixed_dictionaries(
    {
        "task": st.sampled_from(["angle", "rate"]),
        "sensors": st.booleans(),
        "disturbance": st.sampled_from(["posterior", "replay", "surrogate", "none"]),
        "disturbance_scale": st.floats(0.0, 3.0),
        "model": st.sampled_from(["theta", "constant"]),
        "domain_randomization": st.booleans(),
        "setpoint": st.sampled_from(["steps", "zero"]),
        "setpoint_period_s": st.sampled_from([0.4, 1.0, 10.0]),
        "initial_angle_deg": st.sampled_from([0.0, 45.0, 180.0]),
        "encoder_counts": st.sampled_from([0, 256, 1024]),
        "gyro_noise_pct": st.one_of(st.just(0.0), st.floats(0.0, 10.0)),
        "dt_s": st.sampled_from([0.05, 0.1, 0.2]),
    }
)
ACTIONS = st.lists(
    st.one_of(
        st.floats(-3.0, 3.0, width=32),
        st.sampled_from([-1.0, 1.0, 0.0, 5.0, -3.0, 1e9]),
    ),
    min_size=60,
    max_size=60,
)


@settings(max_examples=40, deadline=None, database=None)
@given(
    options=OPTIONS,
    from_arrays=st.booleans(),
    actions=ACTIONS,
    seed=st.integers(0, 2**32 - 1),
)
def test_episodes_keep_their_invariants(default_db, options, from_arrays, actions, seed):
    dt = options["dt_s"]
    substeps = round(dt / 0.01)
    bank = array_bank(options["model"]) if from_arrays else None
    # Surrogates are made of the paper's traces; the rest replays the default, ml.
    method = "paper" if options["disturbance"] == "surrogate" else "ml"
    env = RocketRollEnv(bank=bank, episode_s=3.0, method=method, **options)
    steps = env.config.max_episode_steps
    assert steps == round(3.0 / dt)
    scale = 0.0 if options["disturbance"] == "none" else options["disturbance_scale"]
    error_max = 180.0 if options["task"] == "angle" else 500.0

    obs, info = env.reset(seed=seed)
    index = [t.uid for t in env.bank.traces].index(info["trace"])
    trace = env.bank.traces[index]
    start = round(info["start_s"] / trace.dt_s)
    assert start * trace.dt_s == pytest.approx(info["start_s"])
    params = env._batch.roll_params(0)
    _check_drawn_rocket(env, params, trace, options)
    _check_trace_name(info, options, from_arrays, method)
    assert params.is_constant_damping == (options["model"] == "constant")

    u = scale * np.asarray(trace.samples()[start : start + math.ceil(steps * substeps / 10)])
    _check_starting_state(info, params, u, options)

    history = [info]
    commands = []
    for k in range(1, steps + 1):
        check_observation(env, obs, history[-1], options, error_max)
        action = np.array([actions[k - 1]], np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        commands.append(float(np.clip(np.float64(action[0]), -1.0, 1.0)) * 40.0)
        assert (terminated, truncated) == (False, k == steps)
        _check_step_info(k, info, reward, commands[-1], u, options)
        travel = _check_servo(info, history[-1], dt)
        _check_setpoint(k, info, options)
        _check_tracking_error_and_reward(info, reward, travel, options)
        history.append(info)
    check_observation(env, obs, info, options, error_max)
    with pytest.raises(RuntimeError):
        env.step(np.zeros(1, np.float32))
    _check_against_simulate(params, commands, u, history, substeps)


def _check_drawn_rocket(env, params, trace, options):
    """The episode's rocket: with domain randomization, drawn within the bank's box and
    damped over the whole fin range; without, the trace's own."""
    if options["domain_randomization"]:
        box = np.array(
            [
                [p.alpha, p.theta_bar_deg, p.beta_bar_per_s, p.alpha_bar_per_deg_s]
                for p in env.bank.params
            ]
        )
        drawn = [
            params.alpha,
            params.theta_bar_deg,
            params.beta_bar_per_s,
            params.alpha_bar_per_deg_s,
        ]
        assert np.all(box.min(axis=0) <= drawn) and np.all(drawn <= box.max(axis=0))
        # ... and damped over the whole fin range (a(θ) is linear on each side of -θ̄).
        kink = min(max(-params.theta_bar_deg, -40.0), 40.0)
        assert np.all(params.damping([-40.0, kink, 40.0]) > 0.0)
    else:
        assert params == trace.params


def _check_trace_name(info, options, from_arrays, method):
    """The trace's uid: a surrogate's only where surrogates were asked of the default
    database, and from the database its method, model and kind."""
    if options["disturbance"] == "surrogate" and not from_arrays:
        assert "-iaaft-" in info["trace"]
    else:
        assert "iaaft" not in info["trace"]
    if not from_arrays:
        suffix = {"surrogate": r"-iaaft-\d+", "posterior": r"-posterior-\d+"}.get(
            options["disturbance"], ""
        )
        assert re.fullmatch(rf"[0-9a-f]+-{method}-{options['model']}{suffix}", info["trace"])


def _check_starting_state(info, params, u, options):
    """Starting state: fin 0, steady rate, angle within ±initial_angle_deg."""
    assert info["fin_deg"] == info["fin_cmd_deg"] == 0.0
    assert info["u_d_deg"] == u[0]
    assert info["roll_rate_dps"] == pytest.approx(
        float(params.steady_rate(0.0, u[0])), rel=1e-12, abs=1e-12
    )
    assert abs(info["roll_deg"]) <= options["initial_angle_deg"]


def _check_step_info(k, info, reward, command, u, options):
    """Step ``k``'s reward and info: finite, on the clock, the command clipped to the fin's
    range, ``u_d`` from the trace window."""
    dt = options["dt_s"]
    substeps = round(dt / 0.01)
    assert type(reward) is float  # a Python float, not a numpy scalar
    assert math.isfinite(reward) and reward <= 0.0
    for key, value in info.items():
        assert isinstance(value, str) or math.isfinite(value), key
    assert info["time_s"] == round(k * dt, 9)
    assert info["fin_cmd_deg"] == command
    # u_d of the step's last substep, from the trace window (0.1-s samples).
    assert info["u_d_deg"] == u[(k * substeps - 1) // 10]


def _check_servo(info, previous, dt):
    """The servo: within range, at most 150 °/s; the fin's travel over the step."""
    travel = abs(info["fin_deg"] - previous["fin_deg"])
    assert abs(info["fin_deg"]) <= 40.0
    assert travel <= RATE_LIMIT * dt + 1e-9
    return travel


def _check_setpoint(k, info, options):
    """Setpoints: within the task's range, zero before the first period ends (or always)."""
    setpoint_max = 90.0 if options["task"] == "angle" else 10.0
    sp = info["setpoint"]
    assert abs(sp) <= setpoint_max
    if options["setpoint"] == "zero" or k * options["dt_s"] < options["setpoint_period_s"] - 1e-9:
        assert sp == 0.0


def _check_tracking_error_and_reward(info, reward, travel, options):
    """The true tracking error and the reward of the docstring."""
    dt = options["dt_s"]
    sp = info["setpoint"]
    if options["task"] == "angle":
        assert abs(wrap(info["tracking_error"] - (sp - info["roll_deg"]))) < 1e-9
        assert -180.0 <= info["tracking_error"] < 180.0
        rate_term = 0.1 * (info["roll_rate_dps"] / 10.0) ** 2
        error_norm = 10.0
    else:
        assert info["tracking_error"] == pytest.approx(sp - info["roll_rate_dps"], abs=1e-12)
        rate_term = 0.0
        error_norm = 5.0
    expected = -(
        (info["tracking_error"] / error_norm) ** 2
        + rate_term
        + 0.1 * (travel / (RATE_LIMIT * dt)) ** 2
    )
    assert reward == pytest.approx(expected, rel=1e-9, abs=1e-12)


def _check_against_simulate(params, commands, u, history, substeps):
    """The truth follows identification.model.simulate driven by the same commands and
    u_d on the 0.01-s grid (fin linear within each substep, as in step 9)."""
    steps = len(commands)
    servo = Servo()
    theta_fine = servo_path(np.repeat(commands, substeps), 0.0, 0.01, servo)
    u_fine = u[np.arange(steps * substeps) // 10]
    sim = simulate(
        params,
        0.01,
        theta_fine,
        u_fine,
        rate0_dps=history[0]["roll_rate_dps"],
        angle0_deg=history[0]["roll_deg"],
        servo=None,
        substeps=1,
    )
    fin = np.array([i["fin_deg"] for i in history])
    rate = np.array([i["roll_rate_dps"] for i in history])
    angle = np.array([i["roll_deg"] for i in history])
    # Measured over 300 random episodes: fin equal, rate and angle within 2e-13 relative.
    np.testing.assert_allclose(fin, theta_fine[::substeps], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rate, sim.rate_dps[::substeps], rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(angle, sim.angle_deg[::substeps], rtol=1e-11, atol=1e-11)


def check_observation(env, obs, info, options, error_max):
    """``obs`` is in the space and is what the sensors read from the true state ``info``."""
    assert obs.dtype == np.float32 and obs.shape == (4,)
    assert env.observation_space.contains(obs)
    assert obs[2] == np.float32(info["fin_deg"])
    assert obs[3] == np.float32(info["fin_cmd_deg"])
    truth_rate = np.clip(info["roll_rate_dps"], -250.0, 250.0)  # the gyro's full scale
    truth_error = info["tracking_error"]
    if options["task"] == "rate":
        truth_error = info["setpoint"] - truth_rate
    if not options["sensors"]:
        assert obs[0] == np.float32(np.clip(truth_error, -error_max, error_max))
        assert obs[1] == np.float32(truth_rate)
        return
    if options["gyro_noise_pct"] == 0.0:
        assert obs[1] == np.float32(truth_rate)
    if options["task"] == "angle" and options["encoder_counts"]:
        # The encoder reads floor(angle / resolution) counts: the observed error is a
        # whole number of counts from the setpoint, at most one count off the truth.
        resolution = 360.0 / options["encoder_counts"]
        measured = info["setpoint"] - float(obs[0])
        counts = measured / resolution
        assert abs(counts - round(counts)) < 1e-4
        assert -1e-4 <= wrap(info["roll_deg"] - measured) < resolution + 1e-4


# -------------------------------------------------------------- registration (must show 6)
REGISTRATION = textwrap.dedent(
    """
    import sys
    import gymnasium as gym

    try:
        gym.make("RocketRoll-v0")
    except gym.error.NameNotFound:
        pass
    else:
        raise SystemExit("RocketRoll-v0 is registered before rollenv is imported")
    assert "rollenv" not in sys.modules
    env = gym.make("rollenv:RocketRoll-v0")
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    env.step(env.action_space.sample())
    print(env.spec.id, type(env.unwrapped).__name__, env.unwrapped.config.task)

    import rollenv
    from rollenv.vector import RocketRollVectorEnv

    env = gym.make("RocketRollRate-v0")
    env.reset(seed=0)
    print(env.spec.id, type(env.unwrapped).__name__, env.unwrapped.config.task)
    vec = gym.make_vec("RocketRoll-v0", num_envs=3)
    obs, info = vec.reset(seed=0)
    vec.step(vec.action_space.sample())
    print(type(vec).__name__, isinstance(vec.unwrapped, RocketRollVectorEnv), obs.shape)
    print(vec.unwrapped.bank.description)
    """
)


def test_registration_in_a_fresh_process(default_db):
    env = dict(os.environ)
    assert env["ROCKETROLL_DB"] == str(default_db)  # the session's database, already built
    done = python(["-W", "error", "-c", REGISTRATION], REPO, env)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # in particular, no database was built
    lines = done.stdout.splitlines()
    assert lines[:3] == [
        "RocketRoll-v0 RocketRollEnv angle",
        "RocketRollRate-v0 RocketRollEnv rate",
        "RocketRollVectorEnv True (3, 4)",
    ]
    assert "split='train'" in lines[3]


def test_importing_rollenv_only_registers():
    done = subprocess.run(
        [
            sys.executable,
            "-W",
            "error",
            "-c",
            "import sys, rollenv, gymnasium as gym; "
            "assert 'numba' not in sys.modules and 'rollenv.env' not in sys.modules; "
            "print(sorted(i for i in gym.registry if i.startswith('RocketRoll')))",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == (
        "['RocketRoll-v0', 'RocketRollFlight-v0', 'RocketRollFlightRate-v0', 'RocketRollRate-v0']"
    )
    assert rollenv.RocketRollEnv is RocketRollEnv
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        rollenv.Nope  # noqa: B018


# ------------------------------------------------------------------ beyond the floor (7)
def test_reset_options_fix_the_episode(bank):
    env = RocketRollEnv(bank=bank, episode_s=5.0, sensors=False)
    trace = bank.traces[2]
    obs, info = env.reset(
        seed=0,
        options={
            "trace": trace.uid,
            "start": 37,
            "rate_dps": -12.5,
            "angle_deg": 200.0,
            "fin_deg": 55.0,  # clipped to the fin range
            "setpoint": 20.0,
        },
    )
    assert info["trace"] == trace.uid
    assert info["start_s"] == pytest.approx(3.7)
    assert (info["roll_rate_dps"], info["roll_deg"]) == (-12.5, 200.0)
    assert info["fin_deg"] == info["fin_cmd_deg"] == 40.0
    assert info["setpoint"] == 20.0
    assert info["u_d_deg"] == trace.u_d_deg[37]
    assert obs[0] == np.float32(wrap(20.0 - 200.0))
    assert env._batch.roll_params(0) == trace.params
    u = [env.step(np.zeros(1, np.float32))[4]["u_d_deg"] for _ in range(50)]
    np.testing.assert_array_equal(u, trace.u_d_deg[37:87])
    # By index, and the same trace and start whatever the seed.
    for seed in (1, 2):
        info = env.reset(seed=seed, options={"trace": 2, "start": 37})[1]
        assert (info["trace"], info["start_s"]) == (trace.uid, pytest.approx(3.7))
        assert info["fin_deg"] == 0.0
    # Only a trace: the window starts at its beginning.
    assert env.reset(options={"trace": 1})[1]["start_s"] == 0.0


def test_replay_options_recreate_the_episode(bank):
    env = RocketRollEnv(bank=bank)
    with pytest.raises(RuntimeError, match="reset"):
        env.replay_options()
    actions = np.random.default_rng(3).uniform(-1, 1, size=(600, 1)).astype(np.float32)
    env.reset(seed=11)
    options = env.replay_options()
    assert len(options["setpoints"]) == env.config.setpoint_segments == 6
    assert options["setpoints"][0] == 0.0 and len(set(options["setpoints"])) == 6
    first = [env.step(a)[4] for a in actions]
    # Another seed: the same window and schedule (the gyro noise differs).
    _, info = env.reset(seed=99, options=options)
    assert (info["trace"], info["start_s"]) == (first[0]["trace"], first[0]["start_s"])
    again = [env.step(a)[4] for a in actions]
    for key in ("u_d_deg", "setpoint"):
        assert [i[key] for i in again] == [i[key] for i in first]
    assert env.replay_options() == options
    assert env.core is env._batch


def test_unfixed_resets_draw_every_trace_and_offset(bank):
    env = RocketRollEnv(bank=bank)
    seen = {env.reset(seed=s)[1]["trace"] for s in range(200)}
    assert seen == {t.uid for t in bank.traces}
    starts = {env.reset()[1]["start_s"] for _ in range(60)}
    assert len(starts) > 50


@pytest.mark.parametrize("task", ["angle", "rate"])
def test_no_disturbance_is_zero_scale(bank, task):
    def run(**kw):
        env = RocketRollEnv(bank=bank, task=task, **kw)
        return rollout(env, seed=3, steps=200)

    none = run(disturbance="none")
    zero = run(disturbance_scale=0.0)
    assert all(i["u_d_deg"] == 0.0 for i in none[3])
    assert_same_rollout(none, zero)
    # ... and differs from the replay.
    replay = run()
    assert any(i["u_d_deg"] != 0.0 for i in replay[3])
    assert not np.array_equal(replay[0], none[0])
    # The scale multiplies u_d.
    double = run(disturbance_scale=2.0)
    assert [2.0 * i["u_d_deg"] for i in replay[3]] == [i["u_d_deg"] for i in double[3]]


def test_domain_randomization_varies_the_rocket_within_the_bank(bank):
    env = RocketRollEnv(bank=bank, domain_randomization=True)
    fixed = RocketRollEnv(bank=bank)
    box = np.array(
        [[p.alpha, p.theta_bar_deg, p.beta_bar_per_s, p.alpha_bar_per_deg_s] for p in bank.params]
    )
    drawn = []
    for seed in range(30):
        info = env.reset(seed=seed)[1]
        p = env._batch.roll_params(0)
        drawn.append([p.alpha, p.theta_bar_deg, p.beta_bar_per_s, p.alpha_bar_per_deg_s])
        assert p not in bank.params
        fixed_info = fixed.reset(seed=seed)[1]
        assert (
            fixed._batch.roll_params(0)
            == bank.params[[t.uid for t in bank.traces].index(fixed_info["trace"])]
        )
        assert info["trace"] in {t.uid for t in bank.traces}
    drawn_a = np.array(drawn)
    assert np.all(drawn_a >= box.min(axis=0)) and np.all(drawn_a <= box.max(axis=0))
    spread = drawn_a.std(axis=0) / (box.max(axis=0) - box.min(axis=0))
    assert np.all(spread > 0.15)  # uniform over the box: 0.29


def test_domain_randomization_works_with_the_default_constant_model(default_db):
    env = RocketRollEnv(domain_randomization=True, model="constant")
    params = set()
    for seed in range(5):
        env.reset(seed=seed)
        p = env._batch.roll_params(0)
        assert p.is_constant_damping and p.beta_bar_per_s > 0
        params.add(p)
    assert len(params) == 5


def test_domain_randomization_works_with_the_default_database(default_db):
    # The default database's box has undamped corners (β̄ from 1.36, ᾱ from -0.085):
    # such draws are redrawn, so every rocket drawn is damped over the fin range.
    env = RocketRollEnv(domain_randomization=True)
    low, high = env._batch.param_low, env._batch.param_high
    drawn = []
    for seed in range(40):
        env.reset(seed=seed)
        p = env._batch.params[0].copy()
        assert np.all(p >= low) and np.all(p <= high)
        reach = 40.0 + abs(p[1])
        assert p[2] + min(p[3], 0.0) * reach > 0.0
        drawn.append(p)
    assert np.unique(np.array(drawn)[:, 2]).size == 40


def test_a_box_with_negative_damping_is_refused():
    from identification.model import RollParams

    # Two rockets whose damping falls below 0 near full fin: every draw between them too.
    bad = TraceBank(
        [
            *TraceBank.from_arrays([np.zeros(700)], 0.1, RollParams(0.6, 4.0, 0.5, -0.05)).traces,
            *TraceBank.from_arrays([np.zeros(700)], 0.1, RollParams(0.7, 5.0, 0.6, -0.04)).traces,
        ]
    )
    RocketRollEnv(bank=bad)  # without randomisation the bank's own rockets are used
    with pytest.raises(ValueError, match="domain randomisation"):
        RocketRollEnv(bank=bad, domain_randomization=True)


@pytest.mark.parametrize("split", ["train", "test"])
@pytest.mark.parametrize(
    ("disturbance", "method", "kind"),
    [
        (None, None, "posterior"),  # the default: ml's posterior draws
        ("replay", "paper", "identified"),
        ("replay", "ml", "identified"),
        ("surrogate", "paper", "iaaft"),
        ("posterior", "ml", "posterior"),
    ],
)
@pytest.mark.parametrize("model", ["theta", "constant"])
def test_the_database_selection(default_db, split, disturbance, method, kind, model):
    with open_default(progress=False) as db:
        infos = db.traces()
    split_of = {i.uid: i.split for i in infos}
    model_of = {i.uid: i.model for i in infos}
    kind_of = {i.uid: i.kind for i in infos}
    method_of = {i.uid: i.method for i in infos}
    chosen = {k: v for k, v in (("disturbance", disturbance), ("method", method)) if v is not None}
    env = RocketRollEnv(split=split, model=model, episode_s=10.0, **chosen)
    seen = set()
    for seed in range(40):
        uid = env.reset(seed=seed)[1]["trace"]
        seen.add(uid)
        assert split_of[uid] == split
        assert model_of[uid] == model
        assert method_of[uid] == (method or "ml")
        assert kind_of[uid] == kind
        assert (f"-{kind}-" in uid) == (kind != "identified")
        p = env._batch.roll_params(0)
        assert p.is_constant_damping == (model == "constant")
        assert p == next(i.params for i in infos if i.uid == uid)
    assert len(seen) >= 3


def test_constant_model_uses_constant_damping(bank):
    constant = array_bank("constant")
    env = RocketRollEnv(bank=constant, model="constant")
    env.reset(seed=0)
    assert env._batch.roll_params(0).alpha_bar_per_deg_s == 0.0
    env = RocketRollEnv(bank=bank)
    env.reset(seed=0)
    assert env._batch.roll_params(0).alpha_bar_per_deg_s != 0.0


@pytest.mark.parametrize("task", ["angle", "rate"])
def test_without_sensors_the_observation_is_the_truth(bank, task):
    env = RocketRollEnv(bank=bank, task=task, sensors=False, gyro_noise_pct=10.0)
    emax = 180.0 if task == "angle" else 500.0
    obs, info = env.reset(seed=0, options={"trace": 0, "rate_dps": 400.0, "angle_deg": 170.0})
    assert obs[1] == 250.0  # the gyro's full scale
    if task == "rate":
        assert info["tracking_error"] == -400.0  # the truth, in info
        assert obs[0] == -250.0  # what the saturated gyro tells
    rng = np.random.default_rng(0)
    for _ in range(100):
        expected_error = (
            wrap(info["setpoint"] - info["roll_deg"])
            if task == "angle"
            else info["setpoint"] - info["roll_rate_dps"]
        )
        assert info["tracking_error"] == pytest.approx(expected_error, abs=1e-9)
        gyro = np.clip(info["roll_rate_dps"], -250.0, 250.0)  # saturates, sensors or not
        # The observed error is the setpoint minus the *read* rate (rate task).
        error = info["tracking_error"] if task == "angle" else info["setpoint"] - gyro
        np.testing.assert_array_equal(
            obs,
            np.array(
                [
                    np.clip(error, -emax, emax),
                    gyro,
                    info["fin_deg"],
                    info["fin_cmd_deg"],
                ],
                dtype=np.float32,
            ),
        )
        obs, _, _, _, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))


@pytest.mark.parametrize("counts", [256, 1024])
def test_the_encoder_quantises_the_angle(bank, counts):
    resolution = 360.0 / counts
    env = RocketRollEnv(bank=bank, encoder_counts=counts, gyro_noise_pct=0.0, setpoint_period_s=1)
    obs, info = env.reset(seed=2, options={"trace": 3, "rate_dps": 30.0})
    rng = np.random.default_rng(1)
    offsets = []
    for _ in range(200):
        assert obs[1] == np.float32(info["roll_rate_dps"])  # no gyro noise
        measured = info["setpoint"] - float(obs[0])
        counts_read = measured / resolution
        assert abs(counts_read - round(counts_read)) < 1e-4
        offsets.append(wrap(info["roll_deg"] - measured))
        obs, _, _, _, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
    offsets_a = np.array(offsets)
    assert np.all(offsets_a >= -1e-4) and np.all(offsets_a < resolution + 1e-4)
    assert offsets_a.max() > 0.5 * resolution  # not the truth: it is quantised


def test_gyro_noise_is_multiplicative(bank):
    env = RocketRollEnv(bank=bank, task="rate", gyro_noise_pct=5.0)
    obs, info = env.reset(seed=0, options={"trace": 0, "rate_dps": 20.0})
    ratios = []
    for _ in range(300):
        ratios.append(float(obs[1]) / info["roll_rate_dps"] - 1.0)
        obs, _, _, _, info = env.step(np.array([0.3], np.float32))
    assert np.std(ratios) == pytest.approx(0.05, rel=0.2)
    assert abs(np.mean(ratios)) < 0.01


def test_traces_off_the_substep_grid_are_averaged_onto_the_control_steps():
    odd = TraceBank.from_arrays([np.arange(5000.0)], dt_s=0.015)  # 75 s
    env = RocketRollEnv(bank=odd)
    (trace,) = env.core.bank.traces
    assert (trace.dt_s, trace.n_samples) == (0.1, 750)
    assert trace.u_d_deg is not None
    # The first 0.1 s holds samples 0-5 (0.015 s each) and 0.01 s of sample 6: exactly.
    assert trace.u_d_deg[0] == pytest.approx((0.015 * 15 + 0.01 * 6) / 0.1, rel=1e-12)
    on_grid = TraceBank.from_arrays([np.zeros(3000)], dt_s=0.02)
    assert RocketRollEnv(bank=on_grid).core.bank is on_grid  # replayed as it is


def test_a_bank_with_a_finer_trace_grid_replays_it(bank):
    # u_d sampled every 0.02 s: each of a step's 10 substeps pairs with its own sample.
    u = np.arange(4000.0) / 100.0
    fine = TraceBank.from_arrays([u], dt_s=0.02)
    env = RocketRollEnv(bank=fine, episode_s=5.0, sensors=False)
    env.reset(seed=0, options={"trace": 0, "start": 10})
    u_seen = [env.step(np.zeros(1, np.float32))[4]["u_d_deg"] for _ in range(10)]
    np.testing.assert_array_equal(u_seen, u[10 + 4 : 10 + 50 : 5])


def test_the_bank_and_config_pickle(default_db, bank):
    for env in (RocketRollEnv(), RocketRollEnv(bank=bank)):
        copy = pickle.loads(pickle.dumps(env.bank))
        assert list(copy.traces) == list(env.bank.traces)
        for a, b in zip(copy.traces, env.bank.traces, strict=True):
            np.testing.assert_array_equal(a.u_d_deg, b.u_d_deg)
        assert pickle.loads(pickle.dumps(env.config)) == env.config
        twin = RocketRollEnv(bank=copy)
        assert_same_rollout(rollout(env, 4, 30), rollout(twin, 4, 30))


def test_reset_arguments_are_listed():
    assert set(RESET_OPTIONS) == {
        "trace",
        "start",
        "rate_dps",
        "angle_deg",
        "fin_deg",
        "setpoint",
        "setpoints",
        "scales",
    }
