"""Each step of the paper's pipeline (identification.methods.steps and friends) on a known answer.

Every case here is constructed so that the right result is known exactly (or
to the discretisation error of the method, stated per test):

* step 1 ``detect_segments``  -- commanded jumps and measured ramps at known samples;
* step 2 ``fit_piecewise_linear`` -- an exact continuous piecewise-linear angle, and an
  independent hinge-basis least-squares solution on noisy data;
* step 3 ``fit_steady_state`` -- an exact line;
* step 4 ``fit_bilinear`` -- a velocity that *is* the bi-linear model of eq. 18;
* step 5 ``fin_angle_model`` -- the servo ramp of eq. 23 (0.4 s per 60°);
* step 6 ``fit_damping`` -- an exact first-order response of eq. 21 (and the erratum of
  eq. 32);
* step 7 ``fit_damping_vs_fin`` -- the paper's Table 1 and exact lines;
* step 8 ``identify_disturbance`` -- the model simulated with a known ``u_d`` (and the
  erratum of eq. 39);
* step 9 ``resimulate`` -- the exact ``u_d`` reproduces the exact trajectory;
* the noise study (§3.3), the statistics (§3.4) and the output-error baseline.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.signal import lfilter

from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods.baselines import output_error
from identification.methods.noise import noise_study
from identification.methods.pipeline import IdentifyOptions
from identification.methods.statistics import (
    decorrelation_stride,
    disturbance_statistics,
    newey_west_meat,
    trace_statistics,
)
from identification.methods.steps import (
    PAPER_SERVO,
    FineGrid,
    IdentificationError,
    bilinear_velocity,
    detect_segments,
    fin_angle_model,
    fine_grid,
    fit_bilinear,
    fit_damping,
    fit_damping_vs_fin,
    fit_piecewise_linear,
    fit_steady_state,
    identify_disturbance,
    measured_angle,
    measured_velocity,
    resimulate,
    smooth3,
)
from identification.model import PAPER_THETA, Disturbance, RollParams, Servo, servo_path, simulate
from identification.recordings.recording import Recording

DT = 0.1  # the paper's 10 Hz log
H = 0.01  # the paper's 100 Hz fine grid


def recording(
    n: int,
    *,
    fin_cmd: np.ndarray | None = None,
    fin: np.ndarray | None = None,
    roll: np.ndarray | None = None,
    rate: np.ndarray | None = None,
    dt: float = DT,
    t0: float = 0.0,
) -> Recording:
    """A wind-tunnel recording of ``n`` samples; a flat roll angle unless given."""
    if roll is None and rate is None:
        roll = np.zeros(n)
    return Recording(
        name="unit",
        source="wind-tunnel",
        time_s=np.asarray(t0 + dt * np.arange(n), dtype=np.float64),
        fin_cmd_deg=fin_cmd,
        fin_deg=fin,
        roll_deg=roll,
        roll_rate_dps=rate,
    )


def command_levels(n: int, starts: list[int], levels: list[float], initial: float = 0.0):
    """A command that jumps to ``levels[k]`` at sample ``starts[k]``."""
    cmd = np.full(n, initial)
    for start, level in zip(starts, levels, strict=True):
        cmd[start:] = level
    return cmd


# --------------------------------------------------------------------------- step 1


def test_detect_segments_finds_commanded_jumps_exactly() -> None:
    n = 700
    starts = [50, 120, 400, 455]  # dwells of 7 s, 28 s, 5.5 s and 24.5 s
    levels = [10.0, -7.5, 20.0, 33.25]
    rec = recording(n, fin_cmd=command_levels(n, starts, levels))
    seg = detect_segments(rec)
    assert seg.fin_source == "fin_cmd_deg"
    assert seg.n_steps == 4
    assert seg.start_index.tolist() == starts
    # A command is at its new level on the first sample after the jump.
    assert seg.settle_index.tolist() == starts
    assert seg.levels_deg.tolist() == [0.0, *levels]
    assert seg.step_levels_deg.tolist() == levels
    assert seg.previous_levels_deg.tolist() == [0.0, *levels[:-1]]
    np.testing.assert_allclose(seg.time_s, [5.0, 12.0, 40.0, 45.5], rtol=0, atol=1e-12)
    assert seg.end_index == n - 1
    assert seg.end_s == pytest.approx(69.9, abs=1e-12)
    np.testing.assert_allclose(seg.bounds_s, [5.0, 12.0, 40.0, 45.5, 69.9], atol=1e-12)


def test_detect_segments_on_measured_ramps_starts_at_the_last_sample_before_the_ramp() -> None:
    n = 500
    fin = np.zeros(n)
    # Ramp up 0 -> 15° over samples 50..55 (3° per sample), hold, then down to -24° over
    # samples 200..206 (the first move is only 1.5°), hold.
    fin[51:56] = [3.0, 6.0, 9.0, 12.0, 15.0]
    fin[56:200] = 15.0
    fin[200:207] = [15.0, 13.5, 7.5, 1.5, -4.5, -10.5, -16.5]
    fin[207:] = -24.0
    rec = recording(n, fin=fin)
    seg = detect_segments(rec)
    assert seg.fin_source == "fin_deg"
    assert seg.start_index.tolist() == [50, 200]  # last samples at the old level
    assert seg.settle_index.tolist() == [55, 207]  # first samples at the new level
    assert seg.levels_deg.tolist() == [0.0, 15.0, -24.0]
    np.testing.assert_allclose(seg.time_s, [5.0, 20.0], atol=1e-12)


def test_detect_segments_ignores_isolated_glitches_of_a_measured_fin() -> None:
    n = 400
    fin = command_levels(n, [100], [12.0])
    fin[30] = 9.0  # one bad sample: removed by the 3-sample median
    seg = detect_segments(recording(n, fin=fin))
    assert seg.levels_deg.tolist() == [0.0, 12.0]
    assert seg.start_index.tolist() == [99]


def test_detect_segments_ignores_wiggles_below_min_step() -> None:
    n = 600
    cmd = command_levels(n, [50, 150, 170, 300, 420], [10.0, 10.5, 10.0, -20.0, -20.8])
    seg = detect_segments(recording(n, fin_cmd=cmd))
    assert seg.start_index.tolist() == [50, 300]
    assert seg.levels_deg.tolist() == [0.0, 10.0, -20.0]
    # A smaller threshold sees every move.
    fine = detect_segments(recording(n, fin_cmd=cmd), min_step_deg=0.4)
    assert fine.start_index.tolist() == [50, 150, 170, 300, 420]


def test_detect_segments_raises_when_the_fin_never_steps() -> None:
    n = 300
    cmd = command_levels(n, [100, 200], [0.5, 0.2])  # valid recording, but no 1° step
    with pytest.raises(IdentificationError, match="never steps"):
        detect_segments(recording(n, fin_cmd=cmd))
    # Measured fin alike.
    with pytest.raises(IdentificationError, match="fin_deg"):
        detect_segments(recording(n, fin=cmd))


# --------------------------------------------------------------------------- measurements


def test_smooth3_is_a_three_point_average_with_nearest_edges() -> None:
    np.testing.assert_allclose(smooth3([0.0, 3.0, 0.0, 0.0, 0.0], 1), [1, 1, 1, 0, 0])
    # Nearest-sample padding at the ends: (3 + 3 + 0)/3 and (0 + 0 + 6)/3.
    np.testing.assert_allclose(smooth3([3.0, 0.0, 0.0, 0.0, 6.0], 1), [2, 1, 0, 2, 4])
    # Two passes are one pass applied twice; zero passes change nothing.
    x = np.random.default_rng(0).normal(size=50)
    np.testing.assert_allclose(smooth3(x, 2), smooth3(smooth3(x, 1), 1))
    np.testing.assert_array_equal(smooth3(x, 0), x)
    for passes in (1, 3, 7):
        np.testing.assert_allclose(smooth3(np.full(20, 4.25), passes), 4.25, rtol=0, atol=1e-14)
    # Along the last axis of a 2-D array.
    two = smooth3(np.array([[0.0, 3.0, 0.0], [6.0, 6.0, 6.0]]), 1)
    np.testing.assert_allclose(two, [[1, 1, 1], [6, 6, 6]])


def test_measured_velocity_and_angle() -> None:
    n = 100
    t = DT * np.arange(n)
    roll = 2.0 + 3.0 * t + 0.5 * t**2  # rate 3 + t
    cmd = command_levels(n, [50], [5.0])
    v, source = measured_velocity(recording(n, fin_cmd=cmd, roll=roll), 0)
    assert "central differences" in source
    # Central differences are exact for a quadratic at interior samples.
    np.testing.assert_allclose(v[1:-1], (3.0 + t)[1:-1], rtol=0, atol=1e-9)
    # A rate gyro is taken as it is (and smoothed on request).
    gyro = recording(n, fin_cmd=cmd, rate=3.0 + t)
    v_gyro, source = measured_velocity(gyro, 2)
    assert source == "rate gyro, 3-point moving average x2"
    np.testing.assert_allclose(v_gyro[2:-2], (3.0 + t)[2:-2], atol=1e-12)
    # Without an encoder the angle is the trapezium integral of the gyro (exact here).
    angle, source = measured_angle(gyro)
    assert "trapezium" in source
    np.testing.assert_allclose(angle, 3.0 * t + 0.5 * t**2, atol=1e-12)
    angle_enc, source = measured_angle(recording(n, fin_cmd=cmd, roll=roll))
    assert source == "encoder"
    np.testing.assert_array_equal(angle_enc, roll)


def test_fine_grid_contains_every_sample() -> None:
    cmd = command_levels(200, [100], [5.0])
    grid = fine_grid(recording(200, fin_cmd=cmd, t0=2.0))
    assert grid.per_sample == 10 and grid.step_s == pytest.approx(H, abs=1e-12)
    assert grid.time_s.size == 199 * 10 + 1
    np.testing.assert_allclose(grid.time_s[::10], 2.0 + DT * np.arange(200), atol=1e-12)
    cmd500 = command_levels(500, [250], [5.0])
    grid100 = fine_grid(recording(500, fin_cmd=cmd500, dt=0.01))  # 5 s at 100 Hz
    assert grid100.per_sample == 1 and grid100.time_s.size == 500


# --------------------------------------------------------------------------- step 2

BOUNDS = np.array([5.0, 12.3, 30.0, 45.5, 60.0])
SLOPES = np.array([9.5, -7.25, 20.0, -3.0])


def piecewise_truth(t: np.ndarray, start_deg: float = 17.0) -> tuple[np.ndarray, np.ndarray]:
    """Continuous piecewise-linear angle with SLOPES on BOUNDS; returns (angle, intercepts)."""
    intercepts = np.empty(SLOPES.size)
    value = start_deg
    for i, slope in enumerate(SLOPES):
        intercepts[i] = value - slope * BOUNDS[i]
        value = intercepts[i] + slope * BOUNDS[i + 1]
    k = np.clip(np.searchsorted(BOUNDS, t, side="right") - 1, 0, SLOPES.size - 1)
    return intercepts[k] + SLOPES[k] * t, intercepts


def hinge_least_squares(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Independent solution: continuous piecewise-linear = line + hinges at the interior T_i."""
    use = (t >= BOUNDS[0] - 1e-9) & (t <= BOUNDS[-1] + 1e-9)
    t, y = t[use], y[use]
    interior = BOUNDS[1:-1]
    basis = np.column_stack(
        [np.ones_like(t), t - BOUNDS[0], *(np.maximum(t - b, 0.0) for b in interior)]
    )
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    slopes = coef[1] + np.concatenate([[0.0], np.cumsum(coef[2:])])
    start = coef[0]  # angle at T_1
    values = start + np.concatenate(
        [[0.0], np.cumsum(slopes[:-1] * np.diff(BOUNDS[:-1]))]
    )  # angle at each T_i
    return slopes, values - slopes * BOUNDS[:-1]


