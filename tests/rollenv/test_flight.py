"""RocketRollFlight-v0: the identified rocket carried along an ascent.

The schedule starts where the airspeed reaches the tunnel's and ends at
apogee; the kernel with the flight's per-step gain and damping follows the
closed form of eq. 29 with those coefficients, computed here independently;
the flight computer's angle is the sum of the gyro's readings; a tunnel bank
given to a flight is flown first.
"""

from __future__ import annotations

import functools
import warnings

import gymnasium as gym
import numpy as np
import pytest

import rollenv  # noqa: F401  (registers the variants)
from disturbances.bank import TraceBank
from rocketroll_physics.atmosphere import ISA_SEA_LEVEL_DENSITY_KGM3
from rocketroll_physics.scaling import TUNNEL_AIRSPEED_MPS, roll_scales
from rollenv.config import RollConfig
from rollenv.core import RollBatch
from rollenv.env import RocketRollEnv
from rollenv.flight import MIN_SCALE, flight_schedule, turbulence_of
from rollenv.layout import Obs, State
from tests.rollenv.conftest import CONSTANT_PARAMS, THETA_PARAMS, wrap


@functools.cache
def array_bank(model: str = "theta") -> TraceBank:
    """Two random 0.1-s traces of 250 s (a flight takes 145 s of tunnel turbulence)."""
    rng = np.random.default_rng(17)
    params = THETA_PARAMS if model == "theta" else CONSTANT_PARAMS
    banks = [
        TraceBank.from_arrays([rng.normal(0.0, 5.0, 2500)], dt_s=0.1, params=p) for p in params[:2]
    ]
    return TraceBank([b.traces[0] for b in banks], f"two long traces ({model})")


def test_the_schedule_runs_from_the_tunnels_airspeed_to_apogee() -> None:
    s = flight_schedule("default", 0.1, 0.01)
    profile = s.profile
    assert np.interp(s.start_s, profile.t_s, profile.airspeed_mps) == pytest.approx(
        TUNNEL_AIRSPEED_MPS, rel=1e-9
    )
    assert s.start_s + s.duration_s <= profile.apogee_s < s.start_s + s.duration_s + 0.1
    middle = profile.at(s.start_s + 0.1 * (np.arange(s.steps) + 0.5))
    gain, damping = roll_scales(middle.airspeed_mps, middle.density_kgm3)
    np.testing.assert_allclose(s.scales[:, 0], np.maximum(gain, MIN_SCALE))
    np.testing.assert_allclose(s.scales[:, 1], np.maximum(damping, MIN_SCALE))
    assert s.scales[:, 0].max() == pytest.approx(profile.max_speed_mps / TUNNEL_AIRSPEED_MPS, 0.01)
    assert s.edges_s.size == s.steps * 10 + 1
    # Damping grows less than the gain: the air thins on the way up (rho / rho_ref < 1).
    top = int(np.argmax(s.scales[:, 0]))
    rho = np.interp(s.start_s + 0.1 * (top + 0.5), profile.t_s, profile.density_kgm3)
    assert s.scales[top, 1] / s.scales[top, 0] == pytest.approx(
        rho / ISA_SEA_LEVEL_DENSITY_KGM3, rel=1e-9
    )


def test_the_episode_is_the_flight_and_may_be_cut_not_stretched() -> None:
    config = RollConfig(flight="default")
    schedule = flight_schedule("default", 0.1, 0.01)
    assert config.max_episode_steps == schedule.steps
    assert RollConfig().episode_s == 60.0  # the tunnel keeps its minute
    assert RollConfig(flight="default", episode_s=10.0).max_episode_steps == 100
    with pytest.raises(ValueError, match="longer than the flight"):
        RollConfig(flight="default", episode_s=60.0)
    with pytest.raises(ValueError, match="flight: 'fast'"):
        RollConfig(flight="fast")
    with pytest.raises(ValueError, match="angle_sensor: must be one of"):
        RollConfig(angle_sensor="laser")


