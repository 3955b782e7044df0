"""Fit adequacy: does an identified model describe the recording, and how well?

Every method's own figure (the re-simulation error with its ``u_d`` added back,
§3.5) cannot tell a good model from a bad one: ``u_d`` absorbs any model error.
These figures read the model without it, against the raw measurements:

* **model only** -- the model simulated from the first reading with ``u_d = 0``
  over the whole recording: R² and MAE of the rate against the raw rate (the
  gyro, else the velocity measured from the angle) and MAE of the angle;
* **ahead** -- the rate predicted ``k`` readings ahead from each measured
  velocity with ``u_d = 0``, ``k`` the rocket's time constant ``1/a`` (at least
  one reading): R² against the raw rate, a figure long records cannot drift;
* **u_d explained by the fin** -- the share of ``u_d``'s variance a line in
  the fin angle, its size ``|θ + θ̄|`` and its change over the interval
  explains: turbulence does not know the fin, so a gain, a damping law or a
  servo that is wrong leaks into ``u_d`` as a fin-shaped part (an effect size,
  not a p-value, which on a long record rejects everything), counted where that
  part is material: its SD at least :data:`FIN_ERROR_MATERIAL` of the fin's own
  (a share of a ``u_d`` that is all but zero -- a rig without turbulence -- is
  the fit's rounding, not model error);
* **u_d against the fins' range** -- the 99th percentile of ``|u_d|``, as a
  fraction of the servo's range: a "disturbance" the fins could not cancel is
  the model's error, not turbulence;
* **the fin's range** -- a fin whose 99th percentile of ``|fin|`` stays under
  :data:`~identification.recordings.recording.PLAUSIBLE_FIN_DEG` (1°) is no rocket's: a fin in
  radians read as degrees (±10° reads ±0.17) gives a gain or a ``u_d`` 57 times off,
  which every other figure misses (they are ratios): unreliable, with the unit to check;
* **the gain's relative standard error**, where the method reports one;
* **the innovations' whiteness**, where the method has them (ml: its one-step
  prediction errors of the first sensor): the largest ``|ACF|`` over lags 1-10, an
  effect size counted where it is at least :data:`INNOVATION_ACF` and four times
  white noise's ``1/√n`` and Ljung-Box rejects whiteness (p < :data:`FIN_SHARE_P`);
  a model that is right leaves nothing predictable in them;
* for the paper's method, its assumptions: a steady state in each dwell
  (steady-state R²) and a positive damping ``a_i`` from each step.

Under a rate loop the recording states (its ``loop.*`` lines,
:class:`~identification.recordings.recording.StatedLoop`) the fin follows the rate and so
the turbulence, and a right model's ``u_d`` is correlated with it: the model only is then
the closed loop driven by the excitation on top of it (the loop's command from the
excitation given back from the log and the model's own rate), ``u_d`` is tested against
that excitation instead of the fin (it moves the fin, and the turbulence does not move
it), and the ``ahead`` figure is not judged (the loop regulates the rate it would be
scored against, so a right model predicts little of it).

Two figures name an effect the model lacks (:attr:`Adequacy.suspected`; they do not
change the verdict: the fit may still serve, and the remedy is another model):

* **the fin's delay** -- a lag of the fin behind the modelled servo or late sensors
  leave ``u_d`` a part ``-τ·dθ/dt`` (the model's fin leads the one that acts); in
  first differences, where the turbulence's slow part cancels, ``Δu_d`` regressed on
  the change of the fin's rate gives ``τ`` and its z (Newey-West); suspected where
  the fin acts later than the model by at least :data:`DELAY_MATERIAL_S` at one-sided
  p < :data:`DELAY_P`: a servo lag or a sensor latency (the latency alone where the fin
  is measured);
* **the turbulence's intensity** -- the SD of the log variance of ``u_d`` over
  :data:`INTENSITY_WINDOW_S` windows, against the median of the same for the fitted
  turbulence process (stationary; simulated): at :data:`INTENSITY_RATIO` times it or
  more, the intensity wanders (gusts, regimes), which a stationary turbulence model and
  its surrogates do not replay.

Each figure feeds the verdict, ``good``, ``weak`` or ``unreliable``, through the
thresholds below, with the reasons that set it.  They are calibrated on known
truths (``benchmarks/adequacy.py``: correct fits of the virtual tunnel's rockets
on ramps, doublets and PRBS against deliberately wrong ones).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from identification.compiled import interval_maps
from identification.methods.diagnosis import diagnose, logged_fin, loop_law
from identification.methods.pipeline import Measurements
from identification.methods.statistics import decorrelation_stride, ols_newey_west
from identification.model import (
    Disturbance,
    RollParams,
    Servo,
    damping,
    linear_recurrence,
    roll_step,
)
from identification.recordings.recording import (
    PLAUSIBLE_FIN_DEG,
    FinRange,
    Recording,
    StatedLoop,
    small_fins,
)
from rocketroll_common.arrays import FloatArray

__all__ = [
    "VERDICTS",
    "Adequacy",
    "Findings",
    "ModelOnly",
    "adequacy",
    "beyond",
    "fin_delay",
    "intensity_ratio",
    "model_only",
    "r_squared",
    "suspects",
]

#: The verdicts, best first.
VERDICTS = ("good", "weak", "unreliable")

#: Model-only rate R² below which a fit is weak / unreliable.
RATE_R2 = (0.5, 0.2)
#: Rate R² ``k`` readings ahead below which a fit is weak / unreliable.
AHEAD_R2 = (0.5, 0.2)
#: Share of ``u_d``'s variance the fin explains above which a fit is weak / unreliable.
FIN_SHARE = (0.15, 0.25)
#: Newey-West p-value below which that share counts (it is not chance).
FIN_SHARE_P = 0.001
#: The fin-shaped part of ``u_d`` (SD, ° of fin) as a fraction of the fin's SD below
#: which it is immaterial, whatever its share.
FIN_ERROR_MATERIAL = 0.02
#: 99th percentile of ``|u_d|`` as a fraction of the fins' range above which a fit is
#: weak / unreliable.
UD_RANGE = (1.0, 1.5)
#: Largest |autocorrelation| of the innovations (lags 1-10) from which they count as not
#: white (with four times 1/√n and Ljung-Box p < FIN_SHARE_P): weak.
INNOVATION_ACF = 0.05
#: The gain's relative standard error above which a fit is weak / unreliable.
ALPHA_REL_SE = (0.25, 0.5)
#: The paper's steady-state R² below which its dwells did not settle (weak).
STEADY_STATE_R2 = 0.95
#: One-sided p below which the fin's delay is suspected ...
DELAY_P = 0.005
#: ... where it is at least this long, s.
DELAY_MATERIAL_S = 0.01
#: Window of the turbulence's intensity, s.
INTENSITY_WINDOW_S = 10.0
#: Dispersion of the windowed log variance, over a stationary process's, from which the
#: intensity is suspected to wander.
INTENSITY_RATIO = 1.8
#: Simulations of the stationary process for the intensity's reference.
INTENSITY_SIMULATIONS = 64


def beyond(value: float, limits: tuple[float, float], above: bool) -> int:
    """Which of a figure's ``(weak, unreliable)`` limits ``value`` passes: 0 none, 1 the
    weak one, 2 the unreliable one; ``above``: larger is worse (else smaller is)."""
    sign = 1.0 if above else -1.0
    if sign * value > sign * limits[1]:
        return 2
    return 1 if sign * value > sign * limits[0] else 0


class Findings:
    """The reasons a fit is weak or unreliable, collected figure by figure."""

    def __init__(self) -> None:
        self.weak: list[str] = []
        self.bad: list[str] = []

    def check(self, value: float, limits: tuple[float, float], text: str, above: bool) -> None:
        """``text`` as a reason where ``value`` passes a limit (:func:`beyond`)."""
        severity = beyond(value, limits, above)
        if severity:
            (self.weak if severity == 1 else self.bad).append(text)

    def fin_unit(self, recording: Recording) -> None:
        """A fin that stays under
        :data:`~identification.recordings.recording.PLAUSIBLE_FIN_DEG` (99th percentile of
        ``|fin|``): unreliable, whatever the fit, for the gain or ``u_d`` it gives is then most
        likely in the wrong unit (a fin in radians read as degrees)."""
        for name, p99 in small_fins(recording.columns()).items():
            self.bad.append(
                f"the fin ({name}) stays within {p99:.2g}° (99 % of |fin|), under "
                f"{PLAUSIBLE_FIN_DEG:g}°: a fin logged in radians and read as degrees looks "
                "like this, and the gain or u_d is then 57 times off; check the fin's unit "
                "(set the fin to a known 10° and see the log read 10, not 0.17) and "
                f"re-import with import-csv --unit {name.removesuffix('_deg')}=rad if so"
            )

    def rate_r2(self, r2: float) -> None:
        """The model without ``u_d`` against the measured rate (:data:`RATE_R2`)."""
        self.check(r2, RATE_R2, f"the model without u_d explains {r2:.2f} of the rate (R²)", False)

    @property
    def verdict(self) -> str:
        return "unreliable" if self.bad else "weak" if self.weak else "good"

    @property
    def reasons(self) -> tuple[str, ...]:
        """The unreliable reasons first."""
        return (*self.bad, *self.weak)


@dataclass(frozen=True)
class Adequacy:
    """How well one fit describes its recording (module docstring)."""

    rate_source: str
    rate_r2: float
    rate_mae_dps: float
    angle_mae_deg: float
    ahead_s: float
    ahead_r2: float
    fin_share: float
    fin_share_p: float
    fin_error_ratio: float
    ud_p99_deg: float
    ud_range_fraction: float
    alpha_rel_se: float
    innovation_acf: float
    verdict: str
    reasons: tuple[str, ...]
    fin_delay_s: float = math.nan
    fin_delay_z: float = math.nan
    intensity_ratio: float = math.nan
    suspected: tuple[str, ...] = ()
    diagnosis: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe (NaN as None)."""
        out = asdict(self)
        out["reasons"] = list(self.reasons)
        out["suspected"] = list(self.suspected)
        return {
            k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in out.items()
        }


