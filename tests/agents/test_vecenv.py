"""``RollVecEnv``: the SB3 adapter against SB3's expectations and the environment's physics.

The adapter resets an env whose episode ended in the same step (SB3's
convention), so it draws from its generator in the same order as the single
environment reset after each truncation, and as the Gymnasium vector env
whose autoreset step (NEXT_STEP) it skips.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.utils import check_for_correct_spaces
from stable_baselines3.common.vec_env import VecCheckNan, VecMonitor, VecNormalize

from agents.train import quiet_logger
from agents.vecenv import ENV_ATTRIBUTES, RollVecEnv
from rollenv.env import RocketRollEnv
from rollenv.vector import RocketRollVectorEnv
from tests.rollenv.conftest import array_bank

#: Short episodes (20 steps), short setpoint periods, every source of randomness on.
SHORT: dict[str, Any] = {
    "episode_s": 2.0,
    "setpoint_period_s": 0.5,
    "initial_angle_deg": 30.0,
    "gyro_noise_pct": 5.0,
}


def adapter(n: int = 3, env_id: str = "RocketRoll-v0", **kwargs: Any) -> RollVecEnv:
    return RollVecEnv(n, env_id, bank=array_bank(), **{**SHORT, **kwargs})


def rollout(venv: RollVecEnv, steps: int, *, action_seed: int = 0) -> list[Any]:
    """Everything the adapter returns over ``steps`` random actions after a reset."""
    rng = np.random.default_rng(action_seed)
    out: list[Any] = [venv.reset()]
    for _ in range(steps):
        actions = rng.uniform(-1.2, 1.2, size=(venv.num_envs, 1)).astype(np.float32)
        out.append(venv.step(actions))
    return out


def flatten(result: list[Any]) -> list[np.ndarray]:
    """Arrays of a rollout (observations, rewards, dones, tracking errors), for comparing."""
    arrays = [result[0]]
    for obs, rewards, dones, infos in result[1:]:
        arrays += [obs, rewards, dones, np.array([i["tracking_error"] for i in infos])]
    return arrays


# ------------------------------------------------------------------ SB3's expectations
@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
def test_spaces_dtypes_and_shapes_are_what_sb3_expects(env_id):
    venv = adapter(3, env_id, seed=0)
    single = RocketRollEnv(bank=array_bank(), task=venv.config.task)
    check_for_correct_spaces(venv, single.observation_space, single.action_space)
    assert venv.action_space.dtype == np.float32
    assert venv.render_mode is None and venv.get_attr("render_mode") == [None] * 3
    obs = VecCheckNan(venv, raise_exception=True).reset()
    assert isinstance(obs, np.ndarray) and obs.shape == (3, 4) and obs.dtype == np.float32
    assert all(venv.observation_space.contains(o) for o in obs)
    assert len(venv.reset_infos) == 3 and all("trace" in i for i in venv.reset_infos)
    checked = VecCheckNan(venv, raise_exception=True)
    for k in range(25):  # crosses the end of the 20-step episodes
        actions = np.stack([venv.action_space.sample() for _ in range(3)])
        obs, rewards, dones, infos = checked.step(actions)
        assert isinstance(obs, np.ndarray)
        assert obs.shape == (3, 4) and obs.dtype == np.float32
        assert all(venv.observation_space.contains(o) for o in obs)
        assert rewards.shape == (3,) and rewards.dtype == np.float32
        assert np.all(rewards <= 0.0)
        assert dones.shape == (3,) and dones.dtype == np.bool_
        assert dones.tolist() == [k == 19] * 3
        assert isinstance(infos, list) and len(infos) == 3
        assert all(isinstance(i, dict) and isinstance(i["tracking_error"], float) for i in infos)


def test_short_ppo_run_completes_and_bootstraps_at_truncation(tmp_path: Path):
    torch.set_num_threads(1)
    venv = VecNormalize(VecMonitor(adapter(2, seed=0)))
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=32, n_epochs=2, seed=0, device="cpu")
    model.set_logger(quiet_logger())
    model.learn(total_timesteps=256)
    assert not (tmp_path / "sb3-logs").exists()  # where SB3's default logger would write
    assert model.num_timesteps == 256
    # 20-step episodes: VecMonitor saw many end, each 20 steps long.
    assert model.ep_info_buffer is not None and len(model.ep_info_buffer) >= 10
    assert {int(e["l"]) for e in model.ep_info_buffer} == {20}


def ppo_actions(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The last rollout's actions of a short PPO run, and its policy on fixed observations."""
    torch.set_num_threads(1)
    venv = VecNormalize(VecMonitor(adapter(2)))
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=32,
        batch_size=32,
        n_epochs=1,
        seed=seed,
        device="cpu",
        policy_kwargs={"net_arch": [16, 16]},
    )
    model.set_logger(quiet_logger())
    model.learn(total_timesteps=128)
    probe = np.random.default_rng(1).normal(0.0, 1.0, size=(8, 4)).astype(np.float32)
    policy_actions, _ = model.predict(probe, deterministic=True)
    return model.rollout_buffer.actions.copy(), np.asarray(policy_actions)


