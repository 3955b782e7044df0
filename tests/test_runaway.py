"""No input makes a command run away: what would size memory or work beyond reason is
refused in one line before any work, naming the file or option and what looks wrong."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identification.instruments.bundled import load_bundled
from identification.recordings.recording import load_recording
from rocketroll.cli import main as rocketroll
from tests.cli import refused


@pytest.fixture
def log_in_ms(tmp_path: Path) -> Path:
    """The bundled 10-Hz tunnel run as a logger writes it: time in milliseconds."""
    rec = load_bundled("tunnel-paper-seed0")
    assert rec.fin_cmd_deg is not None and rec.roll_deg is not None
    rows = np.column_stack([rec.time_s * 1e3, rec.fin_cmd_deg, rec.roll_deg])
    path = tmp_path / "log.csv"
    np.savetxt(path, rows, delimiter=",", header="t_ms,fin,roll", comments="")
    return path


def test_a_time_column_in_milliseconds_read_as_seconds_is_refused(
    log_in_ms: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was accepted as 5731 samples every 100 s, and identifying it grew to 10 GB."""
    out = tmp_path / "rec.csv"
    argv = ["import-csv", str(log_in_ms), "--out", str(out), "--columns", "time,fin_cmd,roll"]
    refused(
        capsys,
        argv,
        "the time column ('t_ms', read in s) steps every 100 s (median), outside 1 ms to 1 s",
        "is the time in milliseconds? (rocketroll import-csv --time-unit ms)",
    )
    assert not out.exists()
    assert rocketroll([*argv, "--time-unit", "ms"]) == 0
    capsys.readouterr()


def _recording_file(path: Path, time_s: np.ndarray, fin_cmd_deg: np.ndarray) -> Path:
    """A recording file as a program other than this one may write it (no checks)."""
    lines = ["# format: rocketroll-recording/1", "# name: log", "# source: wind-tunnel"]
    lines.append("time_s,fin_cmd_deg,roll_deg")
    lines += [
        f"{t!r},{f!r},0.0" for t, f in zip(time_s.tolist(), fin_cmd_deg.tolist(), strict=True)
    ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_a_recording_whose_times_are_off_is_refused_by_every_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = load_bundled("tunnel-paper-seed0")
    assert rec.fin_cmd_deg is not None
    slow = _recording_file(tmp_path / "slow.csv", rec.time_s * 1e3, rec.fin_cmd_deg)
    for argv in (["info", str(slow)], ["identify", str(slow)], ["db", "add", str(slow)]):
        refused(capsys, argv, "time_s steps every 100 s (median)", "milliseconds")

    def log(n: int, dt: float) -> Path:
        k = np.arange(n)
        fin = np.where(k < n // 2, 0.0, 10.0)
        return _recording_file(tmp_path / f"log-{n}.csv", k * dt, fin)

    refused(capsys, ["info", str(log(390, 0.01))], "time_s spans 3.89 s, outside 4.9 s to 24 h")
    refused(
        capsys,
        ["info", str(log(90_000, 1.0))],
        "time_s spans 25 h, outside 4.9 s to 24 h",
        "is the time in milliseconds?",
    )


def test_an_mpc_horizon_beyond_reason_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    """mpc:100000 allocated 522 GiB; mpc:600 took over 30 s an episode."""
    for horizon in ("100000", "600", "101"):
        refused(
            capsys,
            ["eval", "--policy", f"mpc:{horizon}", "--episodes", "1"],
            f"mpc:HORIZON must be 1 to 100 steps (10 s ahead), got {horizon}",
        )


def test_training_that_would_run_away_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--envs 100000 --timesteps 100 ran a 25.6 M-step rollout and wrote 126 checkpoints."""
    out = tmp_path / "run"
    base = ["train", "ppo", "--out", str(out)]
    refused(
        capsys, [*base, "--envs", "100000", "--timesteps", "100"], "--envs: must be in [1, 4096]"
    )
    refused(
        capsys,
        [*base, "--envs", "4096", "--timesteps", "100"],
        "--timesteps 100 is less than one rollout: --envs 4096 x n_steps 256",
        "1,048,576 env-steps",
    )
    refused(
        capsys,
        [*base, "--timesteps", "10000000", "--checkpoint-freq", "1000"],
        "writes 10,002 checkpoints, more than 200",
        "--checkpoint-freq 50,013",
    )
    assert not out.exists()


def test_an_environment_option_beyond_reason_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    """`eval --set gyro_noise_pct=1e9` was accepted."""
    base = ["eval", "--policy", "pid", "--episodes", "1"]
    refused(
        capsys,
        [*base, "--set", "gyro_noise_pct=1e9"],
        "gyro_noise_pct: must be in [0, 100]",
    )
    refused(
        capsys,
        [*base, "--set", "disturbance_scale=50"],
        "disturbance_scale: must be in [0, 10]",
    )
    refused(capsys, [*base, "--set", "episode_s=1e7"], "episode_s must be at most 86400 s")


def test_a_file_that_is_not_utf8_is_refused_at_its_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A Latin-1 CSV's error gave a byte offset, not a line."""
    latin = tmp_path / "latin.csv"
    latin.write_bytes(b"t,fin,roll\n0,0,0\n0.1,0,caf\xe9\n")
    refused(capsys, ["info", str(latin)], "latin.csv:3: byte 0xe9 is not UTF-8")
    out = tmp_path / "rec.csv"
    argv = ["import-csv", str(latin), "--out", str(out), "--columns", "time,fin,roll"]
    refused(capsys, argv, "latin.csv:3: byte 0xe9 is not UTF-8", "save the file as UTF-8")


def test_a_log_at_one_kilohertz_is_read(tmp_path: Path) -> None:
    """1 kHz times written in decimal seconds step 0.000999... s on the median: the
    interval's lower bound (1 ms) must not refuse them."""
    t = np.round(np.arange(6000) * 0.001, 6)
    fin = np.where(t % 2.0 < 1.0, 5.0, -5.0)
    path = _recording_file(tmp_path / "khz.csv", t, fin)
    assert load_recording(path).n_samples == 6000
