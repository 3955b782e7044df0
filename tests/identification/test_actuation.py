"""The fin's linkage and the sensors' latency: stated by the user, identified from data.

A stated lag, play or latency shapes the fin the model sees; from a measured fin
column the servo lag and the backlash come out near the truth and stay out where
the rig has none; the latency comes out within one logging interval and is not
invented on a rig without one.  ``benchmarks/actuation.py`` measures the rates
over many seeds; these are single recordings.
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from identification.compiled import linkage_path
from identification.instruments.reference import Effects
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods.actuation import Actuation, fit_linkage, identify_actuation
from identification.methods.pipeline import IdentifyOptions, measurements
from identification.model import Linkage, Rig, Servo, servo_path
from identification.recordings.recording import StatedRig


def _short(seed: int, effects: Effects, **settings: object) -> TunnelSpec:
    """A 100-Hz, ~35-s staircase with a 1 % gyro and a measured fin column."""
    base: dict[str, object] = {
        "seed": seed,
        "log_dt": 0.01,
        "gyro_noise": 1.0,
        "measured_fin": True,
        "schedule": "staircase",
        "steps": 8,
        "dwell_min": 3.0,
        "dwell_max": 5.0,
        "effects": effects,
    }
    return TunnelSpec(**{**base, **settings})  # type: ignore[arg-type]


def test_without_a_linkage_the_path_is_the_servo_of_eq_23() -> None:
    command = np.repeat([0.0, 10.0, -5.0, 30.0, 30.0, -40.0], 37)
    servo = Servo()
    np.testing.assert_allclose(
        linkage_path(command, 2.0, 0.01, servo, Linkage()),
        servo_path(command, 2.0, 0.01, servo),
        atol=1e-12,
    )
    lagged = linkage_path(command, 2.0, 0.01, servo, Linkage(lag_s=0.1))
    assert lagged[40] < servo_path(command, 2.0, 0.01, servo)[40]  # trails on the rise


@pytest.mark.parametrize("seed", [1, 2])
def test_a_measured_fin_gives_the_servo_lag_and_backlash_and_none_on_a_direct_rig(
    seed: int,
) -> None:
    """Servo lag within 20 % and backlash within 25 % of the truth; on the paper's rig
    (the fin is the servo) neither is admitted."""
    servo = Servo()
    rec = run_tunnel(_short(seed, Effects(servo_lag_s=0.05, backlash_deg=0.5)))
    lag, play = fit_linkage(rec, servo)
    assert lag.admitted and play.admitted
    assert lag.value == pytest.approx(0.05, rel=0.2)
    assert play.value == pytest.approx(0.5, rel=0.25)
    direct = run_tunnel(_short(seed, Effects()))
    lag, play = fit_linkage(direct, servo)
    assert not lag.admitted and not play.admitted
    assert lag.value == play.value == 0.0


@dataclass(frozen=True)
class _Identified:
    """``rocketroll identify --actuation`` on a rig whose sensors are 0.03 s late: what it
    printed, the JSON it wrote and what :func:`identify_actuation` returned inside it."""

    out: str
    written: dict[str, Any]
    found: Actuation


@pytest.fixture(scope="module")
def late_rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[_Identified]:
    """One identification (a maximum-likelihood latency and quadratic search, the module's
    dearest step) serves the CLI's test and the latency's."""
    import identification.methods.actuation as actuation
    from identification.recordings.recording import save_recording
    from rocketroll.cli import main

    folder = tmp_path_factory.mktemp("late-rig")
    path = folder / "rig.csv"
    save_recording(run_tunnel(_short(1, Effects(latency_s=0.03))), path)
    out_json = folder / "fit.json"
    found: list[Actuation] = []

    def spy(*args: Any, **kwargs: Any) -> Actuation:
        found.append(identify_actuation(*args, **kwargs))
        return found[-1]

    argv = ["identify", str(path), "--method", "paper", "--mc-runs", "0", "--actuation"]
    argv += ["--json", str(out_json)]
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(io.StringIO()) as out:
        mp.setattr(actuation, "identify_actuation", spy)
        assert main(argv) == 0
    (actuation_found,) = found
    yield _Identified(out.getvalue(), json.loads(out_json.read_text()), actuation_found)


def test_the_latency_is_found_within_one_logging_interval_and_not_invented(
    late_rig: _Identified,
) -> None:
    late = late_rig.found
    term = late.terms[2]
    assert term.name == "sensor latency" and term.admitted
    assert abs(late.rig.latency_s - 0.03) <= 0.01 + 1e-12
    assert late.settings()["sensor_latency_s"] == late.rig.latency_s
    on_time = identify_actuation(run_tunnel(_short(2, Effects())))
    assert not on_time.terms[2].admitted and on_time.rig == Rig()
    assert "not admitted" in on_time.lines()[3]
    # A 35-s record cannot tell a damping growing with the rate: the interval says so.
    damping = on_time.terms[3]
    assert damping.name == "quadratic damping" and not damping.admitted
    assert damping.interval is not None and damping.interval[1] - damping.interval[0] > 0.3
    assert damping.interval[0] < 0.0 < damping.interval[1]


def test_without_a_measured_fin_the_linkage_is_not_looked_for() -> None:
    with pytest.raises(ValueError, match="measured fin_deg"):
        fit_linkage(run_tunnel(_short(1, Effects(), measured_fin=False)), Servo())


@pytest.mark.parametrize(
    ("dropped", "why"),
    [
        ("fin_cmd_deg", "the fin column is the measured fin; the servo's command (fin_cmd)"),
        ("fin_deg", "the fin column is the servo's command; a measured fin (fin)"),
    ],
)
def test_a_linkage_the_fin_columns_cannot_tell_says_why_and_shows_no_test(
    dropped: str, why: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With one fin column the lag and the play are not estimable: their rows say so and
    what is needed, with no LR or p as if they had been tested; every row is aligned."""
    import dataclasses

    import identification.methods.ml as ml

    # The roll response's searches are not what this test reads: the cheapest answers.
    monkeypatch.setattr(
        ml, "delay_search", lambda inputs, model, delays: ml.DelaySearch(0, 0.01, 0.0, 0.0, {})
    )
    monkeypatch.setattr(
        ml, "quadratic_search",
        lambda inputs, model: ml.QuadraticSearch(0.0, 0.0, 0.0, {}, (-0.3, 1.0)),
    )  # fmt: skip
    rec = run_tunnel(_short(1, Effects()))
    if dropped == "fin_cmd_deg":
        rec = dataclasses.replace(rec, fin_cmd_deg=None)
    else:
        rec = dataclasses.replace(rec, fin_deg=None)
    found = identify_actuation(rec)
    lag, play = found.terms[:2]
    assert not lag.estimable and not play.estimable and not lag.admitted
    assert found.rig == Rig()
    rows = found.lines()[1:]
    for row in rows[:2]:
        assert f"not estimable: {why} is needed too" in row
        assert "LR" not in row and " p " not in row and "admitted" not in row
    tested = rows[2:]
    assert all("LR" in row for row in tested)
    # The estimate starts in one column on the tested rows, the reason on the others.
    assert len({row.index("LR") for row in tested}) == 1
    assert len({row.index("not estimable") for row in rows[:2]} | {len("  ") + 18}) == 1


