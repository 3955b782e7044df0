"""Deployable controllers see a flight computer's view; the observer-based controller."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from agents.base import FlightView
from agents.evaluate import EpisodeSpec, env_on, run_episode
from agents.nominal import NominalModel
from agents.observer import ObserverController, RollObserver, TurbulenceModel
from agents.registry import CONTROLLERS, make_controller
from disturbances.bank import TraceBank
from identification.methods.rollspace import stationary_cov
from identification.model import RollParams
from rollenv.bank import load_bank, variant_config
from rollenv.config import RollConfig
from rollenv.layout import Obs


def config(env_id: str = "RocketRoll-v0", **settings) -> RollConfig:
    return variant_config(env_id, settings)


def deployable() -> list[str]:
    """Every registered controller but the two bounds (the oracle and the causal limit,
    which see the truth: checked below, and each of these is checked not to)."""
    return [name for name in CONTROLLERS.names() if name not in ("oracle", "causal-oracle")]


#: Tiny runs of the learned controllers that have no committed policy (seconds each); PPO
#: with the observer's estimate and a history, since those read more than the observation.
TINY_RUNS = {
    "sac": "  learning_starts: 50\n  batch_size: 16\n  buffer_size: 500\n  history: 2\n",
    "td3": "  learning_starts: 50\n  batch_size: 16\n  buffer_size: 500\n  history: 2\n",
    "ppo": "  n_steps: 32\n  batch_size: 32\n  n_epochs: 1\n  history: 2\n  observer: true\n",
}


@pytest.fixture(scope="module")
def tiny_runs(default_db, tmp_path_factory) -> dict[str, str]:
    """``--policy`` values of tiny training runs, by controller name (both tasks)."""
    import contextlib
    import io

    from agents.cli import SAC_COMMAND, TD3_COMMAND
    from agents.cli import TRAIN_COMMAND as COMMAND
    from rocketroll_common.settings import run_command

    folder = tmp_path_factory.mktemp("tiny-runs")
    runs = {}
    for algo, command in (("sac", SAC_COMMAND), ("td3", TD3_COMMAND), ("ppo", COMMAND)):
        for env_id in ("RocketRoll-v0", "RocketRollRate-v0"):
            yml = folder / f"{algo}.yml"
            yml.write_text(
                f"{env_id}:\n  n_envs: 2\n  n_timesteps: 128\n"
                "  policy_kwargs: {net_arch: [8, 8]}\n" + TINY_RUNS[algo],
                encoding="utf-8",
            )
            out = folder / f"{algo}-{env_id}"
            argv = ["--env-id", env_id, "--hyperparams", str(yml), "--out", str(out)]
            argv += ["--eval-freq", "0", "--eval-episodes", "1", "--checkpoint-freq", "0"]
            with contextlib.redirect_stdout(io.StringIO()):
                assert run_command(command, [*argv, "--no-progress-bar"], algo) == 0
            runs[f"{algo}:{env_id}"] = f"{algo}:{out}"
    return runs


# ------------------------------------------------------------------ the flight view
def test_the_flight_view_refuses_what_a_flight_computer_has_not(default_db):
    env = env_on(config(split="test"), load_bank(config(split="test"), None))
    view = FlightView(env)
    assert view.config is env.config
    assert view.observation_space == env.observation_space
    assert view.action_space == env.action_space
    assert view.dt_s == 0.1
    for name in ("core", "unwrapped", "bank", "np_random", "replay_options", "u_d", "step"):
        with pytest.raises(AttributeError, match=f"a flight computer has no '{name}'"):
            getattr(view, name)
    with pytest.raises(AttributeError):
        view.core = env.core  # type: ignore[attr-defined]
    assert "env" not in dir(view) and not hasattr(view, "__dict__")


@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
@pytest.mark.parametrize("name", [*deployable(), "ppo-observer"])
def test_every_deployable_controller_runs_on_the_flight_view(name, env_id, tiny_runs):
    """The protocol hands deployable controllers a FlightView; a controller that reached
    for the truth (env.core, the bank, the future u_d) would raise here.  SAC and TD3 (no
    committed policy) and PPO with the observer's estimate are tiny runs trained here."""
    cfg = config(env_id, split="test")
    bank = load_bank(cfg, None)
    policy = name
    if name in ("sac", "td3", "ppo-observer"):
        policy = tiny_runs[f"{name.split('-')[0]}:{env_id}"]
    controller = make_controller(policy, cfg, env_id)
    assert not getattr(controller, "sees_truth", False)
    seen: list[object] = []

    class Spy:
        def __init__(self, inner):
            self.inner = inner
            self.name = inner.name

        def reset(self, env):
            seen.append(env)
            self.inner.reset(env)

        def act(self, obs, env):
            seen.append(env)
            return self.inner.act(obs, env)

    spec = EpisodeSpec(0, 5, bank.traces[0].uid, 100, (0.0, 40.0, -20.0, 0.0, 10.0, 5.0))
    rollout = run_episode(env_on(cfg, bank), Spy(controller), spec)
    assert len(seen) == cfg.max_episode_steps + 1
    assert all(type(handle) is FlightView for handle in seen)
    assert np.all(np.isfinite(rollout.command_deg))


