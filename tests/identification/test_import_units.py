"""Angles in the wrong unit at import, on truths the tests make.

The virtual tunnel's run is the truth; the user's log is its columns converted by hand
(numpy on the arrays, not the importer's code path) into radians where a rig logs them so.
A fin in radians read as degrees (±40° reads ±0.7) fits a gain 57 times too large that
every adequacy figure calls good; a roll rate in another unit than the angle beside it is
refused at import.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from identification.instruments.bundled import bundled_path
from identification.instruments.flightlog import FlightLogSpec, run_flight
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods.adequacy import Adequacy, adequacy
from identification.methods.ml import MLFit, maximum_likelihood
from identification.methods.pipeline import model_inputs
from identification.recordings.importer import angle_on_integrated_rate, import_csv
from identification.recordings.recording import (
    Recording,
    RecordingError,
    load_recording,
    small_fins,
)
from rocketroll.cli import main
from tests.identification.test_adequacy import PRBS

RAD = 180.0 / math.pi
FIN_WARNING = "fin (column 1): 99 % of its |values| are under"


@pytest.fixture(scope="module")
def truth() -> Recording:
    """A 100-Hz tunnel run with a measured fin, an encoder and a gyro."""
    return run_tunnel(TunnelSpec(seed=11, gyro_noise=1.0, measured_fin=True, **PRBS))


def _log(path: Path, rec: Recording, fin: float, roll: float, rate: float) -> Path:
    """``rec``'s fin, roll angle and rate as a headerless log, each column multiplied by its
    factor (1 for degrees, 1/57.3 for radians)."""
    assert rec.fin_deg is not None and rec.roll_deg is not None
    assert rec.roll_rate_dps is not None
    columns = [rec.fin_deg * fin, rec.roll_deg * roll, rec.roll_rate_dps * rate]
    np.savetxt(path, np.column_stack(columns), fmt="%.9g")
    return path


def _import(
    capsys: pytest.CaptureFixture[str], src: Path, out: Path, *units: str
) -> tuple[int, str]:
    argv = ["import-csv", str(src), "--out", str(out), "--columns", "fin,roll,roll_rate"]
    argv += ["--no-header", "--rate", "100", *(w for u in units for w in ("--unit", u))]
    code = main(argv)
    return code, capsys.readouterr().err


def _fitted(rec: Recording) -> tuple[MLFit, Adequacy]:
    """The maximum-likelihood fit (theta model) to ``rec`` and its adequacy."""
    found = maximum_likelihood(rec, "theta")
    metrics = {"std_errors": found.std_errors}
    inputs = model_inputs(rec, "theta", None)
    return found, adequacy(inputs, found.params, found.disturbance(), metrics)


def _verdict(rec: Recording) -> Adequacy:
    """The adequacy of the maximum-likelihood fit (theta model) to ``rec``."""
    return _fitted(rec)[1]


@pytest.fixture(scope="module")
def truth_verdict(truth: Recording) -> Adequacy:
    """:func:`_verdict` of the tunnel run itself, which both tests set beside a log's."""
    return _verdict(truth)


def test_a_fin_in_radians_beside_a_roll_in_degrees(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], truth: Recording, truth_verdict: Adequacy
) -> None:
    """The rig logs the fin and the gyro in radians, the encoder in degrees."""
    src = _log(tmp_path / "rig.txt", truth, 1.0 / RAD, 1.0, 1.0 / RAD)
    out = tmp_path / "rig.csv"
    code, err = _import(capsys, src, out)  # all read as degrees
    assert code == 2 and err.count("\n") == 1 and not out.exists()
    assert f"{src}: the roll angle changes 57.3 times as fast" in err
    assert "give --unit roll_rate=rad" in err

    code, err = _import(capsys, src, out, "roll_rate=rad")  # the gyro right, the fin not
    assert code == 0 and err.count("\n") == 1
    assert err.startswith(f"warning: {src}: {FIN_WARNING} 0.7°") and "--unit fin=rad" in err
    found, judged = _fitted(load_recording(out))
    assert judged.verdict == "unreliable"
    assert any("(fin_deg) stays within 0.7°" in r and "--unit fin=rad" in r for r in judged.reasons)
    assert found.params.alpha > 20 * truth_alpha(truth)

    code, err = _import(capsys, src, out, "roll_rate=rad", "fin=rad")  # all right: silent
    assert (code, err) == (0, "")
    right = _verdict(load_recording(out))
    assert right.verdict == truth_verdict.verdict == "good"


