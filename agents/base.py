"""What every controller the evaluation protocol runs looks like."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from rollenv.env import RocketRollEnv

__all__ = ["Controller"]


class Controller(Protocol):
    """A roll controller for one :class:`rollenv.env.RocketRollEnv` episode at a time.

    The evaluation protocol calls :meth:`reset` after each ``env.reset`` and
    :meth:`act` with every observation.  A deployable controller uses the
    observation only; ``env`` is passed so that the oracle can read what no
    flight computer has (the true state, the future ``u_d``).
    """

    #: Short name for tables and plots ("PID", "PPO", ...).
    name: str

    def reset(self, env: RocketRollEnv) -> None:
        """Forget the last episode (integrators, filters); ``env`` has just been reset."""

    def act(self, obs: NDArray[np.float32], env: RocketRollEnv) -> NDArray[np.float32]:
        """The action, shape (1,) in [-1, 1], for observation ``obs``."""
        ...