def test_the_bounds_alone_get_the_environment(default_db):
    cfg = config(split="test")
    for bound in ("oracle", "causal-oracle"):
        assert getattr(make_controller(bound, cfg, "RocketRoll-v0"), "sees_truth", False)


# ------------------------------------------------------------- holding a setpoint
def _hold(name: str, env_id: str, setpoint: float):
    cfg = config(env_id, split="test", disturbance="none")
    bank = load_bank(cfg, None)
    env = env_on(cfg, bank)
    for trace in range(len(bank)):
        controller = make_controller(name, cfg, env_id)
        spec = EpisodeSpec(0, 11 + trace, bank.traces[trace].uid, 0, (setpoint,) * 6)
        yield cfg, run_episode(env, controller, spec)


#: PPO as a residual on the observer (agents/hyperparams/ppo-residual.yml), seed 0.
RESIDUAL = "ppo:agents/policies/seeds/RocketRoll-v0/ppo-residual/seed0"
#: The default recipe's PPO (ppo.yml), seed 0: it holds a ~4° offset between slews.
OFFSET = pytest.param(
    "ppo:agents/policies/seeds/RocketRoll-v0/ppo/seed0",
    marks=pytest.mark.xfail(
        strict=True,
        reason="the default recipe's angle PPO holds a ~4° offset between slews "
        "(docs, results: its reward is dominated by the slews)",
    ),
)
HOLDERS = ["pid", "observer", "mpc", "oracle", "ppo", RESIDUAL]


@pytest.mark.parametrize("setpoint", [0.0, 30.0, -47.3])
@pytest.mark.parametrize("name", [*HOLDERS, OFFSET])
def test_controllers_hold_an_angle_within_one_encoder_count(name, setpoint, default_db):
    """No turbulence, gyro noise and encoder on: after 10 s every true angle error is
    within one encoder count (1.40625°), on every rocket of the test split."""
    for cfg, rollout in _hold(name, "RocketRoll-v0", setpoint):
        held = np.abs(rollout.error[100:])
        assert held.max() <= cfg.encoder_resolution_deg, (rollout.trace, held.max())


@pytest.mark.parametrize("name", ["pid", "observer", "mpc", "ppo", "oracle"])
def test_controllers_hold_a_rate_to_the_gyro_noise(name, default_db):
    """Rate task, no turbulence: after 5 s the true rate error's RMS is within 2 SDs
    of the gyro's noise at the setpoint (2 % of 8 °/s = 0.16 °/s) and its mean within
    0.12 °/s (measured on the three test rockets: RMS PID 0.18, observer 0.23-0.25,
    PPO 0.15-0.18, oracle < 0.01; mean PPO -0.07 to -0.10, the others within 0.02)."""
    for cfg, rollout in _hold(name, "RocketRollRate-v0", 8.0):
        noise_sd = cfg.gyro_noise_pct / 100 * 8.0
        held = rollout.error[50:]
        assert np.sqrt(np.mean(held**2)) < 2 * noise_sd, rollout.trace
        assert abs(held.mean()) < 0.12, rollout.trace


