"""``RocketRollVectorEnv``: the batch of environments against the single one and Gymnasium.

Autoreset is ``NEXT_STEP``: the step after an env's episode ends resets it,
ignores its action and returns its first observation with reward 0 and
neither flag set.
"""

from __future__ import annotations

import math
import multiprocessing
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from rollenv import task_of
from rollenv.env import RocketRollEnv
from rollenv.vector import INFO_KEYS, RocketRollVectorEnv
from tests.rollenv.conftest import array_bank


def vector_rollout(envs, seed, steps, *, action_seed=0):
    """Everything a vector env returns over ``steps`` random actions after a seeded reset."""
    obs, info = envs.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    out = [(obs, info)]
    for _ in range(steps):
        actions = rng.uniform(-1.2, 1.2, size=(envs.num_envs, 1)).astype(np.float32)
        out.append(envs.step(actions))
    return out


def assert_same(a, b):
    """Two vector rollouts are identical, bit for bit."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert len(x) == len(y)
        for u, v in zip(x, y, strict=True):
            if isinstance(u, dict):
                assert u.keys() == v.keys()
                for key in u:
                    np.testing.assert_array_equal(u[key], v[key])
            else:
                np.testing.assert_array_equal(u, v)


# ---------------------------------------------------------------- determinism (must show 2)
@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
def test_same_seed_same_rollout_other_seed_another(default_db, env_id):
    # 650 steps of 60-s episodes: every env autoresets once on the way.
    kwargs: dict[str, Any] = {"num_envs": 4, "setpoint_period_s": 5.0, "initial_angle_deg": 20.0}
    a = vector_rollout(gym.make_vec(env_id, **kwargs), seed=3, steps=650)
    b = vector_rollout(gym.make_vec(env_id, **kwargs), seed=3, steps=650)
    assert_same(a, b)
    assert np.any(a[600][3]) and not np.any(a[599][3])  # truncated at step 600
    c = vector_rollout(RocketRollVectorEnv(**kwargs, task=task_of(env_id)), seed=3, steps=650)
    assert_same(a, c)  # gym.make_vec builds exactly this class
    d = vector_rollout(gym.make_vec(env_id, **kwargs), seed=4, steps=650)
    assert not np.array_equal(a[1][0], d[1][0])
    assert not np.array_equal(a[-1][1], d[-1][1])
    # The envs of a batch differ from each other.
    assert len({float(x) for x in a[300][1]}) == 4


@pytest.mark.parametrize("task", ["angle", "rate"])
@pytest.mark.parametrize("source", ["arrays", "database"])
def test_one_env_batch_equals_the_single_env_step_for_step(default_db, task, source):
    # Every source of randomness on: trace windows, setpoint steps, initial angles, gyro
    # noise; short episodes, so both cross several truncations: the single env is
    # reset() without a seed, the batch autoresets on the next step.
    kwargs: dict[str, Any] = {
        "task": task,
        "episode_s": 2.0,
        "setpoint_period_s": 0.5,
        "initial_angle_deg": 60.0,
        "gyro_noise_pct": 5.0,
        "bank": array_bank() if source == "arrays" else None,
    }
    single = RocketRollEnv(**kwargs)
    batch = RocketRollVectorEnv(1, **kwargs)
    rng = np.random.default_rng(17)
    obs, info = single.reset(seed=99)
    vobs, vinfo = batch.reset(seed=99)
    episodes = 4
    compared = 0
    for episode in range(episodes):
        if episode:
            # The batch's autoreset step: its action is ignored.
            vobs, vreward, vterm, vtrunc, vinfo = batch.step(np.array([[0.9]], np.float32))
            obs, info = single.reset()
            assert (vreward[0], vterm[0], vtrunc[0]) == (0.0, False, False)
        assert_step_equal(obs, info, vobs, vinfo)
        for k in range(20):
            action = rng.uniform(-1.5, 1.5, size=1).astype(np.float32)
            obs, reward, terminated, truncated, info = single.step(action)
            vobs, vreward, vterm, vtrunc, vinfo = batch.step(action[None, :])
            assert_step_equal(obs, info, vobs, vinfo)
            assert vreward.dtype == np.float64
            assert reward == vreward[0]
            assert (terminated, truncated) == (vterm[0], vtrunc[0]) == (False, k == 19)
            compared += 1
    assert compared == 80


def assert_step_equal(obs, info, vobs, vinfo):
    assert vobs.shape == (1, 4) and vobs.dtype == np.float32
    np.testing.assert_array_equal(obs, vobs[0])
    for key in INFO_KEYS:
        assert info[key] == vinfo[key][0], key


# --------------------------------------------------------------------- autoreset (7)
def test_next_step_autoreset_of_one_env_while_the_others_go_on():
    kwargs: dict[str, Any] = {
        "bank": array_bank(),
        "episode_s": 2.0,
        "sensors": False,
        "setpoint": "zero",
    }
    envs = [RocketRollVectorEnv(3, **kwargs) for _ in range(3)]
    for e in envs:
        e.reset(seed=5)
    # Env 1 of the first two batches is three steps from the end of its episode.
    for e in envs[:2]:
        e._batch.step_count[1] = 17
    rng = np.random.default_rng(0)
    for k in range(6):
        actions = rng.uniform(-1, 1, size=(3, 1)).astype(np.float32)
        other = actions.copy()
        other[1] = -actions[1]  # a different action for env 1 in the second batch
        obs, reward, terminated, truncated, info = envs[0].step(actions)
        obs2, reward2, _, truncated2, _ = envs[1].step(other)
        obs3, reward3, _, _, _ = envs[2].step(actions)  # no early end
        assert not terminated.any()
        assert truncated.tolist() == [False, k == 2, False]
        # Envs 0 and 2 are not disturbed by env 1's end and reset (nothing random is
        # drawn on their steps with sensors off).
        np.testing.assert_array_equal(obs[[0, 2]], obs3[[0, 2]])
        np.testing.assert_array_equal(reward[[0, 2]], reward3[[0, 2]])
        if k == 3:
            # The autoreset step: env 1 starts again, action ignored, reward 0.
            np.testing.assert_array_equal(obs, obs2)
            np.testing.assert_array_equal(reward, reward2)
            assert reward[1] == 0.0 and not truncated[1]
            assert info["fin_deg"][1] == 0.0 and obs[1][2] == obs[1][3] == 0.0
            assert envs[0]._batch.step_count.tolist() == [4, 0, 4]
            assert reward[0] != 0.0 and reward[2] != 0.0
        else:
            assert reward[1] != 0.0
            assert truncated2.tolist() == truncated.tolist()
            assert not np.array_equal(obs[1], obs2[1])  # env 1's action counts
        if k == 4:
            assert envs[0]._batch.step_count.tolist() == [5, 1, 5]
        assert np.all(np.isfinite(obs))
        for key in INFO_KEYS:
            assert info[key].shape == (3,)
    assert envs[0].metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP


def test_all_envs_autoreset_together_at_the_end_of_the_episode():
    envs = RocketRollVectorEnv(4, bank=array_bank(), episode_s=1.0)
    envs.reset(seed=0)
    zeros = np.zeros((4, 1), np.float32)
    for k in range(10):
        _, reward, terminated, truncated, _ = envs.step(zeros)
        assert truncated.tolist() == [k == 9] * 4
        assert np.all(reward <= 0.0)
    obs, reward, terminated, truncated, _ = envs.step(zeros)
    assert reward.tolist() == [0.0] * 4
    assert not truncated.any() and not terminated.any()
    assert envs.observation_space.contains(obs)
    _, _, _, truncated, _ = envs.step(zeros)
    assert not truncated.any()


def test_info_has_arrays_with_masks(bank):
    envs = gym.make_vec("RocketRoll-v0", num_envs=5, bank=bank)
    for _, info in [envs.reset(seed=0), envs.step(np.zeros((5, 1), np.float32))[3:]]:
        for key in INFO_KEYS:
            assert info[key].shape == (5,)
            assert info[key].dtype == np.float64
            mask = info[f"_{key}"]
            assert mask.dtype == np.bool_ and mask.shape == (5,) and mask.all()
        assert set(info) == set(INFO_KEYS) | {f"_{k}" for k in INFO_KEYS}


def test_reset_options_apply_to_every_env(bank):
    envs = RocketRollVectorEnv(3, bank=bank, sensors=False)
    trace = bank.traces[1]
    obs, info = envs.reset(
        seed=1, options={"trace": trace.uid, "start": 40, "rate_dps": 3.0, "setpoint": 5.0}
    )
    assert info["u_d_deg"].tolist() == [trace.u_d_deg[40]] * 3
    assert info["roll_rate_dps"].tolist() == [3.0] * 3
    assert info["setpoint"].tolist() == [5.0] * 3
    assert (obs == obs[0]).all()
    for k in range(5):
        info = envs.step(np.zeros((3, 1), np.float32))[4]
        assert info["u_d_deg"].tolist() == [trace.u_d_deg[40 + k]] * 3
    with pytest.raises(ValueError, match="'nope'"):
        envs.reset(options={"nope": 1})


# ---------------------------------------------------------------------- bad use (must show 4)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_actions_are_refused(bank, bad):
    envs = RocketRollVectorEnv(3, bank=bank)
    envs.reset(seed=0)
    actions = np.zeros((3, 1), np.float32)
    actions[2, 0] = bad
    with pytest.raises(ValueError, match="finite"):
        envs.step(actions)
    with pytest.raises(ValueError, match="finite"):
        envs.step(actions.ravel())
    assert envs._batch.step_count.tolist() == [0, 0, 0]  # nothing was stepped


def test_out_of_range_actions_are_clipped(bank):
    rng = np.random.default_rng(2)
    raw = rng.choice([5.0, -3.0, 1.0, -1.0, 1e6, 0.3], size=(50, 3, 1))
    results = []
    for actions in (raw, np.clip(raw, -1.0, 1.0), np.clip(raw, -0.5, 0.5)):
        envs = RocketRollVectorEnv(3, bank=bank)
        envs.reset(seed=8)
        results.append([envs.step(a) for a in actions])
    assert_same(results[0], results[1])
    assert not np.array_equal(results[0][-1][0], results[2][-1][0])


@pytest.mark.parametrize(
    "actions", [np.zeros((2, 1)), np.zeros((3, 2)), np.zeros(4), np.zeros(()), "left"]
)
def test_actions_of_the_wrong_shape_are_refused(bank, actions):
    envs = RocketRollVectorEnv(3, bank=bank)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="action must"):
        envs.step(actions)
    envs.step(np.zeros(3))  # (n,) is accepted as well as (n, 1)


def test_bad_construction_and_use(bank):
    with pytest.raises(ValueError, match="renders 'rgb_array' frames"):
        RocketRollVectorEnv(2, bank=bank, render_mode="human")
    with pytest.raises(ValueError, match="renders 'rgb_array' frames"):
        gym.make_vec("RocketRoll-v0", num_envs=2, bank=bank, render_mode="human")
    for n in (0, -1, True, 2.0, "2"):
        with pytest.raises(ValueError, match="num_envs"):
            RocketRollVectorEnv(n, bank=bank)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown option 'foo'"):
        RocketRollVectorEnv(2, bank=bank, foo=1)
    with pytest.raises(ValueError, match="episode_s"):
        RocketRollVectorEnv(2, bank=bank, episode_s=-1.0)
    envs = RocketRollVectorEnv(2, bank=bank)
    with pytest.raises(RuntimeError, match="reset"):
        envs.step(np.zeros((2, 1)))
    with pytest.raises(ValueError, match="one int seed"):
        envs.reset(seed=[1, 2])


# ------------------------------------------------------------------------- threads, processes
def test_parallel_kernel_gives_the_same_rollout(bank):
    serial = vector_rollout(RocketRollVectorEnv(64, bank=bank, episode_s=2.0), 6, 45)
    parallel = vector_rollout(
        RocketRollVectorEnv(64, bank=bank, episode_s=2.0, parallel=True), 6, 45
    )
    assert_same(serial, parallel)


@pytest.mark.skipif(
    "forkserver" not in multiprocessing.get_all_start_methods(), reason="needs forkserver"
)
def test_async_vector_env_over_subprocesses(bank):
    # gym.make_vec's async mode with the forkserver context pickles the constructor's
    # arguments (the bank) into two worker processes; their episodes equal the same
    # single envs run in this process.  (Measured: about 2.5 s, mostly the workers'
    # imports.)
    kwargs: dict[str, Any] = {"num_envs": 2, "bank": bank, "episode_s": 2.0}
    started = time.perf_counter()
    envs = gym.make_vec(
        "RocketRoll-v0",
        vectorization_mode="async",
        vector_kwargs={"context": "forkserver"},
        **kwargs,
    )
    try:
        assert isinstance(envs, gym.vector.AsyncVectorEnv)
        remote = vector_rollout(envs, seed=12, steps=45)
    finally:
        envs.close()
    elapsed = time.perf_counter() - started
    envs = gym.make_vec("RocketRoll-v0", vectorization_mode="sync", **kwargs)
    local = vector_rollout(envs, seed=12, steps=45)
    envs.close()
    for (r_obs, *r_rest), (l_obs, *l_rest) in zip(remote, local, strict=True):
        np.testing.assert_array_equal(r_obs, l_obs)
        if len(r_rest) == 4:
            np.testing.assert_array_equal(r_rest[0], l_rest[0])  # rewards
            np.testing.assert_array_equal(r_rest[2], l_rest[2])  # truncations
    assert remote[20][3].all()  # both truncated at step 20
    assert not np.array_equal(remote[10][0][0], remote[10][0][1])  # two different envs
    assert elapsed < 60.0
