"""Named layouts agree with their users, and the rocket may change during an episode.

The kernel, the environments, the oracle, the PID, the renderer and the
evaluation read the state, observation, parameter and setting arrays by the
names of :mod:`rollenv.layout`; these tests fail if a layout and a user of it
disagree.  The second half checks the per-step multipliers of the rocket's
parameters (:class:`rollenv.layout.Scale`): the constant case is today's rocket
bit for bit, a constant gain or damping multiplier is the rocket with those
parameters, and a schedule that switches mid-episode follows the physics of
eq. 29 after the switch.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle
from typing import Any

import numpy as np
import pytest

from agents.nominal import NominalModel
from agents.pid import PIDController, PIDGains
from disturbances.bank import TraceBank
from identification.model import RollParams
from rollenv.config import RollConfig, observation_bounds
from rollenv.core import RollBatch
from rollenv.env import RocketRollEnv
from rollenv.history import HistoryRecorder
from rollenv.layout import (
    OBSERVATION_NAMES,
    PARAM_FIELDS,
    Cfg,
    Obs,
    Param,
    Scale,
    State,
    params_of_row,
    row_of_params,
)
from rollenv.vector import RocketRollVectorEnv
from tests.rollenv.conftest import array_bank, wrap

STEPS = 60


def quiet(task: str = "angle", **settings: Any) -> RocketRollEnv:
    """An env on the array bank with the truth observed (no sensor noise)."""
    return RocketRollEnv(bank=array_bank(), task=task, sensors=False, **settings)


# ----------------------------------------------------------------------------- layouts
def test_every_layout_is_complete_and_in_order() -> None:
    for layout in (State, Obs, Param, Scale, Cfg):
        assert [int(m) for m in layout] == list(range(len(layout))), layout
    assert len(OBSERVATION_NAMES) == len(Obs)
    assert OBSERVATION_NAMES[Obs.RATE] == "roll_rate_dps"
    assert set(PARAM_FIELDS) == set(Param)
    assert sorted(PARAM_FIELDS.values()) == sorted(f.name for f in dataclasses.fields(RollParams))
    p = RollParams(0.7, -3.0, 2.1, -0.02)
    assert params_of_row(row_of_params(p)) == p
    assert row_of_params(p)[Param.THETA_BAR] == -3.0


def test_the_observation_state_and_info_agree_column_by_column() -> None:
    for task in ("angle", "rate"):
        env = quiet(task)
        obs, info = env.reset(seed=2)
        for _ in range(5):
            obs, _, _, _, info = env.step(np.array([0.3], dtype=np.float32))
        state = env.core.state[0]
        assert env.observation_space.shape == (len(Obs),)
        assert obs[Obs.RATE] == np.float32(info["roll_rate_dps"]) == np.float32(state[State.RATE])
        assert obs[Obs.FIN] == np.float32(info["fin_deg"]) == np.float32(state[State.FIN])
        assert obs[Obs.COMMAND] == np.float32(info["fin_cmd_deg"]) == np.float32(0.3 * 40.0)
        assert info["roll_deg"] == state[State.ANGLE]
        assert obs[Obs.ERROR] == pytest.approx(info["tracking_error"], abs=1e-4)
        high, _ = observation_bounds(env.config)
        assert high[Obs.FIN] == high[Obs.COMMAND] == env.config.fin_range_deg


def test_a_state_written_by_name_is_observed_by_name() -> None:
    """The observation kernel reads the state by the same names it is written by."""
    env = quiet()
    env.reset(seed=0, options={"setpoint": 50.0})
    batch = env.core
    batch.state[0, State.ANGLE] = 12.0
    batch.state[0, State.RATE] = -7.5
    batch.state[0, State.FIN] = 3.0
    batch.state[0, State.COMMAND] = 4.0
    from rollenv.core import observe_kernel

    observe_kernel(
        batch.all,
        batch.state,
        batch.cursor,
        batch.setpoints,
        np.zeros(1),
        batch.cfg,
        batch.obs,
        batch.error,
    )
    assert batch.obs[0].tolist() == [wrap(50.0 - 12.0), -7.5, 3.0, 4.0]


def test_the_kernel_settings_are_filled_by_name() -> None:
    config = RollConfig(task="rate", substep_s=0.02, rate_limit_dps=100.0, gyro_noise_pct=5.0)
    cfg = config.kernel_settings()
    assert cfg.shape == (len(Cfg),)
    assert cfg[Cfg.SUBSTEPS] == 5 and cfg[Cfg.H] == 0.02
    assert cfg[Cfg.MAX_MOVE] == pytest.approx(2.0) and cfg[Cfg.TASK_RATE] == 1.0
    assert cfg[Cfg.GYRO_ETA] == 0.05 and cfg[Cfg.RATE_WEIGHT] == 0.0
    assert cfg[Cfg.ERROR_MAX] == observation_bounds(config)[0][Obs.ERROR]


def test_the_pid_reads_the_observation_by_name() -> None:
    """Swap two entries of the observation and the PID's command changes accordingly."""
    config = RollConfig(sensors=False)
    pid = PIDController(PIDGains.place(NominalModel(2.0, 0.66, 4.0), "angle", 2.0), config)
    obs = np.zeros(len(Obs), dtype=np.float32)
    obs[Obs.ERROR] = 1.0
    first = float(pid.act(obs)[0])
    pid.reset()
    swapped = obs.copy()
    swapped[Obs.ERROR], swapped[Obs.RATE] = 0.0, 5.0
    second = float(pid.act(swapped)[0])
    g = pid.gains
    assert first * 40.0 == pytest.approx(g.trim_deg + g.kp * 1.0)
    assert second * 40.0 == pytest.approx(g.trim_deg - g.kd * 5.0)


