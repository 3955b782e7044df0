"""The pure core shared by :class:`~rollenv.env.RocketRollEnv` and the vector envs.

Two layers, as in Gymnasium's ``phys2d`` and gymnax:

* :class:`~rollenv.config.RollConfig` -- a frozen dataclass of every setting (task,
  timing, servo, sensors, disturbance, reward), validated once (:mod:`rollenv.config`).
* :func:`step_kernel` / :func:`observe_kernel` -- compiled (numba) functions
  of plain arrays that advance any number of environments by one control
  step and compute what their sensors read.  They hold no state and draw no
  random numbers: the caller passes the Gaussian draws in, so every source
  of randomness stays in the environment's ``np_random``.

:class:`RollBatch` is the state of a batch (arrays of length ``n``) with
``reset`` and ``step``; the single environment is a batch of one, the vector
environment a batch of ``num_envs``, and the Stable-Baselines3 adapter of the
agents layer another thin shell over it.

Physics
-------
Each control step of ``dt_s`` (0.1 s) is ``dt_s / substep_s`` substeps of the
paper's δt = 0.01 s.  The fin command is held over the control step; on each
substep the servo moves the fin toward it by at most ``rate_limit·δt``
(eq. 23) within ±``range``, and the fin is linear within the substep -- the
fin-angle model of identification step 5 on its fine grid.  Over a substep
the roll model (eq. 36/49) is advanced by the exact update of
:func:`identification.model.piece_coefficients`, the one closed form of the
project, compiled by numba (:mod:`identification.compiled`): ``u_d`` is held on
its own grid, ``a(θ)`` is taken at the substep's mean fin angle.  Consecutive
substeps with the fin at rest and the same ``u_d`` are merged into one piece,
which is exact.  This is
the computation of the identification's re-simulation (step 9), so a replay
reproduces it to rounding.
"""

from __future__ import annotations

