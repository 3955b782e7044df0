"""The Dryden roll-rate gust (rocketroll_physics.dryden): parameters, variance, exact held averages.

Reference values: MIL-F-8785C §3.7.2 (low altitude: ``L_w = h``,
``σ_w = 0.1·W20``, W20 = 15/30/45 kt) and Figure 7 as tabulated by MATLAB's
Dryden block and JSBSim (high altitude, ft/s).  The statistical tests use
fixed seeds and tolerances of several times the sampling error quoted beside
each, against the exact variance and lag-1 covariance of the interval
average of an Ornstein-Uhlenbeck process (σ², correlation time T, interval h,
u = h/T, φ = e^(−u))::

    Var(avg)      = σ²·2(u − 1 + φ)/u²
    Cov(lag 1)    = σ²·(1 − φ)²/u²
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from rocketroll_common.errors import UsageError
from rocketroll_physics.dryden import (
    DEFAULT_SPAN_M,
    FT_M,
    KNOT_MPS,
    SEVERITIES,
    STILL_AIR_MPS,
    GustParameters,
    Severity,
    gust_parameters,
    roll_gust,
    roll_gust_std,
    roll_gust_time_constant,
)

DEG = 180.0 / math.pi


def held_variance(sigma: float, tau_s: float, h_s: float) -> float:
    """Stationary variance of the OU process's average over an interval ``h_s``."""
    u = h_s / tau_s
    return sigma**2 * 2.0 * (u - 1.0 + math.exp(-u)) / u**2


def held_lag1(sigma: float, tau_s: float, h_s: float) -> float:
    """Covariance of the averages over two adjacent intervals ``h_s``."""
    u = h_s / tau_s
    return sigma**2 * (-math.expm1(-u)) ** 2 / u**2


def ft(value_ft: float) -> float:
    return value_ft * FT_M


# --------------------------------------------------------------------------- parameters
@pytest.mark.parametrize(("severity", "w20_kt"), [("light", 15), ("moderate", 30), ("severe", 45)])
def test_low_altitude_follows_mil_f_8785c(severity: Severity, w20_kt: float) -> None:
    """At 100 ft: L_w = h = 100 ft, σ_w = 0.1·W20 (1.5 kt light)."""
    p = gust_parameters(ft(100.0), severity)
    assert isinstance(p, GustParameters)
    assert float(p.length_w_m) == pytest.approx(30.48, rel=1e-12)
    assert float(p.sigma_w_mps) == pytest.approx(0.1 * w20_kt * KNOT_MPS, rel=1e-12)
    assert float(gust_parameters(ft(100.0)).sigma_w_mps) == pytest.approx(0.771667, abs=1e-6)


@pytest.mark.parametrize(
    ("altitude_ft", "light", "moderate", "severe"),
    [
        (3750.0, 7.4, 10.6, 23.0),  # table column, ft/s
        (7500.0, 6.7, 10.1, 23.6),  # table column, ft/s
        (5625.0, 7.05, 10.35, 23.3),  # halfway: linear in altitude
        (15000.0, 4.6, 8.0, 22.1),
        (90000.0, 0.0, 0.0, 5.1),  # above the table: its last column held
    ],
)
def test_high_altitude_follows_the_intensity_table(
    altitude_ft: float, light: float, moderate: float, severe: float
) -> None:
    """MIL-F-8785C Fig. 7 (MATLAB sigma_vec rows 10⁻², 10⁻³, 10⁻⁵), L_w = 1750 ft."""
    for severity, sigma_ftps in zip(SEVERITIES, (light, moderate, severe), strict=True):
        p = gust_parameters(ft(altitude_ft), severity)
        assert float(p.sigma_w_mps) == pytest.approx(ft(sigma_ftps), rel=1e-12, abs=1e-15)
        assert float(p.length_w_m) == pytest.approx(533.4, rel=1e-12)