def test_a_stated_linkage_and_latency_shape_the_fin_the_model_sees() -> None:
    rec = run_tunnel(_short(1, Effects(), measured_fin=False))
    plain = measurements(rec, IdentifyOptions(noise_runs=0))
    lagged = measurements(rec, IdentifyOptions(noise_runs=0, rig=StatedRig(0.1, 1.0)))
    assert "0.1-s lag and 1° of play" in lagged.theta_source
    assert np.max(np.abs(lagged.theta_fine - plain.theta_fine)) > 1.0
    late = measurements(rec, IdentifyOptions(noise_runs=0, rig=StatedRig(sensor_latency_s=0.03)))
    np.testing.assert_array_equal(late.theta_fine[3:], plain.theta_fine[:-3])
    assert "delayed 0.03 s" in late.theta_source
    with pytest.raises(ValueError, match="sensor_latency_s"):
        StatedRig(sensor_latency_s=0.9)


def test_identify_actuation_prints_and_writes_each_terms_test(late_rig: _Identified) -> None:
    out = late_rig.out
    assert "beyond the model (each term admitted at p < 0.01):" in out
    (line,) = (x for x in out.splitlines() if x.strip().startswith("sensor latency"))
    assert "admitted; resolution 0.01 s" in line and "not admitted" not in line
    (line,) = (x for x in out.splitlines() if x.strip().startswith("servo lag"))
    assert "not admitted; estimate" in line
    terms = late_rig.written["actuation"]
    assert terms["sensor latency"]["admitted"] is True
    assert terms["sensor latency"]["value"] == late_rig.found.rig.latency_s
    assert abs(terms["sensor latency"]["value"] - 0.03) <= 0.01 + 1e-12
    assert terms["servo lag"]["admitted"] is False
    assert set(terms) == {"servo lag", "backlash", "sensor latency", "quadratic damping"}
    assert [terms[t.name]["statistic"] for t in late_rig.found.terms] == [
        t.statistic for t in late_rig.found.terms
    ]