def test_ppo_runs_with_the_same_seed_act_identically_and_another_seed_differently():
    a_rollout, a_policy = ppo_actions(seed=5)
    b_rollout, b_policy = ppo_actions(seed=5)
    np.testing.assert_array_equal(a_rollout, b_rollout)
    np.testing.assert_array_equal(a_policy, b_policy)
    c_rollout, c_policy = ppo_actions(seed=6)
    assert not np.array_equal(a_rollout, c_rollout)
    assert not np.array_equal(a_policy, c_policy)


# --------------------------------------------------------------------------- seeding
def test_same_seed_same_rollout_other_seed_another():
    a = flatten(rollout(adapter(3, seed=11), 45))
    b = flatten(rollout(adapter(3, seed=11), 45))
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    c = flatten(rollout(adapter(3, seed=12), 45))
    assert not np.array_equal(a[0], c[0])
    assert not np.array_equal(a[-4], c[-4])
    assert len({float(x) for x in a[0][:, 1]}) == 3  # the envs of a batch differ


def test_seed_applies_to_the_next_reset_only_as_in_sb3():
    seeded = adapter(3)
    assert seeded.seed(11) == [11, 12, 13]
    a = flatten(rollout(seeded, 30))
    b = flatten(rollout(adapter(3, seed=11), 30))  # the constructor's seed: the same
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    # Used once: the next reset goes on with the generator, not from seed 11 again.
    assert not np.array_equal(seeded.reset(), b[0])
    assert seeded.seed(None) == [None, None, None]


# ------------------------------------------------------------- end of episode (SB3 style)
def test_same_step_reset_with_terminal_observation_matches_the_vector_env():
    # The vector env (NEXT_STEP autoreset) returns the last observation at step 20 and the
    # new episode's first at step 21, with the same draws: the adapter returns both at 20.
    venv = adapter(3, seed=4)
    vector = RocketRollVectorEnv(3, bank=array_bank(), **SHORT)
    obs = venv.reset()
    vobs, _ = vector.reset(seed=4)
    np.testing.assert_array_equal(obs, vobs)
    rng = np.random.default_rng(0)
    ended = 0
    for k in range(1, 46):
        actions = rng.uniform(-1, 1, size=(3, 1)).astype(np.float32)
        obs, rewards, dones, infos = venv.step(actions)
        vobs, vrewards, _, vtrunc, vinfo = vector.step(actions)
        np.testing.assert_array_equal(rewards, vrewards.astype(np.float32))
        assert [i["tracking_error"] for i in infos] == vinfo["tracking_error"].tolist()
        assert dones.tolist() == vtrunc.tolist() == [k % 20 == 0] * 3
        if k % 20:
            np.testing.assert_array_equal(obs, vobs)
            assert all("terminal_observation" not in i for i in infos)
            continue
        ended += 1
        for i in range(3):
            assert infos[i]["TimeLimit.truncated"] is True
            np.testing.assert_array_equal(infos[i]["terminal_observation"], vobs[i])
            assert infos[i]["terminal_observation"].dtype == np.float32
        vobs, vrewards, _, vtrunc, _ = vector.step(actions)  # its autoreset step
        assert not vtrunc.any() and not vrewards.any()
        np.testing.assert_array_equal(obs, vobs)
        assert not np.array_equal(obs, np.stack([i["terminal_observation"] for i in infos]))
        assert [r["trace"] for r in venv.reset_infos] == [
            array_bank().traces[t].uid for t in vector._batch.trace
        ]
    assert ended == 2


def test_one_env_equals_the_single_env_across_truncations():
    # The single env reset() (no seed) after each truncation draws what the adapter draws.
    venv = adapter(1, seed=21)
    single = RocketRollEnv(bank=array_bank(), **SHORT)
    obs = venv.reset()
    sobs, _ = single.reset(seed=21)
    np.testing.assert_array_equal(obs[0], sobs)
    rng = np.random.default_rng(3)
    for k in range(1, 61):
        action = rng.uniform(-1.5, 1.5, size=1).astype(np.float32)
        obs, rewards, dones, infos = venv.step(action[None, :])
        sobs, sreward, _, struncated, sinfo = single.step(action)
        assert rewards[0] == np.float32(sreward)
        assert infos[0]["tracking_error"] == sinfo["tracking_error"]
        assert bool(dones[0]) is struncated is (k % 20 == 0)
        if struncated:
            np.testing.assert_array_equal(infos[0]["terminal_observation"], sobs)
            sobs, _ = single.reset()
        np.testing.assert_array_equal(obs[0], sobs)