def test_the_recorded_history_is_the_episode() -> None:
    env = quiet()
    _, info = env.reset(seed=1)
    recorder = HistoryRecorder(env.config.max_episode_steps + 1)
    recorder.record(env.core, 0)
    infos, rewards = [info], [0.0]
    for _ in range(5):
        _, reward, _, _, info = env.step(np.array([-0.5], dtype=np.float32))
        recorder.record(env.core, 0, float(reward))
        infos.append(info)
        rewards.append(float(reward))
    h = recorder.history("angle", 40.0)
    assert h.angle_deg.tolist() == [i["roll_deg"] for i in infos]
    assert h.rate_dps.tolist() == [i["roll_rate_dps"] for i in infos]
    assert h.command_deg.tolist() == [i["fin_cmd_deg"] for i in infos]
    assert h.u_d_deg.tolist() == [i["u_d_deg"] for i in infos]
    assert h.error.tolist() == [i["tracking_error"] for i in infos]
    assert h.reward.tolist() == rewards
    assert h.time_s == pytest.approx([i["time_s"] for i in infos])


# ------------------------------------------------------------------ a changing rocket
def run(env: RocketRollEnv, options: dict[str, object], steps: int = STEPS) -> np.ndarray:
    """States after each of ``steps`` steps of a fixed action sequence."""
    env.reset(seed=5, options={"trace": 0, "start": 0, **options})
    actions = np.sin(np.arange(steps) * 0.3) * 0.8
    out = [env.core.state[0].copy()]
    for a in actions:
        env.step(np.array([a], dtype=np.float32))
        out.append(env.core.state[0].copy())
    return np.array(out)


def test_all_ones_is_the_rocket_of_the_database_bit_for_bit() -> None:
    env = quiet()
    plain = run(env, {})
    ones = run(env, {"scales": np.ones((env.config.max_episode_steps, len(Scale)))})
    np.testing.assert_array_equal(plain, ones)
    np.testing.assert_array_equal(plain, run(env, {"scales": [1.0, 1.0]}))


def test_a_constant_multiplier_is_the_rocket_with_those_parameters() -> None:
    env = quiet()
    trace = env.bank.traces[0]
    p = trace.rocket()
    gain, damp = 1.7, 0.6
    scaled = RollParams(
        p.alpha * gain, p.theta_bar_deg, p.beta_bar_per_s * damp, p.alpha_bar_per_deg_s * damp
    )
    twin_bank = TraceBank([dataclasses.replace(trace, params=scaled)], "scaled twin")
    twin = RocketRollEnv(bank=twin_bank, sensors=False)
    np.testing.assert_array_equal(run(env, {"scales": [gain, damp]}), run(twin, {}))
    assert env.core.roll_params(0) == scaled


