"""``rocketroll`` commands of the agents layer: ``train``, ``eval``, ``seeds``, ``robustness``,
``sweep``, ``tune``.

Training's commands are here (:data:`TRAIN_COMMAND` and its off-policy siblings: the
arguments dataclasses of :mod:`agents.train` and a function), as are the sweep's
(:mod:`agents.sweep`); the others live beside what they run (:data:`agents.evaluate.COMMAND`,
:data:`agents.tune.COMMAND`, ...). ``python -m agents.train`` and ``rocketroll train ppo``
are one command.
"""

from __future__ import annotations

import agents.train
from agents import evaluate, robustness, seeds, sweep, tune
from agents.train import Args, SACArgs, TD3Args
from rocketroll_common.settings import Command

__all__ = ["COMMANDS", "SAC_COMMAND", "TD3_COMMAND", "TRAIN_COMMAND"]


def _train(args: Args) -> int:
    agents.train.train(args)
    return 0


#: ``rocketroll train ppo`` (``python -m agents.train``).
TRAIN_COMMAND = Command(
    "ppo",
    "train PPO on a RocketRoll environment (Stable-Baselines3)",
    Args,
    _train,
    agents.train.__doc__ or "",
)
#: ``rocketroll train sac`` and ``rocketroll train td3``: the same script, off-policy.
SAC_COMMAND = Command(
    "sac",
    "train SAC on a RocketRoll environment (Stable-Baselines3)",
    SACArgs,
    _train,
    agents.train.__doc__ or "",
)
TD3_COMMAND = Command(
    "td3",
    "train TD3 on a RocketRoll environment (Stable-Baselines3)",
    TD3Args,
    _train,
    agents.train.__doc__ or "",
)

#: The commands of this layer, by name.
COMMANDS: dict[str, Command] = {
    "train": Command(
        "train",
        "train a controller (PPO, SAC, TD3; Stable-Baselines3)",
        description=agents.train.__doc__ or "",
        subcommands=(TRAIN_COMMAND, SAC_COMMAND, TD3_COMMAND),
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