def test_the_kernel_flies_eq29_with_the_flights_coefficients() -> None:
    # No disturbance, the truth observed, the fin held at 0: over each control step the rate
    # relaxes toward alpha0 g_k theta_bar at the rate a0 d_k (eq. 29 with a = beta_bar,
    # constant damping), written out here without the package's closed form.
    bank = array_bank("constant")
    env = RocketRollEnv(bank=bank, flight="default", disturbance="none", sensors=False)
    env.reset(seed=3, options={"trace": 0})
    p = env.core.roll_params(0)
    scales = env.core.episode_scales(0)
    alpha0 = p.alpha / scales[0, 0]
    a0 = p.beta_bar_per_s / scales[0, 1]
    v = 0.0  # off the rail, not rolling
    for k in range(env.config.max_episode_steps):
        steady = alpha0 * scales[k, 0] * p.theta_bar_deg
        v = steady + (v - steady) * np.exp(-a0 * scales[k, 1] * 0.1)
        _, _, _, truncated, info = env.step(np.zeros(1, np.float32))
        assert info["roll_rate_dps"] == pytest.approx(v, rel=1e-9, abs=1e-9)
    assert truncated
    # The spin it reaches at top speed: alpha grows with V, the steady rate with it.
    assert np.max(np.abs(scales[:, 0] * alpha0 * p.theta_bar_deg)) > 10 * abs(
        alpha0 * p.theta_bar_deg
    )


def test_the_flight_computer_sums_the_gyro() -> None:
    env = RocketRollEnv(
        bank=array_bank(),
        flight="default",
        angle_sensor="gyro",
        gyro_noise_pct=5.0,
        setpoint="zero",
    )
    obs, info = env.reset(seed=4, options={"angle_deg": 20.0})
    assert obs[Obs.ERROR] == pytest.approx(-20.0)
    angle = 20.0
    drift = []
    for _ in range(env.config.max_episode_steps):
        obs, _, _, _, info = env.step(np.array([0.3], np.float32))
        angle += 0.1 * float(obs[Obs.RATE])  # the reading the computer summed
        assert obs[Obs.ERROR] == pytest.approx(wrap(-angle), abs=1e-3)
        drift.append(angle - info["roll_deg"])
    assert np.std(drift) > 0.01  # noise and the rectangle rule: it drifts from the truth
    truth = RocketRollEnv(bank=array_bank(), flight="default", angle_sensor="encoder")
    assert truth.config.kernel_settings()[17] == 0.0  # Cfg.ANGLE_GYRO


def test_a_tunnel_bank_given_to_a_flight_is_flown_once() -> None:
    bank = array_bank()
    config = RollConfig(flight="default")
    batch = RollBatch(config, bank, 2)
    assert turbulence_of(batch.bank) == "tunnel" and turbulence_of(bank) is None
    assert batch.bank.traces[0].dt_s == pytest.approx(0.01)
    assert batch.bank.traces[0].n_samples == config.max_episode_steps * 10
    assert RollBatch(config, batch.bank, 1).bank is batch.bank  # not flown twice
    assert config.flights(bank) is batch.bank  # cached


def test_the_flight_variants_and_their_info() -> None:
    env = gym.make("RocketRollFlight-v0")
    assert env.spec is not None and env.spec.max_episode_steps == 212
    _, info = env.reset(seed=0)
    assert info["airspeed_mps"] == pytest.approx(TUNNEL_AIRSPEED_MPS)
    assert info["roll_rate_dps"] == 0.0 and info["setpoint"] == 0.0
    speeds = [info["airspeed_mps"]]
    truncated = False
    while not truncated:
        _, _, terminated, truncated, info = env.step(np.zeros(1, np.float32))
        assert not terminated
        speeds.append(info["airspeed_mps"])
    assert max(speeds) * 3.6 == pytest.approx(603, abs=3)  # about 600 km/h
    assert info["altitude_m"] == pytest.approx(2010, abs=15)  # apogee, about 2 km
    rate = gym.make("RocketRollFlightRate-v0")
    assert rate.unwrapped.config.task == "rate"  # type: ignore[attr-defined]
    vec = gym.make_vec("RocketRollFlight-v0", num_envs=3)
    _, vinfo = vec.reset(seed=1)
    np.testing.assert_allclose(vinfo["airspeed_mps"], TUNNEL_AIRSPEED_MPS)