@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
def test_fixed_reset_options_give_the_single_env_physics(env_id):
    # A fixed trace window, start state and setpoint, fixed actions: the same observations,
    # rewards and true errors as RocketRollEnv with the same options and seed.
    options = {"trace": 1, "start": 7, "setpoint": 25.0 if env_id == "RocketRoll-v0" else 4.0}
    options |= {"angle_deg": -12.0, "rate_dps": 3.0, "fin_deg": 5.0}
    settings: dict[str, Any] = {"episode_s": 6.0, "gyro_noise_pct": 2.0}
    venv = RollVecEnv(1, env_id, bank=array_bank(), **settings)
    single = RocketRollEnv(bank=array_bank(), task=venv.config.task, **settings)
    venv.seed(8)
    venv.set_options(options)
    obs = venv.reset()
    sobs, sinfo = single.reset(seed=8, options=options)
    np.testing.assert_array_equal(obs[0], sobs)
    assert venv.reset_infos[0]["trace"] == sinfo["trace"]
    assert venv.reset_infos[0]["start_s"] == sinfo["start_s"]
    actions = np.sin(np.arange(60) / 4.0).astype(np.float32)
    for a in actions:  # the whole episode: its last observation is the terminal one
        obs, rewards, dones, infos = venv.step(np.array([[a]]))
        sobs, sreward, _, struncated, sinfo = single.step(np.array([a]))
        assert bool(dones[0]) is struncated
        np.testing.assert_array_equal(infos[0].get("terminal_observation", obs[0]), sobs)
        assert rewards[0] == np.float32(sreward)
        assert infos[0]["tracking_error"] == sinfo["tracking_error"]
    assert struncated
    # The options held for that reset only (also for the same-step reset above).
    assert venv._batch.setpoints[0, 0] == 0.0
    venv.reset()
    assert venv._batch.setpoints[0, 0] == 0.0


def test_per_env_options_and_equal_options_for_all():
    venv = adapter(3, seed=0)
    venv.set_options([{"trace": 0}, {"trace": 2}, {"trace": 3, "start": 5}])
    venv.reset()
    uids = [t.uid for t in array_bank().traces]
    assert [i["trace"] for i in venv.reset_infos] == [uids[0], uids[2], uids[3]]
    assert venv.reset_infos[2]["start_s"] == pytest.approx(0.5)
    venv.set_options({"trace": uids[1], "setpoints": [10.0, 20.0, 30.0, 40.0]})
    venv.reset()
    assert [i["trace"] for i in venv.reset_infos] == [uids[1]] * 3
    np.testing.assert_array_equal(venv._batch.setpoints, [[10.0, 20.0, 30.0, 40.0]] * 3)
    venv.set_options({"bogus": 1})
    with pytest.raises(ValueError, match="bogus"):
        venv.reset()


# -------------------------------------------------------------------------- actions
def test_out_of_range_actions_are_clipped():
    a = adapter(2, seed=1)
    b = adapter(2, seed=1)
    a.reset()
    b.reset()
    for _ in range(5):
        oa, ra, _, _ = a.step(np.array([[5.0], [-3.0]], np.float32))
        ob, rb, _, _ = b.step(np.array([1.0, -1.0], np.float32))
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(ra, rb)


@pytest.mark.parametrize("bad", [[[np.nan], [0.0]], [[0.0], [np.inf]]])
def test_non_finite_actions_are_refused(bad):
    venv = adapter(2, seed=1)
    venv.reset()
    with pytest.raises(ValueError, match="finite"):
        venv.step(np.array(bad, np.float32))


def test_actions_of_the_wrong_shape_are_refused():
    venv = adapter(2, seed=1)
    venv.reset()
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 1), np.float32))


# ---------------------------------------------------------------------- bad use, API
def test_bad_construction_is_refused_by_name():
    with pytest.raises(ValueError, match="env_id"):
        RollVecEnv(2, "CartPole-v1", bank=array_bank())
    with pytest.raises(ValueError, match="num_envs"):
        RollVecEnv(0, bank=array_bank())
    with pytest.raises(ValueError, match="num_envs"):
        RollVecEnv(True, bank=array_bank())
    with pytest.raises(ValueError, match="task"):
        RollVecEnv(2, "RocketRollRate-v0", bank=array_bank(), task="angle")
    with pytest.raises(ValueError, match="episode_sec"):
        RollVecEnv(2, bank=array_bank(), episode_sec=3.0)
    with pytest.raises(ValueError, match="render"):
        RollVecEnv(2, bank=array_bank(), render_mode="rgb_array")