# ------------------------------------------------------------------ the observer
def _injected_bank(rocket: RollParams) -> tuple[TraceBank, np.ndarray]:
    """A known u_d: two sines, a 6° step at 30 s and white noise, 0.1-s samples."""
    t = np.arange(700) * 0.1
    rng = np.random.default_rng(15)
    u = 8 * np.sin(2 * np.pi * 0.3 * t) + 3 * np.sin(2 * np.pi * 1.1 * t + 1.0)
    u += 6.0 * (t >= 30.0) + rng.normal(0.0, 1.0, t.size)
    return TraceBank.from_arrays([u], dt_s=0.1, params=rocket), u


@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
def test_the_observer_tracks_an_injected_u_d(env_id, default_db):
    """On a rocket other than its nominal one (α +5 %, θ̄ -0.8°, damping +10 %) the
    filtered estimate of the last step's u_d follows a known u_d (sines, a step,
    noise; SD 6.5°) to an RMS error under 0.8° after the first 2 s (measured: 0.45°
    angle task, 0.32° rate task), and follows the step at 30 s within 2° from the
    first step it acts on."""
    cfg = config(env_id, split="test")
    controller = make_controller("observer", cfg, env_id)
    assert isinstance(controller, ObserverController)
    nominal = controller.rocket.params
    rocket = RollParams(
        nominal.alpha * 1.05,
        nominal.theta_bar_deg - 0.8,
        nominal.beta_bar_per_s * 1.1,
        nominal.alpha_bar_per_deg_s * 1.1,
    )
    bank, u = _injected_bank(rocket)
    env = env_on(cfg, bank)
    obs, _ = env.reset(seed=3, options={"trace": 0, "start": 0, "setpoints": [0.0] * 6})
    controller.reset(FlightView(env))
    estimate = []
    for _ in range(cfg.max_episode_steps):
        action = controller.act(obs, FlightView(env))
        estimate.append(controller.observer.u_d_last)
        obs, *_ = env.step(action)
    # At step k the filter has seen the rate the last step (k - 1) left behind.
    est = np.array(estimate[1:])
    true = u[: est.size]
    # The offset state also carries θ̄'s error (-0.8°): u_d + θ̄ - θ̄_nominal is what acts.
    acting = true + (rocket.theta_bar_deg - nominal.theta_bar_deg)
    err = est - acting
    assert np.sqrt(np.mean(err[20:] ** 2)) < 0.8, np.sqrt(np.mean(err[20:] ** 2))
    assert abs(err[20:].mean()) < 0.1
    # the 6° step at 30 s (sample 300) is in the estimate as soon as it has acted
    assert np.abs(err[300:305]).max() < 2.0, err[300:305]


def test_the_observer_is_a_kalman_filter_of_the_ml_model():
    """With a white encoder model and no offset, one observer step is the ML's state-space
    step: the transition of identification.methods.rollspace.roll_transition with the bias
    column."""
    cfg = config(split="test")
    turbulence = TurbulenceModel(np.array([0.8]), 5.0, 0.3, 0.01, 0.1)
    observer = RollObserver(RollParams(0.66, 4.5, 2.3, -0.027), turbulence, cfg)
    assert observer.m == 5  # v, ψ, u_d[k], u_d[k-1] (AR(1) padded), offset
    t, c = observer.step_model(-4.5, 3.0)
    assert t[0, 2] == t[0, observer.bias] != 0.0  # the offset acts where u_d does
    assert t[2, 2] == 0.8 and t[3, 2] == 1.0 and t[2, observer.bias] == 0.0
    assert t[observer.bias, observer.bias] == 1.0
    # the servo: a 7.5° move at 150 °/s is done after 5 of the 10 substeps
    np.testing.assert_allclose(observer.fin_path(-4.5, 3.0)[[0, 5, 10]], [-4.5, 3.0, 3.0])
    assert np.isfinite(c).all()