def r_squared(predicted: FloatArray, measured: FloatArray) -> float:
    """1 - SSE / SST of ``predicted`` against ``measured`` (NaN where it does not vary)."""
    spread = float(np.sum((measured - measured.mean()) ** 2))
    if spread <= 0.0:
        return float("nan")
    return 1.0 - float(np.sum((measured - predicted) ** 2)) / spread


def _fin_share(
    u: FloatArray, fin: FloatArray, theta_bar: float, lag: FloatArray
) -> tuple[float, float]:
    """Share of ``u``'s variance explained by a line in the fin, its size ``|θ + θ̄|``,
    its change, the model's own lag behind its steady state ``lag`` and that times the
    size (what a wrong gain, damping law or servo leaves), and the p-value of that line
    (a Wald test with Newey-West covariance: turbulence correlated over many readings
    meets the fin's few moves in a short record, and explains some of it by chance).

    The arithmetic of statsmodels' ``OLS(...).fit(cov_type="HAC")`` and its
    ``wald_test(..., scalar=True)`` (Bartlett weights, no small-sample factor, χ²),
    written out (:func:`identification.methods.statistics.ols_newey_west`): the results object's
    machinery and the kernel's loop over lags cost more than the regression (p-values
    equal to statsmodels' to 1e-9 relative, tested)."""
    size = np.abs(fin[:-1] + theta_bar)
    design = np.column_stack(
        [np.ones(u.size), fin[:-1], size, np.diff(fin), lag[:-1], lag[:-1] * size]
    )
    return _explained(u, design)