def test_transition_band_is_linear_and_continuous_at_both_ends() -> None:
    eps = 1e-6
    for severity in SEVERITIES:
        for edge_ft in (1000.0, 2000.0):
            below = gust_parameters(ft(edge_ft - eps), severity)
            above = gust_parameters(ft(edge_ft + eps), severity)
            assert float(above.sigma_w_mps) == pytest.approx(float(below.sigma_w_mps), rel=1e-8)
            assert float(above.length_w_m) == pytest.approx(float(below.length_w_m), rel=1e-8)
    # halfway: the mean of the 1000-ft low-altitude and the 2000-ft table values
    mid = gust_parameters(ft(1500.0), "light")
    table_2000_ftps = 6.9 + (7.4 - 6.9) * (2000.0 - 1750.0) / (3750.0 - 1750.0)
    assert float(mid.length_w_m) == pytest.approx(ft(1375.0), rel=1e-12)
    assert float(mid.sigma_w_mps) == pytest.approx(
        0.5 * (1.5 * KNOT_MPS + ft(table_2000_ftps)), rel=1e-12
    )


def test_scale_length_has_a_10_ft_floor_near_the_ground() -> None:
    p = gust_parameters([0.0, ft(5.0), ft(10.0), ft(20.0)])
    np.testing.assert_allclose(p.length_w_m, [ft(10.0), ft(10.0), ft(10.0), ft(20.0)], rtol=1e-12)
    assert np.isfinite(roll_gust_std(50.0, 0.0))


def test_parameters_keep_the_shape_and_are_read_only() -> None:
    heights = np.linspace(0.0, 3000.0, 12).reshape(3, 4)
    p = gust_parameters(heights, "moderate")
    assert p.sigma_w_mps.shape == p.length_w_m.shape == (3, 4)
    with pytest.raises(ValueError, match="read-only"):
        p.sigma_w_mps[0, 0] = 1.0
    assert "moderate" in repr(p) and "σ_w" in repr(gust_parameters(100.0))


# --------------------------------------------------------------------------- variance
def dryden_roll_spectrum(omega: float, sigma_w: float, length_w: float, span: float) -> float:
    """MIL-F-8785C Φ_p(Ω), one-sided in spatial frequency Ω (rad/m)."""
    return (
        sigma_w**2
        / length_w
        * 0.8
        * (math.pi * length_w / (4.0 * span)) ** (1.0 / 3.0)
        / (1.0 + (4.0 * span * omega / math.pi) ** 2)
    )


@pytest.mark.parametrize(
    ("altitude_m", "span_m"), [(30.0, 0.3), (450.0, 0.3), (2000.0, 0.3), (2000.0, 1.2)]
)
def test_std_is_the_integral_of_the_spectrum_and_of_the_forming_filter(
    altitude_m: float, span_m: float
) -> None:
    """σ_p² = ∫₀^∞ Φ_p(Ω) dΩ = ∫₀^∞ |H_p(jω)|² dω (MATLAB's H_p, one-sided unit noise)."""
    speed = 80.0
    p = gust_parameters(altitude_m, "severe")
    sigma_w, length_w = float(p.sigma_w_mps), float(p.length_w_m)
    variance = roll_gust_std(speed, altitude_m, "severe", span_m) ** 2
    spectral, _ = integrate.quad(
        dryden_roll_spectrum, 0.0, np.inf, args=(sigma_w, length_w, span_m), epsrel=1e-10
    )
    gain = sigma_w * math.sqrt(0.8 / speed) * (math.pi / (4 * span_m)) ** (1 / 6)
    gain /= length_w ** (1 / 3)
    tau = 4 * span_m / (math.pi * speed)
    filtered, _ = integrate.quad(lambda w: gain**2 / (1 + (tau * w) ** 2), 0.0, np.inf)
    assert variance == pytest.approx(spectral, rel=1e-8)
    assert variance == pytest.approx(filtered, rel=1e-8)
    assert roll_gust_time_constant(speed, span_m) == pytest.approx(tau, rel=1e-14)