def test_a_recording_states_its_rig_in_format_1_2_and_older_files_still_read(
    tmp_path: Path,
) -> None:
    from identification.recordings.recording import (
        FORMAT_V1,
        FORMAT_V1_2,
        RecordingError,
        load_recording,
        save_recording,
    )

    spec = _short(1, Effects(servo_lag_s=0.05, latency_s=0.03), state_rig=True)
    rec = run_tunnel(spec)
    assert rec.format == FORMAT_V1_2
    assert rec.rig == Rig(lag_s=0.05, latency_s=0.03)
    path = tmp_path / "rig.csv"
    save_recording(rec, path)
    text = path.read_text(encoding="utf-8")
    assert text.startswith(f"# format: {FORMAT_V1_2}\n") and "# rig.servo_lag_s: 0.05\n" in text
    assert load_recording(path).rig == rec.rig
    # identify's flags over the recording's lines, each on its own
    assert rec.rig_with(StatedRig(backlash_deg=1.0)) == Rig(0.05, 1.0, 0.03)
    plain = run_tunnel(_short(1, Effects()))
    assert plain.format == FORMAT_V1 and plain.rig == Rig()
    older = tmp_path / "older.csv"
    older.write_text(text.replace(FORMAT_V1_2, FORMAT_V1), encoding="utf-8")
    with pytest.raises(RecordingError, match=r"'rig.servo_lag_s' is format 1\.2"):
        load_recording(older)
    wrong = tmp_path / "wrong.csv"
    wrong.write_text(text.replace("# rig.servo_lag_s: 0.05", "# rig.servo_lag_s: 2"), "utf-8")
    with pytest.raises(RecordingError, match=r"must be in \[0, 0\.5\]"):
        load_recording(wrong)


def test_import_csv_stores_what_the_user_states_of_the_rig(tmp_path: Path) -> None:
    from identification.recordings.recording import load_recording
    from rocketroll.cli import main

    source = tmp_path / "log.csv"
    rows = [f"{(k // 20) % 2 * 10},{k * 0.5}" for k in range(80)]
    source.write_text("\n".join(rows) + "\n", encoding="utf-8")
    out = tmp_path / "rec.csv"
    argv = ["import-csv", str(source), "--out", str(out), "--columns", "fin_cmd,roll"]
    argv += ["--no-header", "--rate", "10", "--servo-lag", "0.04", "--sensor-latency", "0.02"]
    assert main(argv) == 0
    assert load_recording(out).rig == Rig(lag_s=0.04, latency_s=0.02)


def test_the_rig_in_memory_is_the_rig_read_back_and_older_databases_take_new_methods(
    tmp_path: Path,
) -> None:
    """The rows made from an identification carry the rig the database reads back; a
    database whose identification options predate the rig (no ``rig`` key) still takes
    another method for the same recording; a bad rig line names itself."""
    import dataclasses

    from disturbances.ingest import _options_key, identification_rows
    from identification.methods import Context

    rec = run_tunnel(_short(1, Effects(servo_lag_s=0.05), state_rig=True))
    context = Context(rec, IdentifyOptions(noise_runs=0, rig=StatedRig(sensor_latency_s=0.02)))
    _, _, traces = identification_rows(context, ["paper"])
    assert {t.rig for t in traces} == {Rig(lag_s=0.05, latency_s=0.02)}
    now = {k: v for k, v in dataclasses.asdict(IdentifyOptions()).items() if k != "progress"}
    older = {k: v for k, v in now.items() if k != "rig"}
    assert _options_key(older) == _options_key(now)
    with pytest.raises(ValueError, match=r"the recording's rig.servo_lag_s must be in \[0, 0.5\]"):
        Rig.resolved({}, {"rig.servo_lag_s": "3"})