def test_fit_piecewise_linear_recovers_an_exact_signal() -> None:
    t = DT * np.arange(601)
    angle, intercepts = piecewise_truth(t)
    fit = fit_piecewise_linear(t, angle, BOUNDS)
    np.testing.assert_allclose(fit.slopes_dps, SLOPES, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fit.intercepts_deg, intercepts, rtol=0, atol=1e-9)
    assert fit.rms_deg < 1e-9
    use = t >= BOUNDS[0]
    np.testing.assert_allclose(fit(t[use]), angle[use], atol=1e-9)
    np.testing.assert_array_equal(fit.bounds_s, BOUNDS)


def test_fit_piecewise_linear_is_continuous_exactly_and_matches_hinge_least_squares() -> None:
    t = DT * np.arange(601)
    angle, _ = piecewise_truth(t)
    noisy = angle + np.random.default_rng(4).normal(0.0, 3.0, t.size)
    fit = fit_piecewise_linear(t, noisy, BOUNDS)
    a, b = fit.intercepts_deg, fit.slopes_dps
    # Eq. 10 holds to rounding: a hard constraint, not a penalty.
    left = a[:-1] + b[:-1] * BOUNDS[1:-1]
    right = a[1:] + b[1:] * BOUNDS[1:-1]
    np.testing.assert_allclose(left, right, rtol=0, atol=1e-9)
    # The same minimiser as an unconstrained fit in a basis that is continuous by construction.
    slopes, intercepts = hinge_least_squares(t, noisy)
    np.testing.assert_allclose(b, slopes, rtol=0, atol=1e-8)
    np.testing.assert_allclose(a, intercepts, rtol=0, atol=1e-8)
    # Noise does move the fit: the check above is not trivially on the truth.
    assert np.max(np.abs(b - SLOPES)) > 1e-3
    residual = noisy[t >= BOUNDS[0]] - fit(t[t >= BOUNDS[0]])
    assert fit.rms_deg == pytest.approx(np.sqrt(np.mean(residual**2)), rel=1e-9)