def test_a_switch_mid_episode_follows_eq_29_after_it() -> None:
    """Fin held, no disturbance, constant damping: after the gain doubles and the damping
    halves at step k, the rate relaxes to the new steady rate α·g·(θ + θ̄) with the new
    time constant 1/(a·d)."""
    a, alpha, theta_bar = 1.5, 0.66, 4.0
    bank = TraceBank.from_arrays([np.zeros(700)], 0.1, RollParams(alpha, theta_bar, a))
    env = RocketRollEnv(bank=bank, sensors=False, model="constant", disturbance="none")
    steps, k = env.config.max_episode_steps, 100
    scales = np.ones((steps, len(Scale)))
    scales[k:, Scale.GAIN] = 2.0
    scales[k:, Scale.DAMPING] = 0.5
    env.reset(seed=0, options={"scales": scales, "fin_deg": 10.0})
    seen = [env.core.state[0, State.RATE]]
    for _ in range(steps):
        env.step(np.array([10.0 / 40.0], dtype=np.float32))
        seen.append(env.core.state[0, State.RATE])
    rates = np.array(seen)
    before, after = alpha * (10.0 + theta_bar), 2.0 * alpha * (10.0 + theta_bar)
    assert rates[:k] == pytest.approx(before, rel=1e-12)  # steady from the start
    t = 0.1 * np.arange(1, 40)
    expected = after + (before - after) * np.exp(-a * 0.5 * t)
    np.testing.assert_allclose(rates[k + 1 : k + 40], expected, rtol=1e-9)
    assert rates[-1] == pytest.approx(after, rel=1e-6)


def test_a_schedule_is_replayed_and_copied_exactly() -> None:
    env = quiet()
    steps = env.config.max_episode_steps
    scales = 1.0 + 0.3 * np.sin(np.linspace(0.0, 6.0, steps))[:, None] * np.array([1.0, -1.0])
    first = run(env, {"scales": scales}, steps=20)
    options = env.replay_options()
    np.testing.assert_array_equal(np.array(options["scales"]), scales)
    np.testing.assert_array_equal(run(env, options, steps=20), first)
    predictor = RollBatch(env.config, env.bank, 3)
    predictor.copy_env(env.core, 0, predictor.all)
    assert predictor.roll_params(2) == env.core.roll_params(0)


def test_the_vector_env_takes_a_schedule_too() -> None:
    envs = RocketRollVectorEnv(2, bank=array_bank(), sensors=False)
    envs.reset(seed=0, options={"trace": 0, "start": 0, "scales": [2.0, 1.0]})
    single = quiet()
    single.reset(seed=0, options={"trace": 0, "start": 0, "scales": [2.0, 1.0]})
    assert envs._batch.state[0, State.RATE] == single.core.state[0, State.RATE]
    p = single.core.params[0]  # the steady rate of eq. 16 at fin 0°, with the gain doubled
    steady = 2.0 * p[Param.ALPHA] * (0.0 + p[Param.THETA_BAR] + single.core.u_now[0])
    assert envs._batch.state[0, State.RATE] == pytest.approx(steady, rel=1e-12)


@pytest.mark.parametrize(
    ("scales", "message"),
    [
        ([1.0, 1.0, 1.0], "shape"),
        (np.ones((5, 2)), "shape"),
        ([0.0, 1.0], "positive"),
        ([math.nan, 1.0], "finite"),
        ("fast", "numbers"),
    ],
)
def test_bad_schedules_are_refused_by_name(scales: object, message: str) -> None:
    env = quiet()
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0, options={"scales": scales})


