"""What every controller looks like, what designing one may use, and what evaluating gives.

* :class:`Controller` -- what the evaluation protocol runs;
* :class:`Design` -- what a controller factory (:mod:`agents.registry`) gets:
  the environment's settings and id, an argument, and the *train* split;
* :class:`EpisodeSpec`, :class:`Evaluation` -- a protocol episode and a
  controller's result (:mod:`agents.evaluate`, :mod:`agents.plots`).

Every other module of this package imports from here; this module imports no
other module of it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from rollenv.config import RollConfig
from rollenv.env import RocketRollEnv
from rollenv.history import EpisodeHistory

if TYPE_CHECKING:
    from disturbances.bank import TraceBank

__all__ = ["Controller", "Design", "EpisodeSpec", "Evaluation", "FlightView", "design_bank"]


class FlightView:
    """What a flight computer has of the environment, and nothing else.

    A deployable controller gets this in place of the environment: the
    observation and action spaces, the control period and the environment's
    configuration (its own sensors, servo and task).  Any other attribute --
    the true state, the rocket, the ``u_d`` trace, ``unwrapped`` -- raises
    ``AttributeError`` saying so, so nothing a real rocket would not tell its
    controller can leak into one.
    """

    __slots__ = ("action_space", "config", "observation_space")

    def __init__(self, env: RocketRollEnv) -> None:
        self.config: RollConfig = env.config
        self.observation_space = env.observation_space
        self.action_space = env.action_space

    @property
    def dt_s(self) -> float:
        """The control period, s."""
        return self.config.dt_s

    def __getattr__(self, name: str) -> Any:
        raise AttributeError(
            f"a flight computer has no {name!r}: a deployable controller sees the observation, "
            f"the spaces, the control period and the configuration only"
        )

    def __repr__(self) -> str:
        return f"FlightView(task={self.config.task!r}, dt_s={self.dt_s:g})"


class Controller(Protocol):
    """A roll controller for one :class:`rollenv.env.RocketRollEnv` episode at a time.

    The evaluation protocol calls :meth:`reset` after each ``env.reset`` and
    :meth:`act` with every observation.  A deployable controller gets a
    :class:`FlightView` as ``env``: the observation and its own configuration
    are all it can use.  Only a controller whose class sets
    ``sees_truth = True`` (the oracle, a bound) gets the environment itself,
    to read what no flight computer has (the true state, the future ``u_d``).
    """

    #: Short name for tables and plots ("PID", "PPO", ...).
    name: str

    def reset(self, env: Any) -> None:
        """Forget the last episode (integrators, filters); ``env`` has just been reset."""

    def act(self, obs: NDArray[np.float32], env: Any) -> NDArray[np.float32]:
        """The action, shape (1,) in [-1, 1], for observation ``obs``."""
        ...


def train_bank(config: RollConfig, db: str | os.PathLike[str] | None) -> TraceBank:
    """The traces of the *train* split for ``config``, from ``db``: what a design may look
    at (never the test split the protocol evaluates on).  Where one recording is replayed
    and the train split holds a part of it (``rocketroll db add --holdout``: the run
    before its held-out end) that part, so the design is of that rocket; else all of the
    train split."""
    from rollenv.bank import find_bank, load_bank

    if config.recording is not None:
        part = find_bank(replace(config, split="train"), db)
        if part is not None:
            return part
    # no part of it to design on: the train split's rockets
    return load_bank(replace(config, split="train", recording=None), db)


def design_bank(config: RollConfig, db: str | os.PathLike[str] | None) -> TraceBank:
    """The train split's tunnel traces for ``config`` (:func:`train_bank`; in flight, the
    tunnel traces its flights fly: :mod:`disturbances.flight`), from ``db``."""
    return train_bank(replace(config, flight=None), db)


@dataclass
class Design:
    """What a controller factory gets (``--policy NAME[:ARG]``).

    Attributes
    ----------
    config : RollConfig
        The environment's settings (task, sensors, servo, ...).
    env_id : str
        The environment id (``RocketRoll-v0``, ...).
    arg : str or None
        The text after ``NAME:`` in ``--policy NAME:ARG``.
    db : str or None
        The database the protocol uses (None: the default one).
    """

    config: RollConfig
    env_id: str
    arg: str | None = None
    db: str | None = None

    @cached_property
    def train_bank(self) -> TraceBank:
        """:func:`train_bank` of the environment's configuration."""
        return train_bank(self.config, self.db)

    @cached_property
    def design_bank(self) -> TraceBank:
        """What a model-based design models the rocket and turbulence on: :attr:`train_bank`,
        and in flight (where that holds flights) the train split's tunnel traces
        (:func:`design_bank`), flown by the design itself."""
        if self.config.flight_schedule is None:
            return self.train_bank
        return design_bank(self.config, self.db)

    def no_argument(self, name: str) -> None:
        """Refuse an argument for a controller that takes none."""
        if self.arg:
            raise ValueError(f"--policy {name} takes no argument, got {name}:{self.arg}")


@dataclass(frozen=True)
class EpisodeSpec:
    """One protocol episode: the reset seed and the options that fix its draw."""

    index: int
    seed: int
    trace: str
    start: int
    setpoints: tuple[float, ...]

    def options(self) -> dict[str, Any]:
        """``reset(options=...)`` for this episode."""
        return {"trace": self.trace, "start": self.start, "setpoints": list(self.setpoints)}


@dataclass
class Evaluation:
    """A controller's protocol result."""

    name: str
    episodes: list[dict[str, float]]
    aggregate: dict[str, dict[str, float]]
    rollouts: list[EpisodeHistory] = field(repr=False)
    seconds: float = 0.0