def test_the_gyro_angle_starts_at_the_true_angle() -> None:
    batch = RollBatch(RollConfig(flight="default", angle_sensor="gyro"), array_bank(), 3)
    batch.reset(np.arange(3), np.random.default_rng(0), angle_deg=12.5)
    np.testing.assert_array_equal(batch.state[:, State.GYRO_ANGLE], 12.5)


def test_dryden_flights_roll_the_air_the_damping_works_against() -> None:
    from rocketroll_physics.dryden import roll_gust_std

    train = RollConfig(flight="default", flight_turbulence="dryden")
    bank = train.flights(array_bank())
    assert turbulence_of(bank) == "dryden" and len(bank) == 256
    assert train.flights(array_bank()) is bank  # cached: the same flights every time
    schedule = train.flight_schedule
    assert schedule is not None
    gain = np.repeat(schedule.scales[:, 0], 10)
    # alpha0 * gain * u_d is the gust rate p_g itself, whichever rocket flies it
    gusts = np.array([t.samples() * t.rocket().alpha * gain for t in bank.traces])
    assert {t.rocket() for t in bank.traces} == set(array_bank().params)
    # fast (T of a few ms) and strong: each 0.01-s average keeps most of sigma_p at full speed
    top = int(np.argmax(schedule.airspeed_edges_mps))
    sigma = np.degrees(
        roll_gust_std(schedule.airspeed_edges_mps[top], schedule.altitude_edges_m[top])
    )
    assert 0.3 * sigma < gusts[:, top].std() < sigma
    test = RollConfig(flight="default", flight_turbulence="dryden", split="test")
    other = test.flights(array_bank())
    assert not np.array_equal(other.traces[0].samples(), bank.traces[0].samples())
    moderate = RollConfig(flight="default", flight_turbulence="dryden", gust_severity="moderate")
    assert np.std(moderate.flights(array_bank()).traces[0].samples()) > np.std(
        bank.traces[0].samples()
    )
    with pytest.raises(ValueError, match="not dryden"):
        train.flights(RollConfig(flight="default").flights(array_bank()))


def test_rocketroll_env_flight_summarises_and_plots(tmp_path, capsys) -> None:
    from rocketroll.cli import main

    png = tmp_path / "profile.png"
    assert main(["env", "ascent", "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "max 603 km/h" in out and "apogee 2010 m" in out and "212 control steps" in out
    assert png.read_bytes()[:4] == b"\x89PNG"
    bad = tmp_path / "rocket.yml"
    bad.write_text("dry_mass_kg: -1\n")
    assert main(["env", "ascent", "--flight", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "propellant_mass_kg: is missing" in err
    assert main(["env", "ascent", "--flight", str(tmp_path / "none.yml")]) == 2
    assert "no such file" in capsys.readouterr().err.lower()


def test_a_profile_past_mach_0_8_warns_that_the_model_is_subsonic(tmp_path) -> None:
    t = np.linspace(0.0, 40.0, 401)
    speed = np.interp(t, [0.0, 5.0, 40.0], [0.0, 320.0, 0.0])  # Mach 0.94 at 5 s
    rows = "\n".join(f"{a:.2f},{v:.3f}" for a, v in zip(t, speed, strict=True))
    fast = tmp_path / "fast.csv"
    fast.write_text("time_s,airspeed_mps\n" + rows + "\n", encoding="utf-8")
    with pytest.warns(UserWarning, match=r"reaches Mach 0\.9\d; .* subsonic"):
        flight_schedule(str(fast), 0.1, 0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flight_schedule("default", 0.1, 0.01)  # Mach 0.50: nothing to say
