"""The fidelity benchmarks run end to end (tiny settings; the figures are the scripts' job)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run_script(name: str, *args: str, db: Path) -> str:
    done = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / name), *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO), "ROCKETROLL_DB": str(db)},
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_ground_truth_reports_every_method_and_the_targets(default_db: Path) -> None:
    out = run_script("ground_truth.py", "--seeds", "1", "--truth", "negative", db=default_db)
    for method in ("paper:", "output-error:", "ml:"):
        assert method in out
    assert "u_d MAE / true-parameter bound" in out
    assert "Targets (issue 14), ml:" in out
    assert out.count("PASS") + out.count("FAIL") == 7


def test_closed_loop_scores_each_replay_against_the_truth(default_db: Path, tmp_path: Path) -> None:
    settings = ["--seeds", "2", "--truth", "rising", "--policies", "trim,pid"]
    settings += ["--tasks", "angle-zero", "--windows", "1", "--draws", "1"]
    serial, parallel = tmp_path / "serial.csv", tmp_path / "parallel.csv"
    out = run_script("closed_loop.py", *settings, "--csv", str(serial), db=default_db)
    for replay in ("paper", "output-error", "ml", "ml posterior"):
        assert f"  {replay}: " in out
    assert "angle-zero" in out and "settled_rms_error" in out and "regulation_rms_error" in out
    # Recordings scored in worker processes give the same rows, in the same order.
    run_script("closed_loop.py", *settings, "--jobs", "2", "--csv", str(parallel), db=default_db)
    rows = serial.read_text().splitlines()
    assert len(rows) == 1 + 2 * 4 * 2 * 3  # header; seeds x replays x controllers x metrics
    assert parallel.read_text().splitlines() == rows


def test_ml_bias_fits_each_seed_three_ways(default_db: Path) -> None:
    out = run_script("ml_bias.py", "--seeds", "2", "--truth", "negative", db=default_db)
    for line in ("quantised ", "white ", "exact ", "quantised - white", "white - exact"):
        assert f"  {line}" in out
    # The two seeds' offsets are numbers with a spread, not NaN.
    assert "nan" not in out.lower()


def test_mpc_speed_times_both_controllers_on_both_tasks(default_db: Path) -> None:
    out = run_script("mpc_speed.py", "--episodes", "1", "--horizon", "5", db=default_db)
    for env_id in ("RocketRoll-v0", "RocketRollRate-v0"):
        assert f"{env_id:<20} observer" in out and f"{env_id:<20} mpc:5" in out
    assert out.count("vs target 10 ms:") == 2
