"""The true rocket outside the model in closed loop, for the benchmarks.

:class:`ReferenceRollEnv` is ``RocketRoll-v0`` (or its rate task) whose rocket
is integrated by :mod:`identification.instruments.reference` -- the independent Runge-Kutta
integrator, with the servo lag, backlash, sensor latency and quadratic damping
of an :class:`~identification.instruments.reference.Effects` -- instead of the
environment's exact kernel; its sensors (encoder, gyro noise with the same
draws), observation and reward are the environment's.  With no effects it scores
what the environment scores (``tests/test_benchmarks.py``), so a replay's score
against it measures the replay, not a second kernel's bug.  Benchmarks and
tests only: the environments the controllers are designed and trained on stay
the one kernel.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any, SupportsFloat

import numpy as np

from disturbances.bank import TraceBank
from identification.instruments.reference import Effects, advance, fine_steps
from identification.model import RollParams
from rollenv.config import RollConfig
from rollenv.core import observe_kernel, step_reward
from rollenv.env import RocketRollEnv
from rollenv.layout import Cfg, Cursor, State

__all__ = ["ReferenceRollEnv"]


class ReferenceRollEnv(RocketRollEnv):
    """``config``'s environment on ``bank`` (one rocket and its ``u_d``), the rocket
    integrated by the reference integrator with ``effects``."""

    def __init__(self, config: RollConfig, bank: TraceBank, effects: Effects) -> None:
        if config.flight is not None or config.angle_sensor != "encoder":
            raise ValueError("the reference env flies the tunnel's rocket with its encoder")
        if config.domain_randomization:
            raise ValueError("the reference env flies the bank's own rocket")
        settings = {f.name: getattr(config, f.name) for f in fields(config)}
        super().__init__(bank=bank, **settings)
        self.effects = effects
        cfg = self._batch.cfg
        self._sub = int(cfg[Cfg.SUBSTEPS])
        self._per, self._h = fine_steps(float(cfg[Cfg.H]))  # the reference's 1-ms steps
        self._delay = effects.latency_s / self._h  # in fine steps
        self._keep = math.ceil(self._delay) + 2
        self._state = np.zeros(5)
        self._past_rate = np.zeros(self._keep)
        self._past_angle = np.zeros(self._keep)

    def _rocket(self) -> RollParams:
        return self._batch.roll_params(0)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = super().reset(seed=seed, options=options)
        state = self._batch.state[0]
        fin, rate, angle = state[State.FIN], state[State.RATE], state[State.ANGLE]
        self._state[:] = (fin, fin, fin, rate, angle)
        self._past_rate[:] = rate  # before the episode the rocket was as it starts
        self._past_angle[:] = angle
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        b = self._batch
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if b.step_count[0] >= self._max_steps:
            raise RuntimeError("the episode ended; call reset()")
        cfg = b.cfg
        a = float(np.clip(np.asarray(action, dtype=float).reshape(-1)[0], -1.0, 1.0))
        fin_range = float(cfg[Cfg.FIN_RANGE])
        command = min(max(a * fin_range, -fin_range), fin_range)
        eps = b._gyro_draws(self.np_random, 1)  # the same draws as the environment's
        step = int(b.step_count[0])
        per_u = int(cfg[Cfg.U_PER])
        first = step * self._sub
        samples = b.u_flat[b.u_start[0] + (first + np.arange(self._sub)) // per_u]
        u = float(cfg[Cfg.U_SCALE]) * np.repeat(samples, self._per)
        before = self._state[2]
        rate, angle = advance(
            self._state, self._rocket(), self.effects, command, u, self._h,
            rate_limit_dps=float(cfg[Cfg.MAX_MOVE]) / float(cfg[Cfg.H]), fin_range_deg=fin_range,
        )  # fmt: skip
        # What the sensors read: the rocket ``latency`` ago, from the fine trajectory.
        self._past_rate = np.concatenate([self._past_rate, rate[1:]])[-(self._keep + rate.size) :]
        self._past_angle = np.concatenate([self._past_angle, angle[1:]])[
            -(self._keep + angle.size) :
        ]
        at = self._past_rate.size - 1 - self._delay
        grid = np.arange(self._past_rate.size, dtype=float)
        seen_rate = float(np.interp(at, grid, self._past_rate))
        seen_angle = float(np.interp(at, grid, self._past_angle))
        true_rate, true_angle, fin = self._state[3], self._state[4], self._state[2]
        b.cursor[0, Cursor.STEP] = step + 1
        b.u_now[0] = u[-1]
        state = b.state
        state[0, State.FIN] = fin
        state[0, State.COMMAND] = command
        # The true error (the env's own), then what the sensors read a latency late.
        state[0, State.RATE], state[0, State.ANGLE] = true_rate, true_angle
        observe_kernel(b.all, state, b.cursor, b.setpoints, eps, cfg, b.obs, b.error)
        error = float(b.error[0])
        state[0, State.RATE], state[0, State.ANGLE] = seen_rate, seen_angle
        observe_kernel(b.all, state, b.cursor, b.setpoints, eps, cfg, b.obs, b.error)
        state[0, State.RATE], state[0, State.ANGLE] = true_rate, true_angle
        b.error[0] = error
        reward = step_reward(error, true_rate, abs(fin - before), cfg)
        b.reward[0] = reward
        truncated = bool(b.step_count[0] >= self._max_steps)
        return b.obs[0].copy(), float(reward), False, truncated, self._info()