def _excitation_share(
    u: FloatArray, excitation: FloatArray, saturated: FloatArray
) -> tuple[float, float]:
    """:func:`_fin_share` under a stated loop: the share of ``u`` a line in the loop's
    excitation and its change explains (the samples where the command was off the stops),
    and its p-value.  In a loop the fin follows the rate and so the turbulence, and explains
    some of a right model's ``u_d``; the excitation, which the turbulence does not move,
    explains none of it unless the model is wrong."""
    off = ~np.asarray(saturated[:-1], dtype=bool) & ~np.asarray(saturated[1:], dtype=bool)
    design = np.column_stack([np.ones(u.size), excitation[:-1], np.diff(excitation)])
    if np.count_nonzero(off) < 8:
        return 0.0, 1.0
    return _explained(u[off], design[off])


def _explained(u: FloatArray, design: FloatArray) -> tuple[float, float]:
    """The share of ``u``'s variance a line in the columns of ``design`` (the constant
    first) explains, and the Wald p-value of that line (Newey-West covariance)."""
    from scipy import stats

    if not np.ptp(u) > 0.0:
        return 0.0, 1.0
    # Lags of the covariance: twice u's correlation length (first lag below 1/e), at most n/4.
    maxlags = min(2 * decorrelation_stride(u, math.exp(-1.0)), u.size // 4)
    # Columns that repeat others (the size is the fin itself where θ + θ̄ keeps one sign):
    # each kept where it is not, to 1e-8 of its own size, a combination of those before it
    # (the diagonal of R in the QR factorisation of the columns scaled to one, the constant
    # first).
    scaled = design / np.maximum(np.abs(design).max(axis=0), 1e-300)
    diagonal = np.abs(np.diag(np.linalg.qr(scaled, mode="r")))
    keep = diagonal > 1e-8 * np.maximum(np.linalg.norm(scaled, axis=0), 1e-300)
    x = design[:, keep]
    if x.shape[1] < 2:
        return 0.0, 1.0
    try:
        beta, resid, cov = ols_newey_west(x, u, max(maxlags, 1))
    except np.linalg.LinAlgError:
        return 0.0, 1.0
    centred = u - u.mean()
    r2 = 1.0 - float(resid @ resid) / float(centred @ centred)
    try:
        wald = float(beta[1:] @ np.linalg.solve(cov[1:, 1:], beta[1:]))
    except np.linalg.LinAlgError:
        return max(r2, 0.0), 1.0
    if not (np.isfinite(r2) and np.isfinite(wald)):
        return 0.0, 1.0
    return max(r2, 0.0), float(stats.chi2.sf(wald, x.shape[1] - 1))


def fin_delay(u: FloatArray, fin: FloatArray, dt_s: float) -> tuple[float, float]:
    """How much later than the model the fin acts, s, and its z: ``Δu`` (one per interval)
    regressed on the change of the fin's rate ``Δ(Δθ/Δt)`` with a constant, Newey-West
    covariance over 10 lags; ``u ≈ −τ·dθ/dt`` gives ``τ = −slope``.  (NaN, NaN) where the
    fin does not move."""
    rate = np.diff(fin[: u.size + 1]) / dt_s
    du, dd = np.diff(u), np.diff(rate)
    if du.size < 8 or not np.ptp(dd) > 0.0:
        return math.nan, math.nan
    x = np.column_stack([np.ones(du.size), dd])
    beta, _, cov = ols_newey_west(x, du, min(10, du.size // 4))
    se = math.sqrt(cov[1, 1]) if cov[1, 1] > 0.0 else math.nan
    return -float(beta[1]), -float(beta[1]) / se


def _log_variance_spread(x: FloatArray, window: int) -> float:
    """SD of the log variance of ``x`` over consecutive windows of ``window`` samples."""
    m = x.size // window
    blocks = x[: m * window].reshape(m, window)
    return float(np.std(np.log(blocks.var(axis=1) + 1e-300)))


def intensity_ratio(u: FloatArray, dt_s: float, ar: FloatArray) -> float:
    """How much more the intensity of ``u`` wanders than a stationary AR(``ar``) process's:
    :func:`_log_variance_spread` over :data:`INTENSITY_WINDOW_S` windows against its
    median over :data:`INTENSITY_SIMULATIONS` simulations of that process (seeded).  NaN
    for fewer than four windows."""
    from scipy.signal import lfilter

    window = max(4, round(INTENSITY_WINDOW_S / dt_s))
    if u.size < 4 * window:
        return math.nan
    rng = np.random.default_rng(0)
    burn = 20 * window
    noise = rng.standard_normal((INTENSITY_SIMULATIONS, u.size + burn))
    paths = lfilter([1.0], np.concatenate([[1.0], -np.asarray(ar, dtype=float)]), noise, axis=1)
    reference = np.median([_log_variance_spread(p[burn:], window) for p in paths])
    return _log_variance_spread(u - u.mean(), window) / float(reference)


def suspects(
    u: FloatArray, fin: FloatArray, dt_s: float, fin_measured: bool, ar: FloatArray | None
) -> tuple[float, float, float, list[str]]:
    """The figures that name an effect the model lacks (module docstring) and what they
    suspect: the fin's delay (:func:`fin_delay`, ``fin`` at the readings; with
    ``fin_measured`` only a sensor latency explains it) and, given the fitted turbulence's
    AR coefficients ``ar``, its intensity (:func:`intensity_ratio`; NaN without them).
    Returns ``(delay_s, delay_z, intensity_ratio, suspected)``."""
    suspected = []
    delay_s, delay_z = fin_delay(u, fin, dt_s)
    one_sided = 0.5 * math.erfc(delay_z / math.sqrt(2.0)) if math.isfinite(delay_z) else 1.0
    if one_sided < DELAY_P and delay_s >= DELAY_MATERIAL_S:
        which = (
            "a sensor latency (the fin is measured)"
            if fin_measured
            else "a servo lag or a sensor latency"
        )
        suspected.append(
            f"the fin acts {1000 * delay_s:.0f} ms later than the model (z = {delay_z:.1f}): "
            f"{which}; state it (identify --servo-lag/--sensor-latency) or measure the fin"
        )
    ratio = math.nan if ar is None else intensity_ratio(u, dt_s, ar)
    if ratio >= INTENSITY_RATIO:
        suspected.append(
            f"the turbulence's intensity wanders: its {INTENSITY_WINDOW_S:g}-s variance "
            f"varies {ratio:.1f}x as much as a stationary turbulence's (gusts, regimes): "
            "replay the posterior draws, which follow it, not surrogates"
        )
    return delay_s, delay_z, ratio, suspected


@dataclass(frozen=True, eq=False)
class ModelOnly:
    """A fit's model driven by the fin alone (``u_d = 0``) from the first reading.

    Attributes
    ----------
    rate_dps, angle_deg : ndarray
        Its roll rate and angle at the recording's readings.
    measured_rate_dps : ndarray
        The rate it is judged against: the gyro's raw readings, else the velocity
        differentiated from the angle (smoothed).
    rate_source : str
        ``gyro`` or ``velocity from the angle``.
    maps : ndarray
        The model's interval maps (:func:`identification.compiled.interval_maps`).
    """

    rate_dps: FloatArray
    angle_deg: FloatArray
    measured_rate_dps: FloatArray
    rate_source: str
    maps: FloatArray


def model_only(inputs: Measurements, params: RollParams, fins: FinRange | None = None) -> ModelOnly:
    """``params``' model without ``u_d`` on the recording of ``inputs``: what the fit
    predicts from the fin alone, the figure the adequacy judges first; under a stated loop,
    the closed loop, saturated at its stops, else at ``fins`` (default: the recording's)."""
    rec, grid = inputs.recording, inputs.grid
    maps = interval_maps(params, np.asarray(inputs.theta_fine), grid.per_sample, grid.step_s)
    e, f, a_phi, g_phi = maps[:, 0], maps[:, 2], maps[:, 3], maps[:, 5]
    smoothed = np.asarray(inputs.velocity_dps, dtype=float)
    if rec.roll_rate_dps is not None:
        rate, source = np.asarray(rec.roll_rate_dps, dtype=float), "gyro"
    else:
        rate, source = smoothed, "velocity from the angle"
    loop = rec.loop
    if loop is not None:  # the closed loop, driven by the excitation on top of it
        stops = loop.stops_within(fins or rec.fin_range())
        v, phi = _closed_loop(inputs, params, loop, stops, rate, float(smoothed[0]))
        return ModelOnly(v, phi, rate, source, maps)
    v = linear_recurrence(e, f, float(smoothed[0]))
    phi = float(np.asarray(inputs.angle_deg)[0]) + np.concatenate(
        [[0.0], np.cumsum(a_phi * v[:-1] + g_phi)]
    )
    return ModelOnly(v, phi, rate, source, maps)


def _closed_loop(
    inputs: Measurements,
    params: RollParams,
    loop: StatedLoop,
    stops: float,
    rate: FloatArray,
    v0: float,
) -> tuple[FloatArray, FloatArray]:
    """``params``' model under the stated ``loop`` without ``u_d``: the loop's command from
    the excitation given back from the log (:meth:`StatedLoop.excitation`) and the model's
    own rate read ``loop.delay_s`` before (linearly between its samples), held over each
    interval and followed by the fin at the servo's rate where the fin is modelled from
    the commands (:func:`identification.model.roll_step`; the rig's linkage and the
    sensors' latency left out); the rate and angle at the readings."""
    rec = inputs.recording
    time = np.asarray(rec.time_s, dtype=float)
    excitation, _ = loop.excitation(time, logged_fin(rec), rate, stops)
    at = np.clip((time - loop.delay_s - time[0]) / rec.dt_s, 0.0, None)
    below = np.floor(at + 1e-9).astype(int)
    fraction = np.where(at - below > 1e-9, at - below, 0.0)
    v = np.empty(time.size)
    phi = np.empty(time.size)
    v[0], phi[0] = v0, float(np.asarray(inputs.angle_deg)[0])
    servo = inputs.servo_rate_dps
    fin = float(logged_fin(rec)[0])
    for k in range(time.size - 1):
        i = min(int(below[k]), k)
        reading = v[i] + (fraction[k] * (v[i + 1] - v[i]) if i < k else 0.0)
        command = loop.command(float(excitation[k]), float(reading), stops)
        h = float(time[k + 1] - time[k])
        end = command if servo is None else fin + float(np.clip(command - fin, -servo * h,
                                                                servo * h))  # fmt: skip
        step = roll_step(params, v[k], phi[k], fin, end, 0.0, h, servo)
        v[k + 1], phi[k + 1], fin = float(step[0]), float(step[1]), end
    return v, phi


def _ahead(
    model: ModelOnly, smoothed: FloatArray, params: RollParams, fin: FloatArray, dt: float
) -> tuple[int, float]:
    """The model's prediction ``k`` readings ahead of each measured velocity (``k`` its time
    constant in readings): ``k`` and the R² of the prediction against the measured rate."""
    e, f = model.maps[:, 0], model.maps[:, 2]
    rate = model.measured_rate_dps
    n = rate.size
    a_mean = float(np.mean(damping(params, fin)))
    k = max(1, round(1.0 / (a_mean * dt))) if a_mean > 0 else 1
    k = min(k, n - 2)
    ahead = smoothed[: n - k].copy()
    for j in range(k):
        ahead = e[j : n - k + j] * ahead + f[j : n - k + j]
    return k, r_squared(ahead, rate[k:])


#: How far (relative) the loop gain the log shows (the diagnosis's) may be from the stated
#: one before the instrumental fit is judged unreliable for it: the diagnosis's estimate
#: was within 8 % of the flown gain on delayed, instant, servo-lag and backlash loops
#: (``benchmarks/instrumental.py``'s logs).
LOOP_GAIN_TOLERANCE = 0.15

#: The methods that read the fin as independent of the turbulence (not consistent in a loop).
_OPEN_LOOP_METHODS = ("paper", "output-error")


def _method_findings(found: Findings, metrics: Mapping[str, Any], method: str) -> float:
    """What a method's own figures say against its fit (innovations that are not white; the
    paper's steps without a damping or a steady state); the innovations' largest |ACF|."""
    innovations = metrics.get("innovations") or {}
    innovation_acf = float(innovations.get("max_acf", math.nan))
    if (
        innovation_acf >= max(INNOVATION_ACF, 4.0 / math.sqrt(max(innovations.get("n", 1), 1)))
        and innovations.get("ljung_box_p", 1.0) < FIN_SHARE_P
    ):
        found.weak.append(
            f"its {innovations.get('sensor', 'sensor')}'s innovations are not white (|ACF| "
            f"up to {innovation_acf:.2f}, Ljung-Box p = {innovations['ljung_box_p']:.2g}): "
            "the model leaves something predictable"
        )
    if method == "paper":
        steps = metrics.get("steps") or []
        negative = [s for s in steps if isinstance(s, dict) and not s.get("a_per_s", 1.0) > 0.0]
        if negative:
            found.bad.append(
                f"{len(negative)} of {len(steps)} steps give a damping a_i <= 0: the dwells "
                "are not the steps from rest to a steady state the method assumes"
            )
        ss = metrics.get("steady_state_r2")
        if ss is not None and ss < STEADY_STATE_R2:
            found.weak.append(
                f"steady-state R² {ss:.2f}: the dwells did not settle to a steady rate"
            )
    return innovation_acf


def _loop_alone_finding(found: Findings, metrics: Mapping[str, Any]) -> None:
    """Where a rate loop alone moves the fin within the log's sample (the ml fit's
    ``loop_alone``): the rocket is not determined, and what would tell it."""
    loop = metrics.get("loop_alone")
    if not loop:
        return
    found.bad.append(
        f"a rate loop alone moves the fin and answers within the log's sample "
        f"({loop_law(loop['gain'], loop['delay_s'])}, "
        f"{'as stated' if loop['stated'] else 'as the log shows'}): the fin carries the "
        "turbulence of the sample it is logged with, so ml is not consistent, and the log does "
        "not tell the rocket's gain, damping and asymmetry apart (nor the loop's damping from "
        "the turbulence's correlation). To identify the rocket, put a dither or PRBS on the fin "
        "command and state the loop (--loop-gain, --loop-delay, --method instrumental), or log "
        "faster than the loop answers"
    )


def _instrument_findings(
    found: Findings, metrics: Mapping[str, Any], figures: Mapping[str, Any]
) -> None:
    """What an instrumental-variables fit's instruments say against it: weak (the first
    stage's F under 10), the fin read as its own instrument in a closed loop, or a stated
    loop's gain the log does not show (``figures``: the diagnosis's)."""
    instruments = metrics.get("instruments")
    if not instruments:
        return
    stated = (instruments.get("loop") or {}).get("gain")
    shown = figures.get("loop_gain")
    if stated and shown is not None and abs(shown / stated - 1.0) > LOOP_GAIN_TOLERANCE:
        found.bad.append(
            f"the stated loop's gain ({stated:.3g}) is not the one the log shows "
            f"({loop_law(shown, figures['loop_delay_s'])}): the "
            "excitation given back with a wrong gain carries the rate, and with it the "
            "turbulence, and biases the fit; check the flight computer's gain (and its "
            "units: ° of fin per °/s)"
        )
    if instruments["source"] == "fin" and figures["closed_loop"]:
        found.bad.append(
            "the fin follows the roll rate (a closed loop) and no loop is stated, so the fin "
            "is no instrument (it carries the turbulence); state the loop (--loop-gain, "
            "--loop-delay) for the excitation on top of it to be the instrument"
        )
    if instruments["weak"]:
        shown = ", ".join(f"{k} {v:.2g}" for k, v in instruments["first_stage_f"].items())
        found.bad.append(
            f"its instruments are weak (first-stage F {shown}, under 10): "
            f"{instruments['described']} moves the fin and the rate too little beside the "
            "turbulence to tell the rocket apart; a larger or longer excitation (a dither "
            "of a few degrees, PRBS bits near the rocket's time constant) makes them strong"
        )


def adequacy(
    inputs: Measurements,
    params: RollParams,
    disturbance: Disturbance,
    metrics: Mapping[str, Any] | None = None,
    *,
    method: str = "",
    servo: Servo | None = None,
) -> Adequacy:
    """The adequacy figures and verdict of one fit (module docstring).

    Parameters
    ----------
    inputs : Measurements
        The recording as the methods read it.
    params : RollParams
        The fit.
    disturbance : Disturbance
        Its ``u_d``.
    metrics : dict, optional
        The method's metrics (standard errors, the paper's steady state and steps).
    method : str
        The method's name (``paper`` adds its assumptions).
    servo : Servo, optional
        A servo whose range the caller states as the fins' range ``u_d`` is measured against
        (default: the recording's,
        :meth:`~identification.recordings.recording.Recording.fin_range`: stated, else the
        log's largest ``|fin|``); the reason names where it comes from.
    """
    rec = inputs.recording
    metrics = metrics or {}
    grid = inputs.grid
    fins = rec.fin_range(None if servo is None else servo.range_deg)
    model = model_only(inputs, params, fins)
    smoothed = np.asarray(inputs.velocity_dps, dtype=float)
    rate, source = model.measured_rate_dps, model.rate_source
    v, phi = model.rate_dps, model.angle_deg
    rate_r2 = r_squared(v, rate)
    rate_mae = float(np.mean(np.abs(v - rate)))
    angle_mae = (
        float(np.mean(np.abs(phi - np.asarray(rec.roll_deg, dtype=float))))
        if rec.roll_deg is not None
        else float("nan")
    )
    fin = np.asarray(inputs.theta_fine[:: grid.per_sample], dtype=float)
    dt = float(np.median(np.diff(rec.time_s)))
    k, ahead_r2 = _ahead(model, smoothed, params, fin, dt)
    # u_d against the fin and the fins' range.
    u = disturbance.at(np.asarray(rec.time_s)[:-1])
    # The model's own distance from its steady state, in fin degrees: input-driven only.
    lag = fin + params.theta_bar_deg - v / params.alpha
    loop = rec.loop
    if loop is None:
        share, share_p = _fin_share(u, fin, params.theta_bar_deg, lag)
        explains = "the fin explains"
    else:
        excitation, saturated = loop.excitation(
            rec.time_s, logged_fin(rec), rate, loop.stops_within(fins)
        )
        share, share_p = _excitation_share(u, excitation[: u.size + 1], saturated[: u.size + 1])
        explains = "the excitation on top of the stated loop explains"
    p99 = float(np.percentile(np.abs(u), 99.0))
    alpha_se = (metrics.get("std_errors") or {}).get("alpha")
    if alpha_se is None or metrics.get("loop_alone"):
        rel_se = math.nan  # the method reports none, or says why the log determines no α
    else:  # NaN where the information matrix is not positive definite: no precision at all
        rel_se = abs(alpha_se / params.alpha) if math.isfinite(alpha_se) else math.inf

    found = Findings()
    check = found.check
    found.fin_unit(rec)
    found.rate_r2(rate_r2)
    if loop is None:  # under a stated loop the loop regulates the rate it would be scored on
        check(
            ahead_r2,
            AHEAD_R2,
            f"{k * dt:.2g} s ahead it predicts the rate to R² {ahead_r2:.2f}",
            False,
        )
    fin_sd = float(np.std(fin))
    fin_error = math.sqrt(share) * float(np.std(u)) / fin_sd if fin_sd > 0 else math.inf
    if share_p < FIN_SHARE_P and fin_error >= FIN_ERROR_MATERIAL:
        check(
            share,
            FIN_SHARE,
            f"{explains} {100 * share:.0f} % of u_d (p = {share_p:.2g}): model error",
            True,
        )
    check(
        p99 / fins.deg,
        UD_RANGE,
        f"u_d reaches {p99:.3g}° (99th percentile), "
        f"{p99 / fins.deg:.2g} of the fins' {fins}{fins.hint}",
        True,
    )
    check(rel_se, ALPHA_REL_SE, f"α's standard error is {100 * rel_se:.3g} % of it", True)
    innovation_acf = _method_findings(found, metrics, method)
    why = diagnose(
        logged_fin(rec)[: fin.size],
        rate[: fin.size],
        dt,
        fins,
        turbulence_sd_deg=metrics.get("u_d_sd_deg") or float(np.std(u)),
    )
    if why.figures["closed_loop"] and method in _OPEN_LOOP_METHODS:
        found.bad.append(
            f"the fin follows the roll rate (a closed loop): {method} is not consistent on "
            "closed-loop data, for the fin carries the turbulence through the loop; use ml, "
            "or state the loop (--loop-gain, --loop-delay) and use instrumental"
        )
    _instrument_findings(found, metrics, why.figures)
    _loop_alone_finding(found, metrics)
    # What the model lacks, named: the fin's delay, the turbulence's wandering intensity.
    ar = metrics.get("ar")
    if ar is None:  # an AR(1) of u_d itself where the method fits no turbulence model
        centred = u - u.mean()
        ar = [float(centred[1:] @ centred[:-1] / max(float(centred @ centred), 1e-300))]
    delay_s, delay_z, ratio, suspected = suspects(
        u, fin, dt, rec.fin_deg is not None, np.asarray(ar, dtype=float)
    )
    verdict = found.verdict
    return Adequacy(
        rate_source=source,
        rate_r2=rate_r2,
        rate_mae_dps=rate_mae,
        angle_mae_deg=angle_mae,
        ahead_s=k * dt,
        ahead_r2=ahead_r2,
        fin_share=share,
        fin_share_p=share_p,
        fin_error_ratio=fin_error,
        ud_p99_deg=p99,
        ud_range_fraction=p99 / fins.deg,
        alpha_rel_se=rel_se,
        innovation_acf=innovation_acf,
        verdict=verdict,
        reasons=found.reasons,
        fin_delay_s=delay_s,
        fin_delay_z=delay_z,
        intensity_ratio=ratio,
        suspected=tuple(suspected),
        diagnosis=why.as_dict(),
    )
