"""The virtual tunnel under a roll-rate loop: the open loop unchanged, the loop's law sample
by sample, the stops, the metadata, determinism."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from identification.instruments.bundled import DATA_DIR, make
from identification.instruments.reference import Effects
from identification.instruments.tunnel import TunnelSpec, run_tunnel, spec_from_command
from identification.recordings.recording import load_recording, recording_text
from rocketroll.cli import main
from rocketroll_common.errors import SettingError

#: The loop most tests fly: a 50 Hz log, a gyro with 1 % noise, the measured fin, fins
#: stopped at ±15°, a PRBS dither on top of the loop, strong turbulence (the stops are hit).
LOOP: dict[str, Any] = {
    "seed": 3,
    "schedule": "prbs",
    "fin_range": 5.0,
    "pulse": 0.5,
    "lead": 1.0,
    "duration": 40.0,
    "log_dt": 0.02,
    "gyro_noise": 1.0,
    "measured_fin": True,
    "loop_gain": 1.5,
    "loop_delay": 0.04,
    "stops": 15.0,
    "turbulence_sd": 30.0,
}

#: Open-loop runs and the SHA-256 of their recording's text, as written before the loop was
#: added (the reference integrator with effects; the model's kernel at 100 Hz; a gyro alone).
OPEN_LOOP = [
    (
        TunnelSpec(
            seed=2,
            schedule="staircase",
            steps=3,
            dwell_min=5,
            dwell_max=8,
            effects=Effects(servo_lag_s=0.05, latency_s=0.03, gust_sd=0.3),
            measured_fin=True,
            gyro_noise=2.0,
        ),
        "23417415e6bc087f914f38d4dad210f10071e5f4a144fd1ca442e8bb69b4218f",
    ),
    (
        TunnelSpec(
            seed=5, schedule="prbs", duration=20, log_dt=0.01, measured_fin=True, state_rig=True
        ),
        "00cff506de9f0b8bae79a1536af6154e977ea95d953c85f0529f6f5106bbf149",
    ),
    (
        TunnelSpec(
            seed=4, schedule="chirp", duration=30, log_dt=0.04, no_encoder=True, gyro_noise=0.5
        ),
        "0cce90b26a4c53000dfed1b44aa085e8a9ef33b99e8744bd50df4336c5429c1c",
    ),
]


def _excitation(spec: TunnelSpec, time_s: np.ndarray) -> np.ndarray:
    return np.asarray(spec.schedule_drawn.command(time_s))


@pytest.mark.parametrize(("spec", "digest"), OPEN_LOOP)
def test_open_loop_runs_are_unchanged(spec: TunnelSpec, digest: str) -> None:
    text = recording_text(run_tunnel(spec))
    assert hashlib.sha256(text.encode()).hexdigest() == digest
    assert "loop." not in text


def test_open_loop_bundled_run_is_unchanged_and_ignores_the_loop_delay() -> None:
    name = "tunnel-paper-seed4.csv"
    assert recording_text(make(name)) == (DATA_DIR / name).read_text(encoding="utf-8")
    spec = TunnelSpec(seed=1, schedule="doublets", steps=2, dwell_min=3, dwell_max=4)
    plain, delayed = run_tunnel(spec), run_tunnel(replace(spec, loop_delay=0.3))
    for column, values in plain.columns().items():
        assert np.array_equal(values, delayed.columns()[column]), column


def test_open_loop_command_saturates_at_the_stops() -> None:
    spec = TunnelSpec(seed=2, schedule="doublets", steps=3, dwell_min=3, dwell_max=4, stops=10.0)
    rec = run_tunnel(spec)
    assert rec.fin_cmd_deg is not None
    excitation = _excitation(spec, rec.time_s)
    assert np.max(np.abs(excitation)) > 10.0
    assert np.array_equal(rec.fin_cmd_deg, np.clip(excitation, -10.0, 10.0))
    assert rec.metadata["truth.fin_range_deg"] == "10.0"


@pytest.mark.parametrize(("log_dt", "delay"), [(0.02, 0.04), (0.04, 0.08), (0.01, 0.0)])
def test_logged_command_is_the_loop_law_on_the_delayed_gyro(log_dt: float, delay: float) -> None:
    spec = TunnelSpec(**{**LOOP, "log_dt": log_dt, "loop_delay": delay})
    rec = run_tunnel(spec)
    cmd, gyro = rec.fin_cmd_deg, rec.roll_rate_dps
    assert cmd is not None and gyro is not None
    d = round(delay / log_dt)
    excitation = _excitation(spec, rec.time_s)
    law = np.clip(excitation[d:] + spec.loop_gain * (0.0 - gyro[: gyro.size - d]), -15.0, 15.0)
    np.testing.assert_array_equal(cmd[d:], law)
    assert 0.0 < np.mean(np.abs(cmd) == 15.0) < 0.9  # the loop reaches the stops, not always


def test_a_delay_between_samples_is_read_on_the_fine_grid() -> None:
    """25 ms at 50 Hz: the rate between two logged samples (a noise-free gyro: the log's
    samples interpolated come within a small fraction of a degree of the command)."""
    spec = TunnelSpec(**{**LOOP, "gyro_noise": 0.0, "loop_delay": 0.03})
    rec = run_tunnel(spec)
    cmd, gyro = rec.fin_cmd_deg, rec.roll_rate_dps
    assert cmd is not None and gyro is not None
    assert rec.metadata["loop.delay_s"] == "0.03"
    excitation = _excitation(spec, rec.time_s)

    def law(read: np.ndarray) -> np.ndarray:
        return np.clip(excitation[2:] + spec.loop_gain * (0.0 - read), -15.0, 15.0)

    between = 0.5 * (gyro[:-2] + gyro[1:-1])  # the rate 30 ms before each command
    error = np.abs(cmd[2:] - law(between))
    whole_sample = np.abs(cmd[2:] - law(gyro[1:-1]))  # the rate 20 ms before
    assert np.max(error) < 0.1
    assert np.max(whole_sample) > 10 * np.max(error)


def test_a_rocket_with_negative_gain_is_damped_by_a_negative_loop_gain() -> None:
    rocket = {"alpha": -0.659, "beta": -2.8856}
    base = {**LOOP, **rocket, "turbulence_sd": 9.8}
    damped = run_tunnel(TunnelSpec(**{**base, "loop_gain": -1.0}))
    open_loop = run_tunnel(TunnelSpec(**{**base, "loop_gain": 0.0}))
    cmd, gyro = damped.fin_cmd_deg, damped.roll_rate_dps
    assert cmd is not None and gyro is not None and open_loop.roll_rate_dps is not None
    law = np.clip(_excitation(TunnelSpec(**base), damped.time_s)[2:] + gyro[:-2], -15.0, 15.0)
    np.testing.assert_array_equal(cmd[2:], law)
    assert np.std(gyro) < 0.8 * np.std(open_loop.roll_rate_dps)


def test_fin_never_passes_the_stops() -> None:
    rec = run_tunnel(TunnelSpec(**{**LOOP, "loop_gain": 3.0, "loop_delay": 0.2}))
    assert rec.fin_deg is not None and rec.fin_cmd_deg is not None
    assert np.max(np.abs(rec.fin_cmd_deg)) == 15.0
    assert np.max(np.abs(rec.fin_deg)) <= 15.0
    assert np.mean(np.abs(rec.fin_cmd_deg) == 15.0) > 0.3


def test_schedule_none_needs_the_loop() -> None:
    with pytest.raises(SettingError, match="loop-gain"):
        TunnelSpec(schedule="none")
    spec = TunnelSpec(schedule="none", loop_gain=0.5, duration=20.0, log_dt=0.02, gyro_noise=1.0)
    rec = run_tunnel(spec)
    assert rec.fin_cmd_deg is not None and rec.roll_rate_dps is not None
    assert rec.n_samples == 1001
    law = np.clip(0.0 + 0.5 * (0.0 - rec.roll_rate_dps[:-1]), -40.0, 40.0)  # 20 ms: 1 sample
    np.testing.assert_array_equal(rec.fin_cmd_deg[1:], law)


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
        TunnelSpec(**{**LOOP, field: value})


def test_metadata_states_the_loop_and_survives_the_file(tmp_path) -> None:
    spec = TunnelSpec(**LOOP)
    out = tmp_path / "loop.csv"
    assert main(["tunnel", *spec.to_args(), "--out", str(out)]) == 0
    rec = load_recording(out)
    meta = rec.metadata
    assert meta["loop.gain"] == "1.5"
    assert meta["loop.delay_s"] == "0.04"
    assert meta["loop.stops_deg"] == "15.0"
    assert meta["loop.rate_sensor"] == "roll_rate_dps"
    assert meta["truth.fin_range_deg"] == "15.0"
    assert rec.fin_range().deg == 15.0
    assert spec_from_command(meta["command"]) == spec
    direct = run_tunnel(spec)
    assert dict(direct.metadata) == dict(meta)
    for column, values in direct.columns().items():
        np.testing.assert_allclose(rec.columns()[column], values, atol=1e-6, rtol=0)


def test_same_seed_same_run_and_the_same_turbulence_as_in_open_loop() -> None:
    spec = TunnelSpec(**LOOP)
    first, again = run_tunnel(spec), run_tunnel(spec)
    assert recording_text(first) == recording_text(again)
    other = run_tunnel(TunnelSpec(**{**LOOP, "seed": 4}))
    assert other.fin_cmd_deg is not None and first.fin_cmd_deg is not None
    assert not np.array_equal(first.fin_cmd_deg, other.fin_cmd_deg)
    open_loop = run_tunnel(TunnelSpec(**{**LOOP, "loop_gain": 0.0}))
    assert open_loop.ud_true_deg is not None and first.ud_true_deg is not None
    np.testing.assert_array_equal(first.ud_true_deg, open_loop.ud_true_deg)
