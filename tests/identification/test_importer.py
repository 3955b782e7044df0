"""Success paths of ``rocketroll import-csv`` and of the recording round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.recordings.importer import import_csv
from identification.recordings.recording import (
    Recording,
    RecordingError,
    load_recording,
    save_recording,
)
from rocketroll.cli import main


def run_cli(capsys: pytest.CaptureFixture[str], *argv: object) -> str:
    """Run ``rocketroll`` in-process, insist on success, return stdout."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert (code, err) == (0, ""), err
    return out


@pytest.fixture(scope="module")
def tunnel_run() -> Recording:
    """A 100 Hz virtual-tunnel run with a measured fin angle."""
    return run_tunnel(
        TunnelSpec(
            seed=3,
            log_dt=0.01,
            measured_fin=True,
            schedule="staircase",
            steps=3,
            dwell_min=5,
            dwell_max=8,
        )
    )


# --------------------------------------------------------------------------- (a) the headline case


@pytest.mark.parametrize("delimiter", [" ", ",", "\t"], ids=["spaces", "commas", "tabs"])
def test_headerless_radians_100hz_in_one_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], tunnel_run: Recording, delimiter: str
) -> None:
    """A user's own headerless log in radians at 100 Hz: fin, roll -> a valid recording."""
    assert tunnel_run.fin_deg is not None and tunnel_run.roll_deg is not None
    fin_deg, roll_deg = tunnel_run.fin_deg, tunnel_run.roll_deg
    src = tmp_path / "run.txt"
    np.savetxt(
        src, np.column_stack([np.deg2rad(fin_deg), np.deg2rad(roll_deg)]), delimiter=delimiter
    )
    rec = tmp_path / "rec.csv"

    out = run_cli(
        capsys,
        "import-csv", src, "--out", rec,
        "--columns", "fin,roll", "--no-header", "--units", "rad", "--rate", "100",
    )  # fmt: skip

    assert out.startswith(f"wrote {rec}: ")
    loaded = load_recording(rec)
    assert loaded.name == "run"
    assert loaded.source == "wind-tunnel"
    assert list(loaded.columns()) == ["time_s", "fin_deg", "roll_deg"]
    assert loaded.fin_cmd_deg is None and loaded.ud_true_deg is None
    assert loaded.n_samples == fin_deg.size
    assert loaded.time_s[0] == 0.0
    assert loaded.dt_s == pytest.approx(0.01, rel=1e-9)
    np.testing.assert_allclose(np.diff(loaded.time_s), 0.01, rtol=0, atol=1e-9)
    assert loaded.fin_deg is not None and loaded.roll_deg is not None
    np.testing.assert_allclose(loaded.fin_deg, fin_deg, rtol=0, atol=1e-6)
    np.testing.assert_allclose(loaded.roll_deg, roll_deg, rtol=0, atol=1e-6)
    assert np.ptp(loaded.roll_deg) > 100  # degrees, not radians
    assert loaded.metadata["imported_from"] == "run.txt"
    assert loaded.metadata["import.columns"] == "fin,roll"
    assert loaded.metadata["import.units"] == "rad"


def test_import_options_name_source_notes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], tunnel_run: Recording
) -> None:
    assert tunnel_run.fin_cmd_deg is not None and tunnel_run.roll_deg is not None
    src = tmp_path / "flight 7.log"
    np.savetxt(src, np.column_stack([tunnel_run.fin_cmd_deg, tunnel_run.roll_deg]), fmt="%.6f")
    rec = tmp_path / "sub" / "rec.csv"
    run_cli(
        capsys,
        "import-csv", src, "--out", rec, "--columns", "fin_cmd,roll", "--no-header",
        "--rate", "100", "--name", "F7", "--source", "flight", "--notes", "launch 2: windy",
    )  # fmt: skip
    loaded = load_recording(rec)
    assert (loaded.name, loaded.source) == ("F7", "flight")
    assert loaded.metadata["notes"] == "launch 2: windy"
    assert loaded.metadata["import.units"] == "deg"
    assert loaded.fin_cmd_deg is not None and loaded.fin_deg is None
    np.testing.assert_allclose(loaded.fin_cmd_deg, tunnel_run.fin_cmd_deg, rtol=0, atol=1e-6)