def test_std_does_not_depend_on_airspeed_but_vanishes_without_airflow() -> None:
    std = roll_gust_std([0.0, STILL_AIR_MPS / 2, STILL_AIR_MPS, 30.0, 300.0], 1000.0)
    assert isinstance(std, np.ndarray)
    assert std[0] == std[1] == 0.0
    np.testing.assert_allclose(std[2:], std[-1], rtol=1e-14)
    assert 0.4 < std[-1] < 0.7  # rad/s: b = 0.3 m makes p_g large (and fast)
    # the span's exponent: σ_p ∝ b^(-2/3)
    assert roll_gust_std(100.0, 1000.0, span_m=8 * DEFAULT_SPAN_M) == pytest.approx(
        std[-1] / 4.0, rel=1e-12
    )


def test_time_constant_is_infinite_without_airflow() -> None:
    t = roll_gust_time_constant([0.0, 100.0])
    assert isinstance(t, np.ndarray)
    assert t[0] == np.inf
    assert t[1] == pytest.approx(1.2 / (math.pi * 100.0), rel=1e-14)


# --------------------------------------------------------------------------- traces
def run(
    n_traces: int, n_intervals: int, dt_s: float, speed: float, seed: int, altitude: float = 2000.0
) -> tuple[np.ndarray, float, float]:
    """Traces (rad/s), σ_p and T for constant airspeed and altitude."""
    edges = np.arange(n_intervals + 1) * dt_s
    p = roll_gust(edges, speed, altitude, rng=np.random.default_rng(seed), size=n_traces) / DEG
    sigma = roll_gust_std(speed, altitude)
    tau = roll_gust_time_constant(speed)
    assert isinstance(sigma, float) and isinstance(tau, float)
    return p, sigma, tau


@pytest.mark.parametrize(
    ("speed", "dt_s", "label"),
    [
        (100.0, 0.01, "T = 3.8 ms, h = 10 ms"),
        (300.0, 0.1, "T = 1.3 ms << h = 100 ms"),
    ],
)
def test_held_variance_and_lag1_covariance_match_theory(
    speed: float, dt_s: float, label: str
) -> None:
    """4000 traces x 200 intervals, nearly independent: the variance's sampling
    error is about 0.2 %, the lag-1 correlation's about 0.002."""
    p, sigma, tau = run(4000, 200, dt_s, speed, seed=7)
    variance = float(np.mean(p**2))
    lag1 = float(np.mean(p[:, :-1] * p[:, 1:]))
    expected = held_variance(sigma, tau, dt_s)
    assert variance == pytest.approx(expected, rel=0.02), label
    assert lag1 / variance == pytest.approx(held_lag1(sigma, tau, dt_s) / expected, abs=0.01)
    assert abs(float(np.mean(p))) < 0.01 * sigma
    # Point samples would have variance σ²: the hold removes much of it.
    assert variance < 0.6 * sigma**2
    if dt_s / tau > 50:  # the white-noise limit: variance 2σ²T/h, neighbours uncorrelated
        assert variance == pytest.approx(2 * sigma**2 * tau / dt_s, rel=0.03)
        assert abs(lag1 / variance) < 0.015


def test_long_correlation_time_gives_point_values_and_averaged_increments() -> None:
    """T = 0.38 s >> h = 1 ms: the held values are the point values (variance
    σ²(1 − u/3)); their increments have variance 2(Var − Cov) ≈ (4/3)·u·σ², not
    the 2·u·σ² of point samples.  20000 traces: the variance's sampling error is
    about 1 %, the increments' about 0.3 %."""
    dt_s, speed = 0.001, 1.0
    p, sigma, tau = run(20_000, 20, dt_s, speed, seed=11)
    expected = held_variance(sigma, tau, dt_s)
    assert float(np.mean(p**2)) == pytest.approx(expected, rel=0.04)
    increments = float(np.mean(np.diff(p, axis=1) ** 2))
    expected_increments = 2 * (expected - held_lag1(sigma, tau, dt_s))
    assert increments == pytest.approx(expected_increments, rel=0.03)
    u = dt_s / tau
    assert expected_increments == pytest.approx(4 / 3 * u * sigma**2, rel=0.01)


