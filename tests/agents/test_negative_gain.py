"""A negative gain α: the aileron convention where a positive fin rolls the rocket negative.

In that convention every angle in fin degrees changes sign -- the fin θ, the asymmetry θ̄,
the turbulence ``u_d`` -- and α with them: the rocket ``(-α, -θ̄)`` under ``-u_d`` rolls
exactly as ``(α, θ̄)`` under ``u_d`` with its fins mirrored (eq. 36: ``α·(θ + θ̄ + u_d)``;
``a(θ) = ᾱ·|θ + θ̄| + β̄`` is the same).  A model-based controller designed on the mirrored
identification must therefore fly the same roll with mirrored fins: the same angle, rate
and score, every fin command negated.

The controllers are made as the registry makes them (``--policy NAME``) from a train split
of one identified rocket (:class:`~agents.base.Design`, its banks given), so the nominal
rocket is taken from the identification as in an evaluation.
"""

from __future__ import annotations

import numpy as np
import pytest

from agents.base import Controller, Design, EpisodeSpec
from agents.evaluate import env_on, metrics, run_episode
from agents.nominal import NominalModel
from agents.pid import PIDController, PIDGains
from agents.registry import CONTROLLERS, available
from disturbances.bank import TraceBank
from identification.model import RollParams
from rollenv.bank import variant_config
from rollenv.config import RollConfig
from rollenv.layout import Obs

#: The model-based deployable controllers of the registry (the oracles read the true
#: rocket from the environment, the learned ones no model); ``pid-tunnel`` is offered in
#: flight only.
MODEL_BASED = ("trim", "pid", "pid-tunnel", "observer", "mpc")

#: Each environment and a setpoint per 10-s period of a 20-s episode.
SETPOINTS = {
    "RocketRoll-v0": (10.0, -20.0),
    "RocketRollRate-v0": (20.0, -10.0),
    "RocketRollFlight-v0": (10.0, -20.0),
    "RocketRollFlightRate-v0": (20.0, -10.0),
}

#: A rocket other than the paper's, with a damping that grows away from trim; and one
#: faster than the PID's designs (a > (1 + 2ζ)ω, 2ζω: its rate gain held at 0).
ROCKETS = {
    "tunnel": RollParams(0.66, 4.5, 2.4, 0.02),
    "fast": RollParams(0.9, -3.0, 20.0),
}


def mirrored(rocket: RollParams) -> RollParams:
    """The same rocket in the other aileron convention."""
    return RollParams(
        -rocket.alpha, -rocket.theta_bar_deg, rocket.beta_bar_per_s, rocket.alpha_bar_per_deg_s
    )


def turbulence(seed: int = 15) -> np.ndarray:
    """``u_d``, °: two sines, a 6° step at 30 s and white noise, 0.1-s samples."""
    t = np.arange(1600) * 0.1
    rng = np.random.default_rng(seed)
    u = 8 * np.sin(2 * np.pi * 0.3 * t) + 3 * np.sin(2 * np.pi * 1.1 * t + 1.0)
    return np.asarray(u + 6.0 * (t >= 30.0) + rng.normal(0.0, 1.0, t.size))


def mirrored_nominal(model: NominalModel) -> NominalModel:
    return NominalModel(
        model.a_per_s,
        -model.alpha,
        -model.theta_bar_deg,
        model.source,
        model.alpha_bar_per_deg_s,
        model.rig,
    )


def designed(name: str, config: RollConfig, env_id: str, bank: TraceBank) -> Controller:
    """``--policy name`` designed on ``bank`` as the train split (and, in flight, the
    tunnel traces the design flies)."""
    design = Design(config, env_id)
    design.__dict__["train_bank"] = bank
    design.__dict__["design_bank"] = bank
    return CONTROLLERS.get(name)(design)