def test_fit_piecewise_linear_rejects_a_segment_without_samples() -> None:
    t = DT * np.arange(100)
    with pytest.raises(IdentificationError, match="fewer than 2 samples"):
        fit_piecewise_linear(t, t, [1.0, 1.05, 5.0])


# --------------------------------------------------------------------------- step 3

TABLE1_FIN = [13.33, -13.33, 26.67, -26.67, 40.0, -40.0, 40.0, -26.67]


def test_fit_steady_state_on_an_exact_line() -> None:
    f = np.array(TABLE1_FIN)
    fit = fit_steady_state(f, 0.659 * f + 2.8856)
    assert fit.alpha == pytest.approx(0.659, abs=1e-12)
    assert fit.beta_dps == pytest.approx(2.8856, abs=1e-12)
    assert fit.r_squared == pytest.approx(1.0, abs=1e-12)
    assert fit.theta_bar_deg == pytest.approx(2.8856 / 0.659, abs=1e-10)
    assert fit.alpha_se == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(fit.rate([0.0, 10.0]), [2.8856, 9.4756], atol=1e-12)
    noisy = fit_steady_state(f, 0.659 * f + 2.8856 + np.sin(f))
    assert 0.9 < noisy.r_squared < 1.0


def test_fit_steady_state_needs_two_levels() -> None:
    with pytest.raises(IdentificationError, match="two distinct fin levels"):
        fit_steady_state([10.0, 10.0], [1.0, 2.0])
    two = fit_steady_state([10.0, -10.0], [9.0, -4.0])
    assert (two.alpha, two.beta_dps) == pytest.approx((0.65, 2.5))
    assert np.isnan(two.alpha_se)


# --------------------------------------------------------------------------- steps 4 and 5

ALPHA, BETA = 0.659, 2.8856


def step_recording(
    n: int, starts: list[int], levels: list[float], initial: float = 0.0
) -> Recording:
    return recording(n, fin_cmd=command_levels(n, starts, levels, initial))