@pytest.mark.parametrize("speed", [100.0, 0.05])
def test_tiny_intervals_give_the_stationary_variance(speed: float) -> None:
    """h = 1 µs << T (u = h/T = 2.6e-4, and 1.3e-7 where the conditional variance
    of the integral, (2/3)u³, is below the rounding of its closed form): held
    values = point values, variance roll_gust_std².  20000 traces: sampling
    error about 1 %."""
    p, sigma, tau = run(20_000, 5, 1e-6, speed, seed=3)
    assert float(np.mean(p**2)) == pytest.approx(sigma**2, rel=0.04)
    assert float(np.mean(p[:, 0] ** 2)) == pytest.approx(sigma**2, rel=0.04)
    # 2(Var - Cov) = σ²·(4/3)·u·(1 - 3u/4 + ...), summed here without cancellation
    u = 1e-6 / tau
    expected_increments = sigma**2 * 4 / 3 * u * (1 - 0.75 * u)
    increments = float(np.mean(np.diff(p, axis=1) ** 2))
    assert increments == pytest.approx(expected_increments, rel=0.05)


def test_airspeed_and_altitude_are_taken_at_the_interval_midpoint() -> None:
    """Edge airspeeds alternating 20/180 m/s have the midpoints of a constant 100 m/s."""
    edges = np.arange(51) * 0.01
    alternating = np.where(np.arange(51) % 2 == 0, 20.0, 180.0)
    heights = np.where(np.arange(51) % 2 == 0, 900.0, 1100.0)
    a = roll_gust(edges, alternating, heights, rng=np.random.default_rng(5), size=3)
    b = roll_gust(edges, 100.0, 1000.0, rng=np.random.default_rng(5), size=3)
    np.testing.assert_array_equal(a, b)


def test_varying_airspeed_keeps_each_interval_at_its_own_theory() -> None:
    """V ramps 20 → 300 m/s at constant altitude: σ_p does not change, so each
    interval's held variance is the theory at its own T.  8000 traces: the pooled
    ratio's sampling error is about 0.2 %."""
    edges = np.arange(101) * 0.01
    speed = np.linspace(20.0, 300.0, 101)
    p = roll_gust(edges, speed, 1500.0, rng=np.random.default_rng(9), size=8000) / DEG
    sigma = roll_gust_std(100.0, 1500.0)
    assert isinstance(sigma, float)
    taus = np.asarray(roll_gust_time_constant(0.5 * (speed[1:] + speed[:-1])))
    expected = np.array([held_variance(sigma, t, 0.01) for t in taus])
    ratio = np.mean(p**2, axis=0) / expected
    assert float(np.mean(ratio)) == pytest.approx(1.0, abs=0.02)
    assert float(np.max(np.abs(ratio - 1.0))) < 0.08  # one interval: about 1.6 % each


def test_no_airflow_gives_zero_and_keeps_the_field() -> None:
    """On the pad and at apogee p_g = 0; across a still stretch the state is frozen, so
    the values on either side stay as correlated as neighbours (T = 0.38 s)."""
    edges = np.arange(121) * 0.001
    speed = np.full(121, 1.0)
    speed[:3] = 0.0  # pad: intervals 0 and 1 have midpoint 0
    speed[50:80] = 0.0  # a still stretch: intervals 50..78
    speed[-2:] = 0.0  # apogee: the last interval
    p = roll_gust(edges, speed, 300.0, rng=np.random.default_rng(2), size=4000)
    still = 0.5 * (speed[1:] + speed[:-1]) < STILL_AIR_MPS
    assert np.all(p[:, still] == 0.0)
    assert np.all(p[:, ~still] != 0.0)
    assert still.sum() == 2 + 29 + 1
    before, after = p[:, 49], p[:, 79]  # the last moving interval before, the first after
    assert float(np.corrcoef(before, after)[0, 1]) > 0.99
    assert float(np.std(after)) == pytest.approx(float(np.std(before)), rel=0.05)