def test_a_setpoint_step_re_anchors_the_angle_only(default_db):
    cfg = config(split="test")
    controller = make_controller("observer", cfg, "RocketRoll-v0")
    assert isinstance(controller, ObserverController)
    observer = controller.observer
    obs = np.zeros(len(Obs), dtype=np.float32)
    for _ in range(30):
        observer.update(obs)
        observer.predict(-controller.rocket.theta_bar_deg, -controller.rocket.theta_bar_deg)
    observer.update(obs)
    before = observer.mean.copy()
    assert observer.setpoint_steps == 0
    obs[Obs.ERROR] = 50.0  # the setpoint moved 50° away
    observer.predict(-controller.rocket.theta_bar_deg, -controller.rocket.theta_bar_deg)
    observer.update(obs)
    assert observer.setpoint_steps == 1
    assert observer.mean[1] == pytest.approx(-50.0 + cfg.encoder_resolution_deg / 2, abs=0.1)
    np.testing.assert_allclose(observer.mean[[0, 2]], before[[0, 2]], atol=0.5)


def test_turbulence_fit_and_its_checks(default_db):
    cfg = config(split="train")
    bank = load_bank(cfg, None)
    nominal = NominalModel.from_bank(bank)
    turbulence = TurbulenceModel.from_bank(bank, 0.1, nominal)
    assert 1 <= turbulence.order <= 3 and "train" in turbulence.source
    assert 0.0 < turbulence.innovation_sd < np.mean([t.sd_deg for t in bank.traces])
    with pytest.raises(ValueError, match="does not divide"):
        TurbulenceModel.from_bank(bank, 0.15, nominal)
    with pytest.raises(ValueError, match="not stationary"):
        TurbulenceModel(np.array([1.2]), 1.0, 0.1, 0.01, 0.1)
    with pytest.raises(ValueError, match="grid"):
        RollObserver(nominal.params, TurbulenceModel(np.array([0.5]), 1.0, 0.1, 0.01, 0.2), cfg)
    with pytest.raises(ValueError, match="takes no argument"):
        make_controller("observer:3", cfg, "RocketRoll-v0")


def test_the_observer_controller_pickles_and_restarts(default_db):
    cfg = config(split="test")
    controller = make_controller("observer", cfg, "RocketRoll-v0")
    clone = pickle.loads(pickle.dumps(controller))
    obs = np.array([2.0, 1.0, -4.0, -4.0], dtype=np.float32)
    np.testing.assert_array_equal(controller.act(obs, None), clone.act(obs, None))
    controller.reset(None)
    clone.reset(None)
    np.testing.assert_array_equal(controller.act(obs, None), clone.act(obs, None))


# ------------------------------------------------------------------ flight
def test_in_flight_the_observer_is_scheduled_on_the_flying_rocket_and_turbulence(default_db):
    from agents.observer import FLIGHT_WEIGHTS

    cfg = config("RocketRollFlight-v0")
    controller = make_controller("observer", cfg, "RocketRollFlight-v0")
    assert isinstance(controller, ObserverController)
    assert controller.weights == FLIGHT_WEIGHTS["angle"]
    schedule = cfg.flight_schedule
    assert schedule is not None and controller.schedule is not None
    assert len(controller.schedule) == cfg.max_episode_steps
    ob = controller.observer
    nominal = controller.rocket.params
    for k in (0, 60, 211):
        gain, damping = schedule.scales[k]
        assert ob.rocket_at(k) == nominal.scaled(gain, damping)
    # The turbulence is the tunnel's flown: per step as correlated as the tunnel's at a lag of
    # V/V_ref steps, its SD scaled by V_ref/V (at top speed: nearly white and 12x smaller).
    tunnel = controller.turbulence
    coefficient, innovation = tunnel.flown(schedule.scales[:, 0])
    fast = int(np.argmax(schedule.scales[:, 0]))
    assert schedule.scales[fast, 0] > 11
    assert abs(coefficient[fast]) < 0.2 < coefficient[0]
    sd = np.sqrt(stationary_cov(tunnel.ar, tunnel.innovation_sd)[0, 0])
    assert innovation[fast] < sd / 10
    assert ob.ar_at(fast)[0][0] == coefficient[fast]
    # Each step's LQR gain is designed on the rocket of that step (held at V_ref's near
    # apogee, where a vanishing gain would ask for unbounded fins), with that step's
    # turbulence; at top speed the fins bite 12x harder and the feedback on the rate and
    # the angle is smaller.
    for k in (0, fast, 211):
        gain, damping = schedule.scales[k]
        speed = max(gain, 1.0)
        designed = controller._design(nominal.scaled(speed, damping * speed / gain), k)
        np.testing.assert_allclose(controller.schedule[k], designed)
    assert schedule.scales[211, 0] < 1.0
    assert np.all(np.abs(controller.schedule[fast][:2]) < np.abs(controller.schedule[0][:2]))
    # In the tunnel nothing is scheduled.
    in_tunnel = make_controller("observer", config(), "RocketRoll-v0")
    assert isinstance(in_tunnel, ObserverController) and in_tunnel.schedule is None


