"""The paper's identification pipeline, one public function per step.

Steps (paper §2.3-§2.7, the algorithm of Fig. 9):

1. :func:`detect_segments` -- the fin-angle steps ``T_i`` (§2.3).
2. :func:`fit_piecewise_linear` -- continuous piecewise-linear roll angle (eq. 9-15).
3. :func:`fit_steady_state` -- ``v_ss = α·f_ss + β`` and its R² (eq. 16-17).
4. :func:`fit_bilinear` -- bi-linear velocity step model, breakpoint ``t0`` (eq. 18).
5. :func:`fin_angle_model` -- the servo-lag fin ramp (eq. 23-24), or the measured fin.
6. :func:`fit_damping` -- integral-based damping: constant ``a`` (eq. 25-28) and
   per-step ``a_i`` (eq. 31-34), with ``b = a·α`` and ``θ̄ = β/α`` (eq. 29-30).
7. :func:`fit_damping_vs_fin` -- ``a(θ) = ᾱ·|θ + θ̄| + β̄`` (eq. 48), outlier rule.
8. :func:`identify_disturbance` -- ``u_d(t)`` per Δt interval (eq. 35-44).
9. :func:`resimulate` -- drive the model with its ``u_d`` and compare (§3.5).

Steps 1-7 use the data after the first deflection (§2.1); steps 8-9 use all
of it.  :func:`identification.methods.pipeline.identify` chains them.

Errata (tested in ``tests/identification/test_steps.py``)
---------------------------------------------------------
* Eq. 39 reads ``ū_d,i = a·u_d,i``.  From eq. 36 the term that multiplies
  ``u_d`` is ``a·α``, so the fitted slope is ``ū_d,i = a·α·u_d,i``; dividing
  by ``a`` alone would give ``u_d`` in °/s, not in degrees of equivalent fin
  angle.  :func:`identify_disturbance` divides by ``a·α``.
* Eq. 32 writes the integrals as ``∫_t^{T_i}``; integrating eq. 21 from
  ``T_i`` to ``t`` gives ``∫_{T_i}^t`` as in eq. 25 (with the reversed limits
  every ``a_i`` would come out negated).  :func:`fit_damping` uses ``∫_{T_i}^t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats
from scipy.integrate import cumulative_trapezoid
from scipy.linalg import lapack
from scipy.ndimage import uniform_filter1d

from identification.compiled import linkage_path
from identification.model import (
    TIME_TOL,
    Disturbance,
    Linkage,
    RollParams,
    Servo,
    damping,
    interval_index,
    servo_path,
    simulate,
)
from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import RocketrollError

__all__ = [
    "BilinearFit",
    "DampingFit",
    "DampingVsFin",
    "FineGrid",
    "PiecewiseLinearFit",
    "Resimulation",
    "Segments",
    "SteadyStateFit",
    "detect_segments",
    "fin_angle_model",
    "fine_grid",
    "fit_bilinear",
    "fit_damping",
    "fit_damping_vs_fin",
    "fit_piecewise_linear",
    "fit_steady_state",
    "identify_disturbance",
    "measured_angle",
    "measured_velocity",
    "moving_average",
    "resimulate",
    "smooth3",
    "smoothing_width",
]

IntArray = NDArray[np.intp]

#: The servo of eq. 23 (150 °/s) without saturation: recorded commands are
#: taken as they are.
PAPER_SERVO = Servo(range_deg=180.0)


class IdentificationError(RocketrollError, ValueError):
    """A recording that the pipeline cannot identify (too few steps, too short, ...)."""


def _first_at(time_s: FloatArray, t: float) -> int:
    """Index of the first sample at or after ``t``."""
    return int(np.searchsorted(time_s, t - TIME_TOL))


# --------------------------------------------------------------------------- step 1


@dataclass(frozen=True, eq=False)
class Segments:
    """Fin-angle steps of a recording (paper §2.3, the ``T_i`` of eq. 9).

    Attributes
    ----------
    fin_source : str
        ``fin_cmd_deg`` or ``fin_deg``: the column the steps were found in.
    start_index : ndarray of int, shape (m,)
        Sample index of each step time ``T_i`` (the first sample of the move).
    settle_index : ndarray of int, shape (m,)
        First sample at which the fin has reached its new level.
    levels_deg : ndarray, shape (m + 1,)
        Fin level before the first step, then after each step (``f_ss``), °.
    end_index : int
        Index of the last sample (``T_end``).
    time_s : ndarray, shape (m,)
        ``T_i``, s.
    end_s : float
        ``T_end``, s.
    """

    fin_source: str
    start_index: IntArray
    settle_index: IntArray
    levels_deg: FloatArray
    end_index: int
    time_s: FloatArray
    end_s: float

    @property
    def n_steps(self) -> int:
        """Number of steps ``m`` (8 in the paper)."""
        return int(self.start_index.size)

    @property
    def bounds_s(self) -> FloatArray:
        """``[T_1, ..., T_m, T_end]``, s."""
        return np.append(self.time_s, self.end_s)

    @property
    def step_levels_deg(self) -> FloatArray:
        """``f_ss`` of each step, °."""
        return self.levels_deg[1:]

    @property
    def previous_levels_deg(self) -> FloatArray:
        """The level each step starts from, °."""
        return self.levels_deg[:-1]


def detect_segments(
    recording: Recording,
    *,
    min_step_deg: float = 1.0,
    tolerance_deg: float = 0.05,
    merge_s: float = 1.0,
) -> Segments:
    """Step 1: find the fin-angle steps ``T_i`` (paper §2.3).

    The commanded fin angle is used when present (its steps are exact jumps),
    else the measured one (ramps).  A sample-to-sample change larger than
    ``tolerance_deg`` (after a 3-sample median filter, which ignores isolated
    glitches) marks the fin as moving; moves closer than ``merge_s`` form one
    transition (a ramp), whose start is ``T_i``.  Transitions whose net change
    is below ``min_step_deg`` are ignored.  Each level is the median of the fin
    between its settling and the next step.

    Parameters
    ----------
    recording : Recording
        Any recording (format v1).
    min_step_deg : float
        Smallest net fin change that counts as a step, °.
    tolerance_deg : float
        Sample-to-sample change below which the fin counts as still, °.
    merge_s : float
        Moves separated by less than this are one transition, s.

    Returns
    -------
    Segments

    Raises
    ------
    IdentificationError
        If the fin never steps.
    """
    if recording.fin_cmd_deg is not None:
        fin, source = np.asarray(recording.fin_cmd_deg), "fin_cmd_deg"
    else:
        assert recording.fin_deg is not None  # validated: at least one fin column
        fin, source = np.asarray(recording.fin_deg), "fin_deg"
    n = fin.size
    filtered = fin if source == "fin_cmd_deg" else _median3(fin)
    moving = np.flatnonzero(np.abs(np.diff(filtered)) > tolerance_deg)  # move i -> i+1
    gap = max(1, round(merge_s / recording.dt_s))
    starts: list[int] = []
    settles: list[int] = []
    # A command jumps at the sample after the difference; a measured fin
    # leaves its level after the last sample at the old level.
    shift = 1 if source == "fin_cmd_deg" else 0
    if moving.size:
        breaks = np.flatnonzero(np.diff(moving) > gap)
        run_first = np.concatenate([[moving[0]], moving[breaks + 1]])
        run_last = np.concatenate([moving[breaks], [moving[-1]]])
        for first, last in zip(run_first.tolist(), run_last.tolist(), strict=True):
            starts.append(first + shift)
            settles.append(last + 1)
    # Levels between transitions; drop transitions with a small net change.
    keep_start: list[int] = []
    keep_settle: list[int] = []
    levels = [float(np.median(filtered[: starts[0] + 1 - shift])) if starts else float(filtered[0])]
    for k, (s0, s1) in enumerate(zip(starts, settles, strict=True)):
        nxt = starts[k + 1] if k + 1 < len(starts) else n - 1
        level = float(np.median(filtered[s1 : nxt + 1]))
        if abs(level - levels[-1]) >= min_step_deg:
            keep_start.append(s0)
            keep_settle.append(s1)
            levels.append(level)
    if not keep_start:
        raise IdentificationError(
            f"{recording.name}: the fin angle ({source}) never steps by {min_step_deg:g}° or "
            "more; the identification needs fin steps (paper §2.3)"
        )
    t = np.asarray(recording.time_s)
    start_index = np.asarray(keep_start, dtype=np.intp)
    return Segments(
        fin_source=source,
        start_index=start_index,
        settle_index=np.asarray(keep_settle, dtype=np.intp),
        levels_deg=readonly_array(levels),
        end_index=n - 1,
        time_s=readonly_array(t[start_index]),
        end_s=float(t[-1]),
    )


def _median3(x: FloatArray) -> FloatArray:
    if x.size < 3:
        return x
    padded = np.concatenate([[x[0]], x, [x[-1]]])
    window = np.lib.stride_tricks.sliding_window_view(padded, 3)
    return np.asarray(np.median(window, axis=1), dtype=float)


# --------------------------------------------------------------------------- measurements


def measured_angle(recording: Recording) -> tuple[FloatArray, str]:
    """Roll angle, °, and where it came from.

    The encoder angle when present; for a rate-only recording the rate gyro
    integrated with the trapezium rule (starting at 0°).
    """
    if recording.roll_deg is not None:
        return np.asarray(recording.roll_deg, dtype=float), "encoder"
    assert recording.roll_rate_dps is not None  # validated: at least one roll column
    angle = cumulative_trapezoid(recording.roll_rate_dps, recording.time_s, initial=0.0)
    return np.asarray(angle, dtype=float), "rate gyro integrated (trapezium rule)"


def moving_average(x: ArrayLike, passes: int, width: int = 3) -> FloatArray:
    """``width``-point moving average applied ``passes`` times (paper §3.2).

    Along the last axis; the ends use the nearest sample (``mode="nearest"``).
    """
    out = np.asarray(x, dtype=float)
    for _ in range(passes):
        out = uniform_filter1d(out, width, axis=-1, mode="nearest")
    return out


def smooth3(x: ArrayLike, passes: int) -> FloatArray:
    """The paper's three-point moving average applied ``passes`` times (§3.2)."""
    return moving_average(x, passes, 3)


