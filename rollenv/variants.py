"""Environment variants: an id and the options it fixes, registered once.

:func:`register_variant` registers a variant with Gymnasium and in
:data:`VARIANTS`; the command line (``--env-id``), training, tuning and the
evaluation read it from there (:func:`rollenv.bank.variant_config`).
Importing this module registers ``RocketRoll-v0`` and ``RocketRollRate-v0`` (the
tunnel) and ``RocketRollFlight-v0`` and ``RocketRollFlightRate-v0`` (the flight).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from gymnasium.envs.registration import register, registry

from rocketroll_common.registry import Registry

__all__ = ["VARIANTS", "register_variant", "task_of", "variant_options"]

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
        :class:`rollenv.core.RollConfig` field.  As with ``gym.make``, a
        setting given by the user overrides an option (but not ``task``).

    Notes
    -----
    Training (the SB3 adapter), tuning and the evaluation protocol run the
    variant's options on the batched core of :class:`rollenv.env.RocketRollEnv`;
    a variant with an environment class of its own is reached through
    ``gym.make`` and ``gym.make_vec``.
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


def variant_options(env_id: str) -> dict[str, Any]:
    """The options a registered variant fixes, ``task`` included (``ValueError`` if
    unknown)."""
    return dict(VARIANTS.get(env_id))


def task_of(env_id: str) -> str:
    """The task (``angle`` or ``rate``) of a registered variant (``ValueError`` if unknown)."""
    task: str = VARIANTS.get(env_id)["task"]
    return task


register_variant("RocketRoll-v0", task="angle", summary="hold the roll angle at a setpoint")
register_variant("RocketRollRate-v0", task="rate", summary="track a roll-rate setpoint")
register_variant(
    "RocketRollFlight-v0",
    task="angle",
    flight="default",
    angle_sensor="gyro",
    setpoint="zero",
    summary="hold the roll angle in flight, from 50 km/h to apogee (600 km/h, 2 km)",
)
register_variant(
    "RocketRollFlightRate-v0",
    task="rate",
    flight="default",
    angle_sensor="gyro",
    setpoint="zero",
    summary="stop the roll in flight (zero roll rate), from 50 km/h to apogee",
)
