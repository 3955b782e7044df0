"""Tunnel traces flown (disturbances.flight): Taylor's time compression, the V_ref/V flow
angle, exact averages over each flown sample, and the bank of flights."""

from __future__ import annotations

import numpy as np
import pytest

from disturbances.bank import TraceBank
from disturbances.flight import flight_bank
from identification.model import RollParams
from rocketroll_physics.flown import fly_trace, tunnel_time

V_REF = 50 / 3.6
H = 0.01  # the env's substep


def edges(n: int) -> np.ndarray:
    return H * np.arange(n + 1)


def test_at_the_tunnels_airspeed_a_flight_is_the_tunnel() -> None:
    u = np.random.default_rng(0).normal(0.0, 5.0, 300)
    e = edges(1000)
    tau = tunnel_time(e, np.full(e.size, V_REF), V_REF)
    np.testing.assert_allclose(tau, e, rtol=0, atol=1e-12)
    flown = fly_trace(u, 0.1, 2.0, tau, np.ones(1000))
    np.testing.assert_allclose(flown, np.repeat(u[20:120], 10), rtol=0, atol=1e-9)


def test_three_times_faster_compresses_time_and_shrinks_the_angle() -> None:
    # Each flown 0.01-s sample covers 0.03 s of tunnel time at a third of the flow angle;
    # the averages computed here on a fine grid, independently of the module.
    u = np.random.default_rng(1).normal(0.0, 5.0, 200)
    e = edges(400)
    speed = np.full(e.size, 3 * V_REF)
    tau = tunnel_time(e, speed, V_REF)
    amplitude = V_REF / np.maximum(0.5 * (speed[1:] + speed[:-1]), V_REF)
    flown = fly_trace(u, 0.1, 1.0, tau, amplitude)
    fine = np.repeat(u, 1000)  # 0.1-ms samples
    start = 10_000  # 1.0 s
    expected = fine[start : start + 400 * 300].reshape(400, 300).mean(axis=1) / 3
    np.testing.assert_allclose(flown, expected, rtol=0, atol=1e-9)


def test_a_varying_airspeed_conserves_the_tunnels_impulse() -> None:
    # sum over flown samples of u_j / amplitude_j * (tau_{j+1} - tau_j) = the integral of the
    # tunnel trace over the tunnel time flown: nothing is lost or counted twice.
    u = np.random.default_rng(2).normal(0.0, 5.0, 1500)
    e = edges(2000)
    speed = V_REF * (0.2 + 11.8 * np.sin(np.pi * e / e[-1]) ** 2)  # 10 km/h .. 600 km/h
    tau = tunnel_time(e, speed, V_REF)
    amplitude = V_REF / np.maximum(0.5 * (speed[1:] + speed[:-1]), V_REF)
    flown = fly_trace(u, 0.1, 3.0, tau, amplitude)
    grid = 0.1 * np.arange(u.size + 1)
    integral = np.concatenate([[0.0], np.cumsum(u) * 0.1])
    whole = np.interp(3.0 + tau[-1], grid, integral) - np.interp(3.0, grid, integral)
    assert np.sum(flown / amplitude * np.diff(tau)) == pytest.approx(whole, rel=1e-9)
    assert tau[-1] == pytest.approx(np.trapezoid(speed / V_REF, e), rel=1e-12)


def test_the_bank_of_flights() -> None:
    rng = np.random.default_rng(3)
    params = RollParams(0.66, 4.4, 2.4, -0.029)
    bank = TraceBank.from_arrays(
        [rng.normal(0.0, 4.0, 600), rng.normal(0.0, 4.0, 450)], 0.1, params
    )
    e = edges(500)  # a 5-s flight at twice the tunnel's airspeed: 10 s of tunnel time
    flown = flight_bank(bank, e, np.full(e.size, 2 * V_REF), v_ref_mps=V_REF, stride_s=5.0)
    # starts 0, 5, ..., 50 s in the 60-s trace and 0, ..., 35 s in the 45-s one
    assert len(flown) == 11 + 8
    first = flown.traces[0]
    assert first.uid == f"{bank.traces[0].uid}@0s" and flown.traces[1].uid.endswith("@5s")
    assert first.dt_s == H and first.n_samples == 500 and first.params == params
    assert first.settings["flown_from"] == bank.traces[0].uid
    # each flown 0.01 s is 0.02 s of tunnel time: five flown samples per tunnel sample, halved
    np.testing.assert_allclose(
        first.samples()[:10], np.repeat(bank.traces[0].samples()[:2], 5) / 2, rtol=0, atol=1e-12
    )
    capped = flight_bank(bank, e, np.full(e.size, 2 * V_REF), v_ref_mps=V_REF, max_traces=4)
    assert len(capped) == 4
    with pytest.raises(ValueError, match=r"takes 100\.0 s of tunnel turbulence"):
        flight_bank(bank, e, np.full(e.size, 20 * V_REF), v_ref_mps=V_REF)
    with pytest.raises(ValueError, match="evenly spaced"):
        flight_bank(bank, e**2, np.full(e.size, V_REF), v_ref_mps=V_REF)
    with pytest.raises(ValueError, match="airspeed_mps must be finite and >= 0"):
        flight_bank(bank, e, np.full(e.size, -1.0), v_ref_mps=V_REF)
