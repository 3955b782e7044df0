"""``rocketroll identify``: the table, ``--json``, ``--report`` and every user error.

User errors exit with code 2, print one line on stderr that names the argument
or file and the problem, and write nothing.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from identification.instruments.bundled import bundled_path
from identification.recordings.recording import Recording, save_recording
from rocketroll.cli import main

PAPER = bundled_path("tunnel-paper-seed0")


def test_table_json_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_json = tmp_path / "result.json"
    report = tmp_path / "report"
    code = main(
        [
            "identify",
            str(PAPER),
            "--json",
            str(out_json),
            "--report",
            str(report),
            "--mc-runs",
            "3",
            "--mc-levels",
            "1,10",
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    # The parameter table with the truth and the paper beside the estimate.
    header = next(line for line in out.splitlines() if line.startswith("parameter"))
    assert header.split() == ["parameter", "identified", "truth", "paper"]
    alpha_row = next(line for line in out.splitlines() if line.startswith("α"))
    assert alpha_row.split()[-2:] == ["0.659", "0.659"]
    assert "synthetic" in out and "noise study" in out
    data = json.loads(out_json.read_text())
    params = data["parameters"]
    assert params["alpha"] == pytest.approx(0.659, rel=0.03)
    assert data["truth"]["alpha"] == pytest.approx(0.659)
    assert len(data["steps"]) == 8
    assert data["noise_study"]["levels_pct"] == [1.0, 10.0]
    assert data["noise_study"]["runs"] == 3
    assert set(data["resimulation"]) == {"constant", "theta"}
    assert all(math.isfinite(v) for v in params.values())
    text = (report / "report.md").read_text()
    # the paper's 13 figures, and a figure judging each method's fit
    pngs = {p.name for p in report.glob("*.png")}
    assert len(pngs) == 15 and {"fit-paper.png", "fit-output-error.png"} <= pngs
    assert "## Fit adequacy of each method" in text and "](fit-output-error.png)" in text
    assert text.count("**paper ") == 2 and "**output-error theta**: good" in text


def test_report_for_any_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = tmp_path / "report"
    argv = ["identify", str(PAPER), "--method", "output-error", "--report", str(report)]
    assert main([*argv, "--mc-runs", "0"]) == 0
    assert "wrote" in capsys.readouterr().out
    listed = sorted(p.name for p in report.iterdir())
    assert listed == [".rocketroll-outputs.json", "fit-output-error.png", "report.md"]
    text = (report / "report.md").read_text()
    assert text.startswith("# Identification report: ") and "fig05" not in text
    assert "**output-error constant**: good" in text
    png = (report / "fit-output-error.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 20_000


def test_real_recording_has_no_truth_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from identification.instruments.bundled import load_bundled

    rec = load_bundled("tunnel-paper-seed1")
    real = Recording(
        name="tunnel-run",
        source="wind-tunnel",
        time_s=rec.time_s,
        fin_cmd_deg=rec.fin_cmd_deg,
        roll_deg=rec.roll_deg,
    )
    path = tmp_path / "real.csv"
    save_recording(real, path)
    assert main(["identify", str(path), "--mc-runs", "0"]) == 0
    out = capsys.readouterr().out
    header = next(line for line in out.splitlines() if line.startswith("parameter"))
    assert header.split() == ["parameter", "identified", "paper"]
    assert "synthetic" not in out and "noise study" not in out


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--smoothing-passes", "-1"], "--smoothing-passes: must be in [0, 1000], got -1"),
        (["--smoothing-passes", "two"], "--smoothing-passes: must be an integer, not 'two'"),
        (["--ud-interval", "0"], "--ud-interval: must be in (0, 600] s, got 0.0"),
        (["--ud-interval", "nan"], "--ud-interval: must be finite, got nan"),
        (["--ud-interval", "0.013"], "not a multiple of the 0.01 s fine grid"),
        (["--servo-rate", "-5"], "--servo-rate: must be in (0, 10000] °/s, got -5.0"),
        (["--max-breakpoint", "inf"], "--max-breakpoint: must be finite, got inf"),
        (["--outlier-level", "1.5"], "--outlier-level: must be in (0, 1), got 1.5"),
        (["--mc-runs", "-3"], "--mc-runs: must be in [0, 1000000], got -3"),
        (["--mc-levels", "1,x"], "--mc-levels: must be comma-separated numbers"),
        (["--mc-levels", "1,-2"], "--mc-levels: must be in [0, 100] %, got -2.0"),
        (["--min-step", "500"], "--min-step: must be in (0, 90] °, got 500.0"),
        (["--max-breakpoint", "0.001"], "--max-breakpoint: must be at least the breakpoint"),
    ],
)
def test_bad_options_exit_2_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], expected: str
) -> None:
    out_json = tmp_path / "r.json"
    report = tmp_path / "rep"
    argv = ["identify", str(PAPER), "--json", str(out_json), "--report", str(report), *args]
    try:
        code = main([*argv, "--mc-runs", "0"] if "--mc-runs" not in args else argv)
    except SystemExit as exc:  # argparse type errors
        code = int(exc.code or 0)
    assert code == 2
    err = capsys.readouterr().err.strip()
    # One error line (argparse's own type errors come after its usage text).
    assert expected in err.splitlines()[-1]
    assert not out_json.exists() and not report.exists()


def test_missing_and_invalid_recordings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.csv"
    assert main(["identify", str(missing)]) == 2
    err = capsys.readouterr().err
    assert "nope.csv" in err and err.count("\n") == 1
    bad = tmp_path / "bad.csv"
    bad.write_text("# name: x\n# source: wind-tunnel\ntime_s,fin_cmd_deg,roll_deg\n0,0,zero\n")
    assert main(["identify", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv:4:" in err


def test_report_path_that_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("keep me")
    out_json = tmp_path / "r.json"
    code = main(
        [
            "identify",
            str(PAPER),
            "--mc-runs",
            "0",
            "--report",
            str(blocker),
            "--json",
            str(out_json),
        ]
    )
    assert code == 2
    assert "--report" in capsys.readouterr().err
    assert blocker.read_text() == "keep me"
    assert not out_json.exists()


def test_a_database_path_that_is_a_folder_is_refused_first(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_work(*args: object, **kwargs: object) -> None:
        raise AssertionError("identified before checking --db")

    monkeypatch.setattr("identification.methods.fit", no_work)
    out_json = tmp_path / "r.json"
    argv = ["identify", str(PAPER), "--db", str(tmp_path), "--json", str(out_json)]
    assert main(argv) == 2
    assert f"--db {tmp_path}: is a folder" in capsys.readouterr().err
    assert not out_json.exists()


def test_single_step_recording_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import numpy as np

    t = np.asarray(0.1 * np.arange(600), dtype=np.float64)
    fin = np.where(t < 20, 0.0, 10.0)
    rate = 0.659 * (fin + 4.38)
    rec = Recording(
        name="one-step",
        source="wind-tunnel",
        time_s=t,
        fin_cmd_deg=fin,
        roll_deg=np.cumsum(rate) * 0.1,
    )
    path = tmp_path / "one.csv"
    save_recording(rec, path)
    # The step methods refuse it in one line (output error once met a NaN start point): the
    # paper's for want of steps, output error for a rate that follows the fin with no lag.
    for method, why in (("paper", "at least two"), ("output-error", "no lag of the roll rate")):
        assert main(["identify", str(path), "--mc-runs", "0", "--method", method]) == 2
        err = capsys.readouterr().err
        assert "one-step" in err and why in err and err.count("\n") == 1
    db = tmp_path / "x.sqlite"
    assert main(["db", "add", str(path), "--db", str(db), "--method", "output-error"]) == 2
    assert "no lag of the roll rate" in capsys.readouterr().err and not db.exists()


def test_a_method_that_cannot_fit_a_recording_says_so_and_the_others_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Doublets have no held fin steps: the paper's method refuses them in one line, ml
    (which reads no steps) fits them; when every method asked refuses, the first one's line
    is the error."""
    rec = tmp_path / "doublets.csv"
    tunnel = ["tunnel", "--schedule", "doublets", "--steps", "8", "--dwell-min", "2"]
    argv = [*tunnel, "--dwell-max", "4", "--lead", "2", "--log-dt", "0.01", "--gyro-noise", "2"]
    assert main([*argv, "--seed", "3", "--out", str(rec)]) == 0
    capsys.readouterr()
    out_json, db = tmp_path / "fit.json", tmp_path / "db.sqlite"
    argv = ["identify", str(rec), "--method", "paper", "--method", "ml", "--mc-runs", "0"]
    assert main([*argv, "--json", str(out_json), "--db", str(db)]) == 0
    out, err = capsys.readouterr()
    assert err.strip().splitlines() == [
        "rocketroll identify: method paper cannot fit it: tunnel-doublets-seed3: the fin angle "
        "(fin_cmd_deg) never steps by 1° or more; the identification needs fin steps (paper §2.3)"
    ]
    assert "ml            theta" in out and "stored in" in out
    assert list(json.loads(out_json.read_text(encoding="utf-8"))["methods"]) == ["ml"]
    # Every method asked refuses: one line, exit 2, and the method that would not.
    assert main(["identify", str(rec), "--method", "paper", "--mc-runs", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.endswith("--method ml reads no fin steps"), err
