"""A flight in the database: its fits at their reference airspeed with the measured
scaling, its u_d and posterior draws, kept apart from the tunnel's traces."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import pytest

from disturbances.bank import TraceBank
from disturbances.db import DisturbanceDB
from identification.instruments.flightlog import FlightLogSpec, run_flight
from identification.recordings.recording import save_recording
from rocketroll.cli import main
from rocketroll_physics.scaling import AirspeedScaling, FlightReference


@pytest.fixture(scope="module")
def stored(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("flights")
    flight = root / "flight.csv"
    save_recording(
        run_flight(FlightLogSpec(seed=3, model="constant", torque_exponent=1.5, split="test")),
        flight,
    )
    db = root / "db.sqlite"
    assert main(["db", "add", str(flight), "--db", str(db), "--posterior", "3"]) == 0
    assert main(["tunnel", "--seed", "0", "--out", str(root / "tunnel.csv")]) == 0
    # The tunnel's recording beside it, by the paper's method (the one the tests replay)
    # without the noise study.
    tunnel = ["db", "add", str(root / "tunnel.csv"), "--db", str(db), "--split", "test"]
    assert main([*tunnel, "--method", "paper", "--mc-runs", "0"]) == 0
    return db


def test_a_flight_is_stored_with_its_reference_and_measured_scaling(stored: Path) -> None:
    with DisturbanceDB(stored, create=False) as db:
        flights = db.identifications(method="flight")
        assert {row.model for row in flights} == {"constant", "theta"}
        for row in flights:
            reference = row.flight_reference
            assert reference is not None
            assert reference.v_ref_mps == row.metrics["v_ref_mps"]
            assert abs(reference.scaling.torque_exponent - 1.5) < 0.1
            assert row.verdict in ("good", "weak")
        assert all(row.flight_reference is None for row in db.identifications(method="paper"))
        traces = db.traces(method="flight")
        assert sorted(t.kind for t in traces).count("posterior") == 6  # 3 draws per model
        assert all(
            t.flight_reference == flights[0].flight_reference
            or t.flight_reference == flights[1].flight_reference
            for t in traces
        )
        assert traces[0].dt_s == pytest.approx(0.01)  # u_d in the flight's own time
        # The tunnel's replay never takes a flight's u_d (which is an equivalent fin angle
        # in flight): its banks are of the tunnel's methods.
        bank = TraceBank.from_db(db, "test", method="paper", model="theta")
        assert all(t.flight_reference is None for t in bank.traces)


def test_the_schema_keeps_a_reference_whole(stored: Path) -> None:
    conn = sqlite3.connect(stored)
    with pytest.raises(sqlite3.IntegrityError, match="CHECK"):
        conn.execute("UPDATE identifications SET torque_exponent = NULL WHERE method = 'flight'")
    with pytest.raises(sqlite3.IntegrityError, match="CHECK"):
        conn.execute("UPDATE identifications SET v_ref_mps = -1 WHERE method = 'flight'")
    conn.close()
    reference = FlightReference(50.0, 1.0, AirspeedScaling(1.5, 1.0))
    gain, damping = reference.scales(100.0, 0.5)
    assert float(gain) == pytest.approx(2.0**0.5) and float(damping) == pytest.approx(1.0)


def test_the_flight_env_flies_a_stored_flight_as_that_rocket(stored: Path) -> None:
    """``recording=`` naming a stored flight: its profile, its measured scaling from its
    reference, and its own posterior u_d, from the moment it reaches the tunnel's airspeed."""
    import gymnasium as gym
    import numpy as np

    import rollenv  # noqa: F401  (registers the variants)
    from rocketroll_physics.scaling import TUNNEL_AIRSPEED_MPS

    with DisturbanceDB(stored, create=False) as db:
        (fit,) = db.identifications(method="flight", model="theta")
        draws = [t for t in db.traces(method="flight", model="theta") if t.kind == "posterior"]
    env = gym.make("RocketRollFlight-v0", db=str(stored), recording=fit.recording)
    config = env.unwrapped.config  # type: ignore[attr-defined]
    assert config.flies_stored_flight and config.method == "flight"
    assert config.flight_turbulence == "recorded" and config.disturbance == "posterior"
    schedule = config.flight_schedule
    assert schedule.reference == fit.flight_reference
    # The gain at each step is the fit's scaling from its reference: (V/V_ref)^(n - m).
    reference = fit.flight_reference
    assert reference is not None
    speeds = schedule.profile.at(schedule.step_times_s() + 0.5 * schedule.dt_s).airspeed_mps
    gain, _ = reference.scales(speeds, 1.0)
    np.testing.assert_allclose(schedule.scales[:, 0], np.maximum(gain, schedule.scales[:, 0].min()))
    assert schedule.profile.airspeed_mps[0] == pytest.approx(TUNNEL_AIRSPEED_MPS, rel=0.01)
    _, info = env.reset(seed=0)
    assert info["trace"].endswith("@recorded")
    assert info["trace"].split("@")[0] in {t.uid for t in draws}
    for _ in range(5):
        env.step(np.zeros(1, dtype=np.float32))
    env.close()
    # A tunnel bank is not a flight's: recorded turbulence of tunnel traces is refused.
    with pytest.raises(ValueError, match="replays a stored flight's own u_d"):
        gym.make(
            "RocketRollFlight-v0",
            db=str(stored),
            method="paper",
            flight_turbulence="recorded",
            split="test",
        )