def test_fit_bilinear_recovers_known_breakpoints() -> None:
    n = 700
    starts, levels = [50, 250, 450], [13.33, -26.67, 40.0]
    t0_true = [1.61, 0.5, 3.99]  # the paper's 1.61 s (Fig. 7a) on the 0.01 s grid
    rec = step_recording(n, starts, levels)
    seg = detect_segments(rec)
    grid = fine_grid(rec)
    steady = fit_steady_state(levels, ALPHA * np.array(levels) + BETA)
    # Velocity that is exactly eq. 18 from T_1 on, v_ss(0°) before.
    v = np.full(grid.time_s.size, ALPHA * 0.0 + BETA)
    previous = 0.0
    for i, (level, t0) in enumerate(zip(levels, t0_true, strict=True)):
        after = grid.time_s >= seg.bounds_s[i] - 1e-9
        tau = grid.time_s[after] - seg.bounds_s[i]
        v0, vss = ALPHA * previous + BETA, ALPHA * level + BETA
        v[after] = np.where(tau < t0, v0 + (vss - v0) * tau / t0, vss)
        previous = level
    fit = fit_bilinear(seg, steady, grid, v)
    np.testing.assert_allclose(fit.t0_s, t0_true, rtol=0, atol=1e-9)
    assert fit.candidates_s.shape == (400,)
    assert fit.errors.shape == (3, 400)
    assert fit.candidates_s[0] == pytest.approx(0.01) and fit.candidates_s[-1] == pytest.approx(4)
    np.testing.assert_array_equal(np.argmin(fit.errors, axis=1), [160, 49, 398])
    assert np.all(fit.errors.min(axis=1) < 1e-20)
    np.testing.assert_allclose(fit.v0_dps, ALPHA * np.array([0.0, *levels[:-1]]) + BETA)
    np.testing.assert_allclose(fit.vss_dps, ALPHA * np.array(levels) + BETA)
    assert fit.window_s == pytest.approx(5.0)
    # The bi-linear velocity on the fine grid is the input from T_1 on, nan before.
    v_model, step = bilinear_velocity(seg, fit, grid)
    first = int(np.searchsorted(grid.time_s, seg.bounds_s[0] - 1e-9))
    assert np.all(np.isnan(v_model[:first])) and np.all(step[:first] == -1)
    np.testing.assert_allclose(v_model[first:], v[first:], rtol=0, atol=1e-9)
    # A coarser search with a shorter ΔT0 finds the nearest candidates.
    coarse = fit_bilinear(seg, steady, grid, v, max_breakpoint_s=2.0, resolution_s=0.5)
    np.testing.assert_allclose(coarse.t0_s, [1.5, 0.5, 2.0])
    assert coarse.errors.shape == (3, 4)


def test_fin_angle_model_ramps_0_4_s_per_60_deg() -> None:
    n = 300
    rec = step_recording(n, [50, 150], [60.0, 30.0])
    grid = fine_grid(rec)
    theta, source = fin_angle_model(rec, grid)
    assert "eq. 23" in source
    k0 = 500  # fine index of T_1 = 5.0 s
    assert theta[k0] == 0.0
    # 150 °/s: 1.5° per 0.01 s, 40 fine steps = 0.4 s for 60° (eq. 23).
    np.testing.assert_allclose(theta[k0 : k0 + 41], 1.5 * np.arange(41), atol=1e-9)
    moving = np.flatnonzero((theta[:1500] > 1e-9) & (theta[:1500] < 60.0 - 1e-9))
    assert grid.time_s[moving[-1] + 1] - grid.time_s[moving[0] - 1] == pytest.approx(0.4)
    np.testing.assert_allclose(theta[k0 + 40 : 1500], 60.0)
    # 60 -> 30°: 0.2 s.
    k1 = 1500
    np.testing.assert_allclose(theta[k1 : k1 + 21], 60.0 - 1.5 * np.arange(21), atol=1e-9)
    np.testing.assert_allclose(theta[k1 + 20 :], 30.0)
    # Eq. 23's own example: 13.3 -> -13.3° takes 26.6 * 0.4/60 = 0.177 s.
    assert float(PAPER_SERVO.lag_s(26.6)) == pytest.approx(26.6 * 0.4 / 60)
    # Without a servo the command is held, no lag.
    held, source = fin_angle_model(rec, grid, servo=None)
    assert source == "commanded fin angle, no lag"
    assert held[k0 - 1] == 0.0 and held[k0] == 60.0 and held[-1] == 30.0


def test_fin_angle_model_interpolates_a_measured_fin_without_lag() -> None:
    n = 300
    fin = np.zeros(n)
    fin[51:56] = [10.0, 20.0, 30.0, 40.0, 50.0]
    fin[56:] = 50.0
    cmd = command_levels(n, [51], [50.0])
    rec = recording(n, fin_cmd=cmd, fin=fin)
    grid = fine_grid(rec)
    theta, source = fin_angle_model(rec, grid)
    assert source.startswith("measured fin angle")
    np.testing.assert_allclose(theta[::10], fin, rtol=0, atol=1e-9)
    np.testing.assert_allclose(theta[500:561], np.clip(np.arange(61) - 0.0, 0, 50), atol=1e-9)


# --------------------------------------------------------------------------- step 6


def first_order_case(a_steps: list[float]):
    """Exact response of eq. 21 to fin steps with no servo lag, on the fine grid."""
    n = 800
    starts, levels = [50, 250, 400, 600], [10.0, -20.0, 30.0, -5.0]
    rec = step_recording(n, starts, levels)
    seg = detect_segments(rec)
    grid = fine_grid(rec)
    theta, _ = fin_angle_model(rec, grid, servo=None)  # θ jumps exactly at T_i
    steady = fit_steady_state(levels, ALPHA * np.array(levels) + BETA)
    t = grid.time_s
    v = np.full(t.size, BETA)  # v_ss at 0° before T_1
    for i, a in enumerate(a_steps):
        k = int(np.searchsorted(t, seg.bounds_s[i] - 1e-9))
        v_start, vss = v[k], ALPHA * levels[i] + BETA  # v[k]: the previous step's exponential
        v[k:] = vss + (v_start - vss) * np.exp(-a * (t[k:] - t[k]))
    return seg, steady, grid, v, theta


