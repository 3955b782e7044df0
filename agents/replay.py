"""How the commands that run episodes on a database choose what they replay.

``rocketroll eval``, ``tune``, ``train``, ``seeds``, ``robustness`` and ``sweep
run`` take the same ``--set KEY=VALUE`` environment options and read them
the same way, through :func:`options_config`: the replay (``method``: whose
rockets and ``u_d`` traces; ``disturbance``: identified traces, posterior
draws, surrogates or none; ``model``; ``recording``: one recording of the
split by name) and any other option of :class:`rollenv.core.RollConfig`.
A database that lacks the selection says so in one line, with what it holds
and the command that adds the rest (:class:`disturbances.bank.BankError`).

This module imports nothing heavy: the commands' argument classes use it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from rocketroll_common.errors import UsageError
from rocketroll_common.settings import setting

if TYPE_CHECKING:
    from rollenv.core import RollConfig

__all__ = [
    "FIXED_OPTIONS",
    "check_options",
    "db_setting",
    "env_options_setting",
    "options_config",
]

#: Environment options a command sets itself (``--env-id``, ``--split``), never ``--set``.
FIXED_OPTIONS = ("task", "split")


def db_setting() -> Any:
    """The ``--db`` setting of the commands that replay a database's traces."""
    return setting(
        None,
        "database (default: $ROCKETROLL_DB or the default database)",
        metavar="DB",
        input=True,
        kind="sqlite",
    )


def env_options_setting() -> Any:
    """The ``--set KEY=VALUE`` setting of the commands that run episodes on a database
    (eval, tune, train, seeds, robustness, sweep run): environment options, among them
    the replay (``method``, ``disturbance``, ``model``, ``recording``); read by
    :func:`options_config`."""
    return setting(
        default_factory=dict,
        help="an environment option for every episode, e.g. setpoint=zero, or the replay: "
        "method=paper, disturbance=replay, recording=NAME (repeatable)",
        flag="--set",
        metavar="KEY=VALUE",
    )


def check_options(options: Mapping[str, Any], flag: str = "--set") -> None:
    """Refuse (``UsageError``) an option the command sets itself (:data:`FIXED_OPTIONS`)."""
    fixed = [name for name in FIXED_OPTIONS if name in options]
    if fixed:
        raise UsageError(
            f"{flag} {fixed[0]}=... is not allowed: the command sets the task (from the "
            "environment id) and the split itself"
        )


def options_config(
    env_id: str, options: Mapping[str, Any], split: str, flag: str = "--set"
) -> RollConfig:
    """The configuration the commands that run episodes on a database replay: the variant
    ``env_id`` with the ``--set`` options (the replay: which method's rockets and ``u_d``,
    which disturbance, model and recording) on ``split``.  One reading for every command,
    so ``--set method=paper`` selects the same traces in each; a bad option is a
    ``UsageError`` that names ``flag``."""
    from rollenv.bank import variant_config

    check_options(options, flag)
    try:
        return variant_config(env_id, {**options, "split": split})
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{flag}: {exc}") from None