def test_a_stored_flights_rocket_flies_another_ascent_its_u_d_flown_anew(
    stored: Path, tmp_path: Path
) -> None:
    """``profile=`` flies the stored rocket on another ascent, its recorded u_d flown anew
    by height (the flown law turned around): on its own log read as a V(t) CSV it is the
    recorded replay again; on the default ascent it keeps the rocket and its scaling; an
    ascent that climbs past the recorded heights is refused with the way out
    (``episode_s``)."""
    import warnings

    import gymnasium as gym
    import numpy as np

    import rollenv  # noqa: F401  (registers the variants)
    from identification.recordings.recording import load_recording
    from rollenv.config import RollConfig
    from rollenv.flight import FlightSchedule

    with DisturbanceDB(stored, create=False) as db:
        (fit,) = db.identifications(method="flight", model="theta")
        log = db.recording(fit.recording_hash)
    own_csv = tmp_path / "own.csv"
    save_recording(log, own_csv)
    assert load_recording(own_csv).airspeed_mps is not None

    def episode_bank(**options: Any) -> tuple[RollConfig, FlightSchedule, TraceBank]:
        env = gym.make("RocketRollFlight-v0", db=str(stored), recording=fit.recording, **options)
        config = env.unwrapped.config  # type: ignore[attr-defined]
        bank = env.unwrapped.bank  # type: ignore[attr-defined]
        env.close()
        schedule = config.flight_schedule
        assert schedule is not None
        return config, schedule, config.flights(bank)

    _, schedule, recorded = episode_bank()
    assert schedule.recorded_on is None
    _, schedule, again = episode_bank(profile=str(own_csv))
    assert schedule.recorded_on is not None and schedule.reference == fit.flight_reference
    assert "flown anew by height" in again.description
    for a, b in zip(recorded.traces, again.traces, strict=True):
        np.testing.assert_allclose(b.samples(), a.samples(), rtol=1e-6, atol=1e-6)
    _, schedule, on_default = episode_bank(profile="default")
    assert schedule.profile.source.startswith("simulated")
    assert schedule.reference == fit.flight_reference
    for flown, own in zip(on_default.traces, recorded.traces, strict=True):
        assert 0.5 < float(np.std(flown.samples())) / float(np.std(own.samples())) < 2.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the supersonic ascent warns of Mach
        with pytest.raises(ValueError, match=r"covers 0-\d+ m above its pad.*episode_s"):
            episode_bank(profile="supersonic")
        short_config, _, short = episode_bank(profile="supersonic", episode_s=5.0)
    assert short_config.max_episode_steps == 50 and len(short.traces) == len(recorded.traces)