def test_fit_damping_recovers_a_constant_damping() -> None:
    seg, steady, grid, v, theta = first_order_case([1.314] * 4)
    fit = fit_damping(seg, steady, grid, v, theta)
    # Trapezium rule on e^{-a t} with δt = 0.01 s: relative error ~ (a·δt)²/12.
    assert fit.a_per_s == pytest.approx(1.314, rel=1e-4)
    np.testing.assert_allclose(fit.a_steps_per_s, 1.314, rtol=1e-4)
    assert fit.alpha == pytest.approx(ALPHA) and fit.theta_bar_deg == pytest.approx(BETA / ALPHA)
    assert fit.b_per_s2 == pytest.approx(1.314 * ALPHA, rel=1e-4)
    assert fit.rms_dps < 1e-3
    params = fit.params()
    assert (params.alpha, params.beta_bar_per_s, params.alpha_bar_per_deg_s) == pytest.approx(
        (ALPHA, fit.a_per_s, 0.0)
    )


def test_fit_damping_per_step_and_the_erratum_of_eq_32() -> None:
    """Per-step a_i (eq. 31-34) of a response whose damping differs per step.

    Erratum of eq. 32: the paper writes ``v(t) = v(T_i) - a_i·∫_t^{T_i}(...)``.
    Integrating eq. 21 from T_i to t gives ``∫_{T_i}^t`` (as eq. 25 has); with the
    printed limits the least-squares a_i come out with the opposite sign.  The
    library must give the true, positive a_i; the reversed-limit solution is
    computed here to show that it would be the negation.
    """
    a_true = [1.6876, 2.2831, 1.1011, 3.2439]
    seg, steady, grid, v, theta = first_order_case(a_true)
    fit = fit_damping(seg, steady, grid, v, theta)
    assert np.all(fit.a_steps_per_s > 0)
    np.testing.assert_allclose(fit.a_steps_per_s, a_true, rtol=1e-3)
    np.testing.assert_allclose(fit.b_steps_per_s2, np.array(a_true) * ALPHA, rtol=1e-3)
    # The constant a lies among the per-step ones.
    assert min(a_true) < fit.a_per_s < max(a_true)
    # Eq. 32 as printed: column ∫_t^{T_i} f = -∫_{T_i}^t f  ->  a_i negated.
    t = grid.time_s
    bounds = seg.bounds_s
    for i, a in enumerate(a_true):
        lo = int(np.searchsorted(t, bounds[i] - 1e-9))
        hi = int(np.searchsorted(t, bounds[i + 1] - 1e-9)) if i + 1 < seg.n_steps else t.size
        f = v[lo:hi] - steady.rate(theta[lo:hi])
        reversed_limits = -cumulative_trapezoid(f, t[lo:hi])  # ∫_t^{T_i} f
        column = -reversed_limits  # eq. 32: v(t) - v(T_i) = -a_i · ∫_t^{T_i} f
        rhs = v[lo + 1 : hi] - v[lo]
        assert (column @ rhs) / (column @ column) == pytest.approx(-a, rel=1e-3)


def test_fit_damping_rejects_a_step_without_excitation() -> None:
    seg, steady, grid, _, theta = first_order_case([1.314] * 4)
    # A velocity at the model's steady state everywhere: every integral is zero.
    v = steady.rate(theta)
    with pytest.raises(IdentificationError, match="does not excite"):
        fit_damping(seg, steady, grid, v, theta)


# --------------------------------------------------------------------------- step 7

TABLE1_A = [1.6876, 2.2831, 3.2439, 2.2208, 1.1011, 1.4018, 1.0997, 1.7653]


def test_fit_damping_vs_fin_on_table_1_drops_the_third_step() -> None:
    fit = fit_damping_vs_fin(TABLE1_FIN, TABLE1_A, 4.38)
    assert fit.outlier == 2  # the 3rd step, 26.67°, a = 3.2439 (Fig. 12's "clear outlier")
    assert fit.outlier_p is not None and fit.outlier_p < 0.05
    assert fit.r_squared == pytest.approx(0.8280, abs=4e-4)  # the paper's R²
    # Slope and intercept: ordinary least squares on Table 1 without the 3rd step gives
    # -0.0321 and 2.549, not the -0.0289 and 2.4075 printed in eq. 48 (the paper's a_i
    # are rounded, but not enough to explain that); assert the computed values.
    x = np.abs(np.array(TABLE1_FIN) + 4.38)
    keep = np.arange(8) != 2
    slope, intercept = np.polyfit(x[keep], np.array(TABLE1_A)[keep], 1)
    assert fit.alpha_bar_per_deg_s == pytest.approx(slope, abs=1e-12)
    assert fit.beta_bar_per_s == pytest.approx(intercept, abs=1e-12)
    assert fit.alpha_bar_per_deg_s == pytest.approx(-0.0321, abs=5e-5)
    assert fit.beta_bar_per_s == pytest.approx(2.549, abs=5e-4)
    np.testing.assert_allclose(fit.x_deg, x)
    np.testing.assert_array_equal(fit.a_per_s, TABLE1_A)
    assert "Bonferroni" in fit.rule
    params = fit.params(0.659, 4.38)
    assert params.alpha_bar_per_deg_s == fit.alpha_bar_per_deg_s
    assert params.beta_bar_per_s == fit.beta_bar_per_s
    # A stricter level keeps every step (the paper's outlier has p ≈ 0.007).
    strict = fit_damping_vs_fin(TABLE1_FIN, TABLE1_A, 4.38, outlier_level=0.001)
    assert strict.outlier is None and strict.r_squared < 0.5


EXACT_LINES = [(4.38, -0.03), (2.0, -0.0289), (2.0, 0.01), (4.38, 0.01)]
#: Exact lines on which studentizing rounding-level residuals once dropped a step.
SPURIOUS_OUTLIER = [(0.0, -0.03), (0.0, -0.0289), (4.38, -0.0289)]