#: Span of one moving-average pass, s: the paper's three points at 0.1 s.
SMOOTHING_WINDOW_S = 0.3


def smoothing_width(dt_s: float, window_s: float = SMOOTHING_WINDOW_S) -> int:
    """Odd number of samples spanning ``window_s`` at step ``dt_s``.

    3 at the paper's 10 Hz; 31 at 100 Hz, so a pass smooths over the same
    time whatever the sampling rate (three points at 100 Hz would leave the
    encoder's quantisation noise, amplified by the differentiation, nearly
    untouched).
    """
    width = max(1, round(window_s / dt_s))
    return width if width % 2 else width + 1


def smoothing_spread_s(dt_s: float, passes: int, window_s: float = SMOOTHING_WINDOW_S) -> float:
    """Standard deviation, s, of the kernel of :func:`moving_average` at ``passes`` passes
    of :func:`smoothing_width` samples: how far in time the smoothing spreads a reading
    (0.15 s for the paper's three passes over 0.3 s)."""
    width = smoothing_width(dt_s, window_s)
    return float(dt_s * np.sqrt(passes * (width**2 - 1) / 12.0))


def measured_velocity(
    recording: Recording, smoothing_passes: int, window_s: float = SMOOTHING_WINDOW_S
) -> tuple[FloatArray, str]:
    """Roll rate at the recording's samples, °/s, and where it came from.

    The rate gyro when present, else the roll angle differentiated by central
    differences (``numpy.gradient``; paper §2.5: "computed by differentiating
    the roll angle data"); then a moving average over ``window_s``
    (:func:`smoothing_width` samples: the paper's three points at 10 Hz)
    applied ``smoothing_passes`` times (§3.2).
    """
    if recording.roll_rate_dps is not None:
        raw, source = np.asarray(recording.roll_rate_dps, dtype=float), "rate gyro"
    else:
        assert recording.roll_deg is not None
        raw = np.gradient(np.asarray(recording.roll_deg, dtype=float), recording.time_s)
        source = "encoder angle, central differences"
    width = smoothing_width(recording.dt_s, window_s)
    if smoothing_passes:
        source += f", {width}-point moving average x{smoothing_passes}"
    return moving_average(raw, smoothing_passes, width), source