# --------------------------------------------------------------------------- (b) header, ms, ';'

N = 300
STEP = 150


def daq_export(status: str) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """Semicolon export with a header, time in ms (50 Hz from 1 s, 6 s long) and a text
    column."""
    k = np.arange(N)
    time_ms = 1000.0 + 20.0 * k
    fin = np.where(k < STEP, -2.5, 7.5)
    roll = 0.125 * np.maximum(k - STEP, 0) ** 2
    lines = ["# DAQ export, v3", "sample;time_ms;status;fin_meas;roll_enc"]
    lines += [
        f"{i};{t:g};{status};{f:g};{r:.10g}"
        for i, t, f, r in zip(k, time_ms, fin, roll, strict=True)
    ]
    return "\n".join(lines) + "\n", time_ms, fin, roll


@pytest.mark.parametrize(
    ("status", "delimiter"),
    [
        pytest.param("ok, steady", [";"], id="explicit-delimiter-comma-in-text"),
        pytest.param("ok", [], id="auto-delimiter"),
    ],
)
def test_header_time_column_in_ms_semicolons_and_text_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], status: str, delimiter: list[str]
) -> None:
    text, time_ms, fin, roll = daq_export(status)
    src = tmp_path / "daq.csv"
    src.write_text(text, encoding="utf-8")
    rec = tmp_path / "rec.csv"
    delimiter_args = [arg for d in delimiter for arg in ("--delimiter", d)]

    run_cli(
        capsys,
        "import-csv", src, "--out", rec, "--columns", "skip,skip,skip,fin,roll",
        "--time-column", "time_ms", "--time-unit", "ms", *delimiter_args,
    )  # fmt: skip

    loaded = load_recording(rec)
    assert list(loaded.columns()) == ["time_s", "fin_deg", "roll_deg"]
    np.testing.assert_allclose(loaded.time_s, time_ms / 1000.0, rtol=0, atol=1e-9)
    assert loaded.dt_s == pytest.approx(0.02)
    assert loaded.fin_deg is not None and loaded.roll_deg is not None
    np.testing.assert_allclose(loaded.fin_deg, fin, rtol=0, atol=1e-9)
    np.testing.assert_allclose(loaded.roll_deg, roll, rtol=0, atol=1e-9)
    assert loaded.metadata["import.columns"] == "skip,skip,skip,fin,roll"


def test_the_first_line_chooses_the_separator_and_quotes_hide_it(tmp_path: Path) -> None:
    """Without --delimiter the first line's separator splits every line (a semicolon before
    a tab before a comma), and a separator inside quotes does not count."""
    t = np.arange(200) * 0.1
    fin = np.where(t < 10, 0.0, 10.0)
    body = "".join(
        f'"{a:.1f}";"{b:g}";"{3 * a:.3f}";"ok, logged"\n' for a, b in zip(t, fin, strict=True)
    )
    src = tmp_path / "quoted.csv"
    src.write_text("t;fin;roll;status\n" + body, encoding="utf-8")
    rec = import_csv(src, ["time", "fin_cmd", "roll", "skip"], source="wind-tunnel")
    assert rec.fin_cmd_deg is not None and rec.roll_deg is not None
    np.testing.assert_allclose(rec.fin_cmd_deg, fin)
    np.testing.assert_allclose(rec.roll_deg, np.round(3 * t, 3))
    # A space-separated header over semicolon data: the header decides, and line 2 says so.
    src.write_text("t fin roll status\n" + body, encoding="utf-8")
    with pytest.raises(RecordingError, match=r"quoted.csv:2: 2 cells but --columns names 4"):
        import_csv(src, ["time", "fin_cmd", "roll", "skip"], source="wind-tunnel")


