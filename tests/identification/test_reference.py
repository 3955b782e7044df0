"""The reference integrator of a rocket outside the roll model, and the virtual tunnel's
effects: servo lag, backlash, sensor latency, quadratic damping, gusty turbulence."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from identification.instruments.reference import (
    Effects,
    ReferenceRun,
    gust_factor,
    simulate_reference,
)
from identification.instruments.tunnel import TunnelSpec, run_tunnel, spec_from_command
from identification.model import PAPER_CONSTANT, simulate
from identification.recordings.recording import recording_text
from rocketroll.cli import main
from rocketroll_common.errors import SettingError


def test_without_effects_the_reference_is_the_models_exact_kernel() -> None:
    """Two implementations of the roll dynamics, written apart: on the paper's run they
    agree to 1.3e-3 °/s with the tunnel's 10 substeps (the kernel's frozen a(θ) over a
    ramp) and to 2e-5 °/s with 100; the reference has converged at its 1-ms step."""
    spec = TunnelSpec(seed=0)
    rec = run_tunnel(spec)
    params = spec.params()
    assert rec.fin_cmd_deg is not None and rec.ud_true_deg is not None
    command, u_d = rec.fin_cmd_deg[:-1], rec.ud_true_deg[:-1]
    rate0 = float(params.steady_rate(command[0], spec.turbulence_model().mean_deg))
    ref = simulate_reference(params, spec.log_dt, command, u_d, Effects(), rate0_dps=rate0)
    for substeps, tolerance in ((10, 2e-3), (100, 5e-5)):
        exact = simulate(params, spec.log_dt, command, u_d, rate0_dps=rate0,
                         servo=spec.servo(), substeps=substeps)  # fmt: skip
        assert np.max(np.abs(ref.rate_dps - exact.rate_dps)) < tolerance
        assert np.max(np.abs(ref.fin_deg - exact.fin_deg)) < 1e-9
    finer = simulate_reference(
        params, spec.log_dt, command, u_d, Effects(), rate0_dps=rate0, fine_step_s=2e-4
    )
    assert np.max(np.abs(finer.rate_dps - ref.rate_dps)) < 1e-4
    np.testing.assert_allclose(ref.rate_dps, ref.true_rate_dps, rtol=0, atol=1e-12)  # no latency


@pytest.mark.parametrize("q", [0.15, 0.5, -0.2])
def test_the_models_quadratic_damping_is_the_reference_integrators(q: float) -> None:
    """A rocket whose damping grows (or shrinks) with the roll rate, on the paper's run:
    the model's kernel (each substep damped at its starting rate, the path settled by
    :func:`simulate`'s passes) within 0.04 °/s of the reference integrator at 10
    substeps and 4e-3 °/s at 100 (first order in the substep: 0.011-0.031 and
    0.0010-0.0032 seen), where the term moves the rate by 5.8-25 °/s; the steady rate
    the root of ``v·(1 + q·|v|/30) = α·(θ + θ̄)``."""
    spec = TunnelSpec(seed=0)
    rec = run_tunnel(spec)
    linear = spec.params()
    params = dataclasses.replace(linear, quadratic_damping=q)
    assert rec.fin_cmd_deg is not None and rec.ud_true_deg is not None
    command, u_d = rec.fin_cmd_deg[:-1], rec.ud_true_deg[:-1]
    rate0 = float(params.steady_rate(command[0], u_d[0]))
    if q > 0:  # the effects' term, on the linear rocket
        ref = simulate_reference(linear, spec.log_dt, command, u_d,
                                 Effects(quadratic_damping=q), rate0_dps=rate0)  # fmt: skip
    else:  # the rocket's own (the effects' is not negative)
        ref = simulate_reference(params, spec.log_dt, command, u_d, Effects(), rate0_dps=rate0)
    plain = simulate(linear, spec.log_dt, command, u_d, rate0_dps=rate0, servo=spec.servo())
    assert np.max(np.abs(ref.rate_dps - plain.rate_dps)) > 5.0
    for substeps, tolerance in ((10, 0.04), (100, 4e-3)):
        exact = simulate(params, spec.log_dt, command, u_d, rate0_dps=rate0,
                         servo=spec.servo(), substeps=substeps)  # fmt: skip
        assert np.max(np.abs(ref.rate_dps - exact.rate_dps)) < tolerance
    x = np.array([-20.0, -1.0, 0.0, 3.0, 25.0])
    v = params.steady_rate(x - params.theta_bar_deg)
    np.testing.assert_allclose(v * (1.0 + q * np.abs(v) / 30.0), linear.alpha * x, atol=1e-9)
    with pytest.raises(ValueError, match="stated twice"):
        simulate_reference(params, spec.log_dt, command, u_d, Effects(quadratic_damping=0.1))


def _step(effects: Effects, level: float = 10.0, seconds: float = 4.0) -> ReferenceRun:
    n = round(seconds / 0.01)
    command = np.r_[0.0, np.full(n - 1, level)]
    return simulate_reference(PAPER_CONSTANT, 0.01, command, np.zeros(n), effects, rate0_dps=0.0)


def test_each_effect_does_what_it_says() -> None:
    plain = _step(Effects())
    # Servo lag: the fin follows the servo (at 10° after 0.077 s) a time constant behind.
    lagged = _step(Effects(servo_lag_s=0.2))
    assert plain.fin_deg[20] == pytest.approx(10.0)
    assert lagged.fin_deg[10] < 5.0 < lagged.fin_deg[60]
    assert lagged.fin_deg[-1] == pytest.approx(10.0, abs=1e-6)
    # Backlash: approached from below, the fin stops half the play short.
    played = _step(Effects(backlash_deg=1.0))
    assert played.fin_deg[-1] == pytest.approx(9.5)
    # Latency: the sensors read the rocket as it was 0.03 s ago.
    late = _step(Effects(latency_s=0.03))
    np.testing.assert_allclose(late.rate_dps[3:], late.true_rate_dps[:-3], atol=1e-9)
    np.testing.assert_allclose(late.true_rate_dps, plain.true_rate_dps)
    # Quadratic damping: the steady rate solves a·(v − α·x) + a·q·v·|v|/30 = 0.
    q = 0.15
    steady = _step(Effects(quadratic_damping=q), seconds=16.0).rate_dps[-1]
    drive = PAPER_CONSTANT.alpha * (10.0 + PAPER_CONSTANT.theta_bar_deg)
    assert steady < plain.rate_dps[-1]
    assert steady - drive + q * steady * abs(steady) / 30.0 == pytest.approx(0.0, abs=1e-6)


def test_the_gust_factor_wanders_about_one() -> None:
    rng = np.random.default_rng(0)
    factor = gust_factor(200_000, 0.1, Effects(gust_sd=0.35, gust_time_s=20.0), rng)
    assert np.mean(factor) == pytest.approx(1.0, abs=0.05)
    assert np.std(np.log(factor)) == pytest.approx(0.35, rel=0.1)
    lo, hi = np.percentile(factor, [5, 95])
    assert 0.45 < lo < 0.65 and 1.5 < hi < 1.9
    np.testing.assert_array_equal(gust_factor(5, 0.1, Effects(), rng), np.ones(5))


def test_the_tunnel_flies_the_effects_and_records_them_in_its_truth() -> None:
    """Off by default (the default run unchanged); on, the run says so in its metadata, its
    command reproduces it, and the gust makes the turbulence's intensity swell."""
    plain = TunnelSpec(seed=2)
    assert not plain.effects.any
    assert "truth.servo_lag_s" not in run_tunnel(plain).metadata
    effects = Effects(servo_lag_s=0.05, backlash_deg=0.5, latency_s=0.03,
                      quadratic_damping=0.15, gust_sd=0.35)  # fmt: skip
    spec = TunnelSpec(seed=2, effects=effects, measured_fin=True)
    rec = run_tunnel(spec)
    meta = rec.metadata
    assert float(meta["truth.servo_lag_s"]) == 0.05 and float(meta["truth.gust_sd"]) == 0.35
    assert "servo lag 0.05 s" in meta["tunnel.effects"]
    assert recording_text(run_tunnel(spec_from_command(meta["command"]))) == recording_text(rec)
    # The same seed's turbulence, its intensity wandering over 20-s windows.
    swells = []
    for run in (run_tunnel(plain), rec):
        assert run.ud_true_deg is not None
        windows = run.ud_true_deg[: run.ud_true_deg.size // 200 * 200].reshape(-1, 200)
        swells.append(float(np.std(np.std(windows, axis=1))))
    assert swells[1] > 1.5 * swells[0]
    with pytest.raises(SettingError, match="servo_lag_s"):
        Effects(servo_lag_s=1.0)
    assert main(["tunnel", "--out", "never.csv", "--backlash", "-1"]) == 2


def test_the_flight_recorder_flies_the_effects_on_the_reference_integrator() -> None:
    """In flight too: with a vanishing effect the reference integrator (its gain and
    damping per 1-ms step) logs what the exact kernel logs to 0.01 °/s on a rate of 40 °/s;
    30 ms of latency delays the gyro by three samples; the log names its effects."""
    from identification.instruments.flightlog import FlightLogSpec, run_flight

    base: dict[str, Any] = {"seed": 0, "gyro_noise": 0.0, "gyro_floor": 0.0, "measured_fin": True}
    exact = run_flight(FlightLogSpec(**base))
    nearly = run_flight(FlightLogSpec(**base, effects=Effects(quadratic_damping=1e-9)))
    assert exact.roll_rate_dps is not None and nearly.roll_rate_dps is not None
    assert np.max(np.abs(nearly.roll_rate_dps - exact.roll_rate_dps)) < 0.01
    assert "flight.effects" in nearly.metadata and "flight.effects" not in exact.metadata
    late = run_flight(FlightLogSpec(**base, effects=Effects(latency_s=0.03)))
    assert late.roll_rate_dps is not None
    np.testing.assert_allclose(late.roll_rate_dps[3:], nearly.roll_rate_dps[:-3], atol=0.02)