def test_in_flight_the_scheduled_observer_holds_within_two_degrees(default_db):
    from agents.evaluate import evaluate, protocol_episodes

    cfg = config("RocketRollFlight-v0", split="test")
    specs = protocol_episodes(cfg, episodes=6, seed=0)
    controller = make_controller("observer", cfg, "RocketRollFlight-v0")
    result = evaluate(cfg, controller, specs).aggregate
    assert result["regulation_rms_error"]["mean"] < 2.0
    assert result["fin_travel_dps"]["mean"] < 40.0  # no chatter at the servo's rate limit


def test_in_flight_the_observer_beats_the_pid_reading_the_summed_gyro_as_noisy(default_db):
    """The flight computer's angle is the gyro's readings summed: the filter's reading of
    it grows noisier along the flight (exact at launch), and so read the scheduled
    observer beats the scheduled PID on the same flights (20 held-out flights: 0.91°
    against 1.10°); read as exact, it held 1.46°."""
    from agents.evaluate import evaluate, protocol_episodes

    cfg = config("RocketRollFlight-v0", split="test")
    specs = protocol_episodes(cfg, episodes=6, seed=0)
    observer = make_controller("observer", cfg, "RocketRollFlight-v0")
    assert isinstance(observer, ObserverController)
    assert observer.observer.summed and observer.observer.walk == 0.0
    scores = [
        evaluate(cfg, c, specs).aggregate["regulation_rms_error"]["mean"]
        for c in (observer, make_controller("pid", cfg, "RocketRollFlight-v0"))
    ]
    assert scores[0] < 0.95 * scores[1]
    assert observer.observer.walk > 0.0  # the last flight's sum carried its noise
    tunnel = make_controller("observer", config("RocketRoll-v0", split="test"), "RocketRoll-v0")
    assert isinstance(tunnel, ObserverController) and not tunnel.observer.summed


def test_in_flight_the_observer_features_are_the_scheduled_controllers(default_db):
    """A learned policy's observer in flight (``observer``/``residual`` recipes) is the
    scheduled observer controller's, designed on the tunnel's train traces: with a zero
    residual the commands are that controller's, step by step, over a held-out flight."""
    from agents.base import design_bank
    from agents.evaluate import protocol_episodes
    from agents.observer import ObserverFeatures

    config = variant_config("RocketRollFlight-v0", {"split": "test"})
    reference = make_controller("observer", config, "RocketRollFlight-v0")
    assert isinstance(reference, ObserverController) and reference.schedule is not None
    features = ObserverFeatures.from_bank(config, design_bank(config, None), 2, residual=0.5)
    assert all(c.schedule is not None for c in features.controllers)
    assert features.controllers[0].schedule is features.controllers[1].schedule  # shared
    bank = load_bank(config, None)
    env = env_on(config, bank)
    spec = next(iter(protocol_episodes(config, 1, seed=0, bank=bank)))
    obs, _ = env.reset(seed=spec.seed, options=spec.options())
    reference.reset(FlightView(env))
    features.clear()
    commands = []
    truncated = False
    while not truncated:
        expected = reference.act(obs, FlightView(env))
        seen = features.one(0, obs)
        estimate = [*reference.observer.mean[:2], reference.observer.u_d]
        np.testing.assert_allclose(seen, estimate, rtol=1e-5, atol=1e-5)
        action = features.record(np.stack([obs, obs]), np.zeros(2, np.float32))[0]
        np.testing.assert_allclose(action, expected, atol=1e-6)
        commands.append(float(action[0]))
        obs, _, _, truncated, _ = env.step(action)
    assert len(commands) == config.max_episode_steps and np.ptp(commands) > 0.05
