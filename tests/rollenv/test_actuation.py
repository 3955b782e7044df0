"""The kernel's fin linkage (servo lag, backlash) and sensor latency.

Off, they leave the kernel's arithmetic as it was (the golden trajectories of the
other tests); on, the kernel flies what the independent reference integrator
(:mod:`identification.instruments.reference`, in closed loop by ``benchmarks/_reference_env.py``)
flies, the vector env steps them like the single env, and the oracle's predictors
copy the sensors' past with the state.
"""

from __future__ import annotations

import contextlib
import dataclasses
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from identification.instruments.reference import Effects
from identification.model import Rig
from rollenv.config import RollConfig
from rollenv.env import RocketRollEnv
from rollenv.layout import Obs, State
from rollenv.vector import RocketRollVectorEnv
from tests.rollenv.conftest import array_bank

REPO = Path(__file__).resolve().parents[2]


def _env(**settings: Any) -> RocketRollEnv:
    return RocketRollEnv(bank=array_bank(), sensors=False, **settings)


def _actions(n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    t = np.arange(n)
    return (0.3 * np.sin(t / 7.0) + 0.1 * rng.standard_normal(n)).astype(np.float32)


@pytest.mark.parametrize(
    "effects",
    [
        Effects(servo_lag_s=0.05),
        Effects(backlash_deg=0.5),
        Effects(latency_s=0.03),
        Effects(servo_lag_s=0.08, backlash_deg=1.0, latency_s=0.25),
    ],
    ids=lambda e: e.describe(),
)
def test_the_kernel_flies_the_reference_integrators_linkage_and_latency(
    effects: Effects, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Against the reference integrator (1-ms Runge-Kutta, the fin's drive integrated
    step by step) over 300 control steps: the fin within 0.15°, the sensed rate within
    0.03 °/s -- the same order as the two integrators differ without any effect (6e-3).
    A kernel that ignored the lag is 0.6° off, one that ignored the latency 1 °/s."""
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    from _reference_env import ReferenceRollEnv

    bank = array_bank()
    config = RollConfig(sensors=False, setpoint="zero")
    reference = ReferenceRollEnv(config, bank, effects)
    kernel = _env(
        setpoint="zero",
        servo_lag_s=effects.servo_lag_s,
        backlash_deg=effects.backlash_deg,
        sensor_latency_s=effects.latency_s,
    )
    assert kernel.config.rig_of(Rig()) == Rig(
        effects.servo_lag_s, effects.backlash_deg, effects.latency_s
    )
    options = {"trace": 0, "start": 0}
    reference.reset(seed=0, options=options)
    kernel.reset(seed=0, options=options)
    fin, rate, ideal_rate = [], [], []
    ideal = _env(setpoint="zero")
    ideal.reset(seed=0, options=options)
    for a in _actions(300):
        ref_obs, *_ = reference.step(np.array([a]))
        obs, *_ = kernel.step(np.array([a]))
        ideal_obs, *_ = ideal.step(np.array([a]))
        fin.append(abs(ref_obs[Obs.FIN] - obs[Obs.FIN]))
        rate.append(abs(ref_obs[Obs.RATE] - obs[Obs.RATE]))
        ideal_rate.append(abs(ref_obs[Obs.RATE] - ideal_obs[Obs.RATE]))
    assert max(fin) < 0.15
    assert max(rate) < 0.03
    assert max(ideal_rate) > 10.0 * max(rate)  # the effect matters at this level


def test_a_late_sensor_reads_the_rate_of_a_latency_ago() -> None:
    """Latency of one control step: the observed rate is the true rate of the step
    before, exactly (the ring holds every substep); a latency longer than the episode's
    start reads the initial state until the rocket has flown it."""
    late = _env(task="rate", sensor_latency_s=0.1)
    late.reset(seed=0, options={"trace": 0, "start": 0})
    before = late.core.state[0, State.RATE]
    for a in _actions(20):
        obs, *_ = late.step(np.array([a]))
        assert obs[Obs.RATE] == np.float32(before)
        before = late.core.state[0, State.RATE]
    longer = _env(task="rate", sensor_latency_s=0.45)
    obs, _ = longer.reset(seed=0, options={"trace": 0, "start": 0, "rate_dps": 3.0})
    for a in _actions(4):
        obs, *_ = longer.step(np.array([a]))
        assert obs[Obs.RATE] == np.float32(3.0)
    obs, *_ = longer.step(np.array([0.0]))
    assert obs[Obs.RATE] != np.float32(3.0)


def test_the_linkage_makes_the_fin_trail_its_command_and_stops_inside_its_play() -> None:
    lagged = _env(servo_lag_s=0.2)
    lagged.reset(seed=0, options={"trace": 0, "start": 0, "fin_deg": 0.0})
    obs, *_ = lagged.step(np.array([0.25]))  # 10° asked, 15° of servo travel in 0.1 s
    assert 0.0 < obs[Obs.FIN] < 0.5 * 10.0
    assert lagged.core.state[0, State.SERVO] == pytest.approx(10.0)
    loose = _env(backlash_deg=2.0)
    loose.reset(seed=0, options={"trace": 0, "start": 0, "fin_deg": 0.0})
    obs, *_ = loose.step(np.array([0.5 / 40.0]))  # 0.5°: inside the 1° half-play
    assert obs[Obs.FIN] == 0.0
    obs, *_ = loose.step(np.array([3.0 / 40.0]))
    assert obs[Obs.FIN] == pytest.approx(2.0)  # the drive at 3°, the fin half the play behind


def test_the_vector_env_steps_linkage_and_latency_like_the_single_env() -> None:
    settings: dict[str, Any] = {"servo_lag_s": 0.05, "backlash_deg": 0.5, "sensor_latency_s": 0.03}
    options = {"trace": 0, "start": 0}
    envs = RocketRollVectorEnv(2, bank=array_bank(), sensors=False, **settings)
    single = _env(**settings)
    envs.reset(seed=0, options=options)
    single.reset(seed=0, options=options)
    for a in _actions(50):
        obs, *_ = envs.step(np.full((2, 1), a, dtype=np.float32))
        one, *_ = single.step(np.array([a]))
        np.testing.assert_array_equal(envs._batch.state[0], single.core.state[0])
        np.testing.assert_array_equal(obs[0], one)


def test_a_predictor_copies_the_sensors_past_with_the_state() -> None:
    from rollenv.core import RollBatch

    env = _env(sensor_latency_s=0.2)
    env.reset(seed=0, options={"trace": 0, "start": 0})
    for a in _actions(5):
        env.step(np.array([a]))
    predictor = RollBatch(env.config, env.bank, 2)
    predictor.copy_env(env.core, 0, predictor.all)
    np.testing.assert_array_equal(predictor.past[1], env.core.past[0])
    rng = np.random.default_rng(0)
    predictor.step(np.full(2, 0.1), rng, predictor.all)
    env.step(np.array([0.1]))
    np.testing.assert_array_equal(predictor.obs[1], env.core.obs[0])


@pytest.mark.parametrize(
    ("name", "value", "says"),
    [
        ("servo_lag_s", -0.1, "servo_lag_s must be in [0, 0.5], got -0.1"),
        ("backlash_deg", 9.0, "backlash_deg must be in [0, 5], got 9.0"),
        ("sensor_latency_s", 0.7, "sensor_latency_s must be in [0, 0.5], got 0.7"),
    ],
)
def test_linkage_and_latency_out_of_range_are_refused_by_name(
    name: str, value: float, says: str
) -> None:
    with pytest.raises(ValueError, match=re.escape(says)):
        settings: dict[str, Any] = {name: value}
        RollConfig(**settings)


def test_each_rocket_flies_its_own_rig_unless_the_settings_give_one() -> None:
    """A bank's rocket carries the rig its identification assumed (``TraceBank.rigs``); by
    default each env flies its rocket's, a setting given overrides it for all, and 0 turns
    it off -- which is the ideal rocket bit for bit."""
    from disturbances.bank import TraceBank

    ideal = array_bank()
    u = ideal.traces[0].samples()
    rigged = TraceBank.from_arrays(
        [u], ideal.traces[0].dt_s, ideal.params[0], rig=Rig(0.05, 0.5, 0.03)
    )
    options = {"trace": 0, "start": 0}
    own = RocketRollEnv(bank=rigged, sensors=False)
    told = _env(servo_lag_s=0.05, backlash_deg=0.5, sensor_latency_s=0.03)
    off = RocketRollEnv(
        bank=rigged, sensors=False, servo_lag_s=0.0, backlash_deg=0.0, sensor_latency_s=0.0
    )
    plain = _env()
    for env in (own, told, off, plain):
        env.reset(seed=0, options=options)
    for a in _actions(40):
        obs_own, *_ = own.step(np.array([a]))
        obs_told, *_ = told.step(np.array([a]))
        obs_off, *_ = off.step(np.array([a]))
        obs_plain, *_ = plain.step(np.array([a]))
        np.testing.assert_array_equal(obs_own, obs_told)
        np.testing.assert_array_equal(obs_off, obs_plain)
    assert not np.array_equal(obs_own, obs_plain)
    assert own.core.link[0].tolist() == told.core.link[0].tolist()


@contextlib.contextmanager
def _ml_fitting_only(model: str) -> Iterator[None]:
    """Within the block, ``ml`` registered as fitting ``model`` alone: a test that reads
    one model's fit does not pay for the other's (with the quadratic damping searched, the
    bulk of the work); registered as before after it."""
    from identification.methods import METHODS, traits

    saved = METHODS.snapshot(["ml"])
    entry = METHODS.entry("ml")
    only = dataclasses.replace(traits("ml"), models=(model,))
    METHODS.register("ml", entry.target, summary=entry.summary, replace=True, traits=only)
    try:
        yield
    finally:
        METHODS.merge(saved)


def test_a_stated_rig_goes_from_the_recording_through_the_database_into_the_replay(
    tmp_path: Path,
) -> None:
    """The tunnel's recording states its rig (format 1.2); its identification in the
    database keeps it; an environment replaying that recording flies it (posterior draws
    and all), unless its settings give another."""
    from disturbances.db import DisturbanceDB
    from disturbances.ingest import add_recording
    from identification.instruments.tunnel import TunnelSpec, run_tunnel
    from identification.methods.pipeline import IdentifyOptions

    effects = Effects(servo_lag_s=0.05, backlash_deg=0.5, latency_s=0.03)
    rec = run_tunnel(TunnelSpec(seed=3, effects=effects, state_rig=True, split="train"))
    path = tmp_path / "rig.sqlite"
    with DisturbanceDB(path, create=True) as db, _ml_fitting_only("theta"):
        add_recording(db, rec, IdentifyOptions(noise_runs=0), methods=["ml"], posterior=2)
    stated = Rig(0.05, 0.5, 0.03)
    env = RocketRollEnv(db=path, recording=rec.name, disturbance="posterior")
    assert set(env.bank.rigs) == {stated}
    env.reset(seed=0)
    assert env.core.link[0].tolist() == env.config.link_row(stated).tolist()
    overridden = RocketRollEnv(db=path, recording=rec.name, sensor_latency_s=0.0)
    overridden.reset(seed=0)
    assert overridden.core.link[0].tolist() == env.config.link_row(Rig(0.05, 0.5)).tolist()


def test_a_latency_ml_found_goes_through_the_database_into_the_replay(tmp_path: Path) -> None:
    """Unstated, a late sensor is found by ``ml`` (``metrics.sensor_latency``); the replay of
    its rocket and ``u_d`` flies that latency, as if it had been stated, and an export
    imported back keeps it."""
    from disturbances.db import DisturbanceDB
    from disturbances.exchange import import_export, write_export
    from disturbances.ingest import add_recording
    from identification.instruments.tunnel import TunnelSpec, run_tunnel
    from identification.methods.pipeline import IdentifyOptions

    rec = run_tunnel(
        TunnelSpec(
            seed=0, model="constant", alpha=1.8, beta=-5.4, beta_bar=1.5, schedule="doublets",
            lead=1.0, fin_range=8.0, log_dt=0.02, duration=30.0, gyro_noise=1.0,
            no_encoder=True, measured_fin=True, turbulence_sd=0.7, split="train",
            effects=Effects(latency_s=0.04),
        )
    )  # fmt: skip
    path = tmp_path / "late.sqlite"
    with DisturbanceDB(path, create=True) as db, _ml_fitting_only("constant"):
        add_recording(db, rec, IdentifyOptions(noise_runs=0), methods=["ml"])
        (row,) = db.identifications(method="ml")
    found = row.metrics["sensor_latency"]
    assert found["admitted"]
    late = Rig(latency_s=found["estimate_s"])
    env = RocketRollEnv(db=path, recording=rec.name, model="constant", disturbance="replay")
    assert set(env.bank.rigs) == {late}
    env.reset(seed=0)
    assert env.core.link[0].tolist() == env.config.link_row(late).tolist()
    folder, again = tmp_path / "export", tmp_path / "imported.sqlite"
    with DisturbanceDB(path, create=False) as db:
        write_export(db, folder, "npz")
    with DisturbanceDB(again, create=True) as db:
        import_export(db, folder)
    replayed = RocketRollEnv(db=again, recording=rec.name, model="constant", disturbance="replay")
    assert set(replayed.bank.rigs) == {late}


def _quadratic_bank(q: float) -> Any:
    """:func:`array_bank` with every rocket's damping growing by ``q`` at 30 °/s."""
    from disturbances.bank import TraceBank

    bank = array_bank()
    traces = []
    for t in bank.traces:
        assert t.params is not None
        traces.append(
            dataclasses.replace(t, params=dataclasses.replace(t.params, quadratic_damping=q))
        )
    return TraceBank(traces, f"array bank, q = {q:g}")


def test_the_kernel_flies_a_rockets_quadratic_damping_as_the_reference_integrator(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A rocket whose damping grows with the roll rate (q = 0.5: half of a(θ) added at
    30 °/s), the rate task driven hard: the kernel (each moving 10-ms substep damped at
    its starting rate, a held run at the mean of its ends') within 0.05 °/s of the
    reference integrator (1-ms Runge-Kutta of ``a·q·v·|v|``) over 300 control steps (7e-3
    seen), the linear rocket 2.1 °/s off; the episode starts at the rocket's own steady
    rate."""
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    from _reference_env import ReferenceRollEnv

    bank = _quadratic_bank(0.5)
    config = RollConfig(sensors=False, task="rate")
    reference = ReferenceRollEnv(config, bank, Effects())
    kernel = RocketRollEnv(bank=bank, sensors=False, task="rate")
    linear = _env(task="rate")
    options = {"trace": 0, "start": 0}
    for env in (reference, kernel, linear):
        env.reset(seed=0, options=options)
    p = kernel.core.roll_params(0)
    assert p.quadratic_damping == 0.5
    start = kernel.core.state[0, State.RATE]
    assert start == pytest.approx(float(p.steady_rate(0.0, kernel.core.u_now[0])))
    assert abs(start) < abs(linear.core.state[0, State.RATE])  # damped more than linear
    rate, linear_rate = [], []
    for a in 2.5 * _actions(300):
        ref_obs, *_ = reference.step(np.array([min(max(a, -1.0), 1.0)]))
        obs, *_ = kernel.step(np.array([min(max(a, -1.0), 1.0)]))
        lin_obs, *_ = linear.step(np.array([min(max(a, -1.0), 1.0)]))
        rate.append(abs(ref_obs[Obs.RATE] - obs[Obs.RATE]))
        linear_rate.append(abs(ref_obs[Obs.RATE] - lin_obs[Obs.RATE]))
    assert max(rate) < 0.05
    assert max(linear_rate) > 1.5 and max(linear_rate) > 20.0 * max(rate)


def test_an_identified_quadratic_damping_goes_through_the_database_into_the_replay(
    tmp_path: Path,
) -> None:
    """The paper's 10-Hz schedule on a rocket whose damping is 50 % stronger at 30 °/s:
    ``ml`` with the term searched admits it (its 95 % interval covering the truth, not 0),
    refits the rest with it, the database stores ``q`` with the parameters and the
    posterior draws, and the replay flies it."""
    from disturbances.db import DisturbanceDB
    from disturbances.ingest import add_recording
    from identification.instruments.tunnel import TunnelSpec, run_tunnel
    from identification.methods.pipeline import IdentifyOptions

    rec = run_tunnel(TunnelSpec(seed=0, effects=Effects(quadratic_damping=0.5)))
    path = tmp_path / "q.sqlite"
    options = IdentifyOptions(noise_runs=0, fit_quadratic_damping=True)
    with DisturbanceDB(path, create=True) as db, _ml_fitting_only("theta"):
        add_recording(db, rec, options, methods=["ml"], posterior=2)
        stored = db.traces(model="theta")
        (ident,) = db.identifications(model="theta")
    term = ident.metrics["quadratic_damping"]
    low, high = term["interval"]
    assert term["admitted"] and 0.0 < low < 0.5 < high and term["p"] < 0.01
    assert {r.kind for r in stored} == {"identified", "posterior"}
    assert {r.params and r.params.quadratic_damping for r in stored} == {
        ident.params.quadratic_damping
    }
    assert ident.params.quadratic_damping == term["estimate"]
    env = RocketRollEnv(db=path, recording=rec.name, model="theta", disturbance="posterior")
    env.reset(seed=0)
    assert env.core.roll_params(0).quadratic_damping == term["estimate"]


def test_with_a_quadratic_damping_the_latency_changes_what_is_read_not_the_rocket() -> None:
    """The sensors' latency splits no held run of a rocket with a quadratic damping (whose
    merged run is damped at its own mean rate): the rocket flies the same to the bit with
    and without it; a negative q beyond its data keeps the damping's factor at its floor
    and the roll finite at full fin."""
    rng = np.random.default_rng(2)
    actions = np.repeat(rng.uniform(-1, 1, 30), 10).astype(np.float32)
    for q in (0.5, -0.2):
        runs = []
        for latency in (0.0, 0.03, 0.25):
            env = RocketRollEnv(bank=_quadratic_bank(q), sensors=False, task="rate",
                                sensor_latency_s=latency)  # fmt: skip
            env.reset(seed=0, options={"trace": 1, "start": 5})
            states = []
            for a in actions:
                env.step(np.array([a]))
                states.append(env.core.state[0, :2].copy())
            runs.append(states)
        assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])
    runaway = RocketRollEnv(bank=_quadratic_bank(-0.3), sensors=False, task="rate")
    runaway.reset(seed=0, options={"trace": 0, "start": 0})
    for _ in range(100):
        runaway.step(np.array([1.0]))
    assert np.isfinite(runaway.core.state).all()
