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
:func:`register_variant` registers it with Gymnasium and in
:data:`VARIANTS`, where the command line (``--env-id``), training and the
evaluation find it.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from gymnasium.envs.registration import register, registry

from rocketroll_common.registry import Registry

__all__ = [
    "VARIANTS",
    "RocketRollEnv",
    "RocketRollVectorEnv",
    "register_variant",
    "task_of",
]

#: Environment variants by id: the options each one fixes (``task`` and any field
#: of :class:`rollenv.core.RollConfig`).
VARIANTS: Registry[Mapping[str, Any]] = Registry("environment id")


def register_variant(
    env_id: str,
    *,
    summary: str = "",
    entry_point: str = "rollenv.env:RocketRollEnv",
    vector_entry_point: str = "rollenv.vector:RocketRollVectorEnv",
    **options: Any,
) -> None:
    """Register an environment variant with Gymnasium and in :data:`VARIANTS`.

    Parameters
    ----------
    env_id : str
        ``Name-vN``, as for ``gym.make``.
    summary : str
        One line for ``--help``.
    entry_point, vector_entry_point : str
        The single and the vector environment (``"module:Class"``).
    **options
        What the variant fixes: ``task`` ("angle" or "rate") and any
        :class:`rollenv.core.RollConfig` field.
    """
    if options.get("task") not in ("angle", "rate"):
        raise ValueError(f"{env_id}: a variant needs task='angle' or task='rate'")
    fixed = MappingProxyType(dict(options))
    VARIANTS.register(env_id, fixed, summary=summary, entry_point=entry_point)
    if env_id not in registry:
        register(
            id=env_id,
            entry_point=entry_point,
            vector_entry_point=vector_entry_point,
            kwargs=dict(options),
        )


def task_of(env_id: str) -> str:
    """The task (``angle`` or ``rate``) of a registered variant (``ValueError`` if unknown)."""
    task: str = VARIANTS.get(env_id)["task"]
    return task


register_variant("RocketRoll-v0", task="angle", summary="hold the roll angle at a setpoint")
register_variant("RocketRollRate-v0", task="rate", summary="track a roll-rate setpoint")


def __getattr__(name: str) -> object:
    # The classes load numba and compile on first use; importing rollenv only registers.
    if name == "RocketRollEnv":
        from rollenv.env import RocketRollEnv

        return RocketRollEnv
    if name == "RocketRollVectorEnv":
        from rollenv.vector import RocketRollVectorEnv

        return RocketRollVectorEnv
    raise AttributeError(f"module 'rollenv' has no attribute {name!r}")