# --------------------------------------------------------------------------- step 2


@dataclass(frozen=True, eq=False)
class PiecewiseLinearFit:
    """Continuous piecewise-linear roll angle ``a_i + b_i·t`` (eq. 9-15).

    Attributes
    ----------
    bounds_s : ndarray, shape (m + 1,)
        ``T_1 ... T_m, T_end``, s.
    intercepts_deg : ndarray, shape (m,)
        ``a_i``, ° (the paper's form, absolute time).
    slopes_dps : ndarray, shape (m,)
        ``b_i``: the steady roll rate of each step, °/s.
    rms_deg : float
        RMS residual against the fitted roll angle, °.
    angle_source : str
        ``encoder`` or how the angle was obtained from a rate gyro.
    """

    bounds_s: FloatArray
    intercepts_deg: FloatArray
    slopes_dps: FloatArray
    rms_deg: float
    angle_source: str

    def __call__(self, time_s: ArrayLike) -> FloatArray:
        """The fitted angle at ``time_s`` (extrapolated at both ends), °."""
        t = np.asarray(time_s, dtype=float)
        last = self.slopes_dps.size - 1
        k = np.clip(interval_index(self.bounds_s, t), 0, last)
        return np.asarray(self.intercepts_deg[k] + self.slopes_dps[k] * t, dtype=float)


