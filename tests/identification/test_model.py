"""The one roll model (identification.model) against a reference integration.

Reference: scipy ``solve_ivp`` (DOP853, rtol = atol = 1e-11) of eq. 36/49 with
the *continuous* rate-limited servo path of eq. 23 (computed here
independently of the model's own servo code) and u_d held per interval.

Stated tolerance of the exact update (0.01 s substeps) against it, through
servo ramps (ending on or inside substeps), fin saturation and the |θ + θ̄|
kink of a(θ):
    θ-dependent damping:  |Δv| <= 2e-3 °/s,  |Δφ| <= 2e-3 °
    constant damping:     |Δv| <= 1e-7 °/s,  |Δφ| <= 1e-7 ° (exact up to the reference)
With θ-dependent damping the remaining error is that of freezing a(θ) over a
0.01 s ramp piece; it is second order in the substep (checked below) and 50
times below the paper's rate MAE of 0.1 °/s.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from identification.model import (
    PAPER_CONSTANT,
    PAPER_THETA,
    RollParams,
    Servo,
    damping,
    roll_step,
    servo_path,
    servo_step,
    simulate,
)

DT = 0.1
TOL_RATE_DPS = 2e-3
TOL_ANGLE_DEG = 2e-3
TOL_EXACT = 1e-7


def continuous_servo(commands: np.ndarray, theta0: float, servo: Servo):
    """θ(t) for commands held over [k·DT, (k+1)·DT): exact rate-limited path."""
    targets = np.clip(commands, -servo.range_deg, servo.range_deg)
    starts = np.empty(len(commands) + 1)
    starts[0] = theta0
    for k, target in enumerate(targets):
        delta = target - starts[k]
        starts[k + 1] = starts[k] + np.sign(delta) * min(abs(delta), servo.rate_limit_dps * DT)

    def theta(t: float, k: int) -> float:
        delta = targets[k] - starts[k]
        move = min(abs(delta), servo.rate_limit_dps * (t - k * DT))
        return float(starts[k] + np.sign(delta) * move)

    return theta


def reference(params: RollParams, commands, u_d, v0: float, servo: Servo):
    """solve_ivp of eq. 36/49, interval by interval (u_d and commands jump at the edges)."""
    theta = continuous_servo(np.asarray(commands, float), float(commands[0]), servo)
    state = np.array([v0, 0.0])
    out = [state.copy()]
    for k in range(len(commands)):

        def rhs(t, y, k=k):
            th = theta(t, k)
            a = params.alpha_bar_per_deg_s * abs(th + params.theta_bar_deg) + params.beta_bar_per_s
            return [-a * (y[0] - params.alpha * (th + params.theta_bar_deg + u_d[k])), y[0]]

        sol = solve_ivp(
            rhs,
            (k * DT, (k + 1) * DT),
            state,
            method="DOP853",
            rtol=1e-11,
            atol=1e-11,
            max_step=DT / 20,
        )
        state = sol.y[:, -1]
        out.append(state.copy())
    return np.array(out)


def scenario(seed: int):
    """Commands with small steps, large ramps (> one interval) and saturating commands."""
    rng = np.random.default_rng(seed)
    commands = np.repeat([0.0, 13.33, -26.67, 60.0, -70.0, 40.0, -4.38, 12.0], 8)
    u_d = rng.normal(0.0, 8.4, commands.size)
    return commands, u_d


@pytest.mark.parametrize("params", [PAPER_THETA, PAPER_CONSTANT], ids=["theta", "constant"])
def test_exact_update_matches_solve_ivp(params: RollParams) -> None:
    commands, u_d = scenario(0)
    servo = Servo()
    v0 = float(params.steady_rate(commands[0]))
    ref = reference(params, commands, u_d, v0, servo)
    sim = simulate(params, DT, commands, u_d, rate0_dps=v0, servo=servo, substeps=10)
    err_v = np.max(np.abs(sim.rate_dps - ref[:, 0]))
    err_phi = np.max(np.abs(sim.angle_deg - ref[:, 1]))
    tol_v, tol_phi = (
        (TOL_EXACT, TOL_EXACT) if params.is_constant_damping else (TOL_RATE_DPS, TOL_ANGLE_DEG)
    )
    assert err_v <= tol_v, err_v
    assert err_phi <= tol_phi, err_phi
    # The scenario really exercises the limits it claims to.
    assert sim.fin_deg.max() == pytest.approx(40.0) and sim.fin_deg.min() == pytest.approx(-40.0)
    assert np.max(np.abs(np.diff(sim.fin_deg))) == pytest.approx(150.0 * DT)


def test_theta_dependent_error_is_second_order_in_the_substep() -> None:
    commands, u_d = scenario(0)
    v0 = float(PAPER_THETA.steady_rate(0.0))
    ref = reference(PAPER_THETA, commands, u_d, v0, Servo())
    errors = [
        np.max(
            np.abs(
                simulate(PAPER_THETA, DT, commands, u_d, rate0_dps=v0, substeps=n).rate_dps
                - ref[:, 0]
            )
        )
        for n in (10, 40)
    ]
    # Four times finer: a first-order method gains 4x, a second-order one 16x.
    assert errors[1] < errors[0] / 8, errors


def test_ramp_ending_inside_a_substep_is_followed_exactly() -> None:
    # A 13.33° step takes 0.0889 s at 150 °/s: the ramp ends inside the 9th substep.
    # Treating the fin as linear over that whole substep (no rate limit) is measurably
    # worse than the exact ramp-then-hold composition.
    commands = np.repeat([0.0, 13.33, -13.33], 5)
    u_d = np.zeros(commands.size)
    v0 = float(PAPER_CONSTANT.steady_rate(0.0))
    ref = reference(PAPER_CONSTANT, commands, u_d, v0, Servo())
    exact = simulate(PAPER_CONSTANT, DT, commands, u_d, rate0_dps=v0)
    theta = servo_path(np.repeat(commands, 10), 0.0, DT / 10, Servo())
    linear = simulate(
        PAPER_CONSTANT, DT / 10, theta, np.repeat(u_d, 10), rate0_dps=v0, servo=None, substeps=1
    )
    assert np.max(np.abs(exact.rate_dps - ref[:, 0])) <= TOL_EXACT
    assert np.max(np.abs(linear.rate_dps[::10] - ref[:, 0])) > 100 * TOL_EXACT


def test_forward_euler_would_fail_the_same_tolerance() -> None:
    """The reference is sharp enough to tell a crude integrator from the exact one."""
    commands, u_d = scenario(2)
    v0 = float(PAPER_THETA.steady_rate(0.0))
    ref = reference(PAPER_THETA, commands, u_d, v0, Servo())
    theta = servo_path(np.repeat(commands, 10), 0.0, DT / 10, Servo())
    v = v0
    rates = [v]
    for k in range(commands.size * 10):
        a = float(damping(PAPER_THETA, theta[k]))
        v += (
            DT
            / 10
            * -a
            * (v - PAPER_THETA.alpha * (theta[k] + PAPER_THETA.theta_bar_deg + u_d[k // 10]))
        )
        if (k + 1) % 10 == 0:
            rates.append(v)
    assert np.max(np.abs(np.array(rates) - ref[:, 0])) > 10 * TOL_RATE_DPS


def test_damping_is_eq48() -> None:
    # a(θ) = ᾱ|θ + θ̄| + β̄ with the paper's values (eq. 48); θ̄ = 2.8856/0.6590.
    theta_bar = 2.8856 / 0.6590
    for theta in (-40.0, -theta_bar, 0.0, 13.33, 40.0):
        expected = -0.0289 * abs(theta + theta_bar) + 2.4075
        assert float(damping(PAPER_THETA, theta)) == pytest.approx(expected, rel=1e-12)
    assert float(PAPER_CONSTANT.damping(25.0)) == 1.314


def test_steady_state_is_eq16() -> None:
    # A held fin angle settles at v_ss = α·θ + β (eq. 16) plus α·u_d (eq. 36).
    for params in (PAPER_THETA, PAPER_CONSTANT):
        v, _ = roll_step(params, 0.0, 0.0, 26.67, 26.67, 1.5, 60.0)
        assert float(v) == pytest.approx(0.6590 * (26.67 + 1.5) + 2.8856, rel=1e-9)


def test_roll_step_broadcasts_over_a_batch() -> None:
    rng = np.random.default_rng(3)
    v = rng.normal(0, 10, (4, 3))
    phi = rng.normal(0, 100, (4, 3))
    th0 = rng.uniform(-40, 40, (4, 3))
    th1 = servo_step(th0, rng.uniform(-40, 40, (4, 3)), 0.01, Servo())
    u = rng.normal(0, 8, (4, 3))
    v1, phi1 = roll_step(PAPER_THETA, v, phi, th0, th1, u, 0.01)
    assert v1.shape == phi1.shape == (4, 3)
    for i in range(4):
        for j in range(3):
            vs, ps = roll_step(PAPER_THETA, v[i, j], phi[i, j], th0[i, j], th1[i, j], u[i, j], 0.01)
            assert float(vs) == v1[i, j] and float(ps) == phi1[i, j]


def test_servo_lag_is_eq23() -> None:
    # Paper §2.6.1: a step from 13.3° to -13.3° takes |−13.3 − 13.3|·0.4/60 = 0.177 s.
    servo = Servo()
    assert float(servo.lag_s(-13.3 - 13.3)) == pytest.approx(0.17733, abs=1e-5)
    path = servo_path(np.full(30, -13.3), 13.3, 0.01, servo)
    reached = np.flatnonzero(np.isclose(path, -13.3))[0]
    assert reached * 0.01 == pytest.approx(0.18, abs=1e-9)  # first 0.01-s sample after 0.177 s
    assert path[17] > -13.3  # still moving at 0.17 s


def test_servo_saturates_commands_at_the_fin_range() -> None:
    servo = Servo()
    assert float(servo_step(39.0, 75.0, 1.0, servo)) == 40.0
    assert float(servo_step(-39.0, -75.0, 1.0, servo)) == -40.0
    assert float(servo_step(0.0, 75.0, 0.1, servo)) == pytest.approx(15.0)


def test_zero_damping_limit_is_finite() -> None:
    # ᾱ|θ + θ̄| + β̄ can reach 0 under domain randomisation; the update must stay finite
    # and reduce to constant rate (no forcing reaches the rate when a = 0).
    params = RollParams(alpha=0.659, theta_bar_deg=0.0, beta_bar_per_s=0.0)
    v, phi = roll_step(params, 5.0, 1.0, 10.0, 12.0, 3.0, 0.01)
    assert float(v) == pytest.approx(5.0) and float(phi) == pytest.approx(1.05)


def test_measured_fin_input_without_servo() -> None:
    # servo=None replays an actual fin angle (linear between samples).  Replaying the
    # servo's own path sampled every substep reproduces the servo simulation to within
    # the corner cut where a ramp ends inside a substep.
    commands, u_d = scenario(4)
    with_servo = simulate(PAPER_THETA, DT, commands, u_d)
    theta = servo_path(np.repeat(commands, 10), commands[0], DT / 10, Servo())
    replay = simulate(
        PAPER_THETA,
        DT / 10,
        theta,
        np.repeat(u_d, 10),
        servo=None,
        substeps=1,
        rate0_dps=float(with_servo.rate_dps[0]),
    )
    assert np.max(np.abs(replay.rate_dps[::10] - with_servo.rate_dps)) < 0.01
    assert np.array_equal(replay.fin_deg[::10], with_servo.fin_deg)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dt_s": 0.0}, "dt_s"),
        ({"substeps": 0}, "substeps"),
        ({"fin_deg": [[1.0]]}, "one-dimensional"),
        ({"fin_deg": [np.nan, 1.0]}, "finite"),
    ],
)
def test_simulate_rejects_bad_input(kwargs, message) -> None:
    args = {"dt_s": 0.1, "fin_deg": [0.0, 1.0]} | kwargs
    with pytest.raises(ValueError, match=message):
        simulate(PAPER_THETA, **args)


def test_params_validation() -> None:
    with pytest.raises(ValueError, match="alpha"):
        RollParams(alpha=0.0, theta_bar_deg=1.0, beta_bar_per_s=1.0)
    with pytest.raises(ValueError, match="finite"):
        RollParams(alpha=1.0, theta_bar_deg=np.inf, beta_bar_per_s=1.0)
    with pytest.raises(ValueError, match="rate_limit"):
        Servo(rate_limit_dps=0.0)
    assert PAPER_THETA.beta_dps == pytest.approx(2.8856)
    assert PAPER_THETA.theta_bar_deg == pytest.approx(4.3788, abs=1e-4)  # paper eq. 46: 4.38°


def test_the_quadratic_steady_rate_is_the_root_and_its_bound() -> None:
    """``v·(1 + q·|v|/30) = α·x``: the root of the same sign, the linear rate itself at
    q = 0 (to the bit); beyond a negative q's largest steady rate, that rate
    (``v₀/(2·|q|)``); :func:`simulate` starts a rocket at its own gain's steady rate."""
    from identification.model import QUADRATIC_RATE_DPS, quadratic_steady_rate, simulate

    linear = np.array([-40.0, -2.0, 0.0, 3.0, 25.0])
    assert np.array_equal(quadratic_steady_rate(linear, 0.0), linear)
    for q in (0.15, 1.0, -0.1):  # -0.1: steady rates up to 75 °/s of linear
        v = quadratic_steady_rate(linear, q)
        grown = v * (1 + q * np.abs(v) / QUADRATIC_RATE_DPS)
        np.testing.assert_allclose(grown, linear, atol=1e-9)
    assert quadratic_steady_rate(100.0, -0.3) == pytest.approx(QUADRATIC_RATE_DPS / 0.6)
    assert quadratic_steady_rate(-100.0, -0.3) == pytest.approx(-QUADRATIC_RATE_DPS / 0.6)
    rocket = dataclasses.replace(PAPER_THETA, quadratic_damping=1.0)
    held = simulate(rocket, 0.1, np.full(50, 10.0), gain=3.0)
    assert held.rate_dps[0] == pytest.approx(held.rate_dps[-1], abs=1e-6)