import math
import types
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from disturbances.bank import TraceBank
from identification.compiled import linkage, piece
from identification.model import (
    QUADRATIC_FLOOR,
    QUADRATIC_RATE_DPS,
    RollParams,
    quadratic_steady_rate,
)
from rollenv.config import RollConfig
from rollenv.layout import (
    OBSERVATION_NAMES,
    Cfg,
    Cursor,
    Link,
    Obs,
    Param,
    Scale,
    State,
    params_of_row,
    row_of_params,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = [
    "OBSERVATION_NAMES",  # re-exported from rollenv.layout
    "RollBatch",
    "step_reward",
    "wrap_deg",
]


# ----------------------------------------------------------------------------- kernels
_piece = piece  # the one closed form, compiled (identification.compiled)
#: The column of ``RollBatch.rig`` where an env's ring of past substeps starts.
_RING = len(Link)
_linkage = linkage  # the one servo linkage, compiled (identification.compiled)


@numba.njit(cache=True, nogil=True, inline="always")
def _roll(
    v: float,
    phi: float,
    alpha: float,
    theta_bar: float,
    beta_bar: float,
    alpha_bar: float,
    quadratic: float,
    theta0: float,
    theta1: float,
    u: float,
    h: float,
    held: int,
) -> tuple[float, float]:
    """The rate and angle after ``h`` with the fin from ``theta0`` to ``theta1`` and ``u``
    held (``held`` substeps merged into it, or 1).  With a quadratic damping (``quadratic``
    the coefficient over :data:`~identification.model.QUADRATIC_RATE_DPS`) the damping is
    ``a(θ)·(1 + q·|v|/v₀)`` at the start rate (the factor held at or above
    :data:`~identification.model.QUADRATIC_FLOOR`), the gain divided by the same; over a merged
    run of held substeps at the mean of the start's and that step's end's |v| (a second
    pass: the run may be a whole control step).  Without it, the exact linear piece."""
    if quadratic == 0.0:
        e, c, a_, b_ = _piece(alpha, theta_bar, beta_bar, alpha_bar, theta0, theta1, u, h)
        return e * v + c, phi + a_ * v + b_
    grow = max(1.0 + quadratic * abs(v), QUADRATIC_FLOOR)
    e, c, a_, b_ = _piece(
        alpha / grow, theta_bar, beta_bar * grow, alpha_bar * grow, theta0, theta1, u, h
    )
    if held > 1:
        grow = max(1.0 + 0.5 * quadratic * (abs(v) + abs(e * v + c)), QUADRATIC_FLOOR)
        e, c, a_, b_ = _piece(
            alpha / grow, theta_bar, beta_bar * grow, alpha_bar * grow, theta0, theta1, u, h
        )
    return e * v + c, phi + a_ * v + b_


def wrap_deg(angle_deg: Any) -> Any:
    """An angle or angle difference wrapped to [-180°, 180°): the one wrap of the kernel
    (compiled), the observer and the renderer.

    Parameters
    ----------
    angle_deg : float or numpy.ndarray
        Angle, °.

    Returns
    -------
    float or numpy.ndarray
        The same angle in [-180°, 180°), °.

    Examples
    --------
    >>> float(wrap_deg(370.0)), float(wrap_deg(-190.0))
    (10.0, 170.0)
    """
    return angle_deg - 360.0 * np.floor((angle_deg + 180.0) / 360.0)


_wrap = numba.njit(cache=True, nogil=True)(wrap_deg)


@numba.njit(cache=True, nogil=True)
def _gyro(rate: float, eps: float, cfg: FloatArray) -> float:
    """The gyro's reading of ``rate`` (eq. 52's noise with the draw ``eps``, clipped)."""
    gyro = cfg[Cfg.GYRO_RANGE]
    return min(max((1.0 + cfg[Cfg.GYRO_ETA] * eps) * rate, -gyro), gyro)


@numba.njit(cache=True, nogil=True)
def _observe_one(
    i: int,
    state: FloatArray,
    seen_rate: float,
    seen_angle: float,
    setpoint: float,
    eps: float,
    cfg: FloatArray,
    obs: NDArray[np.float32],
) -> float:
    """Sensor readings of env ``i`` into ``obs[i]``, the sensors seeing the roll rate
    ``seen_rate`` and angle ``seen_angle`` (the state's own, or as it was a latency ago);
    returns the true tracking error."""
    rate = state[i, State.RATE]
    angle = state[i, State.ANGLE]
    res = cfg[Cfg.ENCODER_RES]
    measured_angle = seen_angle
    if cfg[Cfg.ANGLE_GYRO] > 0.0:
        measured_angle = state[i, State.GYRO_ANGLE]
    elif res > 0.0:
        measured_angle = math.floor(seen_angle / res + 1e-9) * res
    measured_rate = _gyro(seen_rate, eps, cfg)
    if cfg[Cfg.TASK_RATE] > 0.0:
        error = setpoint - rate
        measured_error = setpoint - measured_rate
    else:
        error = _wrap(setpoint - angle)
        measured_error = _wrap(setpoint - measured_angle)
    emax = cfg[Cfg.ERROR_MAX]
    obs[i, Obs.ERROR] = min(max(measured_error, -emax), emax)
    obs[i, Obs.RATE] = measured_rate
    obs[i, Obs.FIN] = state[i, State.FIN]
    obs[i, Obs.COMMAND] = state[i, State.COMMAND]
    return error


@numba.njit(cache=True, nogil=True)
def observe_kernel(
    index: IntArray,
    state: FloatArray,
    cursor: IntArray,
    setpoints: FloatArray,
    eps: FloatArray,
    cfg: FloatArray,
    obs: NDArray[np.float32],
    error: FloatArray,
) -> None:
    """Observations of the envs in ``index`` (``eps[k]`` is the gyro draw of ``index[k]``),
    the sensors reading the state as it is now."""
    period = int(cfg[Cfg.SETPOINT_PERIOD])
    last = setpoints.shape[1] - 1
    for k in range(index.size):
        i = index[k]
        sp = setpoints[i, min(cursor[i, Cursor.STEP] // period, last)]
        rate, angle = state[i, State.RATE], state[i, State.ANGLE]
        error[i] = _observe_one(i, state, rate, angle, sp, eps[k], cfg, obs)


@numba.njit(cache=True, nogil=True)
def step_reward(error: float, rate: float, travel: float, cfg: FloatArray) -> float:
    """One control step's reward: minus the squared normalised tracking error, the weighted
    squared normalised roll rate and the weighted squared normalised fin travel."""
    e_n = error / cfg[Cfg.ERROR_NORM]
    v_n = rate / cfg[Cfg.RATE_NORM]
    t_n = travel / cfg[Cfg.TRAVEL_NORM]
    return -(e_n * e_n + cfg[Cfg.RATE_WEIGHT] * v_n * v_n + cfg[Cfg.FIN_WEIGHT] * t_n * t_n)


def _step_envs(
    index: IntArray,
    action: FloatArray,
    state: FloatArray,
    cursor: IntArray,
    params: FloatArray,
    scales: FloatArray,
    u_flat: FloatArray,
    setpoints: FloatArray,
    eps: FloatArray,
    cfg: FloatArray,
    obs: NDArray[np.float32],
    reward: FloatArray,
    error: FloatArray,
    u_now: FloatArray,
    rig: FloatArray,
) -> None:
    """Advance the envs in ``index`` by one control step.

    ``action`` holds fin commands in [-1, 1] (already checked and clipped),
    ``state[i]`` env ``i``'s :class:`~rollenv.layout.State`, ``cursor[i]``
    its :class:`~rollenv.layout.Cursor` (step, u_d start, multiplier row and
    stride), ``params[i]`` its rocket (:class:`~rollenv.layout.Param`),
    multiplied over this step by ``scales[start + step·stride]``
    (:class:`~rollenv.layout.Scale`: a stride of 0 holds one row, the
    constant rocket), ``u_flat[u_start + m]`` is env ``i``'s ``m``-th ``u_d``
    sample, ``eps[k]`` the gyro draw for ``index[k]``.  Writes the new state,
    the step plus one, observation, reward, true error and the last ``u_d``.

    ``rig[i]`` is env ``i``'s rig (:class:`~rollenv.layout.Link` columns), then its ring
    of past substeps (two columns each: rate, angle; one array, so a step passes the
    kernel one argument for both: its dispatch costs per argument).  With a linkage
    (a decay or half a play above 0) the servo moves at its rate limit towards the
    command, the fin's drive follows it through the first-order lag (exact for the
    servo's ramp over the substep) and the fin its drive through the play; the fin
    moves linearly over each substep as without.  With a sensor latency the sensors
    read the rocket that many substeps ago, linearly between substeps: the rate and angle
    at the two substep boundaries each step reads (the same two of every step, mod the
    substeps per step) go into the ring (row ``g % rows`` for boundary ``g`` of the
    episode), a run of held substeps applied there (with a quadratic damping, read off the
    run, which goes on whole: the sensors' latency never changes the rocket).
    With a quadratic damping (``Param.QUADRATIC``) the damping is
    ``a(θ)·(1 + q·|v|/QUADRATIC_RATE_DPS)``, the gain divided by the same factor, at each
    moving substep's starting rate and over a held run at the mean of its ends'
    (:func:`_roll`).  All three off, the step is the model's and its arithmetic today's.
    """
    n_sub = int(cfg[Cfg.SUBSTEPS])
    h = cfg[Cfg.H]
    max_move = cfg[Cfg.MAX_MOVE]
    fin_range = cfg[Cfg.FIN_RANGE]
    scale = cfg[Cfg.U_SCALE]
    u_per = int(cfg[Cfg.U_PER])
    period = int(cfg[Cfg.SETPOINT_PERIOD])
    last_sp = setpoints.shape[1] - 1
    rows = (rig.shape[1] - _RING) // 2
    for k in numba.prange(index.size):
        i = index[k]
        decay = rig[i, Link.DECAY]
        ramp = rig[i, Link.RAMP]
        half = rig[i, Link.HALF]
        linked = ramp > 0.0 or half > 0.0
        delay = rig[i, Link.LATENCY]
        late = delay > 0.0
        step = cursor[i, Cursor.STEP]
        row = cursor[i, Cursor.SCALE_START] + step * cursor[i, Cursor.SCALE_STRIDE]
        gain = scales[row, Scale.GAIN]
        damp = scales[row, Scale.DAMPING]
        alpha = params[i, Param.ALPHA] * gain
        theta_bar = params[i, Param.THETA_BAR]
        beta_bar = params[i, Param.BETA_BAR] * damp
        alpha_bar = params[i, Param.ALPHA_BAR] * damp
        quadratic = params[i, Param.QUADRATIC] / QUADRATIC_RATE_DPS
        # With a latency the sensors read the boundaries ``floor(n_sub - delay)`` and the
        # next of every step (mod n_sub): those go into the ring, a held run applied there.
        read_at = math.floor(n_sub - delay) % n_sub
        v = state[i, State.RATE]
        phi = state[i, State.ANGLE]
        theta = state[i, State.FIN]
        previous_theta = theta
        command = min(max(action[i] * fin_range, -fin_range), fin_range)
        first = step * n_sub
        u_index = cursor[i, Cursor.U_START] + first // u_per  # u_d sample of the current substep
        u_phase = first % u_per
        held = 0  # fin-at-rest substeps with the same u_d, not yet applied (merged: exact)
        held_u = 0.0
        u = 0.0
        servo = state[i, State.SERVO]
        drive = state[i, State.DRIVE]
        for sub in range(n_sub):
            u = scale * u_flat[u_index]
            u_phase += 1
            if u_phase == u_per:
                u_phase = 0
                u_index += 1
            if linked:
                servo, drive, moved = _linkage(
                    servo, drive, theta, command, max_move, decay, ramp, half
                )
            else:
                moved = theta + min(max(command - theta, -max_move), max_move)
            if held > 0 and (moved != theta or u != held_u):
                v, phi = _roll(v, phi, alpha, theta_bar, beta_bar, alpha_bar, quadratic,
                               theta, theta, held_u, held * h, held)  # fmt: skip
                held = 0
            if moved == theta:
                held += 1
                held_u = u
            else:
                v, phi = _roll(v, phi, alpha, theta_bar, beta_bar, alpha_bar, quadratic,
                               theta, moved, u, h, 1)  # fmt: skip
                theta = moved
            if late and (sub + 1 - read_at) % n_sub <= 1:  # the roll the sensors will read
                seen_v, seen_phi = v, phi
                if held > 0:  # the held run so far, read off
                    seen_v, seen_phi = _roll(
                        v, phi, alpha, theta_bar, beta_bar, alpha_bar, quadratic,
                        theta, theta, held_u, held * h, held,
                    )  # fmt: skip
                    if quadratic == 0.0:  # a linear run splits exactly: applied here
                        v, phi, held = seen_v, seen_phi, 0
                slot = (first + sub + 1) % rows
                rig[i, _RING + 2 * slot] = seen_v
                rig[i, _RING + 2 * slot + 1] = seen_phi
        if held > 0:
            v, phi = _roll(v, phi, alpha, theta_bar, beta_bar, alpha_bar, quadratic,
                           theta, theta, held_u, held * h, held)  # fmt: skip
        travel = abs(theta - previous_theta)
        state[i, State.RATE] = v
        state[i, State.ANGLE] = phi
        state[i, State.FIN] = theta
        state[i, State.COMMAND] = command
        state[i, State.SERVO] = servo
        state[i, State.DRIVE] = drive
        cursor[i, Cursor.STEP] = step + 1
        u_now[i] = u
        seen_v = v
        seen_phi = phi
        if late:  # what the sensors read: the rocket ``delay`` substeps ago
            at = max(first + n_sub - delay, 0.0)
            g = int(at)  # at >= 0: its floor
            w = at - g
            s0 = g % rows
            s1 = (g + 1) % rows
            seen_v = (1.0 - w) * rig[i, _RING + 2 * s0] + w * rig[i, _RING + 2 * s1]
            seen_phi = (1.0 - w) * rig[i, _RING + 2 * s0 + 1] + w * rig[i, _RING + 2 * s1 + 1]
        if cfg[Cfg.ANGLE_GYRO] > 0.0:  # the flight computer sums the gyro's reading
            state[i, State.GYRO_ANGLE] += n_sub * h * _gyro(seen_v, eps[k], cfg)
        sp = setpoints[i, min((step + 1) // period, last_sp)]
        err = _observe_one(i, state, seen_v, seen_phi, sp, eps[k], cfg, obs)
        error[i] = err
        reward[i] = step_reward(err, v, travel, cfg)


#: The step kernel, one env after the other (small batches, the single env).
step_kernel = numba.njit(cache=True, nogil=True)(_step_envs)


def _renamed(func: Any, name: str) -> Any:
    """A copy of ``func`` under another name: numba keys its disk cache by name, so
    the serial and the parallel build of one kernel need two."""
    copy = types.FunctionType(func.__code__, func.__globals__, name, func.__defaults__)
    copy.__qualname__ = name
    copy.__doc__ = func.__doc__
    return copy


#: The same kernel with its env loop spread over numba's threads (large batches).
step_kernel_parallel = numba.njit(cache=True, nogil=True, parallel=True)(
    _renamed(_step_envs, "_step_envs_parallel")
)


# ----------------------------------------------------------------------------- batch
class RollBatch:
    """The state of ``n`` environments and the two operations on it.

    Parameters
    ----------
    config : RollConfig
        Settings.
    bank : TraceBank
        Disturbance traces with their identified parameters.  Every trace's
        Δt must be a whole number of substeps, and some trace must be at
        least one episode long.
    n : int
        Batch size.
    parallel : bool
        Step with :data:`step_kernel_parallel` (numba's threads) instead of
        one env after the other.  Worth it only for large batches on cores
        nothing else uses: with the cores oversubscribed (a test run, torch's
        own threads during training) the threads' barriers stall and a step
        can take ten times longer than serially.

    Notes
    -----
    ``reset(index, rng)`` and ``step(action, rng, index)`` draw from the
    generator they are given in a fixed order -- per reset: windows, then
    parameters (with domain randomisation), setpoints, initial angles, gyro
    noise; per step: gyro noise -- so a batch of one and a single
    environment given the same generator agree exactly.
    """

    def __init__(
        self, config: RollConfig, bank: TraceBank, n: int, *, parallel: bool = False
    ) -> None:
        if n < 1:
            raise ValueError(f"the batch needs at least one environment, got {n}")
        bank = config.flights(bank)  # in flight, a tunnel bank is flown first
        bank = bank.on_grid(config.dt_s, config.substep_s)  # mixed or off-grid Δt: averaged
        schedule = config.flight_schedule
        self.config = config
        self.bank = bank
        self.n = n
        self.duration_s = config.max_episode_steps * config.dt_s
        bank.require(self.duration_s)
        dts = np.array([t.dt_s for t in bank.traces])
        per = dts / config.substep_s
        if np.any(np.abs(per - np.round(per)) > 1e-9 * per) or np.any(np.round(per) < 1):
            raise ValueError(
                f"the traces' Δt ({', '.join(f'{d:g}' for d in np.unique(dts))} s) must be a "
                f"whole number of {config.substep_s:g} s substeps"
            )
        if np.unique(np.round(per)).size != 1:
            raise ValueError("all traces of a bank must share one Δt")
        self.u_flat, self.u_offsets = bank.concatenated()
        self.cfg = config.kernel_settings()
        self.cfg[Cfg.U_PER] = float(np.round(per[0]))
        self.bank_params = np.array([row_of_params(p) for p in bank.params])
        self.param_low = self.bank_params.min(axis=0)
        self.param_high = self.bank_params.max(axis=0)
        if config.domain_randomization:
            _check_damping_box(self.param_low, self.param_high, config.fin_range_deg)
        self.all = np.arange(n, dtype=np.int64)
        self.state = np.zeros((n, len(State)))
        # Where each env is (Cursor columns); step_count, u_start, scale_start and
        # scale_stride are views of it (_cursor_views, once the rig is made below; rebuilt
        # when unpickled or copied).
        self.cursor = np.zeros((n, len(Cursor)), dtype=np.int64)
        self.params = np.zeros((n, len(Param)))
        # Multipliers of the rocket's parameters (Scale columns): row 0 is the constant
        # rocket (all ones, stride 0); in flight rows 1.. are the flight's, shared by every
        # env (stride 1); a schedule given at reset gets a block of its own after those.
        self.scales = np.ones((1, len(Scale)))
        self._default_scale = (0, 0)  # (start, stride) of an env without its own schedule
        if schedule is not None:
            self.scales = np.vstack([self.scales, schedule.scales[: config.max_episode_steps]])
            self._default_scale = (1, 1)
        self._base_rows = self.scales.shape[0]
        self._scales_shared = False
        self.trace = np.zeros(n, dtype=np.int64)
        self.start = np.zeros(n, dtype=np.int64)
        self.setpoints = np.zeros((n, config.setpoint_segments))
        self.obs = np.zeros((n, len(Obs)), dtype=np.float32)
        self.reward = np.zeros(n)
        self.error = np.zeros(n)
        self.u_now = np.zeros(n)
        # Each trace's rocket's rig as the kernel reads it (Link columns), each env's now;
        # the sensors' ring of past substeps (rate, angle), as deep as the longest latency
        # needs (see _step_envs); one unused row without a latency.
        self.trace_link = np.array([config.link_row(r) for r in bank.rigs])
        delay = float(self.trace_link[:, Link.LATENCY].max())
        rows = math.ceil(delay) + 2 if delay > 0.0 else 1
        self.rig = np.zeros((n, _RING + 2 * rows))  # link and past are views of it
        self._cursor_views()
        self.parallel = bool(parallel)
        self._noisy = bool(self.cfg[Cfg.GYRO_ETA] > 0.0)
        self._no_noise = np.zeros(n)

    _VIEWS = ("step_count", "u_start", "scale_start", "scale_stride", "link", "past")

    def _cursor_views(self) -> None:
        """Name the columns of ``cursor`` and ``rig`` (views: the kernel writes the arrays):
        ``link`` each env's :class:`~rollenv.layout.Link` row, ``past`` its ring of past
        substeps (rows of rate, angle)."""
        self.step_count = self.cursor[:, Cursor.STEP]
        self.u_start = self.cursor[:, Cursor.U_START]
        self.scale_start = self.cursor[:, Cursor.SCALE_START]
        self.scale_stride = self.cursor[:, Cursor.SCALE_STRIDE]
        self.link = self.rig[:, :_RING]
        self.past = self.rig[:, _RING:].reshape(self.n, -1, 2)

    def __getstate__(self) -> dict[str, Any]:
        # Pickling (and copy.deepcopy) would turn the views into arrays of their own.
        return {k: v for k, v in self.__dict__.items() if k not in self._VIEWS}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._cursor_views()

    # ------------------------------------------------------------------ reset
    def reset(
        self,
        index: IntArray,
        rng: np.random.Generator,
        *,
        trace: int | None = None,
        start: int | None = None,
        rate_dps: float | None = None,
        angle_deg: float | None = None,
        fin_deg: float | None = None,
        setpoint: float | None = None,
        setpoints: FloatArray | None = None,
        scales: FloatArray | None = None,
    ) -> None:
        """Start new episodes for the envs in ``index``.

        Keyword arguments fix what would otherwise be drawn (replays,
        evaluation episodes): the trace index in the bank, the start sample,
        the initial rate, angle and fin angle, a constant setpoint or the
        whole schedule (one value per ``setpoint_period_s``, length
        ``config.setpoint_segments``).  ``scales`` makes the rocket change
        during the episode: multipliers of its parameters
        (:class:`~rollenv.layout.Scale` columns), one row per control step
        (shape ``(max_episode_steps, 2)``) or one row for the whole episode
        (shape ``(2,)``); without it the rocket is the database's.
        """
        cfg = self.config
        m = index.size
        if m == 0:
            return
        if trace is None:
            traces, starts = self.bank.draw(rng, self.duration_s, m)
            if start is not None:
                starts = np.full(m, start, dtype=np.int64)
        else:
            window = self.bank.at(trace, 0 if start is None else start, self.duration_s)
            traces = np.full(m, window.trace, dtype=np.int64)
            starts = np.full(m, window.start, dtype=np.int64)
        self.trace[index] = traces
        self.start[index] = starts
        self.link[index] = self.trace_link[traces]
        self.u_start[index] = self.u_offsets[traces] + starts
        if cfg.domain_randomization:
            self.params[index] = self._randomized_params(rng, m)
        else:
            self.params[index] = self.bank_params[traces]
        if setpoints is not None:
            self.setpoints[index] = setpoints
        elif setpoint is not None:
            self.setpoints[index] = setpoint
        elif cfg.setpoint == "steps" and self.setpoints.shape[1] > 1:
            sp = rng.uniform(-cfg.setpoint_max, cfg.setpoint_max, size=(m, self.setpoints.shape[1]))
            sp[:, 0] = 0.0
            self.setpoints[index] = sp
        else:
            self.setpoints[index] = 0.0
        if angle_deg is None:
            angles = (
                rng.uniform(-cfg.initial_angle_deg, cfg.initial_angle_deg, size=m)
                if cfg.initial_angle_deg > 0
                else np.zeros(m)
            )
        else:
            angles = np.full(m, float(angle_deg))
        fin = np.clip(
            0.0 if fin_deg is None else float(fin_deg), -cfg.fin_range_deg, cfg.fin_range_deg
        )
        self._set_scales(index, scales)
        p = self.params[index]
        gain = self.scales[self.scale_start[index], Scale.GAIN]
        u0 = self.cfg[Cfg.U_SCALE] * self.u_flat[self.u_start[index]]
        if rate_dps is None and cfg.flight is not None:  # off the launch rail: not rolling
            self.state[index, State.RATE] = 0.0
        elif rate_dps is None:  # the steady rate for the initial fin angle (eq. 16, 36)
            self.state[index, State.RATE] = quadratic_steady_rate(
                p[:, Param.ALPHA] * gain * (fin + p[:, Param.THETA_BAR] + u0),
                p[:, Param.QUADRATIC],
            )
        else:
            self.state[index, State.RATE] = float(rate_dps)
        self.state[index, State.ANGLE] = angles
        self.state[index, State.GYRO_ANGLE] = angles  # aligned on the pad
        self.state[index, State.FIN] = fin
        self.state[index, State.COMMAND] = fin
        self.state[index, State.SERVO] = fin
        self.state[index, State.DRIVE] = fin
        # Before the episode the rocket was as it starts (what a late sensor reads first).
        self.past[index, :, 0] = self.state[index, State.RATE][:, None]
        self.past[index, :, 1] = angles[:, None]
        self.step_count[index] = 0
        self.u_now[index] = u0
        eps = self._gyro_draws(rng, m)
        observe_kernel(
            index, self.state, self.cursor, self.setpoints, eps, self.cfg, self.obs, self.error
        )

    # ------------------------------------------------------------------- step
    def step(self, action: FloatArray, rng: np.random.Generator, index: IntArray) -> None:
        """Advance the envs in ``index`` with fin commands ``action`` in [-1, 1] (length n)."""
        eps = self._gyro_draws(rng, index.size)
        (step_kernel_parallel if self.parallel else step_kernel)(
            index,
            action,
            self.state,
            self.cursor,
            self.params,
            self.scales,
            self.u_flat,
            self.setpoints,
            eps,
            self.cfg,
            self.obs,
            self.reward,
            self.error,
            self.u_now,
            self.rig,
        )

    def _randomized_params(self, rng: np.random.Generator, m: int) -> FloatArray:
        """``m`` parameter sets uniform over the bank's box, redrawing any that is undamped.

        A draw whose a(θ) is not positive over the whole fin range is drawn
        again (the corners of the box can be rockets that do not exist).
        """
        span = self.param_high - self.param_low
        # the quadratic damping drawn only where the bank's rockets differ in it (the draws
        # of a bank of linear rockets as they were before it existed)
        drawn = len(Param) if span[Param.QUADRATIC] > 0.0 else int(Param.QUADRATIC)
        out = self.param_low + np.zeros((m, len(Param)))
        out[:, :drawn] += rng.uniform(size=(m, drawn)) * span[:drawn]
        for _ in range(_MAX_REDRAWS):
            bad = np.flatnonzero(_min_damping(out, self.config.fin_range_deg) <= 0.0)
            if bad.size == 0:
                return out
            out[bad, :drawn] = (
                self.param_low[:drawn] + rng.uniform(size=(bad.size, drawn)) * span[:drawn]
            )
        raise RuntimeError("domain randomisation found no damped rocket in the parameter box")

    def _gyro_draws(self, rng: np.random.Generator, m: int) -> FloatArray:
        if self._noisy:
            return rng.standard_normal(m)
        return self._no_noise[:m]

    # ---------------------------------------------------------------- queries
    @property
    def truncated(self) -> NDArray[np.bool_]:
        """Envs whose episode has reached ``max_episode_steps``."""
        return self.step_count >= self.config.max_episode_steps

    def setpoint_of(self, i: int) -> float:
        """Env ``i``'s current setpoint, ° or °/s (:meth:`setpoint_now` for one env)."""
        segment = int(self.step_count[i]) // self.config.setpoint_period_steps
        return float(self.setpoints[i, min(segment, self.setpoints.shape[1] - 1)])

    def setpoint_now(self) -> FloatArray:
        """Each env's current setpoint, ° or °/s."""
        seg = np.minimum(
            self.step_count // self.config.setpoint_period_steps, self.setpoints.shape[1] - 1
        )
        return self.setpoints[self.all, seg]

    def u_ahead(self, i: int, steps: int) -> FloatArray:
        """The ``u_d`` (scaled, °) acting at the start of env ``i``'s next ``steps`` control
        steps -- the future, for privileged controllers (the oracle bound)."""
        left = self.config.max_episode_steps - int(self.step_count[i])
        if not 0 <= steps <= left:
            raise ValueError(f"env {i} has {left} steps left, asked for {steps}")
        k = self.step_count[i] + np.arange(steps)
        per = int(self.cfg[Cfg.U_PER])
        samples = self.u_flat[self.u_start[i] + (k * self.config.substeps) // per]
        return np.asarray(self.cfg[Cfg.U_SCALE] * samples)

    def roll_params(self, i: int) -> RollParams:
        """The model parameters env ``i`` runs with (at its current step's multipliers)."""
        row = self.params[i].copy()
        gain, damping = self.scales[self._scale_row(i)]
        row[Param.ALPHA] *= gain
        row[Param.BETA_BAR] *= damping
        row[Param.ALPHA_BAR] *= damping
        return params_of_row(row)

    def _scale_row(self, i: int) -> int:
        """Env ``i``'s row of multipliers now (the last step's once the episode ended)."""
        step = min(int(self.step_count[i]), self.config.max_episode_steps - 1)
        return int(self.scale_start[i] + step * self.scale_stride[i])

    def _set_scales(self, index: IntArray, scales: FloatArray | None) -> None:
        """Give the envs in ``index`` the constant rocket, or the multipliers ``scales``."""
        if scales is None:
            self.scale_start[index], self.scale_stride[index] = self._default_scale
            return
        values = np.asarray(scales, dtype=np.float64)
        steps = self.config.max_episode_steps
        if values.shape == (len(Scale),):
            values = np.broadcast_to(values, (steps, len(Scale)))
        if values.shape != (steps, len(Scale)):
            raise ValueError(
                f"scales must have shape ({len(Scale)},) or ({steps}, {len(Scale)}) "
                f"(one row of {', '.join(m.name.lower() for m in Scale)} per control step), "
                f"got {values.shape}"
            )
        if not np.all(np.isfinite(values)) or np.any(values <= 0.0):
            raise ValueError("scales must be finite and positive")
        self._own_scales()
        for i in np.asarray(index).tolist():
            first = self._base_rows + i * steps
            self.scales[first : first + steps] = values
            self.scale_start[i] = first
            self.scale_stride[i] = 1

    def _own_scales(self) -> None:
        """A table of multipliers this batch may write: one block of rows per env.

        The first schedule grows the table of the constant rocket (and the
        flight's rows); a table shared by :meth:`copy_env` is copied first,
        each env's own schedule into its block.
        """
        steps = self.config.max_episode_steps
        base = self._base_rows
        size = base + self.n * steps
        if not self._scales_shared and self.scales.shape[0] == size:
            return
        old = self.scales
        table = np.ones((size, len(Scale)))
        table[:base] = old[:base]
        k = np.arange(steps)
        for i in np.flatnonzero(self.scale_start >= base).tolist():
            first = base + i * steps
            table[first : first + steps] = old[self.scale_start[i] + k * self.scale_stride[i]]
            self.scale_start[i] = first
            self.scale_stride[i] = 1
        self.scales = table
        self._scales_shared = False

    def episode_scales(self, i: int) -> FloatArray:
        """Env ``i``'s multipliers over its whole episode, one row per control step."""
        k = np.arange(self.config.max_episode_steps)
        return np.asarray(self.scales[self.scale_start[i] + k * self.scale_stride[i]])

    def copy_env(self, source: RollBatch, i: int, index: IntArray) -> None:
        """Make the envs in ``index`` exact copies of env ``i`` of ``source`` (same bank):
        state, rocket and its multipliers, disturbance, step and setpoints -- for
        predictors that simulate ahead of an episode (the oracle bound)."""
        if source.bank is not self.bank:
            raise ValueError("copy_env needs two batches over the same bank")
        self.state[index] = source.state[i]
        self.rig[index] = source.rig[i]
        self.params[index] = source.params[i]
        self.trace[index] = source.trace[i]
        self.start[index] = source.start[i]
        self.cursor[index] = source.cursor[i]
        self.setpoints[index] = source.setpoints[i]
        # Shared, not copied (the predictor copies every step); whichever of the two
        # writes a schedule next copies the table first (_own_scales).
        self.scales = source.scales
        self._scales_shared = source._scales_shared = True


#: Rounds of redrawing undamped rockets before domain randomisation gives up.
_MAX_REDRAWS = 200


def _min_damping(params: FloatArray, fin_range: float) -> FloatArray:
    """Smallest a(θ) = ᾱ·|θ + θ̄| + β̄ over θ in ±fin_range, per row (α, θ̄, β̄, ᾱ)."""
    reach = fin_range + np.abs(params[:, Param.THETA_BAR])
    return np.asarray(
        params[:, Param.BETA_BAR] + np.minimum(params[:, Param.ALPHA_BAR], 0.0) * reach
    )


def _check_damping_box(low: FloatArray, high: FloatArray, fin_range: float) -> None:
    """Refuse a randomisation box in which (almost) no rocket is damped over the fin range."""
    probe = low + np.random.default_rng(0).uniform(size=(4096, len(Param))) * (high - low)
    accepted = float(np.mean(_min_damping(probe, fin_range) > 0.0))
    if accepted < 0.01:
        raise ValueError(
            f"domain randomisation over the bank's parameter range gives a(θ) <= 0 somewhere "
            f"in ±{fin_range:g}° for {1 - accepted:.1%} of draws (β̄ from {low[2]:.3g}, ᾱ from "
            f"{low[3]:.3g}); select traces with a narrower spread"
        )