def test_model_based_designs_on_a_stored_flight_model_its_turbulence_in_the_tunnels_frame(
    stored: Path,
) -> None:
    """The observer's and the MPC's turbulence model is stated in the tunnel's frame and
    flown by the airspeed: a stored flight's own u_d (recorded in flight) is taken there
    first (rollenv.flight.tunnel_frame), where it has the recorder's tunnel process's SD
    (9.8°), and is flown by V/V_ref, not by the stored rocket's gain; on the flight the
    scheduled observer then holds the roll better than trim. For the tunnel's rocket the
    airspeed ratio is the gain of eq. 4-8, as before."""
    import math

    import gymnasium as gym
    import numpy as np

    import rollenv  # noqa: F401  (registers the variants)
    from agents.base import Design
    from agents.evaluate import evaluate, headline_scores, protocol_episodes
    from agents.observer.controller import designed_on
    from agents.observer.estimator import TurbulenceModel, stationary_cov
    from agents.registry import make_controller
    from rollenv.config import RollConfig
    from rollenv.flight import tunnel_frame

    def sd(model: TurbulenceModel) -> float:
        return math.sqrt(float(stationary_cov(model.ar, model.innovation_sd)[0, 0]))

    with DisturbanceDB(stored, create=False) as db:
        (fit,) = db.identifications(method="flight", model="theta")
    env = gym.make("RocketRollFlight-v0", db=str(stored), recording=fit.recording)
    config = env.unwrapped.config  # type: ignore[attr-defined]
    replayed = env.unwrapped.bank  # type: ignore[attr-defined]
    env.close()
    schedule = config.flight_schedule
    bank = Design(config, "RocketRollFlight-v0", db=str(stored)).design_bank
    assert all(t.flight_reference is not None for t in bank.traces)
    nominal, turbulence = designed_on(bank, config)
    assert 0.8 * 9.8 < sd(turbulence) < 1.2 * 9.8
    in_flight = TurbulenceModel.from_bank(bank, config.dt_s, nominal)  # as recorded
    assert sd(in_flight) < 0.5 * 9.8
    framed = tunnel_frame(bank, schedule)
    assert "tunnel's frame" in framed.description
    assert all(t.duration_s > s.duration_s for t, s in zip(framed.traces, bank.traces, strict=True))
    # The stored rocket's gain is not the airspeed ratio the turbulence is flown by.
    assert not np.allclose(schedule.airspeed_ratio, schedule.scales[:, 0])
    specs = protocol_episodes(config, 4, 0, bank=replayed)
    scores = {
        policy: evaluate(
            config,
            make_controller(policy, config, "RocketRollFlight-v0", db=str(stored)),
            specs,
            bank=replayed,
        )
        for policy in ("trim", "observer")
    }
    observer, trim = (float(headline_scores(scores[p]).mean()) for p in ("observer", "trim"))
    assert observer < 0.7 * trim, (observer, trim)
    tunnel = RollConfig(flight="default").flight_schedule
    assert tunnel is not None
    np.testing.assert_array_equal(tunnel.airspeed_ratio, tunnel.scales[:, 0])


def test_a_flight_exported_and_imported_back_keeps_its_reference_and_draws(
    stored: Path, tmp_path: Path
) -> None:
    """A flight's fits keep their reference airspeed, density, scaling and verdict through
    `db export` and `db import`, with every trace of the database row for row."""
    from disturbances.exchange import import_export, write_export
    from tests.disturbances.test_draw_order import stored_rows

    folder, new = tmp_path / "export", tmp_path / "imported.sqlite"
    with DisturbanceDB(stored, create=False) as db:
        write_export(db, folder, "npz")
    with DisturbanceDB(new, create=True) as db:
        import_export(db, folder)
        flights = db.identifications(method="flight")
        assert len(flights) == 2
        assert all(row.flight_reference is not None and row.verdict for row in flights)
    assert stored_rows(new) == stored_rows(stored)