@pytest.mark.parametrize(("theta_bar", "slope"), EXACT_LINES + SPURIOUS_OUTLIER)
def test_fit_damping_vs_fin_recovers_an_exact_line(theta_bar: float, slope: float) -> None:
    x = np.abs(np.array(TABLE1_FIN) + theta_bar)
    fit = fit_damping_vs_fin(TABLE1_FIN, slope * x + 2.5, theta_bar)
    assert fit.alpha_bar_per_deg_s == pytest.approx(slope, abs=1e-12)
    assert fit.beta_bar_per_s == pytest.approx(2.5, abs=1e-12)
    assert fit.r_squared == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize(("theta_bar", "slope"), EXACT_LINES + SPURIOUS_OUTLIER)
def test_fit_damping_vs_fin_finds_no_outlier_on_an_exact_line(
    theta_bar: float, slope: float
) -> None:
    x = np.abs(np.array(TABLE1_FIN) + theta_bar)
    fit = fit_damping_vs_fin(TABLE1_FIN, slope * x + 2.5, theta_bar)
    assert fit.outlier is None
    assert fit.outlier_p is None


def test_fit_damping_vs_fin_leaves_out_non_positive_damping() -> None:
    a = np.array([1.5, 1.4, -25.0, 1.2, 1.1])
    fin = np.array([10.0, -10.0, 20.0, 30.0, -30.0])
    fit = fit_damping_vs_fin(fin, a, 0.0)
    assert fit.excluded == (2,)
    assert fit.alpha_bar_per_deg_s < 0 and fit.beta_bar_per_s > 0


def test_fit_damping_vs_fin_refuses_a_non_positive_a_theta() -> None:
    # Scattered a_i whose line crosses zero inside the recorded fin range.
    with pytest.raises(IdentificationError, match="not a damping"):
        fit_damping_vs_fin([5.0, 20.0], [0.2, 3.0], 0.0)  # intercept < 0: a(0) < 0


def test_fit_damping_vs_fin_needs_two_abscissae() -> None:
    with pytest.raises(IdentificationError, match="two or more"):
        fit_damping_vs_fin([10.0, -18.76], [1.0, 2.0], 4.38)  # |θ + θ̄| = 14.38 twice
    few = fit_damping_vs_fin([10.0, 20.0, 30.0], [1.0, 5.0, 1.5], 0.0)  # < 4: no outlier rule
    assert few.outlier is None


# --------------------------------------------------------------------------- steps 8 and 9

N_INTERVALS = 600  # 60 s of 0.1 s intervals
PER = 10


def disturbance_case(params: RollParams, seed: int = 1):
    """The model simulated on the 100 Hz grid with u_d piecewise constant over 0.1 s."""
    rng = np.random.default_rng(seed)
    n = N_INTERVALS * PER
    t = H * np.arange(n + 1)
    cmd = np.select([t[:-1] < 10, t[:-1] < 25, t[:-1] < 40], [0.0, 20.0, -30.0], 35.0)
    theta = servo_path(cmd, 0.0, H, Servo())  # servo ramps included
    u_true = rng.normal(0.0, 8.0, N_INTERVALS)
    sim = simulate(params, H, theta, np.repeat(u_true, PER), servo=None, substeps=1)
    grid = FineGrid(time_s=sim.time_s, step_s=H, per_sample=PER)
    return grid, theta, u_true, sim


CONSTANT = RollParams(0.659, 4.38, 1.314)


@pytest.mark.parametrize(
    ("params", "max_err", "mean_err"),
    [(CONSTANT, 5e-3, 5e-4), (PAPER_THETA, 2e-2, 1e-3)],
    ids=["constant", "theta"],
)
def test_identify_disturbance_recovers_a_known_u_d(
    params: RollParams, max_err: float, mean_err: float
) -> None:
    grid, theta, u_true, sim = disturbance_case(params)
    dist = identify_disturbance(params, "m", grid, theta, sim.rate_dps)
    assert dist.model == "m" and dist.params == params and dist.interval_s == 0.1
    assert dist.u_d_deg.shape == (N_INTERVALS,)
    np.testing.assert_allclose(dist.start_s, 0.1 * np.arange(N_INTERVALS), atol=1e-9)
    err = np.abs(dist.u_d_deg - u_true)
    # Left: the trapezium rule on the 0.01 s grid (and a(θ) frozen per piece while the
    # fin ramps in the simulation of the θ-dependent model).
    assert err.max() < max_err and err.mean() < mean_err
    # The piecewise-constant u_d(t) of eq. 44.
    at = dist.at([0.0, 0.05, 0.1, 59.95, 100.0])
    np.testing.assert_array_equal(at, dist.u_d_deg[[0, 0, 1, -1, -1]])


