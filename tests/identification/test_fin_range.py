"""The fins' range the adequacy measures ``u_d`` against: stated (``--fin-range``, the
recording's ``rig.fin_range_deg``), else the log's largest ``|fin|``, and named as such; a
synthetic recording's own servo where the virtual instrument wrote it."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from identification.instruments.bundled import load_bundled
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods.adequacy import Adequacy, adequacy
from identification.methods.pipeline import IdentifyOptions, model_inputs, recover_disturbance
from identification.recordings.recording import (
    FIN_RANGE_KEY,
    FORMAT_V1_2,
    FinRange,
    Recording,
    RecordingError,
    load_recording,
    recording_text,
    save_recording,
)
from rocketroll.cli import main


@pytest.fixture(scope="module")
def real() -> Recording:
    """A wind-tunnel log as a user imports it: no truth lines, fins within about ±8°, the
    measured fin reaching 90 % of the command."""
    rec = run_tunnel(
        TunnelSpec(seed=3, schedule="staircase", steps=8, fin_range=10.0, dwell_min=5.0,
                   dwell_max=8.0, measured_fin=True)
    )  # fmt: skip
    assert rec.fin_cmd_deg is not None
    return Recording(
        name="canards",
        source="wind-tunnel",
        time_s=rec.time_s,
        fin_cmd_deg=rec.fin_cmd_deg,
        fin_deg=0.9 * np.asarray(rec.fin_cmd_deg),
        roll_deg=rec.roll_deg,
    )


def _judged(rec: Recording) -> Adequacy:
    """The adequacy of the paper's rocket (the tunnel's truth) on ``rec``."""
    params = load_bundled("tunnel-paper-seed0").truth()
    assert params is not None
    inputs = model_inputs(rec, "theta", None)
    dist, _ = recover_disturbance(inputs, params, "theta", IdentifyOptions())
    return adequacy(inputs, params, dist, {})


def _range_reason(judged: Adequacy) -> str:
    (reason,) = [r for r in judged.reasons if r.startswith("u_d reaches")]
    return reason


def test_a_stated_fin_range_is_used_and_labelled(real: Recording) -> None:
    stated = real.stating_fin_range(5.0)
    assert stated.fin_range() == FinRange(5.0, FinRange.STATED)
    assert real.fin_range(5.0) == FinRange(5.0, FinRange.STATED)  # the flag
    assert stated.fin_range(6.0).deg == 6.0  # the flag over the recording's line
    judged = _judged(stated)
    assert judged.ud_range_fraction == pytest.approx(judged.ud_p99_deg / 5.0)
    reason = _range_reason(judged)
    assert "of the fins' ±5° (stated)" in reason and "--fin-range" not in reason
    assert judged.verdict == "unreliable"


def test_an_unstated_fin_range_is_the_logs_largest_fin_and_labelled(real: Recording) -> None:
    assert real.fin_deg is not None and real.fin_cmd_deg is not None
    largest = float(np.max(np.abs(real.fin_deg)))  # the measured fin, not the command
    assert largest < float(np.max(np.abs(real.fin_cmd_deg))) < 40.0
    fins = real.fin_range()
    assert fins == FinRange(largest, FinRange.LARGEST)
    assert str(fins) == f"±{largest:g}° (the log's largest |fin|)"
    judged = _judged(real)
    assert judged.ud_range_fraction == pytest.approx(judged.ud_p99_deg / largest)
    reason = _range_reason(judged)
    assert f"of the fins' ±{largest:g}° (the log's largest |fin|)" in reason
    assert "--fin-range" in reason  # how to state it
    # Without a measured fin, the command's largest.
    command_only = replace(real, fin_deg=None)
    assert command_only.fin_range() == FinRange(
        float(np.max(np.abs(real.fin_cmd_deg))), FinRange.LARGEST
    )
    assert fins.as_dict() == {"fin_range_deg": largest, "fin_range_source": FinRange.LARGEST}


def test_a_virtual_instruments_recording_states_its_own_servo() -> None:
    tunnel = load_bundled("tunnel-paper-seed0")
    assert tunnel.metadata["truth.fin_range_deg"] == "40.0"
    assert tunnel.fin_range() == FinRange(40.0, FinRange.TRUTH)
    assert tunnel.stating_fin_range(15.0).fin_range() == FinRange(15.0, FinRange.STATED)
    # Truth lines count only in a synthetic recording.
    claimed = replace(tunnel, source="wind-tunnel", ud_true_deg=None)
    assert claimed.fin_range().source == FinRange.LARGEST


def test_import_csv_fin_range_writes_the_rig_line_and_reads_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, out = tmp_path / "log.csv", tmp_path / "rec.csv"
    log.write_text("".join(f"{k % 30 - 15},{k * 0.5}\n" for k in range(100)), encoding="utf-8")
    argv = ["import-csv", str(log), "--out", str(out), "--columns", "fin,roll", "--no-header"]
    assert main([*argv, "--rate", "10", "--fin-range", "15"]) == 0
    capsys.readouterr()
    text = out.read_text(encoding="utf-8")
    assert f"# {FIN_RANGE_KEY}: 15.0\n" in text and f"# format: {FORMAT_V1_2}\n" in text
    rec = load_recording(out)
    assert rec.metadata[FIN_RANGE_KEY] == "15.0"
    assert rec.fin_range() == FinRange(15.0, FinRange.STATED)
    assert rec.rig.ideal  # not a Rig field: the environments' rig is unchanged
    save_recording(rec, tmp_path / "again.csv")  # the line survives a round trip
    assert load_recording(tmp_path / "again.csv").fin_range() == FinRange(15.0, FinRange.STATED)
    # Without the flag: no line, and the log's largest |fin| (15°), named.
    plain = tmp_path / "plain.csv"
    assert main([*argv[:3], str(plain), *argv[4:], "--rate", "10"]) == 0
    capsys.readouterr()
    assert FIN_RANGE_KEY not in plain.read_text(encoding="utf-8")
    assert load_recording(plain).fin_range() == FinRange(15.0, FinRange.LARGEST)


@pytest.mark.parametrize("value", ["0", "-3", "90.5", "nan"])
def test_a_bad_fin_range_is_refused_in_one_line(
    value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, out = tmp_path / "log.csv", tmp_path / "rec.csv"
    log.write_text("".join(f"{k % 30 - 15},{k * 0.5}\n" for k in range(100)), encoding="utf-8")
    argv = ["import-csv", str(log), "--out", str(out), "--columns", "fin,roll", "--no-header"]
    assert main([*argv, "--rate", "10", f"--fin-range={value}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--fin-range" in err, err
    assert not out.exists()
    # identify refuses it the same way, before any work.
    rec = tmp_path / "ok.csv"
    save_recording(load_bundled("tunnel-paper-seed0"), rec)
    assert main(["identify", str(rec), f"--fin-range={value}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--fin-range" in err, err


@pytest.mark.parametrize("value", ["0", "-1", "91"])
def test_a_recording_stating_a_bad_fin_range_is_refused(value: str, real: Recording) -> None:
    text = recording_text(real.stating_fin_range(10.0))
    assert f"# {FIN_RANGE_KEY}: 10.0\n" in text
    with pytest.raises(RecordingError, match=FIN_RANGE_KEY):
        Recording(
            name="bad", source="wind-tunnel", time_s=real.time_s, fin_cmd_deg=real.fin_cmd_deg,
            roll_deg=real.roll_deg, metadata={FIN_RANGE_KEY: value},
        )  # fmt: skip
