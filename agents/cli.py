"""``rocketroll`` commands of the agents layer: ``train``, ``eval``, ``seeds``, ``robustness``,
``sweep``, ``tune``.

The commands themselves live beside what they run (:data:`agents.train.COMMAND`,
:data:`agents.evaluate.COMMAND`, :data:`agents.tune.COMMAND`, each a settings
dataclass and a function), so ``python -m agents.train`` and ``rocketroll
train ppo`` are one command; this module only groups them.
"""

from __future__ import annotations

from agents import evaluate, robustness, seeds, sweep, train, tune
from rocketroll_common.settings import Command

__all__ = ["COMMANDS"]

#: The commands of this layer, by name.
COMMANDS: dict[str, Command] = {
    "train": Command(
        "train",
        "train a controller (PPO, SAC, TD3; Stable-Baselines3)",
        description=train.__doc__ or "",
        subcommands=(train.COMMAND, train.SAC_COMMAND, train.TD3_COMMAND),
    ),
    "eval": evaluate.COMMAND,
    "seeds": seeds.COMMAND,
    "robustness": robustness.COMMAND,
    "sweep": sweep.COMMAND,
    "tune": Command(
        "tune",
        "re-tune a controller's design on train episodes (the PID's bandwidth)",
        description=tune.__doc__ or "",
        subcommands=(tune.COMMAND,),
    ),
}
