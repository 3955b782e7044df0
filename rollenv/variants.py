"""Environment variants: an id and the options it fixes, registered once, with Gymnasium.

:func:`register_variant` registers a variant in Gymnasium's registry, which holds
its options (the spec's ``kwargs``) and entry points; the command line
(``--env-id``), training, tuning and the evaluation read them from there
(:func:`variant_ids`, :func:`variant_options`, :func:`rollenv.bank.variant_config`).
Importing this module registers ``RocketRoll-v0`` and ``RocketRollRate-v0`` (the
tunnel) and ``RocketRollFlight-v0`` and ``RocketRollFlightRate-v0`` (the flight).
"""

from __future__ import annotations

from typing import Any

from gymnasium.envs.registration import register, registry

from rocketroll_common.registry import load_plugins, unknown

__all__ = [
    "register_variant",
    "task_of",
    "unregister_variant",
    "variant_ids",
    "variant_options",
]

#: The ids :func:`register_variant` registered, in order, with their one-line summaries
#: (which Gymnasium's specs have no field for); everything else is in Gymnasium's registry.
_SUMMARIES: dict[str, str] = {}


def register_variant(
    env_id: str,
    *,
    summary: str = "",
    entry_point: str = "rollenv.env:RocketRollEnv",
    vector_entry_point: str = "rollenv.vector:RocketRollVectorEnv",
    **options: Any,
) -> None:
    """Register an environment variant with Gymnasium.

    Parameters
    ----------
    env_id : str
        ``Name-vN``, as for ``gym.make``.
    summary : str
        One line for listings.
    entry_point, vector_entry_point : str
        The single and the vector environment (``"module:Class"``).
    **options
        What the variant fixes: ``task`` ("angle" or "rate") and any
        :class:`rollenv.config.RollConfig` field.  As with ``gym.make``, a
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
    if env_id in _SUMMARIES:
        raise ValueError(f"environment id {env_id!r} is registered already")
    if env_id not in registry:
        register(
            id=env_id,
            entry_point=entry_point,
            vector_entry_point=vector_entry_point,
            kwargs=dict(options),
        )
    _SUMMARIES[env_id] = summary


def unregister_variant(env_id: str) -> None:
    """Remove a variant :func:`register_variant` registered (from Gymnasium's registry too)."""
    _SUMMARIES.pop(env_id, None)
    registry.pop(env_id, None)


def variant_ids() -> tuple[str, ...]:
    """The registered variants' ids, in registration order (plugins' included)."""
    load_plugins()
    return tuple(env_id for env_id in _SUMMARIES if env_id in registry)


def variant_options(env_id: str) -> dict[str, Any]:
    """The options a registered variant fixes, ``task`` included: its Gymnasium spec's
    ``kwargs`` (``ValueError`` naming the known ids for another)."""
    known = variant_ids()
    if env_id not in known:
        raise unknown("environment id", env_id, known)
    return dict(registry[env_id].kwargs)


def task_of(env_id: str) -> str:
    """The task (``angle`` or ``rate``) of a registered variant (``ValueError`` if unknown)."""
    task: str = variant_options(env_id)["task"]
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
