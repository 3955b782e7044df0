"""One episode's history: the type rendering and evaluation share.

:class:`EpisodeHistory` holds one row per control step (row 0: just after
``reset``) of the true state, the command, ``u_d``, the setpoint, the true
tracking error and the reward.  :class:`HistoryRecorder` fills it from a
:class:`~rollenv.core.RollBatch`; the environment keeps one when it renders
(a frame shows its last seconds), the evaluation protocol one per episode
(its metrics and plots read it).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rollenv.core import RollBatch
from rollenv.layout import State

__all__ = ["EpisodeHistory", "HistoryRecorder"]

_TASKS = ("angle", "rate")


class _Col(IntEnum):
    """Columns of the recorder's buffer; the order of :class:`EpisodeHistory`'s arrays."""

    TIME = 0
    ANGLE = 1
    RATE = 2
    FIN = 3
    COMMAND = 4
    U_D = 5
    SETPOINT = 6
    ERROR = 7
    REWARD = 8


@dataclass(frozen=True, eq=False)
class EpisodeHistory:
    """An episode (or its last part), one sample per control step, oldest first.

    The arrays are 1-D floats of one length ≥ 1 (converted on construction).

    Attributes
    ----------
    time_s : numpy.ndarray
        Episode time of each sample, s.
    angle_deg : numpy.ndarray
        True roll angle, ° (unwrapped, may exceed 360°).
    rate_dps : numpy.ndarray
        True roll rate, °/s.
    fin_deg : numpy.ndarray
        Actual fin deflection, ° (within ±``fin_range_deg``).
    command_deg : numpy.ndarray
        Fin command, °.
    u_d_deg : numpy.ndarray
        Turbulence as an equivalent fin angle, °.
    setpoint : numpy.ndarray
        Setpoint: roll angle in ° (task ``"angle"``) or roll rate in °/s (``"rate"``).
    error : numpy.ndarray
        True tracking error (° wrapped to ±180°, or °/s).
    reward : numpy.ndarray
        Reward of the step that led to each sample (0 at reset).
    task : str
        ``"angle"`` or ``"rate"``.
    fin_range_deg : float
        Fin deflection limit, °.
    label : str
        Short text shown small in a rendered frame (the trace uid and split).

    Raises
    ------
    ValueError
        If the arrays are not 1-D of one length ≥ 1, the task is unknown or
        the fin range is not positive.
    """

    time_s: NDArray[Any]
    angle_deg: NDArray[Any]
    rate_dps: NDArray[Any]
    fin_deg: NDArray[Any]
    command_deg: NDArray[Any]
    u_d_deg: NDArray[Any]
    setpoint: NDArray[Any]
    error: NDArray[Any]
    reward: NDArray[Any]
    task: str
    fin_range_deg: float = 40.0
    label: str = ""

    def __post_init__(self) -> None:
        lengths = set()
        for name in _ARRAYS:
            value = np.asarray(getattr(self, name), dtype=float)
            if value.ndim != 1:
                raise ValueError(f"EpisodeHistory.{name} must be 1-D, got shape {value.shape}")
            lengths.add(value.size)
            object.__setattr__(self, name, value)
        if len(lengths) != 1 or 0 in lengths:
            sizes = {name: getattr(self, name).size for name in _ARRAYS}
            raise ValueError(f"EpisodeHistory arrays must have one length >= 1, got {sizes}")
        if self.task not in _TASKS:
            raise ValueError(f"EpisodeHistory.task must be one of {_TASKS}, got {self.task!r}")
        if not self.fin_range_deg > 0.0:
            raise ValueError(f"EpisodeHistory.fin_range_deg must be > 0, got {self.fin_range_deg}")

    def __len__(self) -> int:
        return int(self.time_s.size)

    def tail(self, samples: int) -> EpisodeHistory:
        """The last ``samples`` samples (all of them if there are fewer)."""
        if samples >= len(self):
            return self
        cut = slice(len(self) - max(samples, 1), None)
        arrays = {name: getattr(self, name)[cut] for name in _ARRAYS}
        return EpisodeHistory(
            **arrays, task=self.task, fin_range_deg=self.fin_range_deg, label=self.label
        )

    def __repr__(self) -> str:
        return (
            f"EpisodeHistory(task={self.task!r}, samples={len(self)}, "
            f"time_s={self.time_s[0]:.2f}..{self.time_s[-1]:.2f}, "
            f"fin_range_deg={self.fin_range_deg}, label={self.label!r})"
        )


#: The array fields, in :class:`_Col` order.
_ARRAYS = tuple(f.name for f in fields(EpisodeHistory))[: len(_Col)]


class HistoryRecorder:
    """Records one env of a batch, sample by sample, into an :class:`EpisodeHistory`.

    Parameters
    ----------
    capacity : int
        Samples one episode has (``max_episode_steps + 1``); the buffer never
        grows.
    """

    def __init__(self, capacity: int) -> None:
        self._rows = np.zeros((max(int(capacity), 1), len(_Col)))
        self._n = 0

    def clear(self) -> None:
        """Forget the episode."""
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def record(self, batch: RollBatch, i: int, reward: float = 0.0) -> None:
        """Append env ``i``'s state as it is now (``reward``: of the step that led here)."""
        if self._n >= self._rows.shape[0]:
            raise RuntimeError(f"the episode has more than {self._rows.shape[0]} samples")
        row = self._rows[self._n]
        state = batch.state[i]
        row[_Col.TIME] = float(batch.step_count[i]) * batch.config.dt_s
        row[_Col.ANGLE] = state[State.ANGLE]
        row[_Col.RATE] = state[State.RATE]
        row[_Col.FIN] = state[State.FIN]
        row[_Col.COMMAND] = state[State.COMMAND]
        row[_Col.U_D] = batch.u_now[i]
        row[_Col.SETPOINT] = batch.setpoint_of(i)
        row[_Col.ERROR] = batch.error[i]
        row[_Col.REWARD] = reward
        self._n += 1

    def history(self, task: str, fin_range_deg: float, label: str = "") -> EpisodeHistory:
        """What was recorded (copies), as an :class:`EpisodeHistory`."""
        if self._n == 0:
            raise RuntimeError("nothing recorded yet: call reset() first")
        columns = self._rows[: self._n].T.copy()
        arrays = {name: columns[col] for name, col in zip(_ARRAYS, _Col, strict=True)}
        return EpisodeHistory(**arrays, task=task, fin_range_deg=fin_range_deg, label=label)
