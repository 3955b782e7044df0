"""ActorChain: a trained policy's deterministic action, the same bits on every processor,
within float32 rounding of SB3's predict()."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import A2C, PPO, SAC, TD3

from agents.actor import ActorChain
from agents.learned import LearnedController
from agents.registry import COMMITTED

REPO = Path(__file__).resolve().parents[2]


def _env() -> gym.Env:
    return gym.make("Pendulum-v1")  # a Box action of bounds ±2: unscaling shows


@pytest.mark.parametrize(
    ("algorithm", "kwargs"),
    [
        (PPO, {"net_arch": [16, 8]}),
        (PPO, {"net_arch": [16], "activation_fn": torch.nn.ReLU}),
        (A2C, {"net_arch": [8, 8]}),
        (SAC, {"net_arch": [16, 16]}),
        (TD3, {"net_arch": [16, 16]}),
    ],
    ids=["ppo", "ppo-relu", "a2c", "sac", "td3"],
)
def test_the_chain_is_predict_within_float32_rounding(algorithm, kwargs) -> None:
    model = algorithm("MlpPolicy", _env(), seed=0, device="cpu", policy_kwargs=kwargs)
    chain = ActorChain.from_policy(model.policy)
    assert chain is not None
    observations = np.random.default_rng(0).normal(0.0, 3.0, size=(200, 3)).astype(np.float32)
    observations[:3] *= 1e3  # far outside: clipped (PPO) or squashed (SAC, TD3) at the bounds
    for obs in observations:
        expected, _ = model.predict(obs, deterministic=True)
        got = chain(obs)
        assert got.dtype == np.float32 and got.shape == (1,)
        np.testing.assert_allclose(got, expected, rtol=0, atol=4e-6)  # 2 units of float32 at 2
        assert -2.0 <= got[0] <= 2.0


def test_a_layer_or_an_observation_it_does_not_know_leaves_the_action_to_torch() -> None:
    model = PPO(
        "MlpPolicy",
        _env(),
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [8], "activation_fn": torch.nn.ELU},
    )
    assert ActorChain.from_policy(model.policy) is None
    # SB3 one-hot encodes a discrete observation before the first layer.
    discrete = PPO("MlpPolicy", gym.make("FrozenLake-v1"), seed=0, device="cpu")
    assert ActorChain.from_policy(discrete.policy) is None


def test_an_observation_of_another_size_is_refused() -> None:
    model = PPO("MlpPolicy", _env(), seed=0, device="cpu", policy_kwargs={"net_arch": [8]})
    chain = ActorChain.from_policy(model.policy)
    assert chain is not None
    with pytest.raises(ValueError, match="takes 3 values, got 4"):
        chain(np.zeros(4, np.float32))


@pytest.fixture(scope="module")
def committed() -> LearnedController:
    """The committed angle policy, loaded once for the module."""
    return LearnedController.load(COMMITTED / "RocketRoll-v0")


def test_the_committed_policy_acts_through_the_chain(committed: LearnedController) -> None:
    assert committed.chain is not None


#: The committed angle policy's actions on fixed inputs (observation and history), hashed: the
#: chain's, torch's (``_hashes`` in this process, ``_ACTIONS`` in another).
_ACTIONS = """
from agents.learned import LearnedController
from agents.registry import COMMITTED
from tests.agents.test_actor import _hashes
print(*_hashes(LearnedController.load(COMMITTED / "RocketRoll-v0")))
"""


def _hashes(c: LearnedController) -> tuple[str, str]:
    """The sha256 of the chain's actions and of torch's on 500 fixed observations."""
    assert c.chain is not None
    width = c.model.observation_space.shape[0]
    obs = np.random.default_rng(0).normal(0.0, 30.0, size=(500, width)).astype(np.float32)
    chain = np.concatenate([c.chain(c.normalizer(o[None])) for o in obs])
    torch = np.concatenate([c.predict(o) for o in obs])
    return hashlib.sha256(chain.tobytes()).hexdigest(), hashlib.sha256(torch.tobytes()).hexdigest()


def test_the_chain_has_the_same_bits_under_every_torch_kernel(
    committed: LearnedController,
) -> None:
    """torch's kernels (its own, chosen by ATEN_CPU_CAPABILITY, and MKL's, by MKL_CBWR)
    give other bits on other processors; the chain does not use them.  The kernels as this
    process has them are read here; each other setting in a process started with it."""
    found = {_hashes(committed)}
    for varied in ({"ATEN_CPU_CAPABILITY": "default"}, {"MKL_CBWR": "COMPATIBLE"}):
        done = subprocess.run(
            [sys.executable, "-c", _ACTIONS],
            cwd=REPO,
            env={**os.environ, **varied},
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        chain, torch = done.stdout.split()
        found.add((chain, torch))
    assert len({chain for chain, _ in found}) == 1, found
    if len({torch for _, torch in found}) == 1:
        pytest.skip("torch's own bits do not change under these settings on this machine")