def fit_piecewise_linear(
    time_s: ArrayLike, angle_deg: ArrayLike, bounds_s: ArrayLike, *, angle_source: str = "encoder"
) -> PiecewiseLinearFit:
    """Step 2: least squares with the continuity constraints of eq. 10, exactly.

    Minimises ``‖A·X - B‖`` (eq. 14-15) subject to
    ``a_i + b_i·T_{i+1} = a_{i+1} + b_{i+1}·T_{i+1}`` (eq. 10) with LAPACK's
    equality-constrained least-squares solver (``gglse``, generalised RQ), so
    the constraints hold to rounding -- no penalty weight.  Each segment is
    parametrised about its own start for conditioning; the result is returned
    in the paper's form ``a_i + b_i·t``.

    Parameters
    ----------
    time_s, angle_deg : array_like, shape (n,)
        Samples; only ``T_1 <= t <= T_end`` are used.
    bounds_s : array_like, shape (m + 1,)
        ``T_1, ..., T_m, T_end``.
    angle_source : str
        Recorded in the result.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(angle_deg, dtype=float)
    bounds = np.asarray(bounds_s, dtype=float)
    m = bounds.size - 1
    use = (t >= bounds[0] - TIME_TOL) & (t <= bounds[-1] + TIME_TOL)
    t, y = t[use], y[use]
    seg = np.clip(interval_index(bounds, t), 0, m - 1)
    counts = np.bincount(seg, minlength=m)
    if np.any(counts < 2):
        raise IdentificationError(
            f"step {int(np.argmin(counts)) + 1} at {bounds[np.argmin(counts)]:g} s has fewer "
            "than 2 samples; cannot fit its roll slope (eq. 9)"
        )
    # Unknowns per segment: (c_i, b_i) with angle = c_i + b_i·(t - T_i).
    design = np.zeros((t.size, 2 * m))
    rows = np.arange(t.size)
    design[rows, 2 * seg] = 1.0
    design[rows, 2 * seg + 1] = t - bounds[seg]
    constraint = np.zeros((max(m - 1, 0), 2 * m))
    for i in range(m - 1):  # c_i + b_i·(T_{i+1} - T_i) - c_{i+1} = 0  (eq. 10)
        constraint[i, 2 * i] = 1.0
        constraint[i, 2 * i + 1] = bounds[i + 1] - bounds[i]
        constraint[i, 2 * i + 2] = -1.0
    if m == 1:
        x, *_ = np.linalg.lstsq(design, y, rcond=None)
    else:
        result = lapack.dgglse(design, constraint, y, np.zeros(m - 1))
        x, info = result[3], result[-1]
        if info != 0:
            raise IdentificationError(f"constrained least squares failed (LAPACK info {info})")
    c, b = x[0::2], x[1::2]
    intercepts = c - b * bounds[:-1]
    residual = y - (design @ x)
    return PiecewiseLinearFit(
        bounds_s=readonly_array(bounds),
        intercepts_deg=readonly_array(intercepts),
        slopes_dps=readonly_array(b),
        rms_deg=float(np.sqrt(np.mean(residual**2))),
        angle_source=angle_source,
    )


# --------------------------------------------------------------------------- step 3


@dataclass(frozen=True, eq=False)
class SteadyStateFit:
    """``v_ss = α·f_ss + β`` (eq. 16-17).

    Attributes
    ----------
    alpha : float
        α, (°/s)/°.
    beta_dps : float
        β, °/s.
    r_squared : float
        Coefficient of determination (the paper: 0.9914).
    alpha_se, beta_se : float
        Standard errors of α and β (``nan`` with only two steps).
    fin_deg, rate_dps : ndarray
        The points ``(f_ss, v_ss)`` fitted.
    """

    alpha: float
    beta_dps: float
    r_squared: float
    alpha_se: float
    beta_se: float
    fin_deg: FloatArray
    rate_dps: FloatArray

    @property
    def theta_bar_deg(self) -> float:
        """θ̄ = β/α, ° (eq. 30)."""
        return self.beta_dps / self.alpha

    def rate(self, fin_deg: ArrayLike) -> FloatArray:
        """``v_ss,new = α·f + β`` (eq. 16), °/s."""
        return self.alpha * np.asarray(fin_deg, dtype=float) + self.beta_dps


def fit_steady_state(fin_deg: ArrayLike, rate_dps: ArrayLike) -> SteadyStateFit:
    """Step 3: straight line through the steps' ``(f_ss, v_ss)`` (eq. 16).

    ``v_ss`` are the slopes ``b_i`` of step 2.  Ordinary least squares
    (``scipy.stats.linregress``); R² is the squared correlation.

    Raises
    ------
    IdentificationError
        With fewer than two distinct fin levels, or no response to the fin.
    """
    f = np.asarray(fin_deg, dtype=float)
    v = np.asarray(rate_dps, dtype=float)
    if np.unique(f).size < 2:
        raise IdentificationError(
            "the steady-state fit (eq. 16) needs at least two distinct fin levels"
        )
    fit = stats.linregress(f, v)
    if fit.slope == 0.0:
        raise IdentificationError("the roll rate does not respond to the fin (α = 0)")
    se_ok = f.size > 2
    return SteadyStateFit(
        alpha=float(fit.slope),
        beta_dps=float(fit.intercept),
        r_squared=float(fit.rvalue**2),
        alpha_se=float(fit.stderr) if se_ok else float("nan"),
        beta_se=float(fit.intercept_stderr) if se_ok else float("nan"),
        fin_deg=readonly_array(f),
        rate_dps=readonly_array(v),
    )


# --------------------------------------------------------------------------- fine grid


@dataclass(frozen=True, eq=False)
class FineGrid:
    """The 100 Hz grid of §2.7.1 on which velocities are interpolated.

    Attributes
    ----------
    time_s : ndarray, shape (n_fine + 1,)
        ``t_0 + k·δt``.
    step_s : float
        δt (0.01 s in the paper).
    per_sample : int
        Fine steps per recording sample.
    """

    time_s: FloatArray
    step_s: float
    per_sample: int


def fine_grid(recording: Recording, fine_step_s: float = 0.01) -> FineGrid:
    """A grid of step ≈ ``fine_step_s`` that contains every recording sample.

    The step is ``dt / m`` with ``m = max(1, round(dt / fine_step_s))``, so a
    10 Hz recording gets the paper's 100 Hz grid and a 100 Hz recording its
    own samples.
    """
    dt = recording.dt_s
    per = max(1, round(dt / fine_step_s))
    n_fine = (recording.n_samples - 1) * per
    t0 = float(recording.time_s[0])
    h = recording.duration_s / n_fine
    time = t0 + h * np.arange(n_fine + 1, dtype=float)
    return FineGrid(time_s=readonly_array(time), step_s=h, per_sample=per)


# --------------------------------------------------------------------------- step 5


def fin_angle_model(
    recording: Recording,
    grid: FineGrid,
    servo: Servo | None = PAPER_SERVO,
    link: Linkage | None = None,
) -> tuple[FloatArray, str]:
    """Step 5: the actual fin angle θ(t) on the fine grid (eq. 23-24).

    With a measured fin angle (``fin_deg``) it is interpolated and no lag is
    applied.  Otherwise the commanded angle, held over each sample interval,
    is passed through the servo of eq. 23: the fin ramps at
    ``servo.rate_limit_dps`` (150 °/s: 0.4 s per 60°) to the command -- and
    through ``link`` where the rig states one (a lag and play behind the servo).

    Returns
    -------
    theta : ndarray, shape (n_fine + 1,)
        Fin angle, °.
    source : str
        How it was obtained.
    """
    if recording.fin_deg is not None:
        return (
            np.interp(grid.time_s, recording.time_s, recording.fin_deg),
            "measured fin angle (no servo lag applied)",
        )
    assert recording.fin_cmd_deg is not None
    command = np.repeat(np.asarray(recording.fin_cmd_deg)[:-1], grid.per_sample)
    if servo is None:
        return np.append(command, recording.fin_cmd_deg[-1]), "commanded fin angle, no lag"
    rate = servo.rate_limit_dps
    if link is not None and not link.direct:
        theta = linkage_path(command, float(recording.fin_cmd_deg[0]), grid.step_s, servo, link)
        return theta, (
            f"commanded fin angle through the servo of eq. 23 ({rate:g} °/s), a "
            f"{link.lag_s:g}-s lag and {link.backlash_deg:g}° of play"
        )
    theta = servo_path(command, float(recording.fin_cmd_deg[0]), grid.step_s, servo)
    return theta, f"commanded fin angle through the servo lag of eq. 23 ({rate:g} °/s)"


# --------------------------------------------------------------------------- step 4


@dataclass(frozen=True, eq=False)
class BilinearFit:
    """Bi-linear step responses (eq. 18) of every step.

    Attributes
    ----------
    t0_s : ndarray, shape (m,)
        Breakpoint of each step, s after ``T_i``.
    v0_dps, vss_dps : ndarray, shape (m,)
        Start (previous ``v_ss``) and steady-state rate of each step (eq. 16), °/s.
    candidates_s : ndarray, shape (k,)
        The breakpoints tried (0.01 s to ``ΔT0``).
    errors : ndarray, shape (m, k)
        Sum of squared errors for each step and candidate (Fig. 7a).
    window_s : float
        Length after ``T_i`` over which the error is computed, s.
    """

    t0_s: FloatArray
    v0_dps: FloatArray
    vss_dps: FloatArray
    candidates_s: FloatArray
    errors: FloatArray
    window_s: float

    def velocity(self, step: int, time_since_step_s: ArrayLike) -> FloatArray:
        """``v_model`` of eq. 18 for one step, °/s."""
        tau = np.asarray(time_since_step_s, dtype=float)
        t0, v0, vss = self.t0_s[step], self.v0_dps[step], self.vss_dps[step]
        return np.where(tau < t0, v0 + (vss - v0) * tau / t0, vss)


def fit_bilinear(
    segments: Segments,
    steady: SteadyStateFit,
    grid: FineGrid,
    velocity_fine: ArrayLike,
    *,
    max_breakpoint_s: float = 4.0,
    resolution_s: float = 0.01,
) -> BilinearFit:
    """Step 4: breakpoint ``t0`` of the bi-linear model (eq. 18) for each step.

    ``v_ss = α·f_ss + β`` (eq. 16) for the step's level and ``v0`` the previous
    ``v_ss`` (for the first step, that of the level before it).  Every
    ``t0`` in ``(0, ΔT0]`` on a ``resolution_s`` grid is tried against the
    measured velocity interpolated on the fine grid; the error is the sum of
    squares over ``[T_i, T_i + ΔT0 + 1 s]``, beyond which all candidates agree
    (the model is flat at ``v_ss``).

    Parameters
    ----------
    velocity_fine : array_like, shape (n_fine + 1,)
        Measured velocity on ``grid``, °/s.
    max_breakpoint_s : float
        ΔT0 (4 s in the paper).
    resolution_s : float
        Search step (0.01 s in the paper).
    """
    v = np.asarray(velocity_fine, dtype=float)
    candidates = resolution_s * np.arange(1, round(max_breakpoint_s / resolution_s) + 1)
    vss = steady.rate(segments.step_levels_deg)
    v0 = steady.rate(segments.previous_levels_deg)
    window = max_breakpoint_s + 1.0
    bounds = segments.bounds_s
    errors = np.empty((segments.n_steps, candidates.size))
    for i in range(segments.n_steps):
        lo = _first_at(grid.time_s, bounds[i])
        hi = _first_at(grid.time_s, min(bounds[i] + window, bounds[i + 1]))
        tau = grid.time_s[lo:hi] - bounds[i]
        ramp = tau[None, :] / candidates[:, None]
        model = np.where(ramp < 1.0, v0[i] + (vss[i] - v0[i]) * ramp, vss[i])
        errors[i] = np.sum((model - v[None, lo:hi]) ** 2, axis=1)
    t0 = candidates[np.argmin(errors, axis=1)]
    return BilinearFit(
        t0_s=readonly_array(t0),
        v0_dps=readonly_array(v0),
        vss_dps=readonly_array(vss),
        candidates_s=readonly_array(candidates),
        errors=readonly_array(errors),
        window_s=window,
    )


def bilinear_velocity(
    segments: Segments, bilinear: BilinearFit, grid: FineGrid
) -> tuple[FloatArray, IntArray]:
    """The bi-linear velocity (eq. 18) on the fine grid from ``T_1`` on.

    Returns the velocity (°/s; ``nan`` before ``T_1``) and the step index of
    each fine point (-1 before ``T_1``).
    """
    t = grid.time_s
    bounds = segments.bounds_s
    step = interval_index(bounds, t)
    step = np.where(step >= segments.n_steps, segments.n_steps - 1, step)
    v = np.full(t.size, np.nan)
    after = step >= 0
    k = step[after]
    tau = t[after] - bounds[k]
    t0 = bilinear.t0_s[k]
    v0, vss = bilinear.v0_dps[k], bilinear.vss_dps[k]
    v[after] = np.where(tau < t0, v0 + (vss - v0) * tau / t0, vss)
    return v, step.astype(np.intp)


# --------------------------------------------------------------------------- step 6


@dataclass(frozen=True, eq=False)
class DampingFit:
    """Integral-based damping (eq. 25-34) and the derived b, θ̄ (eq. 29-30).

    Attributes
    ----------
    a_per_s : float
        Constant damping ``a`` (eq. 26), 1/s (the paper: 1.314).
    a_steps_per_s : ndarray, shape (m,)
        Per-step ``a_i`` (eq. 33, Table 1), 1/s.
    alpha : float
        α used, (°/s)/°.
    theta_bar_deg : float
        θ̄ = β/α (eq. 30), °.
    rms_dps : float
        RMS residual of eq. 26, °/s.
    """

    a_per_s: float
    a_steps_per_s: FloatArray
    alpha: float
    theta_bar_deg: float
    rms_dps: float

    @property
    def b_per_s2(self) -> float:
        """b = a·α (eq. 30), (°/s²)/° (the paper: 0.8665)."""
        return self.a_per_s * self.alpha

    @property
    def b_steps_per_s2(self) -> FloatArray:
        """Per-step b_i = a_i·α (Table 1)."""
        return self.a_steps_per_s * self.alpha

    def params(self) -> RollParams:
        """The constant-damping model of eq. 29."""
        return RollParams(self.alpha, self.theta_bar_deg, self.a_per_s)


def fit_damping(
    segments: Segments,
    steady: SteadyStateFit,
    grid: FineGrid,
    velocity_fine: ArrayLike,
    theta_fine: ArrayLike,
) -> DampingFit:
    """Step 6: constant ``a`` (eq. 25-28) and per-step ``a_i`` (eq. 31-34).

    For each step ``i`` and every fine time ``t`` in ``(T_i, T_{i+1})``::

        v(t) - v(T_i) = -a_i · ∫_{T_i}^t (v - (α·θ + β)) dt

    (eq. 25; eq. 32 prints the limits reversed -- see the module docstring).
    The integrals are cumulative trapezium sums from ``T_i``.  Stacking all
    steps with one ``a`` is eq. 26; a separate ``a_i`` per step is the
    block-diagonal system of eq. 33-34, whose least-squares solution is one
    scalar fit per block.

    Parameters
    ----------
    velocity_fine : array_like
        The velocity to fit on the fine grid: the bi-linear velocity of step 4
        (§2.6: it "effectively removes the disturbance"); ``nan`` before ``T_1``.
    theta_fine : array_like
        Fin angle from step 5 on the fine grid, °.
    """
    v = np.asarray(velocity_fine, dtype=float)
    theta = np.asarray(theta_fine, dtype=float)
    t = grid.time_s
    bounds = segments.bounds_s
    num = np.empty(segments.n_steps)
    den = np.empty(segments.n_steps)
    sq = np.empty(segments.n_steps)
    rows: list[FloatArray] = []
    for i in range(segments.n_steps):
        lo = _first_at(t, bounds[i])
        hi = _first_at(t, bounds[i + 1]) if i + 1 < segments.n_steps else t.size
        integrand = v[lo:hi] - steady.rate(theta[lo:hi])
        col = -cumulative_trapezoid(integrand, t[lo:hi])  # I_Ni of eq. 28
        rhs = v[lo + 1 : hi] - v[lo]  # v̄_data,Ni of eq. 27
        num[i] = col @ rhs
        den[i] = col @ col
        sq[i] = rhs @ rhs
        rows.append(rhs)
    if np.any(den <= 0):
        bad = int(np.argmin(den))
        raise IdentificationError(
            f"step {bad + 1} at {bounds[bad]:g} s does not excite the damping (zero integral)"
        )
    a_steps = num / den
    a = float(num.sum() / den.sum())
    if a <= 0.0:
        raise IdentificationError(
            f"the identified constant damping a = {a:.4g} 1/s (eq. 26) is not positive; "
            "the step responses do not decay towards their steady states"
        )
    # Residual of the stacked system with the common a.
    resid_sq = float(sq.sum() - 2 * a * num.sum() + a * a * den.sum())
    count = sum(len(r) for r in rows)
    return DampingFit(
        a_per_s=a,
        a_steps_per_s=readonly_array(a_steps),
        alpha=steady.alpha,
        theta_bar_deg=steady.theta_bar_deg,
        rms_dps=float(np.sqrt(max(resid_sq, 0.0) / max(count, 1))),
    )


# --------------------------------------------------------------------------- step 7


@dataclass(frozen=True, eq=False)
class DampingVsFin:
    """``a(θ) = ᾱ·|θ + θ̄| + β̄`` fitted to the per-step ``a_i`` (eq. 48).

    Attributes
    ----------
    alpha_bar_per_deg_s : float
        ᾱ, 1/(s·°) (the paper: -0.0289).
    beta_bar_per_s : float
        β̄, 1/s (the paper: 2.4075).
    r_squared : float
        R² of the fit without the outlier (the paper: 0.8280).
    x_deg : ndarray
        ``|θ_effective| = |f_ss + θ̄|`` of every step (eq. 47), °.
    a_per_s : ndarray
        The ``a_i``.
    outlier : int or None
        Index of the step left out, if any.
    outlier_p : float or None
        Its Bonferroni-adjusted p-value.
    rule : str
        The outlier rule, in words.
    excluded : tuple of int
        Steps left out because their ``a_i <= 0`` is not a damping.
    """

    alpha_bar_per_deg_s: float
    beta_bar_per_s: float
    r_squared: float
    x_deg: FloatArray
    a_per_s: FloatArray
    outlier: int | None
    outlier_p: float | None
    rule: str
    excluded: tuple[int, ...] = ()

    def params(self, alpha: float, theta_bar_deg: float) -> RollParams:
        """The θ-dependent model of eq. 49."""
        return RollParams(alpha, theta_bar_deg, self.beta_bar_per_s, self.alpha_bar_per_deg_s)


#: Outlier rule of step 7.
OUTLIER_RULE = (
    "steps with a_i <= 0 are left out (not a damping); then at most one more step is left "
    "out: the one with the largest externally studentized residual, if its "
    "Bonferroni-adjusted two-sided p-value is below {level:g} (needs at least 4 steps; "
    "a fit exact to rounding has no outlier)"
)


def fit_damping_vs_fin(
    fin_deg: ArrayLike,
    a_per_s: ArrayLike,
    theta_bar_deg: float,
    *,
    outlier_level: float = 0.05,
) -> DampingVsFin:
    """Step 7: ``a(θ) = ᾱ·|θ + θ̄| + β̄`` by least squares (eq. 47-48).

    The paper drops "the clear outlier" of its Fig. 12.  The rule here is
    deterministic (:data:`OUTLIER_RULE`): fit all steps, compute each step's
    externally studentized residual (``statsmodels`` OLS influence), and leave
    out the single largest one if its Bonferroni-adjusted p-value is below
    ``outlier_level``.  On the paper's Table 1 this drops the 3rd step
    (26.67°, a = 3.2439, p ≈ 0.007) and gives R² = 0.8280, as in Fig. 12.

    Raises
    ------
    IdentificationError
        With fewer than two steps or all ``|θ + θ̄|`` equal.
    """
    f = np.asarray(fin_deg, dtype=float)
    a = np.asarray(a_per_s, dtype=float)
    x = np.abs(f + theta_bar_deg)
    if np.unique(np.round(x, 9)).size < 2:
        raise IdentificationError("a(θ) (eq. 48) needs steps at two or more different |θ + θ̄|")
    keep = np.ones(x.size, dtype=bool)
    outlier: int | None = None
    outlier_p: float | None = None
    # A non-positive a_i is not a damping (e.g. a breakpoint shorter than the
    # servo ramp); such steps are left out and reported.
    excluded = tuple(int(i) for i in np.flatnonzero(a <= 0.0))
    keep[list(excluded)] = False
    if np.unique(np.round(x[keep], 9)).size < 2:
        raise IdentificationError(
            "a(θ) (eq. 48) needs positive per-step damping a_i at two or more different "
            f"|θ + θ̄|; the a_i are {np.array2string(a, precision=3)} 1/s"
        )
    candidates = np.flatnonzero(keep)
    if candidates.size >= 4:
        worst, p = _largest_outlier(x[candidates], a[candidates])
        rest = np.delete(candidates, worst)
        if p < outlier_level and np.unique(np.round(x[rest], 9)).size >= 2:
            outlier, outlier_p = int(candidates[worst]), p
            keep[outlier] = False
    fit = stats.linregress(x[keep], a[keep])
    # The fin passes every |θ + θ̄| from 0 to the largest step while it ramps.
    lowest = float(min(fit.intercept, fit.intercept + fit.slope * x.max()))
    if lowest <= 0.0:
        raise IdentificationError(
            f"the fitted a(θ) = {fit.slope:.4g}·|θ + θ̄| + {fit.intercept:.4g} (eq. 48) is not a "
            f"damping: {lowest:.3g} 1/s within the recorded fin range; the per-step a_i "
            f"{np.array2string(a, precision=3)} 1/s are too scattered for the θ-dependent model"
        )
    return DampingVsFin(
        alpha_bar_per_deg_s=float(fit.slope),
        beta_bar_per_s=float(fit.intercept),
        r_squared=float(fit.rvalue**2),
        x_deg=readonly_array(x),
        a_per_s=readonly_array(a),
        outlier=outlier,
        outlier_p=outlier_p,
        rule=OUTLIER_RULE.format(level=outlier_level),
        excluded=excluded,
    )


def _largest_outlier(x: FloatArray, a: FloatArray) -> tuple[int, float]:
    """Index of the largest externally studentized residual and its Bonferroni p.

    A fit that is exact to rounding has no outlier (p = 1): its studentized
    residuals would be rounding divided by rounding.
    """
    import statsmodels.api as sm

    design = np.column_stack([np.ones_like(x), x])
    result = sm.OLS(a, design).fit()
    scale = max(float(np.max(np.abs(a))), 1.0)
    if float(np.sqrt(np.mean(result.resid**2))) <= 1e-9 * scale:
        return 0, 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        table = result.outlier_test(method="bonf")
    residuals = np.abs(table[:, 0])
    if not np.any(np.isfinite(residuals)):  # nothing to test (e.g. two points)
        return 0, 1.0
    worst = int(np.nanargmax(residuals))
    return worst, float(table[worst, 2])


# --------------------------------------------------------------------------- step 8


def disturbance_system(
    params: RollParams,
    grid: FineGrid,
    theta_fine: ArrayLike,
    *,
    interval_s: float = 0.1,
) -> tuple[FloatArray, FloatArray, IntArray, int]:
    """The velocity-independent parts of eq. 42-43 for every interval.

    Returns ``(q_int, offset_int, index, per)``: with ``W(t) = ∫ a(θ)·v`` and
    the returned cumulative integrals ``Q(t) = ∫ a(θ)·α`` and
    ``F(t) = ∫ a(θ)·α·(θ + θ̄)``, row ``k`` of interval ``i`` of eq. 42 is
    ``C = Q[j] - Q[j0]`` and ``D = v[j] - v[j0] + W[j] - W[j0] - (F[j] - F[j0])``,
    ``j = index[i, k]``, ``j0 = index[i, 0]``.
    """
    theta = np.asarray(theta_fine, dtype=float)
    per = round(interval_s / grid.step_s)
    if per < 1 or abs(per * grid.step_s - interval_s) > 1e-6 * max(interval_s, 1.0):
        raise IdentificationError(
            f"the disturbance interval Δt = {interval_s:g} s is not a multiple of the "
            f"{grid.step_s:g} s fine grid"
        )
    n_intervals = (grid.time_s.size - 1) // per
    if n_intervals < 1:
        raise IdentificationError("the recording is shorter than one disturbance interval")
    a = damping(params, theta)
    q = cumulative_trapezoid(a * params.alpha, grid.time_s, initial=0.0)
    f = cumulative_trapezoid(
        a * params.alpha * (theta + params.theta_bar_deg), grid.time_s, initial=0.0
    )
    index = per * np.arange(n_intervals)[:, None] + np.arange(per + 1)[None, :]
    return q, f, index.astype(np.intp), per


def solve_disturbance(
    grid: FineGrid,
    a_fine: FloatArray,
    q: FloatArray,
    f: FloatArray,
    index: IntArray,
    velocity_fine: FloatArray,
) -> FloatArray:
    """``u_d,i`` of eq. 42 for one or many velocity traces (last axis: fine grid).

    Least squares of ``C̄_i·ū_d,i = D̄_i`` per interval with
    ``ū_d,i = a·α·u_d,i`` (erratum of eq. 39) folded into ``C̄``, so the
    result is already ``u_d,i`` in °.
    """
    v = velocity_fine
    h = grid.step_s
    av = a_fine * v
    # Cumulative trapezium of a(θ)·v along the last axis, starting at 0.
    w = np.zeros_like(v)
    np.cumsum(0.5 * h * (av[..., 1:] + av[..., :-1]), axis=-1, out=w[..., 1:])
    j0 = index[:, :1]
    j = index[:, 1:]
    c = q[j] - q[j0]  # (N, per)
    d = v[..., j] - v[..., j0] + w[..., j] - w[..., j0] - (f[j] - f[j0])
    return np.asarray(np.sum(c * d, axis=-1) / np.sum(c * c, axis=-1), dtype=float)


def identify_disturbance(
    params: RollParams,
    model: str,
    grid: FineGrid,
    theta_fine: ArrayLike,
    velocity_fine: ArrayLike,
    *,
    interval_s: float = 0.1,
) -> Disturbance:
    """Step 8: ``u_d(t)``, piecewise constant over ``Δt = interval_s`` (eq. 37-44).

    Integrating eq. 36 over each interval from ``t_{i-1}``::

        v(t) - v(t_{i-1}) + ∫ a(θ)·(v - α·(θ + θ̄)) = u_d,i · ∫ a(θ)·α

    at the ``N_t`` fine times ``t_{i-1} + k·δt`` (eq. 40-41) gives ``N_t``
    equations in ``u_d,i``, solved by least squares (eq. 42-43).  With
    constant damping ``∫ a·α = a·α·k·δt``: eq. 43's ``C̄_i`` times ``a·α`` --
    the corrected eq. 39, ``ū_d,i = a·α·u_d,i``.  For the θ-dependent model
    ``a(θ(t))`` is integrated with the fin angle instead of being frozen at
    ``t_{i-1}``; the two agree wherever the fin is still.

    Parameters
    ----------
    params : RollParams
        α, θ̄ and the damping (constant or a(θ)).
    model : str
        Label stored in the result (``constant`` or ``theta``).
    grid : FineGrid
        The 100 Hz grid.
    theta_fine, velocity_fine : array_like, shape (n_fine + 1,)
        Fin angle (step 5) and the smoothed measured velocity, interpolated.
    interval_s : float
        Δt (0.1 s).
    """
    theta = np.asarray(theta_fine, dtype=float)
    q, f, index, _ = disturbance_system(params, grid, theta, interval_s=interval_s)
    a = damping(params, theta)
    u = solve_disturbance(grid, a, q, f, index, np.asarray(velocity_fine, dtype=float))
    return Disturbance(
        model=model,
        params=params,
        interval_s=interval_s,
        start_s=readonly_array(grid.time_s[index[:, 0]]),
        u_d_deg=readonly_array(u),
    )


# --------------------------------------------------------------------------- step 9


@dataclass(frozen=True, eq=False)
class Resimulation:
    """Re-simulation of one model driven by its ``u_d`` (§3.5, Figs. 19-21).

    Attributes
    ----------
    model : str
        ``constant`` or ``theta``.
    time_s : ndarray
        Recording sample times, s.
    rate_dps, angle_deg : ndarray
        Simulated roll rate and angle at the samples.
    rate_mae_dps, rate_sd_dps : float
        Mean and SD of ``|v_sim - v_measured|`` (the paper: < 0.10, < 0.08 °/s).
    angle_mae_deg, angle_sd_deg : float
        Mean and SD of ``|φ_sim - φ_measured|`` (the paper: < 0.20°, < 0.15°).
    """

    model: str
    time_s: FloatArray
    rate_dps: FloatArray
    angle_deg: FloatArray
    rate_mae_dps: float
    rate_sd_dps: float
    angle_mae_deg: float
    angle_sd_deg: float


def resimulate(
    disturbance: Disturbance,
    recording: Recording,
    grid: FineGrid,
    theta_fine: ArrayLike,
    velocity: ArrayLike,
    angle: ArrayLike,
    *,
    initial: tuple[float, float] | None = None,
) -> Resimulation:
    """Step 9: simulate eq. 29/49 with the identified ``u_d`` from the initial state.

    The model (:func:`identification.model.simulate`, exact update) runs on the
    fine grid with the fin angle of step 5, starting from the measured
    velocity and angle at the first sample -- or from ``initial`` (rate °/s,
    angle °), a method's own estimate of them -- open loop to the end.  Errors
    are taken at the recording's samples against the measured velocity (the
    smoothed one the disturbance was fitted to) and the measured angle.
    """
    theta = np.asarray(theta_fine, dtype=float)
    v_meas = np.asarray(velocity, dtype=float)
    phi_meas = np.asarray(angle, dtype=float)
    rate0, angle0 = (float(v_meas[0]), float(phi_meas[0])) if initial is None else initial
    u_fine = disturbance.at(grid.time_s[:-1])
    sim = simulate(
        disturbance.params,
        grid.step_s,
        theta,
        u_fine,
        rate0_dps=rate0,
        angle0_deg=angle0,
        servo=None,
        substeps=1,
        t0_s=float(grid.time_s[0]),
    )
    rate = sim.rate_dps[:: grid.per_sample]
    phi = sim.angle_deg[:: grid.per_sample]
    rate_err = np.abs(rate - v_meas)
    angle_err = np.abs(phi - phi_meas)
    return Resimulation(
        model=disturbance.model,
        time_s=readonly_array(recording.time_s),
        rate_dps=readonly_array(rate),
        angle_deg=readonly_array(phi),
        rate_mae_dps=float(rate_err.mean()),
        rate_sd_dps=float(rate_err.std(ddof=1)),
        angle_mae_deg=float(angle_err.mean()),
        angle_sd_deg=float(angle_err.std(ddof=1)),
    )
