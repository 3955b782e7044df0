"""Model-predictive control on the observer's estimate (``--policy mpc[:HORIZON]``).

The observer-based controller of :mod:`agents.observer` with its LQR replaced
by a constrained finite-horizon plan, solved every control step by OSQP:

* *Model*: the observer's design model (:meth:`ObserverController.design_model`:
  the maximum-likelihood method's transition at trim, the fin as a state, the
  turbulence's AR model and offset inside).  Predicting it forward from the
  filter's estimate *is* the ``u_d`` forecast: the AR recursion carries the
  estimated lags into the coming steps.
* *Cost*: the LQR's stage cost over ``HORIZON`` steps plus the LQR's own
  Riccati matrix as the terminal cost, so where no constraint binds the first
  move is the LQR's (a test checks this) and the plan only differs where the
  limits matter.
* *Constraints*: what the servo can do -- the command within ±``fin_range_deg``
  and each step's move within ``rate_limit_dps · dt`` of the fin (the first
  from the fin the observation reports).  The LQR meets them by clipping; the
  plan knows them in advance (a slew is ended before the fin hits the stop,
  a large correction is spread over the steps the servo needs).
* *Solver*: the condensed QP (the moves the only variables, ``HORIZON`` of
  them) is set up once; each step updates its linear term and bounds and
  warm-starts from the last plan -- from that plan's primal and dual
  solution and OSQP's initial step size, set explicitly, unscaled and with
  the step size adapted every 25 iterations, so that a plan depends on the
  episode so far and nothing else (not on the episodes before it, the clock,
  or whether the controller was pickled on the way).
  ``benchmarks/mpc_speed.py`` measures the time per step against the 10-ms
  budget and the LQR in the same run.
* *On the rig* (a servo lag, play, late sensors): the observer's design
  (:mod:`agents.observer`): the lag's drive one more state of the plan, which
  starts from where the servo stands; the plan's first command sent through
  the play.
* *In flight* (``scheduled``, as the observer controller): the plan predicts
  with each coming step's model -- the nominal rocket carried to that step's
  airspeed and density, the turbulence flown -- and ends on that step's
  Riccati matrix; the condensed QP of each control step is built once per
  controller (the nominal flight is the same every episode) and swapped in
  (OSQP's ``Px`` update) as the flight goes on.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from agents.base import Design, FlightView
from agents.nominal import NominalModel
from agents.observer import ObserverController, TurbulenceModel, designed_on, scheduling
from rollenv.config import RollConfig

__all__ = ["DEFAULT_HORIZON", "MAX_HORIZON", "MPCController", "check_horizon", "make_mpc"]

FloatArray = NDArray[np.float64]

#: Steps planned ahead (0.1 s each).  ``rocketroll eval --policy mpc:10 --policy mpc
#: --policy mpc:40`` (20 test episodes, seed 0) printed the same table rows to their last
#: digit on both tasks: with the Riccati terminal cost the horizon only has to see the
#: limits coming, and 20 covers the servo's full swing (80° at 15° a step) with room.
DEFAULT_HORIZON = 20
#: Longest horizon, steps (10 s): its condensed QP is MAX_HORIZON² and each control step
#: solves it -- 600 steps took over 30 s an episode, 100 000 asked for 522 GiB.
MAX_HORIZON = 100

#: A planned command closer than this to a limit is set on it, °.
_SNAP_DEG = 1e-3
#: OSQP's ADMM step size at the start of every solve (its default; adaptive within one).
_RHO = 0.1


class MPCController(ObserverController):
    """Constrained receding-horizon control on the observer's estimate (module docstring)."""

    name = "MPC"
    #: The Hessian's upper-triangle entries, row and column, in the solver's order.
    _p_rows: NDArray[np.intp]
    _p_cols: NDArray[np.intp]
    #: The control step whose QP the solver holds.
    _step: int
    _qp: Any

    def __init__(
        self,
        config: RollConfig,
        rocket: NominalModel,
        turbulence: TurbulenceModel,
        weights: dict[str, float] | None = None,
        horizon: int = DEFAULT_HORIZON,
        *,
        scheduled: bool = False,
    ) -> None:
        if not 1 <= horizon <= MAX_HORIZON:
            raise ValueError(f"the MPC's horizon must be 1 to {MAX_HORIZON} steps, got {horizon}")
        self.horizon = horizon
        super().__init__(config, rocket, turbulence, weights, scheduled=scheduled)
        self.name = "MPC" if horizon == DEFAULT_HORIZON else f"MPC N={horizon}"
        self._step_max = config.rate_limit_dps * config.dt_s
        #: In flight: each control step's condensed QP (Hessian, linear map) and its
        #: model ``(A, B)``, built once.
        self._by_step: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._step_models: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._condense()
        #: The last plan's primal and dual solution, where the next solve starts (None:
        #: from zero, as at an episode's start).
        self._warm: tuple[FloatArray, FloatArray] | None = None
        self.solves = 0
        self.fallbacks = 0

    def reset(self, env: FlightView | None = None) -> None:
        """A new episode: the observer back to its prior, the plan from zero."""
        super().reset(env)
        self._warm = None

    def _horizon_models(
        self, step: int | None
    ) -> tuple[list[tuple[FloatArray, FloatArray]], FloatArray, FloatArray, FloatArray, FloatArray]:
        """The ``(A, B)`` of each planned step from control ``step`` (the nominal design's
        when None or unscheduled), the stage cost ``Q, R, S`` and the terminal matrix."""
        a, b, q, r, s = self.design_model()
        if step is None or self.schedule is None:
            return [(a, b)] * self.horizon, q, r, s, self.riccati
        last = len(self.rockets) - 1
        models = []
        for k in (min(j, last) for j in range(step, step + self.horizon)):
            if k not in self._step_models:  # each step's model serves HORIZON plans
                self._step_models[k] = self.design_model(self.rockets[k], k)[:2]
            models.append(self._step_models[k])
        return models, q, r, s, self.riccati_schedule[min(step + self.horizon, last)]

    def _condensed(self, step: int | None) -> tuple[FloatArray, FloatArray]:
        """The QP ``min ½U'PU + q'U`` over the moves ``U`` planned from control ``step``:
        its Hessian ``P`` and the map ``F`` of ``q = F x₀``."""
        models, q, r, s, p_end = self._horizon_models(step)
        n, horizon = q.shape[0], self.horizon
        # X = [x_1 .. x_N] = Φ x0 + Γ U, with x_{k+1} = A_k x_k + B_k u_k
        phi = np.zeros((horizon * n, n))
        gamma = np.zeros((horizon * n, horizon))
        power = np.eye(n)
        for k, (a, b) in enumerate(models):
            power = a @ power
            phi[k * n : (k + 1) * n] = power
            if k:
                gamma[k * n : (k + 1) * n, :k] = a @ gamma[(k - 1) * n : k * n, :k]
            gamma[k * n : (k + 1) * n, k] = b[:, 0]
        q_bar = sparse.block_diag([q] * (horizon - 1) + [p_end]).toarray()
        # cross terms 2 x_k' S u_k for k = 1 .. N-1 (x_k is X's block k-1); k = 0 goes to F
        s_bar = np.zeros((horizon * n, horizon))
        for k in range(1, horizon):
            s_bar[(k - 1) * n : k * n, k] = s[:, 0]
        hessian = gamma.T @ q_bar @ gamma + r[0, 0] * np.eye(horizon)
        hessian += gamma.T @ s_bar + s_bar.T @ gamma
        hessian = 0.5 * (hessian + hessian.T)
        linear = gamma.T @ q_bar @ phi + s_bar.T @ phi
        linear[0] += s[:, 0]
        return hessian, 2.0 * linear

    def _use_step(self, step: int) -> None:
        """In flight: the QP of control ``step`` into the solver."""
        if step == self._step:
            return
        if step not in self._by_step:
            self._by_step[step] = self._condensed(step)
        hessian, self._linear = self._by_step[step]
        self._qp.update(Px=2.0 * hessian[self._p_rows, self._p_cols])
        self._step = step

    def _condense(self) -> None:
        """Set up the solver on the nominal design's QP (control step 0's in flight)."""
        import osqp

        horizon = self.horizon
        hessian, self._linear = self._condensed(None if self.schedule is None else 0)
        self._step = 0
        # The upper triangle, every entry kept (a flight swaps in Hessians of this pattern).
        pattern = sparse.triu(np.ones((horizon, horizon)), format="csc")
        self._p_rows = pattern.indices.copy()
        self._p_cols = np.repeat(np.arange(horizon), np.diff(pattern.indptr))
        upper = sparse.csc_matrix(
            (2.0 * hessian[self._p_rows, self._p_cols], pattern.indices, pattern.indptr),
            shape=(horizon, horizon),
        )
        # constraints: the commands' range, then each step's move (the first from the fin)
        difference = sparse.eye(horizon) - sparse.eye(horizon, k=-1)
        constraints = sparse.vstack([sparse.eye(horizon), difference], format="csc")
        self._lower = np.full(2 * horizon, -np.inf)
        self._upper = np.full(2 * horizon, np.inf)
        self._lower[horizon:] = -self._step_max
        self._upper[horizon:] = self._step_max
        #: OSQP's statuses of a usable plan (max-iterations, infeasible ... are not).
        done = (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
        self._solved = {int(status.value) for status in done}
        self._qp = osqp.OSQP()
        self._qp.setup(
            upper,
            np.zeros(horizon),
            constraints,
            self._lower,
            self._upper,
            verbose=False,
            warm_starting=True,
            rho=_RHO,
            # Every 25 iterations: OSQP's default (0) times its own setup and adapts when
            # that share of the time has passed -- a plan that depends on the clock.
            adaptive_rho_interval=25,
            # Unscaled: OSQP re-equilibrates the problem at each Hessian update (a flight's
            # every step) from the data it holds then, the last step's linear term too.
            scaling=0,
            polishing=False,
            eps_abs=1e-6,
            eps_rel=1e-6,
            max_iter=4000,
        )

    def plan(self, state: FloatArray, shift: float, fin: float) -> FloatArray:
        """The planned commands (design input ``u``, ``command = u - shift``) from ``state``."""
        horizon = self.horizon
        if self.schedule is not None:
            self._use_step(self.schedule_step)
        x0 = state[self.design_states]
        lo, hi = -self._range + shift, self._range + shift
        self._lower[:horizon], self._upper[:horizon] = lo, hi
        start = fin + shift  # the servo in design coordinates (the fin without a linkage)
        self._lower[horizon] = start - self._step_max
        self._upper[horizon] = start + self._step_max
        self._qp.update(q=self._linear @ x0, l=self._lower, u=self._upper)
        if self._warm is None:
            self._qp.warm_start(x=np.zeros(horizon), y=np.zeros(2 * horizon))
        else:
            self._qp.warm_start(x=self._warm[0], y=self._warm[1])
        self._qp.update_settings(rho=_RHO)  # not the last solve's adapted step size
        result: Any = self._qp.solve(raise_error=False)
        self.solves += 1
        solved = result.info.status_val in self._solved
        if not solved or result.x is None or not np.all(np.isfinite(result.x)):
            # not solved (never seen on the protocol: every solve of the four variants'
            # 20 test episodes is OSQP_SOLVED): the LQR's move within the limits
            self.fallbacks += 1
            self._warm = None
            u0 = float(self.gain @ state)
            return np.full(horizon, min(max(u0, lo), hi))
        self._warm = (np.array(result.x, dtype=float), np.array(result.y, dtype=float))
        return np.asarray(result.x, dtype=float)

    def command(self, state: FloatArray, shift: float, fin: float) -> float:
        """The plan's first command, within the fin's range.

        OSQP's ADMM meets an active bound to within its tolerance (1e-6
        relative): a command that close to the range or to the servo's step is
        set on it, as an active-set polish would."""
        command = float(self.plan(state, shift, fin)[0]) - shift
        for edge in (fin - self._step_max, fin + self._step_max, -self._range, self._range):
            if abs(command - edge) < _SNAP_DEG:
                command = edge
        return min(max(command, -self._range), self._range)

    def __getstate__(self) -> dict[str, Any]:  # OSQP's solver does not pickle: rebuilt
        state = self.__dict__.copy()
        state.pop("_qp", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._condense()
        if self.schedule is not None:
            self._use_step(self.schedule_step)


def check_horizon(policy: str, arg: str | None, env_id: str = "") -> int:
    """``HORIZON`` of ``--policy mpc:HORIZON`` (:data:`DEFAULT_HORIZON` when not given);
    ``ValueError`` naming the value if it is not a whole number of steps from 1 to
    :data:`MAX_HORIZON`.  The registry's check, before any design."""
    if not arg:
        return DEFAULT_HORIZON
    try:
        horizon = int(arg)
    except ValueError:
        raise ValueError(
            f"--policy {policy}:HORIZON needs a whole number of steps, got {arg!r}"
        ) from None
    if not 1 <= horizon <= MAX_HORIZON:
        raise ValueError(
            f"--policy {policy}:HORIZON must be 1 to {MAX_HORIZON} steps "
            f"({MAX_HORIZON / 10:g} s ahead), got {horizon}"
        )
    return horizon


def make_mpc(design: Design) -> MPCController:
    """``--policy mpc[:HORIZON]``: the observer's design, planned over HORIZON steps
    (in flight scheduled as the observer controller is, :func:`agents.observer.make_observer`)."""
    horizon = check_horizon("mpc", design.arg)
    nominal, turbulence = designed_on(design.design_bank, design.config)
    return MPCController(
        design.config, nominal, turbulence, horizon=horizon, **scheduling(design.config)
    )
