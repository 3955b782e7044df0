"""Whether the oracle and the causal limit bound every deployable controller, task by task.

The five tasks of the evaluation (:data:`TASKS`: angle with setpoint steps and held at
zero, rate with setpoint steps, in the tunnel; angle and rate in flight), each
deployable controller (:func:`deployable`: the registry's defaults that run on the task
without an argument, less the floor and the bounds), the oracle (perfect preview of
``u_d``) and the causal oracle (the future of ``u_d`` predicted: :mod:`agents.oracle`) on
the same protocol episodes: :func:`bound_rows` gives each one's headline, the bounds'
ratios to it and where it sits between the PID and the causal limit.
The test suite runs it on a few episodes, ``benchmarks/oracle_bound.py`` on the whole
protocol.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from agents.evaluate import HEADLINE, evaluate, protocol_episodes
from agents.registry import available, default_policies, make_controller
from rollenv.bank import load_bank, variant_config

__all__ = ["NOT_DEPLOYABLE", "TASKS", "BoundRow", "bound_rows", "deployable"]

#: name -> (environment id, settings on top of it)
TASKS: dict[str, tuple[str, dict[str, object]]] = {
    "angle-steps": ("RocketRoll-v0", {}),
    "angle-zero": ("RocketRoll-v0", {"setpoint": "zero"}),
    "rate-steps": ("RocketRollRate-v0", {}),
    "flight-angle": ("RocketRollFlight-v0", {}),
    "flight-rate": ("RocketRollFlightRate-v0", {}),
}
#: The default rows that are not controllers a rocket could fly: the floor and the bound.
NOT_DEPLOYABLE = ("trim", "oracle", "causal-oracle")


def deployable(env_id: str) -> list[str]:
    """The registry's default controllers that run on ``env_id`` and could fly."""
    return [p for p in default_policies() if p not in NOT_DEPLOYABLE and available(p, env_id)]


@dataclass(frozen=True)
class BoundRow:
    """One task's headlines (regulation RMS, mean over the episodes): the oracle's, the
    causal oracle's and each deployable controller's."""

    task: str
    oracle: float
    causal: float
    others: dict[str, float]

    @property
    def ratios(self) -> dict[str, float]:
        """The oracle's headline over each deployable controller's."""
        return {name: self.oracle / value for name, value in self.others.items()}

    @property
    def causal_ratios(self) -> dict[str, float]:
        """The causal oracle's headline over each deployable controller's."""
        return {name: self.causal / value for name, value in self.others.items()}

    def gap_closed(self, name: str) -> float:
        """How much of the way from the PID to the causal limit controller ``name`` goes
        (0: the PID's score, 1: the limit's; below 0: worse than the PID)."""
        pid = self.others["pid"]
        return (pid - self.others[name]) / (pid - self.causal)


def bound_rows(
    tasks: Sequence[str] = tuple(TASKS),
    episodes: int = 20,
    seed: int = 0,
    *,
    progress: Callable[[str], None] | None = None,
) -> list[BoundRow]:
    """Per task, the oracle's headline and every deployable controller's, over the same
    ``episodes`` protocol episodes of the test split (``seed``)."""
    rows = []
    for task in tasks:
        env_id, settings = TASKS[task]
        config = variant_config(env_id, {"split": "test", **settings})
        bank = load_bank(config, None)
        specs = protocol_episodes(config, episodes, seed, bank=bank)
        scores = {}
        for policy in [*deployable(env_id), "oracle", "causal-oracle"]:
            if progress is not None:
                progress(f"{task}: {policy}")
            found = evaluate(config, make_controller(policy, config, env_id), specs, bank=bank)
            scores[policy] = float(np.mean([e[HEADLINE] for e in found.episodes]))
        rows.append(BoundRow(task, scores.pop("oracle"), scores.pop("causal-oracle"), scores))
    return rows