def test_a_semicolon_export_with_decimal_commas_imports(tmp_path: Path) -> None:
    """A European logger's export: ';' between cells, ',' in the numbers (it failed with
    '2 cells but --columns names 3')."""
    t = np.arange(100) * 0.1
    lines = ["zeit;flosse;rollwinkel"]
    lines += [f"{a:.1f};{0 if a < 5 else 7.5:g};{-1.25 * a:.3f}".replace(".", ",") for a in t]
    src = tmp_path / "export.csv"
    src.write_text("\n".join(lines) + "\n", encoding="utf-8")
    rec = import_csv(src, ["time", "fin_cmd", "roll"], source="wind-tunnel")
    assert rec.roll_deg is not None and rec.fin_cmd_deg is not None
    np.testing.assert_allclose(rec.roll_deg, np.round(-1.25 * t, 3))
    assert rec.fin_cmd_deg[-1] == 7.5


def test_a_cell_the_csv_module_cannot_read_is_one_error_naming_its_line(tmp_path: Path) -> None:
    src = tmp_path / "binary.csv"
    src.write_text("time,fin,roll\n0,0,0\n" + "1," * 3 + "x" * 200_000 + "\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"binary.csv:3: unreadable cells"):
        import_csv(src, ["time", "fin_cmd", "roll"], source="wind-tunnel")


def test_time_column_may_have_role_time(tmp_path: Path) -> None:
    text, time_ms, _, _ = daq_export("ok")
    src = tmp_path / "daq.csv"
    src.write_text(text, encoding="utf-8")
    rec = import_csv(
        src, ["skip", "time", "skip", "fin", "roll"], time_column="time_ms", time_unit="ms"
    )
    np.testing.assert_allclose(rec.time_s, time_ms / 1000.0, rtol=0, atol=1e-9)


def test_headerless_time_column_by_number(tmp_path: Path) -> None:
    text, time_ms, fin, _ = daq_export("ok")
    src = tmp_path / "daq.csv"
    src.write_text("\n".join(text.splitlines()[2:]) + "\n", encoding="utf-8")
    rec = import_csv(
        src, ["skip", "skip", "skip", "fin", "roll"], header=False, time_column="2", time_unit="ms"
    )
    np.testing.assert_allclose(rec.time_s, time_ms / 1000.0, rtol=0, atol=1e-12)
    assert rec.fin_deg is not None
    np.testing.assert_allclose(rec.fin_deg, fin, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- (c) --unwrap


def wrapped_roll_input(units: str) -> tuple[str, np.ndarray, np.ndarray]:
    """Roll that turns more than two revolutions, logged wrapped into [-180, 180)."""
    rng = np.random.default_rng(7)
    k = np.arange(N)
    true = -170.0 + np.cumsum(rng.uniform(-40.0, 100.0, N))  # steps well under 180°
    wrapped = (true + 180.0) % 360.0 - 180.0
    fin = np.where(k < STEP, 0.0, 20.0)
    scale = np.pi / 180.0 if units == "rad" else 1.0
    lines = ["time,fin_cmd,roll"]
    lines += [
        f"{0.1 * i:.1f},{f * scale:.17g},{w * scale:.17g}"
        for i, f, w in zip(k, fin, wrapped, strict=True)
    ]
    return "\n".join(lines) + "\n", true, wrapped


@pytest.mark.parametrize("units", ["deg", "rad"])
def test_unwrap_roll_angle(tmp_path: Path, capsys: pytest.CaptureFixture[str], units: str) -> None:
    text, true, wrapped = wrapped_roll_input(units)
    assert np.ptp(true) > 720 and np.all(np.abs(wrapped) <= 180)
    src = tmp_path / "wrapped.csv"
    src.write_text(text, encoding="utf-8")
    args = ["import-csv", src, "--columns", "time,fin_cmd,roll", "--units", units]

    run_cli(capsys, *args, "--out", tmp_path / "unwrapped.csv", "--unwrap")
    run_cli(capsys, *args, "--out", tmp_path / "raw.csv")

    unwrapped = load_recording(tmp_path / "unwrapped.csv").roll_deg
    raw = load_recording(tmp_path / "raw.csv").roll_deg
    assert unwrapped is not None and raw is not None
    np.testing.assert_allclose(unwrapped, true, rtol=0, atol=1e-6)
    np.testing.assert_allclose(raw, wrapped, rtol=0, atol=1e-6)  # no --unwrap: left alone


# --------------------------------------------------------------------------- (d) rate gyro


@pytest.mark.parametrize(("units", "scale"), [("rad", 180.0 / np.pi), ("deg", 1.0)])
def test_roll_rate_units(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], units: str, scale: float
) -> None:
    k = np.arange(N)
    fin = np.where(k < STEP, 0.0, 10.0 / scale)  # 10° in the file's unit
    rate = 0.8 * np.sin(0.3 * k) + 0.1
    src = tmp_path / "gyro.csv"
    lines = ["t;fin;p"] + [
        f"{0.05 * i:.2f};{f:.17g};{r:.17g}" for i, f, r in zip(k, fin, rate, strict=True)
    ]
    src.write_text("\n".join(lines) + "\n", encoding="utf-8")
    rec = tmp_path / "rec.csv"

    run_cli(
        capsys, "import-csv", src, "--out", rec, "--columns", "time,fin,roll_rate", "--units", units
    )

    loaded = load_recording(rec)
    assert list(loaded.columns()) == ["time_s", "fin_deg", "roll_rate_dps"]
    assert loaded.roll_deg is None
    assert loaded.roll_rate_dps is not None and loaded.fin_deg is not None
    np.testing.assert_allclose(loaded.roll_rate_dps, rate * scale, rtol=0, atol=1e-6)
    np.testing.assert_allclose(loaded.fin_deg, fin * scale, rtol=0, atol=1e-6)
    assert loaded.dt_s == pytest.approx(0.05)


# --------------------------------------------------------------------------- (e) round trip


def assert_same_recording(a: Recording, b: Recording, atol: float = 1e-6) -> None:
    assert (a.name, a.source) == (b.name, b.source)
    assert list(a.metadata.items()) == list(b.metadata.items())  # exact, order included
    assert list(a.columns()) == list(b.columns())
    for column, values in a.columns().items():
        np.testing.assert_allclose(b.columns()[column], values, rtol=0, atol=atol, err_msg=column)


def synthetic_recording() -> Recording:
    rng = np.random.default_rng(11)
    n = 400
    t = 12.5 + 0.02 * np.arange(n, dtype=np.float64)
    fin_cmd = np.repeat(rng.uniform(-40, 40, 4), n // 4)
    return Recording(
        name="round-trip",
        source="synthetic",
        time_s=t,
        fin_cmd_deg=fin_cmd,
        fin_deg=fin_cmd + rng.normal(0, 0.3, n),
        roll_deg=np.cumsum(rng.normal(3, 2, n)) * np.pi,
        roll_rate_dps=rng.normal(0, 50, n) / 3,
        ud_true_deg=rng.normal(0, 8.4, n),
        metadata={
            "notes": "θ from eq. 49: α = 0.659, u_d: gaussian",
            "seed": "11",
            "truth.alpha": repr(0.659),
            "tunnel.x-y_z": "",
        },
    )


def test_round_trip_reproduces_arrays_and_metadata(tmp_path: Path) -> None:
    original = synthetic_recording()
    path = tmp_path / "rec.csv"
    save_recording(original, path)
    loaded = load_recording(path)
    assert_same_recording(original, loaded)
    assert loaded.seed == 11


def test_round_trip_of_tunnel_run_keeps_truth(tmp_path: Path, tunnel_run: Recording) -> None:
    path = tmp_path / "tunnel.csv"
    save_recording(tunnel_run, path)
    loaded = load_recording(path)
    assert_same_recording(tunnel_run, loaded)
    assert loaded.truth() == tunnel_run.truth()
    assert loaded.truth() is not None


def test_saving_is_deterministic_and_a_fixed_point(tmp_path: Path) -> None:
    original = synthetic_recording()
    first, second, third = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    save_recording(original, first)
    save_recording(original, second)
    assert first.read_bytes() == second.read_bytes()
    save_recording(load_recording(first), third)  # load + save changes nothing
    assert third.read_bytes() == first.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv", "c.csv"]


def test_save_overwrites_atomically(tmp_path: Path) -> None:
    path = tmp_path / "rec.csv"
    path.write_text("old contents\n", encoding="utf-8")
    save_recording(synthetic_recording(), path)
    assert path.read_text(encoding="utf-8").startswith("# format: rocketroll-recording/1\n")
    assert [p.name for p in tmp_path.iterdir()] == ["rec.csv"]


def test_imported_file_is_a_fixed_point(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text, _, _, _ = daq_export("ok")
    src = tmp_path / "daq.csv"
    src.write_text(text, encoding="utf-8")
    rec, again = tmp_path / "rec.csv", tmp_path / "again.csv"
    run_cli(
        capsys,
        "import-csv",
        src,
        "--out",
        rec,
        "--columns",
        "skip,skip,skip,fin,roll",
        "--time-column",
        "time_ms",
        "--time-unit",
        "ms",
    )
    save_recording(load_recording(rec), again)
    assert again.read_bytes() == rec.read_bytes()


@pytest.mark.parametrize("value", ["one\rtwo", "one\u2028two"], ids=["CR", "U+2028"])
def test_metadata_with_other_line_breaks_round_trips_or_is_rejected(
    tmp_path: Path, value: str
) -> None:
    base = synthetic_recording()
    try:
        rec = Recording(
            name=base.name, source=base.source, metadata={"notes": value}, **base.columns()
        )
    except RecordingError:
        return  # rejecting the value up front would be fine too
    path = tmp_path / "rec.csv"
    save_recording(rec, path)
    assert load_recording(path).metadata["notes"] == value


def test_metadata_whitespace_is_trimmed_so_round_trips_are_exact(tmp_path: Path) -> None:
    base = synthetic_recording()
    rec = Recording(
        name=" padded ", source=base.source, metadata={"notes": "  x  "}, **base.columns()
    )
    assert rec.name == "padded" and rec.metadata["notes"] == "x"
    path = tmp_path / "rec.csv"
    save_recording(rec, path)
    back = load_recording(path)
    assert back.name == rec.name and dict(back.metadata) == dict(rec.metadata)


def test_byte_order_mark_is_tolerated(tmp_path: Path) -> None:
    base = synthetic_recording()
    plain = tmp_path / "plain.csv"
    save_recording(base, plain)
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    assert_same_recording(load_recording(bom), base)
    raw = tmp_path / "raw.csv"
    raw.write_bytes(
        b"\xef\xbb\xbft,fin,roll\n"
        + b"".join(f"{k / 10},{0 if k < 30 else 5},{k}\n".encode() for k in range(60))
    )
    rec = import_csv(raw, ["time", "fin", "roll"], time_column="t")
    assert rec.n_samples == 60


def test_fast_logger_round_trips_uniformly(tmp_path: Path) -> None:
    # 1 kHz, the fastest a recording may be sampled; 3 kHz (a third of a millisecond) is not.
    n = 5_000
    raw = tmp_path / "fast.txt"
    raw.write_text("".join(f"{0 if k < 100 else 0.1} {k * 1e-6}\n" for k in range(n)))
    rec = import_csv(raw, ["fin", "roll"], header=False, rate_hz=1_000.0, units="rad")
    path = tmp_path / "fast.csv"
    save_recording(rec, path)
    # Times are written to the nanosecond: 1 ns in 1 ms is 1e-6 relative.
    assert load_recording(path).dt_s == pytest.approx(1e-3, rel=1e-6)
    with pytest.raises(RecordingError, match=r"--rate 3000 Hz steps every 0\.333333 ms"):
        import_csv(raw, ["fin", "roll"], header=False, rate_hz=3_000.0, units="rad")


def test_an_import_is_never_labelled_synthetic(tmp_path: Path) -> None:
    """`--source synthetic` was accepted for a foreign log: reports then called measured
    data the virtual tunnel's, which carries a known truth an import never has."""
    log = tmp_path / "log.csv"
    log.write_text("0,1,2\n0.1,1,2\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"source: must be one of wind-tunnel, flight, not"):
        import_csv(log, ["time", "fin_cmd", "roll"], header=False, source="synthetic")


def test_a_window_per_column_units_scale_offset_and_sign(tmp_path: Path) -> None:
    """A real log as it comes: a stretch of it, the roll in radians beside a fin in
    degrees, a fin whose sign is the other way round and trimmed 1.5° off zero."""
    from identification.recordings.importer import ImportSettings, read_csv

    t = np.arange(0.0, 20.0, 0.01)
    fin = np.where(t < 10.0, 10.0, -10.0)
    roll = np.radians(3.0 * t)
    log = tmp_path / "log.csv"
    np.savetxt(log, np.column_stack([t, fin, roll]), delimiter=",", fmt="%.10g")
    settings = ImportSettings(
        columns=("time", "fin", "roll"),
        header=False,
        unit={"roll": "rad"},
        scale={"fin": -1},
        offset={"fin": -1.5},
        time_from=5.0,
        time_to=15.0,
    )
    rec = read_csv(log, settings)
    assert rec.time_s[0] == pytest.approx(5.0) and rec.time_s[-1] == pytest.approx(15.0)
    assert rec.fin_deg is not None and rec.roll_deg is not None
    np.testing.assert_allclose(rec.fin_deg, -np.where(rec.time_s < 10.0, 10.0, -10.0) - 1.5)
    np.testing.assert_allclose(rec.roll_deg, 3.0 * rec.time_s, atol=1e-6)
    assert rec.metadata["import.scale"] == "fin=-1"
    assert (rec.metadata["import.from_s"], rec.metadata["import.to_s"]) == ("5.0", "15.0")


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["--scale", "time=2"], "--scale: 'time' is not a column of --columns (roll, fin)"),
        (["--unit", "fin=km"], "--unit: fin='km': the units of fin are deg, rad"),
        (["--scale", "fin=0"], "--scale: fin=0 would erase the column"),
        (["--offset", "fin=nan"], "--offset: fin=nan is not a finite number"),
        (["--from", "30"], "--from/--to keep no rows: the time column runs 0 to 9.9 s"),
        (["--from", "5", "--to", "2"], "--from: 5 s must be below --to 2 s"),
    ],
)
def test_a_bad_column_setting_or_window_is_one_line(
    extra: list[str], said: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log.csv"
    log.write_text("".join(f"{k},{k % 7}\n" for k in range(100)), encoding="utf-8")
    out = tmp_path / "rec.csv"
    argv = ["import-csv", str(log), "--out", str(out), "--columns", "roll,fin", "--no-header"]
    assert main([*argv, "--rate", "10", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and said in err, err
    assert not out.exists()


def test_the_time_column_by_name_takes_its_own_unit_and_offset_and_nan_times_are_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "log.csv"
    rows = ["t_ms,fin,roll", *(f"{k * 100},{10 if k < 40 else -10},{k * 0.5}" for k in range(100))]
    log.write_text("\n".join(rows) + "\n", encoding="utf-8")
    out = tmp_path / "rec.csv"
    argv = ["import-csv", str(log), "--out", str(out), "--columns", "skip,fin,roll"]
    argv += ["--time-column", "t_ms", "--unit", "time=ms", "--offset", "time=-1"]
    assert main(argv) == 0
    capsys.readouterr()
    rec = load_recording(out)
    assert rec.time_s[0] == pytest.approx(-1.0) and rec.time_s[1] == pytest.approx(-0.9)
    # A window leaves rows without a finite time to the validation, which names their line.
    nan = tmp_path / "nan.csv"
    nan.write_text("".join(f"{'nan' if k in (0, 99) else k / 10},1,{k}\n" for k in range(100)))
    argv = ["import-csv", str(nan), "--out", str(tmp_path / "n.csv"), "--columns"]
    assert main([*argv, "time,fin,roll", "--no-header", "--from", "-100"]) == 2
    assert "nan.csv:1: time_s is nan (not finite)" in capsys.readouterr().err


def _spinning_log(path: Path, rate_scale: float) -> None:
    """A roll log of angle (°) and rate (the rate column times ``rate_scale``: 1 for °/s,
    π/180 for a rate logged in rad/s) at 100 Hz, the fin stepping."""
    t = np.arange(1000) * 0.01
    rate = 30.0 * np.sin(0.7 * t) + 10.0
    angle = np.cumsum(rate) * 0.01
    fin = np.where(t > 2.0, 10.0, 0.0)
    rows = [f"{a:.6f},{r * rate_scale:.6f},{f:g}" for a, r, f in zip(angle, rate, fin, strict=True)]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def test_a_rate_column_in_another_unit_than_the_angle_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """rad/s read as °/s is plausible on its own (a few °/s): beside the angle it is not."""
    src, out = tmp_path / "log.txt", tmp_path / "rec.csv"
    words = ["import-csv", str(src), "--out", str(out), "--columns", "roll,roll_rate,fin"]
    _spinning_log(src, np.pi / 180.0)
    assert main([*words, "--no-header", "--rate", "100"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the rate looks like rad/s; give --unit roll_rate=rad" in err
    assert str(src) in err and not out.exists()
    assert main([*words, "--no-header", "--rate", "100", "--unit", "roll_rate=rad"]) == 0
    _spinning_log(src, 1.0)
    assert main([*words, "--no-header", "--rate", "100", "--unit", "roll_rate=rad"]) == 2
    assert "the rate looks like °/s; give --unit roll_rate=deg" in capsys.readouterr().err
    assert main([*words, "--no-header", "--rate", "100"]) == 0


def test_a_site_elevation_makes_altitude_above_ground_above_sea_level(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    t = np.arange(600) * 0.01
    rows = [
        f"{ti:.2f},{10.0 if i > 50 else 0.0},{i * 0.5},{50.0 + i},{20.0 + i}"
        for i, ti in enumerate(t)
    ]
    src, out = tmp_path / "log.txt", tmp_path / "rec.csv"
    src.write_text("t,fin,rate,v,h\n" + "\n".join(rows) + "\n", encoding="utf-8")
    words = ["import-csv", str(src), "--out", str(out), "--source", "flight"]
    columns = ["--columns", "time,fin_cmd,roll_rate,airspeed,altitude"]
    assert main([*words, *columns, "--site-elevation", "1200"]) == 0
    rec = load_recording(out)
    assert rec.altitude_m is not None and float(rec.altitude_m[0]) == pytest.approx(1220.0)
    assert rec.metadata["import.site_elevation_m"] == "1200.0"
    capsys.readouterr()
    assert (
        main([*words, "--columns", "time,fin_cmd,roll_rate,airspeed,skip", "--site-elevation", "5"])
        == 2
    )
    err = capsys.readouterr().err
    assert "--site-elevation" in err and "altitude column" in err and err.count("\n") == 1