def test_a_copied_or_pickled_batch_keeps_its_named_columns_on_its_cursor() -> None:
    """step_count and friends are views of ``cursor`` (the kernel writes only that): a copy
    must keep them so, or it would never see its episode end."""
    env = quiet()
    scales = np.linspace(1.0, 2.0, env.config.max_episode_steps)[:, None] * np.ones(2)
    env.reset(seed=1, options={"scales": scales})
    twins: tuple[RocketRollEnv, ...] = (copy.deepcopy(env), pickle.loads(pickle.dumps(env)))
    for twin in twins:
        core = twin.core
        for name in ("step_count", "u_start", "scale_start", "scale_stride"):
            assert np.shares_memory(getattr(core, name), core.cursor), name
        for _ in range(twin.config.max_episode_steps):
            truncated = twin.step(np.zeros(1, dtype=np.float32))[3]
        assert truncated
        np.testing.assert_array_equal(twin.core.episode_scales(0), scales)
        with pytest.raises(RuntimeError, match="episode ended"):
            twin.step(np.zeros(1, dtype=np.float32))
    np.testing.assert_array_equal(env.core.episode_scales(0), scales)


def test_a_copy_that_takes_a_schedule_leaves_its_source_alone() -> None:
    env = quiet()
    steps = env.config.max_episode_steps
    scales = np.linspace(1.0, 1.5, steps)[:, None] * np.ones(2)
    env.reset(seed=0, options={"scales": scales})
    for n in (1, 3):  # a predictor of the source's size, and a larger one
        predictor = RollBatch(env.config, env.bank, n)
        predictor.copy_env(env.core, 0, predictor.all)
        np.testing.assert_array_equal(predictor.episode_scales(n - 1), scales)
        predictor.reset(predictor.all[:1], np.random.default_rng(0), scales=np.full(2, 3.0))
        np.testing.assert_array_equal(env.core.episode_scales(0), scales)
        assert np.all(predictor.episode_scales(0) == 3.0)
        for i in range(1, n):  # the other copies keep the source's schedule
            np.testing.assert_array_equal(predictor.episode_scales(i), scales)
    # ... and a source that takes a new schedule leaves an earlier copy alone.
    predictor = RollBatch(env.config, env.bank, 2)
    predictor.copy_env(env.core, 0, predictor.all)
    env.reset(seed=0, options={"scales": np.full(2, 0.5)})
    np.testing.assert_array_equal(predictor.episode_scales(1), scales)


def test_a_schedule_in_the_vector_env_is_stepped_like_the_single_env_and_ends_with_it() -> None:
    """The vector env runs a schedule step for step as the single env does; it is an option
    of that reset only, so the episode after an autoreset has the database's rocket."""
    steps = RollConfig().max_episode_steps
    scales = 1.0 + 0.5 * np.sin(np.linspace(0.0, 9.0, steps))[:, None] * np.array([1.0, 0.5])
    options = {"trace": 0, "start": 0, "scales": scales}
    envs = RocketRollVectorEnv(2, bank=array_bank(), sensors=False)
    single = quiet()
    envs.reset(seed=0, options=options)
    single.reset(seed=0, options=options)
    actions = np.sin(np.arange(steps) * 0.2) * 0.7
    for a in actions:
        envs.step(np.full((2, 1), a, dtype=np.float32))
        single.step(np.array([a], dtype=np.float32))
        np.testing.assert_array_equal(envs._batch.state[0], single.core.state[0])
    assert envs._batch.scale_stride.tolist() == [1, 1]
    envs.step(np.zeros((2, 1), dtype=np.float32))  # NEXT_STEP autoreset: no options
    assert envs._batch.scale_stride.tolist() == [0, 0]
    assert envs._batch.roll_params(0) == params_of_row(envs._batch.params[0])


def test_replay_options_carry_the_initial_state_given_or_drawn() -> None:
    env = quiet(initial_angle_deg=30.0)
    _, first = env.reset(seed=4, options={"fin_deg": 12.0, "rate_dps": 3.0})
    options = env.replay_options()
    assert options["fin_deg"] == 12.0 and options["rate_dps"] == 3.0
    assert options["angle_deg"] == first["roll_deg"] != 0.0  # drawn in ±30°
    _, again = env.reset(seed=77, options=options)
    for key in ("roll_deg", "roll_rate_dps", "fin_deg", "trace", "start_s"):
        assert again[key] == first[key], key
