"""The MPC: the observer's LQR where no limit binds, the servo's limits where they do."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from agents.evaluate import env_on, protocol_episodes, run_episode
from agents.mpc import MPCController
from agents.registry import make_controller
from rollenv.bank import load_bank, variant_config


@pytest.fixture(scope="module", params=["RocketRoll-v0", "RocketRollRate-v0"])
def pair(request, default_db):
    env_id = request.param
    cfg = variant_config(env_id, {"split": "test"})
    return cfg, make_controller("observer", cfg, env_id), make_controller("mpc", cfg, env_id)


def test_where_no_limit_binds_the_first_move_is_the_lqrs(pair):
    """Terminal cost = the LQR's Riccati matrix: the unconstrained plan's first move is the
    LQR's, for any horizon (checked on random small states: fin near trim, errors of a
    few degrees, so neither the range nor the rate limit binds)."""
    cfg, observer, mpc = pair
    assert isinstance(mpc, MPCController)
    rng = np.random.default_rng(3)
    n = observer.gain.size
    for _ in range(20):
        state = rng.normal(0.0, 0.3, n)
        fin = float(state[-1]) - observer.rocket.theta_bar_deg  # shift θ̄: fin = x - θ̄
        lqr = observer.command(state, observer.rocket.theta_bar_deg, fin)
        planned = mpc.command(state, observer.rocket.theta_bar_deg, fin)
        assert abs(lqr - fin) < cfg.rate_limit_dps * cfg.dt_s  # the LQR's move is feasible
        assert planned == pytest.approx(lqr, abs=1e-3)


def test_where_a_limit_binds_the_plan_keeps_to_it(pair):
    """A large error: the LQR asks for a move beyond what the servo does in one step (and
    the range); the plan's first move is exactly the servo's step, within the range."""
    cfg, observer, mpc = pair
    step = cfg.rate_limit_dps * cfg.dt_s
    state = np.zeros(observer.gain.size)
    state[0 if cfg.task == "rate" else 1] = 40.0  # 40 °/s or 40° off the setpoint
    shift = observer.rocket.theta_bar_deg
    fin = -shift  # at trim
    lqr = observer.command(state, shift, fin)
    planned = mpc.command(state, shift, fin)
    assert abs(lqr - fin) > step  # the LQR would ask for more ...
    assert abs(planned - fin) == pytest.approx(step, abs=1e-4)  # ... the servo's step
    assert np.sign(planned - fin) == np.sign(lqr - fin)
    plan = mpc.plan(state, shift, fin) - shift
    assert np.all(np.abs(plan) <= cfg.fin_range_deg + 1e-4)
    assert np.all(np.abs(np.diff(np.concatenate([[fin], plan]))) <= step + 1e-4)


def test_protocol_episodes_keep_the_servo_limits_and_every_qp_solves(pair):
    cfg, _, mpc = pair
    bank = load_bank(cfg, None)
    env = env_on(cfg, bank)
    step = cfg.rate_limit_dps * cfg.dt_s
    before = mpc.solves
    for spec in protocol_episodes(cfg, 3, seed=0, bank=bank):
        rollout = run_episode(env, mpc, spec)
        moves = rollout.command_deg[1:] - rollout.fin_deg[:-1]
        assert np.abs(moves).max() <= step + 1e-3
        assert np.abs(rollout.command_deg).max() <= cfg.fin_range_deg
    assert mpc.solves - before == 3 * cfg.max_episode_steps
    assert mpc.fallbacks == 0


def test_the_mpc_pickles_and_takes_a_horizon(default_db):
    cfg = variant_config("RocketRoll-v0", {"split": "test"})
    mpc = make_controller("mpc:5", cfg, "RocketRoll-v0")
    assert isinstance(mpc, MPCController)
    assert mpc.name == "MPC N=5" and mpc.horizon == 5
    clone = pickle.loads(pickle.dumps(mpc))
    obs = np.array([2.0, 1.0, -4.0, -4.0], dtype=np.float32)
    np.testing.assert_array_equal(mpc.act(obs, None), clone.act(obs, None))
    for bad, message in [
        ("mpc:0", "must be 1 to 100 steps"),
        ("mpc:101", "must be 1 to 100 steps"),
        ("mpc:100000", "got 100000"),
        ("mpc:x", "whole number"),
    ]:
        with pytest.raises(ValueError, match=message):
            make_controller(bad, cfg, "RocketRoll-v0")


@pytest.fixture(scope="module")
def flight(default_db):
    cfg = variant_config("RocketRollFlight-v0", {"split": "test"})
    mpc = make_controller("mpc", cfg, "RocketRollFlight-v0")
    observer = make_controller("observer", cfg, "RocketRollFlight-v0")
    assert isinstance(mpc, MPCController)
    return cfg, mpc, observer


def test_in_flight_the_plan_is_the_time_varying_lqr_where_no_limit_binds(flight):
    """Scheduled, the plan predicts with each coming step's rocket (not the step's own
    frozen): where no limit binds its first move is the finite-horizon LQR of those
    models, by the backward Riccati recursion from the terminal step's Riccati matrix."""
    cfg, mpc, _ = flight
    assert mpc.schedule is not None
    rng = np.random.default_rng(4)
    shift = mpc.rocket.theta_bar_deg
    for step in (0, 40, 120):  # the rail, top speed, the coast
        models, q, r, s, p = mpc._horizon_models(step)
        assert not np.allclose(models[0][0], models[-1][0])  # the rocket changes
        for a, b in reversed(models):
            k = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a + s.T)
            p = q + a.T @ p @ a - (a.T @ p @ b + s) @ k
        mpc.observer.steps = step + 1  # the controller reads the step from its filter
        for _ in range(5):
            state = rng.normal(0.0, 0.05, mpc.gain.size)
            fin = float(state[-1]) - shift
            expected = float(-k[0] @ state[mpc.design_states]) - shift
            assert abs(expected - fin) < cfg.rate_limit_dps * cfg.dt_s
            assert mpc.command(state, shift, fin) == pytest.approx(expected, abs=1e-3)
    mpc.reset()