def test_a_flight_fit_sees_the_fin_its_rig_makes() -> None:
    from identification.instruments.flightlog import FlightLogSpec, run_flight
    from identification.methods.flightfit import flight_inputs

    rec = run_flight(FlightLogSpec(seed=1))
    plain = flight_inputs(rec)
    late = flight_inputs(rec, rig=Rig(latency_s=0.05))
    lagged = flight_inputs(rec, rig=Rig(lag_s=0.1))
    assert plain.rig == Rig() and late.rig == Rig(latency_s=0.05)
    moved = np.flatnonzero(np.abs(np.diff(plain.theta)) > 0)
    assert moved.size and not np.allclose(late.theta, plain.theta)
    assert not np.allclose(lagged.theta, plain.theta)


def test_a_quadratic_damping_is_not_invented_on_the_papers_rocket() -> None:
    """The paper's 573-s schedule at 10 Hz on the paper's linear rocket: the profile
    interval covers 0 and the term is not admitted (where it is present, the database's
    chain finds it: ``tests/rollenv/test_actuation.py``)."""
    from identification.methods.ml import quadratic_search
    from identification.methods.pipeline import model_inputs

    options = IdentifyOptions(noise_runs=0)
    plain = quadratic_search(
        model_inputs(run_tunnel(TunnelSpec(seed=0)), "theta", options), "theta"
    )
    assert plain.interval[0] < 0.0 < plain.interval[1] and plain.statistic < 6.63
    assert plain.p > 0.01 and not plain.summary()["admitted"]


#: Logs of the kinds whose gain a late sensor biases: a pilot's smooth bank-to-bank
#: aileron at 25 Hz (a negative gain, the roll read a sample late), and a rocket of the
#: other sign on doublets at 50 Hz, each with a gyro only and its measured fin.
_LATE_LOGS: dict[str, dict[str, Any]] = {
    "pilot 25 Hz": {
        "model": "constant", "alpha": -2.9, "beta": -1.45, "beta_bar": 2.4,
        "schedule": "ramps", "steps": 12, "ramp": 0.6, "dwell_min": 1.0, "dwell_max": 2.0,
        "lead": 1.0, "fin_range": 10.0, "log_dt": 0.04,
    },
    "doublets 50 Hz": {
        "model": "constant", "alpha": 1.8, "beta": -5.4, "beta_bar": 1.5,
        "schedule": "doublets", "lead": 1.0, "fin_range": 8.0, "log_dt": 0.02,
        "duration": 30.0,
    },
}  # fmt: skip


def _late_log(kind: str, seed: int, latency_s: float) -> Any:
    return run_tunnel(
        TunnelSpec(
            seed=seed, gyro_noise=1.0, no_encoder=True, measured_fin=True, turbulence_sd=0.7,
            correlation_time=1.0, effects=Effects(latency_s=latency_s), **_LATE_LOGS[kind],
        )
    )  # fmt: skip


@pytest.mark.parametrize("kind", sorted(_LATE_LOGS))
def test_ml_finds_a_late_sensor_itself_and_fits_the_rocket_through_it(kind: str) -> None:
    from identification.methods import Context, fit

    truth = _LATE_LOGS[kind]
    for seed in (0,):
        rec = _late_log(kind, seed, 0.04)
        found = fit(Context(rec), "ml", ["constant"])["constant"]
        term = found.metrics["sensor_latency"]
        assert term["admitted"] and term["p"] < 0.01, (kind, seed, term)
        assert abs(term["estimate_s"] - 0.04) <= 0.02 + 1e-12, (kind, seed, term)
        assert found.params.alpha == pytest.approx(truth["alpha"], rel=0.05), (kind, seed)
        assert found.params.beta_bar_per_s == pytest.approx(truth["beta_bar"], rel=0.1)
        # Everything after the fit reads the fin it was fitted on.
        assert "delayed" in found.metrics["sources"]["fin_angle"]
        # Stated, the latency is not searched: the user's word stands.
        stated = IdentifyOptions(rig=StatedRig(sensor_latency_s=0.0))
        said = fit(Context(rec, stated), "ml", ["constant"])["constant"]
        assert "sensor_latency" not in said.metrics
        assert abs(said.params.alpha - truth["alpha"]) > abs(found.params.alpha - truth["alpha"])


@pytest.mark.parametrize("kind", sorted(_LATE_LOGS))
def test_ml_does_not_invent_a_late_sensor(kind: str) -> None:
    from identification.methods.ml import maximum_likelihood

    for seed in (3, 4):
        found = maximum_likelihood(_late_log(kind, seed, 0.0), "constant")
        assert not found.latency["admitted"], (kind, seed, found.latency)
        assert found.latency["searched_s"][1] == pytest.approx(0.1)