def test_identify_disturbance_erratum_of_eq_39() -> None:
    """Eq. 39 reads ``ū_d,i = a·u_d,i``; from eq. 36 it must be ``ū_d,i = a·α·u_d,i``.

    The slope fitted in eq. 42 (computed here independently with C̄ = [δt, ..., N_t·δt]
    and D̄ of eq. 43) is ū_d,i.  Divided by a·α it is the true u_d in degrees of
    equivalent fin angle whatever α; divided by a alone (eq. 39 as printed) it would be
    α·u_d -- off by the factor α.
    """
    for alpha in (0.5, 1.0):
        params = RollParams(alpha, 4.0, 1.3)
        grid, theta, u_true, sim = disturbance_case(params, seed=2)
        v = sim.rate_dps
        dist = identify_disturbance(params, "constant", grid, theta, v)
        np.testing.assert_allclose(dist.u_d_deg, u_true, rtol=0, atol=5e-3)
        # Eq. 42-43 by hand, for every interval.
        a = params.beta_bar_per_s
        f = v - alpha * (theta + params.theta_bar_deg)
        integral = cumulative_trapezoid(f, grid.time_s, initial=0.0)
        c = H * np.arange(1, PER + 1)
        u_bar = np.empty(N_INTERVALS)
        for i in range(N_INTERVALS):
            j0, j = i * PER, i * PER + np.arange(1, PER + 1)
            d = v[j] - v[j0] + a * (integral[j] - integral[j0])
            u_bar[i] = (c @ d) / (c @ c)
        np.testing.assert_allclose(u_bar / (a * alpha), dist.u_d_deg, rtol=0, atol=1e-7)
        np.testing.assert_allclose(u_bar / (a * alpha), u_true, atol=5e-3)
        if alpha != 1.0:  # dividing by a only: α·u_d, not u_d
            np.testing.assert_allclose(u_bar / a, alpha * u_true, atol=5e-3)
            assert np.max(np.abs(u_bar / a - u_true)) > 1.0


def test_identify_disturbance_rejects_an_interval_off_the_grid() -> None:
    grid, theta, _, sim = disturbance_case(CONSTANT)
    with pytest.raises(IdentificationError, match="not a multiple"):
        identify_disturbance(CONSTANT, "constant", grid, theta, sim.rate_dps, interval_s=0.015)


def sampled_recording(grid: FineGrid, theta: np.ndarray, sim) -> Recording:
    return Recording(
        name="sim",
        source="synthetic",
        time_s=grid.time_s[::PER],
        fin_deg=theta[::PER],
        roll_deg=sim.angle_deg[::PER],
    )


@pytest.mark.parametrize("params", [CONSTANT, PAPER_THETA], ids=["constant", "theta"])
def test_resimulate_with_the_exact_u_d_reproduces_the_trajectory(params: RollParams) -> None:
    grid, theta, u_true, sim = disturbance_case(params)
    rec = sampled_recording(grid, theta, sim)
    exact = Disturbance("constant", params, 0.1, grid.time_s[:-1:PER], u_true)
    rate, angle = sim.rate_dps[::PER], sim.angle_deg[::PER]
    res = resimulate(exact, rec, grid, theta, rate, angle)
    assert res.model == "constant"
    assert res.rate_mae_dps < 1e-9 and res.angle_mae_deg < 1e-9
    np.testing.assert_array_equal(res.time_s, rec.time_s)
    assert res.rate_dps.shape == res.angle_deg.shape == rec.time_s.shape
    # With the identified u_d: close, but not exact.
    identified = identify_disturbance(params, "theta", grid, theta, sim.rate_dps)
    res2 = resimulate(identified, rec, grid, theta, rate, angle)
    assert res2.model == "theta"
    assert res2.rate_mae_dps < 5e-3 and res2.angle_mae_deg < 5e-3
    # A wrong u_d is seen.
    off = Disturbance("constant", params, 0.1, exact.start_s, u_true + 1.0)
    assert resimulate(off, rec, grid, theta, rate, angle).rate_mae_dps > 0.3


# --------------------------------------------------------------------------- noise study


@pytest.fixture(scope="module")
def noise_case():
    grid, theta, _, sim = disturbance_case(CONSTANT, seed=3)
    return grid, theta, sim.rate_dps


def test_noise_study_zero_noise_gives_zero_error(noise_case) -> None:
    grid, theta, v = noise_case
    study = noise_study(CONSTANT, grid, theta, v, levels_pct=(0.0,), runs=3, smoothing_passes=3)
    # Zero to rounding (the runs are solved as a batch, the reference alone).
    assert study.mae_deg[0] == pytest.approx(0.0, abs=1e-12)
    assert study.p90_deg[0] == pytest.approx(0.0, abs=1e-12)
    assert study.run_mae_deg.shape == (1, 3)


def test_noise_study_error_is_linear_in_eta(noise_case) -> None:
    grid, theta, v = noise_case
    study = noise_study(CONSTANT, grid, theta, v, levels_pct=(5.0, 10.0), runs=20)
    assert study.mae_deg[1] / study.mae_deg[0] == pytest.approx(2.0, rel=0.10)
    assert study.p90_deg[1] / study.p90_deg[0] == pytest.approx(2.0, rel=0.10)
    assert np.all(study.p90_deg > study.mae_deg)
    np.testing.assert_allclose(study.mae_deg, study.run_mae_deg.mean(axis=1), rtol=1e-12)


def test_noise_study_is_reproducible_and_silent(noise_case, capsys) -> None:
    grid, theta, v = noise_case

    def study(seed: int, levels: tuple[float, ...] = (2.0, 5.0)):
        return noise_study(
            CONSTANT,
            grid,
            theta,
            v,
            levels_pct=levels,
            runs=4,
            seed=seed,
            smoothing_passes=1,
            progress=False,
        )

    a, b, c = study(7), study(7), study(8)
    np.testing.assert_array_equal(a.run_mae_deg, b.run_mae_deg)
    assert not np.any(a.run_mae_deg == c.run_mae_deg)
    # Each level has its own stream: dropping a level does not change the others.
    single = study(7, (2.0,))
    np.testing.assert_array_equal(single.run_mae_deg[0], b.run_mae_deg[0])
    assert capsys.readouterr() == ("", "")
    assert a.to_dict()["runs"] == 4


# --------------------------------------------------------------------------- statistics