def test_everything_in_radians_read_as_degrees(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], truth: Recording, truth_verdict: Adequacy
) -> None:
    """Every angle in radians: they agree with each other (nothing to refuse), the gain comes
    out right, u_d 57 times too small: only the fin's range tells."""
    src = _log(tmp_path / "rad.txt", truth, 1.0 / RAD, 1.0 / RAD, 1.0 / RAD)
    out = tmp_path / "rad.csv"
    code, err = _import(capsys, src, out)
    assert code == 0 and err.count("\n") == 1 and FIN_WARNING in err
    judged = _verdict(load_recording(out))
    assert judged.verdict == "unreliable"
    assert any("stays within 0.7°" in r for r in judged.reasons)
    assert judged.ud_p99_deg < 0.05 * truth_verdict.ud_p99_deg

    code, err = _import(capsys, src, tmp_path / "half.csv", "roll=rad")  # the rate forgotten
    assert code == 2 and err.count("\n") == 1 and not (tmp_path / "half.csv").exists()
    assert "give --unit roll_rate=rad" in err

    code, err = _import(capsys, src, out, "fin=rad", "roll=rad", "roll_rate=rad")
    assert (code, err) == (0, "")


def truth_alpha(rec: Recording) -> float:
    return float(rec.metadata["truth.alpha"])


def _wrap(angle: np.ndarray, period: float) -> np.ndarray:
    return (angle + period / 2) % period - period / 2


@pytest.mark.parametrize(
    ("case", "expected"),
    [
        ("agree", 1.0),
        ("rate in rad/s", RAD),
        ("angle in rad", 1.0 / RAD),
        ("wrapped at ±180°, rate in rad/s", RAD),
        ("wrapped at ±π, rate in °/s", 1.0 / RAD),
        ("gyro bias 2 °/s, in rad/s", RAD),
        ("gyro bias 2 °/s", 1.0),
    ],
)
def test_the_angle_against_the_integrated_rate_survives_wrapping_drift_and_10_hz(
    case: str, expected: float
) -> None:
    rec = run_tunnel(TunnelSpec(seed=2, gyro_noise=2.0, schedule="staircase"))  # 10 Hz
    assert rec.roll_deg is not None and rec.roll_rate_dps is not None
    t, angle, rate = rec.time_s, rec.roll_deg, rec.roll_rate_dps
    assert np.ptp(angle) > 720.0  # it does wrap
    logged = {
        "agree": (angle, rate),
        "rate in rad/s": (angle, rate / RAD),
        "angle in rad": (angle / RAD, rate),
        "wrapped at ±180°, rate in rad/s": (_wrap(angle, 360.0), rate / RAD),
        "wrapped at ±π, rate in °/s": (_wrap(angle / RAD, 2 * math.pi), rate),
        "gyro bias 2 °/s, in rad/s": (angle, (rate + 2.0) / RAD),
        "gyro bias 2 °/s": (angle, rate + 2.0),
    }[case]
    slope, r2 = angle_on_integrated_rate(t, *logged)
    assert slope == pytest.approx(expected, rel=0.03) and r2 > 0.99