def test_in_flight_the_mpc_flies_as_the_observer_within_the_servo_limits(flight):
    cfg, mpc, observer = flight
    bank = load_bank(cfg, None)
    env = env_on(cfg, bank)
    step = cfg.rate_limit_dps * cfg.dt_s
    for spec in protocol_episodes(cfg, 2, seed=0, bank=bank):
        planned = run_episode(env, mpc, spec)
        moves = planned.command_deg[1:] - planned.fin_deg[:-1]
        assert np.abs(moves).max() <= step + 1e-3
        lqr = run_episode(env, observer, spec)
        mine, theirs = (float(np.sqrt(np.mean(x.angle_deg**2))) for x in (planned, lqr))
        assert mine < 3.0  # unscheduled, the tunnel's MPC held 83°
        assert mine == pytest.approx(theirs, rel=0.2)
    assert mpc.fallbacks == 0
    # Pickled mid-flight, it acts on as it was.
    obs = np.array([2.0, 1.0, -4.0, -4.0], dtype=np.float32)
    mpc.reset()
    for _ in range(30):
        mpc.act(obs, None)
    clone = pickle.loads(pickle.dumps(mpc))
    for _ in range(5):
        np.testing.assert_array_equal(mpc.act(obs, None), clone.act(obs, None))


def test_a_plan_depends_on_its_episode_alone(flight):
    """Reset after another episode, the MPC acts as a new one does: OSQP starts each solve
    from the last plan and its initial step size, unscaled (its own timing-based
    adaptation, and its rescaling at each Hessian update, made plans depend on the
    episodes before)."""
    cfg = flight[0]
    used, fresh = (make_controller("mpc", cfg, "RocketRollFlight-v0") for _ in range(2))
    obs = np.array([2.0, 1.0, -4.0, -4.0], dtype=np.float32)
    used.reset(None)
    for _ in range(35):
        used.act(obs, None)
    used.reset(None)
    fresh.reset(None)
    for _ in range(35):
        np.testing.assert_array_equal(used.act(obs, None), fresh.act(obs, None))


def test_a_plan_osqp_did_not_solve_is_not_flown(flight):
    """Only OSQP_SOLVED (or _INACCURATE) plans are used and warm-start the next; stopped at
    its iteration limit, the LQR's move is flown instead and the next plan starts cold."""
    mpc = make_controller("mpc", flight[0], "RocketRollFlight-v0")
    assert isinstance(mpc, MPCController)
    mpc.reset(None)
    mpc._qp.update_settings(max_iter=1)
    mpc.act(np.array([2.0, 1.0, -4.0, -4.0], dtype=np.float32), None)
    assert (mpc.solves, mpc.fallbacks) == (1, 1)
    assert mpc._warm is None