def ar1(n: int, rho: float, seed: int) -> np.ndarray:
    """A stationary unit-variance AR(1) with lag-one correlation ``rho``."""
    eps = np.random.default_rng(seed).standard_normal(n)
    tail = lfilter([np.sqrt(1 - rho * rho)], [1.0, -rho], eps[1:], zi=[rho * eps[0]])[0]
    return np.concatenate([eps[:1], tail])


def test_decorrelation_stride_of_an_ar1() -> None:
    # ρ^k: 0.123 at lag 5, 0.081 at lag 6 -> first lag below 0.1 is 6 (sampling error of
    # the autocorrelation ~0.003 with 200 000 samples).
    rho = 0.1 ** (1 / 5.5)
    assert decorrelation_stride(ar1(200_000, rho, 0)) == 6
    assert decorrelation_stride(ar1(200_000, 0.5, 1)) == 4  # 0.125, then 0.0625
    assert decorrelation_stride(np.random.default_rng(2).normal(size=5000)) == 1
    assert decorrelation_stride(np.full(100, 3.0)) == 1
    # With threshold 0.35: ρ² = 0.433, ρ³ = 0.285.
    assert decorrelation_stride(ar1(200_000, rho, 3), threshold=0.35) == 3


@pytest.mark.parametrize(("n", "k", "lags"), [(10, 1, 0), (10, 2, 3), (9, 3, 8), (4000, 6, 150)])
def test_newey_west_meat_is_statsmodels_kernel(n: int, k: int, lags: int) -> None:
    from statsmodels.stats.sandwich_covariance import S_hac_simple

    rng = np.random.default_rng(n + k + lags)
    z = np.cumsum(rng.standard_normal((n, k)), axis=0) * 0.1 + rng.standard_normal((n, k))
    expected = S_hac_simple(z, nlags=lags)
    assert newey_west_meat(z, lags) == pytest.approx(
        expected, rel=1e-12, abs=1e-12 * np.abs(expected).max()
    )
    assert np.all(np.linalg.eigvalsh(newey_west_meat(z, lags)) > -1e-9 * np.abs(expected).max())


def test_lilliefors_flags_student_t_and_not_gaussian() -> None:
    heavy = trace_statistics(np.random.default_rng(11).standard_t(3, 2000))
    assert heavy.stride == 1
    assert heavy.normal is False and heavy.lilliefors_p < 0.01
    gauss = trace_statistics(np.random.default_rng(12).normal(1.0, 5.0, 2000))
    assert gauss.stride == 1
    assert gauss.normal is True and gauss.lilliefors_p > 0.05


def test_trace_statistics_histogram_and_interval() -> None:
    x = np.random.default_rng(13).normal(1.0, 5.0, 3000)
    st = trace_statistics(x)
    widths = np.diff(st.bin_edges_deg)
    assert float(np.sum(st.density * widths)) == pytest.approx(1.0, abs=1e-12)
    assert float(np.sum(st.normal_density * widths)) == pytest.approx(1.0, abs=0.02)
    assert st.density.shape == st.normal_density.shape == widths.shape
    assert (st.q05_deg, st.q95_deg) == pytest.approx(tuple(np.percentile(x, [5, 95])))
    assert (st.mean_deg, st.sd_deg) == pytest.approx((x.mean(), x.std(ddof=1)))
    assert st.histogram_mad == pytest.approx(np.mean(np.abs(st.density - st.normal_density)))
    assert st.histogram_mad < 0.01
    assert st.to_dict()["interval90_deg"] == [st.q05_deg, st.q95_deg]


def test_disturbance_statistics_compares_the_two_traces() -> None:
    u = ar1(2000, 0.8, 14) * 9.0
    start = np.asarray(0.1 * np.arange(u.size), dtype=np.float64)
    theta = Disturbance("theta", PAPER_THETA, 0.1, start, u)
    same = disturbance_statistics(theta, Disturbance("constant", CONSTANT, 0.1, start, u))
    assert same.ks_stat == 0.0 and same.ks_p == pytest.approx(1.0)
    shifted = disturbance_statistics(theta, Disturbance("constant", CONSTANT, 0.1, start, u + 9))
    assert shifted.ks_p < 1e-3
    assert shifted.theta.stride == shifted.constant.stride == decorrelation_stride(u)
    assert set(shifted.to_dict()) == {"theta", "constant", "ks_two_sample"}


# --------------------------------------------------------------------------- output error


@pytest.fixture(scope="module")
def quiet_tunnel() -> Recording:
    """Constant damping, no turbulence, no encoder quantisation: nothing but the model."""
    return run_tunnel(TunnelSpec(seed=5, model="constant", turbulence_sd=0.0, encoder_counts=0))


def test_output_error_recovers_the_truth_on_noise_free_data(quiet_tunnel: Recording) -> None:
    truth = quiet_tunnel.truth()
    assert truth is not None
    fit = output_error(quiet_tunnel)
    assert fit.success and fit.model == "constant"
    assert fit.params.alpha == pytest.approx(truth.alpha, rel=1e-3)
    assert fit.params.theta_bar_deg == pytest.approx(truth.theta_bar_deg, abs=0.01)
    # The 3-pass moving average (the pipeline's default) flattens the transients a little.
    assert fit.params.beta_bar_per_s == pytest.approx(truth.beta_bar_per_s, rel=0.03)
    raw = output_error(quiet_tunnel, options=IdentifyOptions(smoothing_passes=0))
    assert raw.params.beta_bar_per_s == pytest.approx(truth.beta_bar_per_s, rel=5e-3)
    assert raw.rate_rmse_dps < fit.rate_rmse_dps
    with pytest.raises(IdentificationError, match="model must be"):
        output_error(quiet_tunnel, "quadratic")
