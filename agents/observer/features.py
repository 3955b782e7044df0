"""The observer's estimate as observation values of a learned policy, and the observer
controller's command as the base of a residual policy."""

from __future__ import annotations

import copy
import math

import numpy as np
from numpy.typing import NDArray

from agents.nominal import NominalModel
from agents.observer.controller import ObserverController, clone, designed_on, scheduling
from agents.observer.estimator import TurbulenceModel
from disturbances.bank import TraceBank
from rollenv.config import RollConfig
from rollenv.layout import Obs


class ObserverFeatures:
    """The observer's estimate as extra observation values for a learned policy, and
    (``residual > 0``) the observer controller's command as the base its action adds to.

    One :class:`RollObserver` per environment, designed on the train split as
    the observer controller is; per step the filter takes the observation (and
    the step the last command made) and yields ``[v̂, ψ̂, û_d]`` (``ψ̂`` is 0 on
    the rate task, where no encoder anchors it).  Used by
    :class:`agents.memory.PolicyObservation` in training and by the learned
    controller when acting, the same code in both.

    With ``residual`` the filters are those of one :class:`ObserverController`
    per environment, and the action a policy chooses is a *residual* (Silver
    et al. 2018, "Residual policy learning"; Johannink et al. 2019): the fin
    command applied is the observer controller's plus ``residual`` × the
    action (both as fractions of the fin's range), clipped to the range
    (:meth:`record` returns it).  A policy whose action is 0 is the observer
    controller, so learning starts from it instead of from nothing.

    In flight (a config with a flight schedule) the filters and the controllers are
    scheduled as :func:`make_observer`'s, designed on the *tunnel's* train traces
    (:meth:`from_bank` takes those) with :data:`FLIGHT_WEIGHTS`; the per-step design
    is made once and shared by the environments.
    """

    SIZE = 3

    def __init__(
        self,
        config: RollConfig,
        rocket: NominalModel,
        turbulence: TurbulenceModel,
        n: int,
        residual: float = 0.0,
    ):
        if not (math.isfinite(residual) and 0.0 <= residual <= 1.0):
            raise ValueError(f"residual must be a number in [0, 1], got {residual!r}")
        self._range = config.fin_range_deg
        self._angle = config.task == "angle"
        self.residual = float(residual)
        self.controllers: list[ObserverController] = []
        # One design (in flight: one per control step), copied: each env its own filter.
        first = ObserverController(config, rocket, turbulence, **scheduling(config))
        if residual:
            self.controllers = [first] + [clone(first) for _ in range(n - 1)]
            self.filters = [c.observer for c in self.controllers]
        else:
            self.filters = [first.observer] + [copy.deepcopy(first.observer) for _ in range(n - 1)]
        self._last: list[tuple[float, float] | None] = [None] * n
        #: The observer controller's command per env for the coming step, fraction of the range.
        self.base = np.zeros(n)

    @classmethod
    def from_bank(
        cls, config: RollConfig, train_bank: TraceBank, n: int, residual: float = 0.0
    ) -> ObserverFeatures:
        """Designed on ``train_bank`` (the *train* split; in flight, its tunnel traces:
        :func:`agents.base.design_bank`), for ``n`` environments."""
        return cls(config, *designed_on(train_bank, config), n, residual)

    def clear(self, i: int | None = None) -> None:
        """A new episode for env ``i`` (all by default)."""
        for k in range(len(self.filters)) if i is None else (i,):
            self.filters[k].reset()
            self._last[k] = None

    def one(self, i: int, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        """Env ``i``'s filter takes ``obs``; its features (and, residual, the base command)."""
        f = self.filters[i]
        last = self._last[i]
        if last is not None:
            f.predict(*last)
        f.update(obs)
        if self.controllers:
            controller = self.controllers[i]
            state, shift = controller.state_of(obs)
            controller.follow_schedule()
            self.base[i] = controller.fin_command(state, shift, float(obs[Obs.FIN])) / self._range
        now = f.present(float(obs[Obs.FIN]))
        psi = float(now[1]) if self._angle else 0.0
        return np.array([now[0], psi, f.u_d], dtype=np.float32)

    def record(self, obs: NDArray[np.float32], actions: NDArray[np.float32]) -> NDArray[np.float32]:
        """The step each env is about to take, from the policy's ``actions``: the fin it
        starts from and the command applied, which is returned (the actions themselves,
        clipped to [-1, 1], or with ``residual`` the base command plus the residual)."""
        actions = np.clip(np.asarray(actions, dtype=np.float64).reshape(len(self.filters)), -1, 1)
        if self.controllers:
            actions = np.clip(self.base + self.residual * actions, -1.0, 1.0)
        for i in range(len(self.filters)):
            self._last[i] = (float(obs[i, Obs.FIN]), float(actions[i]) * self._range)
        return actions.astype(np.float32).reshape(-1, 1)