def test_same_seed_same_traces_and_one_trace_without_the_axis() -> None:
    edges = np.linspace(0.0, 0.2, 21)
    a = roll_gust(edges, 80.0, 500.0, severity="severe", rng=np.random.default_rng(42), size=5)
    b = roll_gust(edges, 80.0, 500.0, severity="severe", rng=np.random.default_rng(42), size=5)
    c = roll_gust(edges, 80.0, 500.0, severity="severe", rng=np.random.default_rng(43), size=5)
    one = roll_gust(edges, 80.0, 500.0, severity="severe", rng=np.random.default_rng(42))
    assert a.shape == (5, 20) and one.shape == (20,)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert abs(float(np.corrcoef(a[0], a[1])[0, 1])) < 0.6  # independent traces
    first = roll_gust(edges, 80.0, 500.0, severity="severe", rng=np.random.default_rng(42), size=1)
    np.testing.assert_array_equal(one, first[0])


def test_severity_scales_the_traces() -> None:
    """Below 1000 ft σ_w ∝ W20 and L_w does not depend on severity: same noise, 3x."""
    edges = np.linspace(0.0, 0.1, 11)
    light = roll_gust(edges, 60.0, 100.0, rng=np.random.default_rng(1), size=2)
    severe = roll_gust(edges, 60.0, 100.0, severity="severe", rng=np.random.default_rng(1), size=2)
    np.testing.assert_allclose(severe, 3.0 * light, rtol=1e-12)


# --------------------------------------------------------------------------- refusals
EDGES = np.linspace(0.0, 0.05, 6)
RNG = np.random.default_rng(0)


@pytest.mark.parametrize(
    ("call", "argument"),
    [
        (lambda: gust_parameters(100.0, "extreme"), "severity"),  # type: ignore[arg-type]
        (lambda: gust_parameters(100.0, 3), "severity"),  # type: ignore[arg-type]
        (lambda: gust_parameters(-1.0), "altitude_m"),
        (lambda: gust_parameters([10.0, np.nan]), "altitude_m"),
        (lambda: roll_gust_std(-5.0, 100.0), "airspeed_mps"),
        (lambda: roll_gust_std(5.0, 100.0, span_m=0.0), "span_m"),
        (lambda: roll_gust_std([1.0, 2.0], [1.0, 2.0, 3.0]), "altitude_m"),
        (lambda: roll_gust_time_constant(10.0, span_m=-0.3), "span_m"),
        (lambda: roll_gust(EDGES[::-1], 50.0, 100.0, rng=RNG), "edges_s"),
        (lambda: roll_gust([0.0, 0.01, 0.01, 0.02], 50.0, 100.0, rng=RNG), "edges_s"),
        (lambda: roll_gust([0.0], 50.0, 100.0, rng=RNG), "edges_s"),
        (lambda: roll_gust(EDGES, [50.0, -1.0, 50.0, 50.0, 50.0, 50.0], 1.0, rng=RNG), "airspeed"),
        (lambda: roll_gust(EDGES, np.full(5, 50.0), 100.0, rng=RNG), "airspeed_mps"),
        (lambda: roll_gust(EDGES, 50.0, np.full((6, 1), 100.0), rng=RNG), "altitude_m"),
        (lambda: roll_gust(EDGES, 50.0, -10.0, rng=RNG), "altitude_m"),
        (lambda: roll_gust(EDGES, 50.0, 100.0, severity="heavy", rng=RNG), "severity"),  # type: ignore[arg-type]
        (lambda: roll_gust(EDGES, 50.0, 100.0, rng=np.random.RandomState(0)), "rng"),  # type: ignore[arg-type]
        (lambda: roll_gust(EDGES, 50.0, 100.0, rng=RNG, size=0), "size"),
        (lambda: roll_gust(EDGES, 50.0, 100.0, rng=RNG, size=2.5), "size"),  # type: ignore[arg-type]
    ],
)
def test_bad_arguments_are_refused_by_name(call: object, argument: str) -> None:
    assert callable(call)
    with pytest.raises(UsageError, match=rf"^{argument}"):
        call()
