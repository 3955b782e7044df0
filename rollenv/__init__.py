"""RocketRoll: a Gymnasium environment replaying identified turbulence through the roll model.

Importing this package registers the environments::

    import gymnasium as gym
    import rollenv  # registers RocketRoll-v0 and RocketRollRate-v0

    env = gym.make("RocketRoll-v0")                      # hold the roll angle
    env = gym.make("RocketRollRate-v0", split="test")    # track a roll rate
    envs = gym.make_vec("RocketRoll-v0", num_envs=4096)  # RocketRollVectorEnv

Gymnasium 1.x has no plugin entry points, so without the import use the
``module:id`` form, which imports this package first:
``gym.make("rollenv:RocketRoll-v0")``.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

__all__ = ["ENV_IDS", "RocketRollEnv", "RocketRollVectorEnv"]

#: The registered ids and the task each one sets.
ENV_IDS = {"RocketRoll-v0": "angle", "RocketRollRate-v0": "rate"}

for _env_id, _task in ENV_IDS.items():
    if _env_id not in registry:
        register(
            id=_env_id,
            entry_point="rollenv.env:RocketRollEnv",
            vector_entry_point="rollenv.vector:RocketRollVectorEnv",
            kwargs={"task": _task},
        )


def __getattr__(name: str) -> object:
    # The classes load numba and compile on first use; importing rollenv only registers.
    if name == "RocketRollEnv":
        from rollenv.env import RocketRollEnv

        return RocketRollEnv
    if name == "RocketRollVectorEnv":
        from rollenv.vector import RocketRollVectorEnv

        return RocketRollVectorEnv
    raise AttributeError(f"module 'rollenv' has no attribute {name!r}")