def test_an_angle_that_hardly_moves_is_not_judged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A rocket held still: the encoder flickers one count, the gyro reads its noise in
    rad/s.  Nothing to tell the unit from: imported as it is."""
    rng = np.random.default_rng(0)
    n = 1000
    count = 360.0 / 1024
    angle = np.where(rng.random(n) < 0.3, count, 0.0)
    rate = 0.01 * rng.standard_normal(n)
    fin = np.where(np.arange(n) > 100, 10.0, 0.0)
    _, r2 = angle_on_integrated_rate(np.arange(n, dtype=np.float64) * 0.01, angle, rate)
    assert r2 < 0.5
    src, out = tmp_path / "still.txt", tmp_path / "still.csv"
    np.savetxt(src, np.column_stack([fin, angle, rate]), fmt="%.9g")
    assert _import(capsys, src, out) == (0, "")


def _export(path: Path, rec: Recording) -> list[str]:
    """``rec``'s columns but time and the truth, as a headerless log; their roles."""
    roles = {
        "fin_cmd_deg": "fin_cmd",
        "fin_deg": "fin",
        "roll_deg": "roll",
        "roll_rate_dps": "roll_rate",
        "airspeed_mps": "airspeed",
        "altitude_m": "altitude",
    }
    kept = [name for name in rec.columns() if name in roles]
    np.savetxt(path, np.column_stack([rec.columns()[c] for c in kept]), fmt="%.9g")
    return [roles[c] for c in kept]


@pytest.mark.parametrize(
    "name",
    [
        "tunnel-paper-seed0",
        "tunnel-paper-seed4",  # a measured fin, an encoder and a gyro
        "tunnel-staircase-seed10",
        "a virtual flight",
        "a virtual flight with an encoder",
    ],
)
def test_correct_logs_import_silently(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    if name.startswith("a virtual flight"):
        counts = 1024 if "encoder" in name else 0
        rec = run_flight(FlightLogSpec(encoder_counts=counts, measured_fin=True))
    else:
        rec = load_recording(bundled_path(name))
    assert small_fins(rec.columns()) == {}  # the adequacy finds no implausible fin either
    src, out = tmp_path / "log.txt", tmp_path / "log.csv"
    roles = _export(src, rec)
    argv = ["import-csv", str(src), "--out", str(out), "--columns", ",".join(roles)]
    argv += ["--no-header", "--rate", f"{1.0 / rec.dt_s:.9g}"]
    if rec.is_flight:
        argv += ["--source", "flight"]
    assert main(argv) == 0
    assert capsys.readouterr().err == ""
    assert load_recording(out).n_samples == rec.n_samples


def test_a_wrapping_angle_beside_a_rate_in_rad_per_s_is_refused_at_import(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An encoder that wraps at ±180° (no --unwrap) at 10 Hz, a gyro in rad/s with a bias:
    the angle's rate of change jumps at each wrap, its integral does not."""
    rec = run_tunnel(TunnelSpec(seed=2, gyro_noise=2.0, schedule="staircase", measured_fin=True))
    assert rec.fin_deg is not None and rec.roll_deg is not None
    assert rec.roll_rate_dps is not None
    columns = [rec.fin_deg, _wrap(rec.roll_deg, 360.0), (rec.roll_rate_dps + 1.0) / RAD]
    src, out = tmp_path / "wrapped.txt", tmp_path / "wrapped.csv"
    np.savetxt(src, np.column_stack(columns), fmt="%.9g")
    argv = ["import-csv", str(src), "--out", str(out), "--columns", "fin,roll,roll_rate"]
    argv += ["--no-header", "--rate", "10"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give --unit roll_rate=rad" in err and not out.exists()
    assert main([*argv, "--unit", "roll_rate=rad"]) == 0
    assert capsys.readouterr().err == ""


def test_a_value_that_overflows_in_its_unit_is_refused_naming_its_line(tmp_path: Path) -> None:
    """1e308 in a column read in radians is beyond any float in degrees: one error naming
    the line and the column, no numpy warning (hypothesis found it)."""
    import warnings

    path = tmp_path / "log.csv"
    rows = [f"{0.01 * k:.2f},{0.5 if k > 50 else 0.0},{k * 0.001}" for k in range(120)]
    rows[7] = "0.07,0.0,1e308"
    path.write_text("\n".join(["t,fin,rate", *rows]) + "\n", encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(RecordingError, match=r"log.csv:9: roll_rate_dps is inf \(not finite\)"):
            import_csv(path, ["time", "fin", "roll_rate"], units="rad")
