"""The virtual flight recorder under a roll-rate loop: the open loop unchanged, the loop's
law sample by sample, the stops, the metadata, determinism."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from identification.instruments.flightlog import FlightLogSpec, run_flight
from identification.instruments.reference import Effects
from identification.recordings.recording import (
    FinRange,
    Recording,
    load_recording,
    recording_text,
)
from rocketroll.cli import main
from rocketroll_common.errors import SettingError
from rocketroll_common.settings import parse

#: The loop most tests fly: the supersonic ascent, canards stopped at ±15°, a small
#: staircase dithered on top of the loop, the measured fin.
LOOP: dict[str, Any] = {
    "seed": 3,
    "ascent": "supersonic",
    "fin_range": 3.0,
    "stops": 15.0,
    "loop_gain": 1.0,
    "loop_delay": 0.02,
    "measured_fin": True,
}

#: Open-loop flights and the SHA-256 of their recording's text, as written before the loop
#: was added (the exact kernel subsonic and supersonic, a descent, the reference integrator
#: with every effect).
OPEN_LOOP = [
    (FlightLogSpec(), "4c0e9d790cf7ad81f4933e1d2d4728dbc1dfc608871034d4c1065e37edf683d6"),
    (
        FlightLogSpec(seed=2, ascent="supersonic", measured_fin=True, encoder_counts=4096),
        "c513c8004ba0ff9f71c6b6a27e2785b3fd884368add884f6a5e438668e11c6fc",
    ),
    (
        FlightLogSpec(seed=1, descent=3.0, measured_fin=True),
        "5cb6bf95b62e78604031fd6d93a89140267d1967f23b527155bbc7b8e7ece86b",
    ),
    (
        FlightLogSpec(
            seed=4,
            effects=Effects(
                servo_lag_s=0.03,
                backlash_deg=1.0,
                latency_s=0.015,
                quadratic_damping=0.5,
                gust_sd=0.3,
            ),
            measured_fin=True,
        ),
        "6e23a89c94e91d11aa60936b0c7aae60a9e3c0949b195af3e23acf5faaf2b85b",
    ),
]


def _columns(rec: Recording, *names: str) -> list[np.ndarray]:
    out = []
    for name in names:
        values = getattr(rec, name)
        assert values is not None, name
        out.append(np.asarray(values))
    return out


def _excitation(spec: FlightLogSpec) -> np.ndarray:
    """The flight's excitation: its open loop's command with the fins' stops out of reach
    (the staircase is drawn alike whatever the loop)."""
    if spec.schedule == "none":
        return np.zeros(run_flight(replace(spec, loop_gain=0.0, schedule="staircase")).n_samples)
    (command,) = _columns(run_flight(replace(spec, loop_gain=0.0, stops=40.0)), "fin_cmd_deg")
    return command


@pytest.mark.parametrize(("spec", "digest"), OPEN_LOOP)
def test_open_loop_flights_are_unchanged(spec: FlightLogSpec, digest: str) -> None:
    text = recording_text(run_flight(spec))
    assert hashlib.sha256(text.encode()).hexdigest() == digest
    assert "loop." not in text and "truth.fin_range_deg" not in text


def test_open_loop_ignores_the_loop_delay_and_saturates_at_the_stops() -> None:
    spec = FlightLogSpec(seed=5, fin_range=20.0)
    plain, delayed = run_flight(spec), run_flight(replace(spec, loop_delay=0.3))
    for column, values in plain.columns().items():
        assert np.array_equal(values, delayed.columns()[column]), column
    stopped = run_flight(replace(spec, stops=10.0))
    (excitation,) = _columns(plain, "fin_cmd_deg")
    (command,) = _columns(stopped, "fin_cmd_deg")
    assert np.max(np.abs(excitation)) > 10.0
    assert np.array_equal(command, np.clip(excitation, -10.0, 10.0))
    assert stopped.metadata["truth.fin_range_deg"] == "10.0"
    assert stopped.fin_range() == FinRange(10.0, FinRange.TRUTH)
    assert plain.fin_range() == FinRange(40.0, FinRange.TRUTH)  # the eq. 23 servo's


@pytest.mark.parametrize(
    ("changes", "delay_samples"),
    [
        ({}, 2),
        ({"log_dt": 0.005, "loop_delay": 0.015}, 3),
        ({"loop_delay": 0.0, "loop_gain": 0.3}, 0),
        ({"ascent": "default", "descent": 2.0, "loop_gain": 0.5}, 2),
        ({"effects": Effects(servo_lag_s=0.02, latency_s=0.01), "gyro_bias": 2.0}, 2),
    ],
)
def test_logged_command_is_the_loop_law_on_the_delayed_gyro(
    changes: dict[str, Any], delay_samples: int
) -> None:
    spec = FlightLogSpec(**{**LOOP, **changes})
    rec = run_flight(spec)
    command, gyro = _columns(rec, "fin_cmd_deg", "roll_rate_dps")
    d = delay_samples
    read = gyro[: gyro.size - d]
    law = np.clip(_excitation(spec)[d:] + spec.loop_gain * (0.0 - read), -15.0, 15.0)
    np.testing.assert_array_equal(command[d:], law)
    assert np.max(np.abs(command)) <= 15.0


def test_a_delay_between_samples_is_read_on_the_fine_grid() -> None:
    """15 ms at 100 Hz: the rate between two logged samples (a noise-free gyro: the log's
    samples interpolated come within a fraction of a degree of the command)."""
    spec = FlightLogSpec(
        seed=1, fin_range=3.0, stops=15.0, loop_gain=0.3, loop_delay=0.015,
        gyro_noise=0.0, gyro_floor=0.0,
    )  # fmt: skip
    rec = run_flight(spec)
    command, gyro = _columns(rec, "fin_cmd_deg", "roll_rate_dps")
    assert rec.metadata["loop.delay_s"] == "0.015"
    excitation = _excitation(spec)

    def law(read: np.ndarray) -> np.ndarray:
        return np.clip(excitation[2:] + spec.loop_gain * (0.0 - read), -15.0, 15.0)

    error = np.abs(command[2:] - law(0.5 * (gyro[:-2] + gyro[1:-1])))
    whole_sample = np.abs(command[2:] - law(gyro[1:-1]))  # the rate 10 ms before
    assert np.max(error) < 0.25
    assert np.max(whole_sample) > 4 * np.max(error)


def test_the_canards_saturate_at_the_stops_and_never_pass_them() -> None:
    rec = run_flight(FlightLogSpec(**{**LOOP, "servo_rate": 600.0}))
    command, fin = _columns(rec, "fin_cmd_deg", "fin_deg")
    assert np.max(np.abs(command)) == 15.0
    assert np.max(np.abs(fin)) <= 15.0 + 1e-12
    assert 0.3 < np.mean(np.abs(command) == 15.0) < 0.9
    assert np.mean(np.abs(fin) >= 15.0 - 1e-9) > 0.1


def test_a_loop_of_the_right_sign_damps_the_roll() -> None:
    base = {**LOOP, "loop_gain": 0.1}
    (damped,) = _columns(run_flight(FlightLogSpec(**base)), "roll_rate_dps")
    open_spec = FlightLogSpec(**{**base, "loop_gain": 0.0})
    (free,) = _columns(run_flight(open_spec), "roll_rate_dps")
    assert np.std(damped) < 0.7 * np.std(free)


def test_schedule_none_needs_the_loop() -> None:
    with pytest.raises(SettingError, match="loop-gain"):
        FlightLogSpec(schedule="none")
    spec = FlightLogSpec(schedule="none", loop_gain=0.2, loop_delay=0.01)
    rec = run_flight(spec)
    command, gyro = _columns(rec, "fin_cmd_deg", "roll_rate_dps")
    law = np.clip(0.0 + 0.2 * (0.0 - gyro[:-1]), -40.0, 40.0)  # 10 ms: 1 sample
    np.testing.assert_array_equal(command[1:], law)
    assert rec.metadata["flight.schedule"] == "none"


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("loop_gain", -10.5),
        ("loop_gain", 12.0),
        ("loop_delay", 0.6),
        ("stops", 45.0),
        ("stops", 1.0),
    ],
)
def test_loop_settings_are_bounded(field: str, value: float) -> None:
    with pytest.raises(SettingError, match=field):
        FlightLogSpec(**{**LOOP, field: value})


def test_metadata_states_the_loop_and_survives_the_file(tmp_path: Path) -> None:
    spec = FlightLogSpec(**LOOP)
    out = tmp_path / "loop.csv"
    argv = ["record-flight", "--seed", "3", "--ascent", "supersonic", "--fin-range", "3"]
    argv += ["--stops", "15", "--loop-gain", "1", "--measured-fin", "--out", str(out)]
    assert main(argv) == 0
    rec = load_recording(out)
    meta = rec.metadata
    assert meta["flight.schedule"] == "staircase"
    assert meta["loop.gain"] == "1.0"
    assert meta["loop.delay_s"] == "0.02"
    assert meta["loop.stops_deg"] == "15.0"
    assert meta["loop.rate_sensor"] == "roll_rate_dps"
    assert "excitation: flight.schedule" in meta["loop.law"]
    assert meta["truth.fin_range_deg"] == "15.0"
    assert rec.fin_range() == FinRange(15.0, FinRange.TRUTH)
    command = meta["command"].split()
    assert command[:2] == ["rocketroll", "record-flight"]
    assert parse(FlightLogSpec, command[2:], prog="rocketroll record-flight") == spec
    direct = run_flight(spec)
    assert dict(direct.metadata) == dict(meta)
    for column, values in direct.columns().items():
        np.testing.assert_allclose(rec.columns()[column], values, atol=1e-6, rtol=0)
    blind = run_flight(FlightLogSpec(**{**LOOP, "no_gyro": True, "encoder_counts": 4096}))
    assert blind.metadata["loop.rate_sensor"] == "the true roll rate"


def test_same_seed_same_flight_and_the_same_turbulence_as_in_open_loop() -> None:
    spec = FlightLogSpec(**LOOP)
    first, again = run_flight(spec), run_flight(spec)
    assert recording_text(first) == recording_text(again)
    (other,) = _columns(run_flight(replace(spec, seed=4)), "fin_cmd_deg")
    (mine,) = _columns(first, "fin_cmd_deg")
    assert not np.array_equal(mine, other)
    (open_loop,) = _columns(run_flight(replace(spec, loop_gain=0.0)), "ud_true_deg")
    (turbulence,) = _columns(first, "ud_true_deg")
    np.testing.assert_array_equal(turbulence, open_loop)