def test_stepping_before_reset_is_refused():
    venv = adapter(2)
    with pytest.raises(RuntimeError, match="reset"):
        venv.step(np.zeros((2, 1), np.float32))
    venv.reset()
    with pytest.raises(RuntimeError, match="step_async"):
        venv.step_wait()


def test_attribute_and_method_access():
    venv = adapter(3, "RocketRollRate-v0", seed=0)
    assert venv.get_attr("env_id") == ["RocketRollRate-v0"] * 3
    assert venv.get_attr("config", indices=[0, 2]) == [venv.config] * 2
    assert venv.get_attr("render_mode", indices=1) == [None]
    assert all(venv.has_attr(name) for name in ENV_ATTRIBUTES)
    assert not venv.has_attr("np_random")
    with pytest.raises(AttributeError, match="np_random"):
        venv.get_attr("np_random")
    with pytest.raises(IndexError, match="out of range"):
        venv.get_attr("config", indices=[3])
    with pytest.raises(AttributeError, match="fixed at construction"):
        venv.set_attr("config", None)
    with pytest.raises(AttributeError, match="render"):
        venv.env_method("render")
    assert venv.env_is_wrapped(Monitor) == [False] * 3
    assert venv.env_is_wrapped(Monitor, indices=[1]) == [False]
    with pytest.raises(NotImplementedError, match="render"):
        venv.get_images()
    assert venv.unwrapped is venv
    venv.close()


class _ConstantFeatures:
    """An observer's estimate stand-in: three constants per env, the action as the command."""

    def __init__(self, n: int) -> None:
        self.cleared: list[int | None] = []
        self.n = n

    def clear(self, i: int | None = None) -> None:
        self.cleared.append(i)

    def one(self, i: int, obs: Any) -> np.ndarray:
        return np.array([1.0, 2.0, 3.0 + i], dtype=np.float32)

    def record(self, obs: Any, actions: Any) -> np.ndarray:
        return np.asarray(actions, dtype=np.float32).reshape(-1, 1)


@pytest.mark.parametrize(
    "layout",
    [
        {"history": 2},
        {"observer": True, "history": 1},
        {"integral": 2.0, "integral_clip": 3.0},
        {"flight_clock": True, "integral": 1.0, "history": 3},
        {"incremental": 0.375},
    ],
    ids=str,
)
def test_the_policy_observation_its_names_and_its_space_agree(layout: dict[str, Any]) -> None:
    """Every layout's observation has as many values as its names, inside its space, in
    training's wrapper and in the acting controller alike (one PolicyObservation); a
    terminal observation is the policy's view of it, and an ended episode starts afresh."""
    from agents.memory import PolicyLayout, PolicyObservation, observation_names
    from agents.vecenv import VecPolicyObservation

    policy = PolicyLayout(**layout)
    env = adapter(2)
    scales = np.repeat(1.0 + np.arange(40.0)[:, None], 2, axis=1)  # step k reads 1 + k
    stack = PolicyObservation(
        policy,
        2,
        dt_s=env.config.dt_s,
        fin_range_deg=env.config.fin_range_deg,
        features=_ConstantFeatures(2) if policy.observer else None,
        scales=scales if policy.flight_clock else None,
    )
    wrapped = VecPolicyObservation(env, stack)
    names = observation_names(policy)
    assert wrapped.observation_space.shape == (len(names),) == (stack.size,)
    env.seed(3)
    seen = wrapped.reset()
    assert seen.shape == (2, len(names)) and seen.dtype == np.float32
    for _ in range(25):  # 20-step episodes: both envs end and start again
        stepped, _, dones, infos = wrapped.step(np.array([[0.5], [-0.5]], dtype=np.float32))
        seen = np.asarray(stepped)
        assert wrapped.observation_space.contains(seen[0]) and seen.shape == (2, len(names))
        for i in np.flatnonzero(dones):
            assert infos[i]["terminal_observation"].shape == (len(names),)
            if policy.history:  # the new episode's history is empty
                assert not np.any(seen[i, stack.width :])
    if policy.flight_clock:  # the clock restarted with the episode: 5 steps into it
        assert seen[0, names.index("flight_gain")] == 6.0
    if policy.observer:
        assert seen[1, names.index("u_d_hat_deg")] == 4.0