def fly(
    name: str, env_id: str, rocket: RollParams, u: np.ndarray
) -> tuple[dict[str, float], np.ndarray, np.ndarray, np.ndarray]:
    """One 20-s episode of ``--policy name`` designed on, and flying, ``rocket`` under
    ``u``: its metrics, error, roll rate and fin angle, step by step."""
    config = variant_config(env_id, {"episode_s": 20.0})
    bank = TraceBank.from_arrays([u], dt_s=0.1, params=rocket)
    controller = designed(name, config, env_id, bank)
    env = env_on(config, bank)  # in flight, the trace flown from its start
    spec = EpisodeSpec(0, 7, env.bank.traces[0].uid, 0, SETPOINTS[env_id])
    rollout = run_episode(env, controller, spec)
    return metrics(rollout, config), rollout.error, rollout.rate_dps, rollout.fin_deg


@pytest.mark.parametrize("rocket", list(ROCKETS))
@pytest.mark.parametrize("env_id", list(SETPOINTS))
@pytest.mark.parametrize("name", MODEL_BASED)
def test_the_controller_of_a_negative_gain_is_the_mirror_image(
    name: str, env_id: str, rocket: str
) -> None:
    if not available(name, env_id):
        pytest.skip(f"--policy {name} is not offered on {env_id}")
    u = turbulence()
    score, error, rate, fin = fly(name, env_id, ROCKETS[rocket], u)
    score_m, error_m, rate_m, fin_m = fly(name, env_id, mirrored(ROCKETS[rocket]), -u)
    # To rounding: the trim's and the PID's commands mirror exactly, the LQR's Riccati
    # solution (observer, MPC) to 1e-7° on the fast rocket.
    np.testing.assert_allclose(error_m, error, rtol=0, atol=1e-5)
    np.testing.assert_allclose(rate_m, rate, rtol=0, atol=1e-5)
    np.testing.assert_allclose(fin_m, -fin, rtol=0, atol=1e-5)
    assert score_m["rms_error"] == pytest.approx(score["rms_error"], abs=1e-6)
    assert np.ptp(fin) > 1.0  # the fins did move: a mirror of nothing proves nothing


@pytest.mark.parametrize("task", ["angle", "rate"])
@pytest.mark.parametrize("a", [2.4, 20.0])
def test_pid_gains_change_sign_with_the_gain(task: str, a: float) -> None:
    """Every gain, the feedforward and the trim change sign with α, the tracking time does
    not -- also where the rocket is faster than the design and its rate gain is held at 0
    (a = 20 1/s): by the damping it would add, not by the sign of α."""
    model = NominalModel(a, 0.66, 4.5)
    plus = PIDGains.place(model, task)
    minus = PIDGains.place(mirrored_nominal(model), task)
    for field in ("kp", "ki", "kd", "k_ff", "trim_deg"):
        assert getattr(minus, field) == -getattr(plus, field), field
    assert minus.tt_s == plus.tt_s > 0
    rate_gain = plus.kd if task == "angle" else plus.kp
    assert (rate_gain == 0.0) == (a == 20.0)
    config = variant_config("RocketRoll-v0" if task == "angle" else "RocketRollRate-v0")
    obs = np.zeros(len(Obs), dtype=np.float32)
    obs[Obs.ERROR], obs[Obs.RATE], obs[Obs.FIN], obs[Obs.COMMAND] = 3.0, -7.0, 5.0, 6.0
    mirror_obs = obs.copy()
    mirror_obs[[Obs.FIN, Obs.COMMAND]] *= -1.0
    pid_plus, pid_minus = PIDController(plus, config), PIDController(minus, config)
    for _ in range(5):  # the integral and its back-calculation mirror too
        assert pid_minus.act(mirror_obs)[0] == -pid_plus.act(obs)[0]


def test_the_nominal_model_takes_a_negative_gain() -> None:
    bank = TraceBank.from_arrays([-turbulence()], dt_s=0.1, params=mirrored(ROCKETS["tunnel"]))
    assert NominalModel.from_bank(bank).alpha == pytest.approx(-0.66)
