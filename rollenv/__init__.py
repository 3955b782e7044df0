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

A variant is an id with the options it fixes (its ``task`` at least):
:func:`register_variant` registers it with Gymnasium, whose registry the command
line (``--env-id``), training, tuning and the evaluation read it from
(:func:`variant_ids`, :func:`variant_options`, :func:`rollenv.bank.variant_config`).
"""

from __future__ import annotations

from rollenv import variants
from rollenv.variants import register_variant as register_variant
from rollenv.variants import task_of as task_of
from rollenv.variants import unregister_variant as unregister_variant
from rollenv.variants import variant_ids as variant_ids
from rollenv.variants import variant_options as variant_options

__all__ = ["RocketRollEnv", "RocketRollVectorEnv", *variants.__all__]


def __getattr__(name: str) -> object:
    # The classes load numba and compile on first use; importing rollenv only registers.
    if name == "RocketRollEnv":
        from rollenv.env import RocketRollEnv

        return RocketRollEnv
    if name == "RocketRollVectorEnv":
        from rollenv.vector import RocketRollVectorEnv

        return RocketRollVectorEnv
    raise AttributeError(f"module 'rollenv' has no attribute {name!r}")
