"""Every validation failure of a recording, fed through the ``rocketroll`` CLI.

Each bad file is built from one small valid recording (60 rows every 0.1 s, a
fin step at row 30).  For every failure the CLI must exit with code 2, print
exactly one line on stderr that names the file, the 1-based line (where there
is one) and the problem, and write nothing.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest

from identification.recordings.importer import import_csv
from identification.recordings.recording import (
    MIN_FIN_CHANGE_DEG,
    MIN_SAMPLES,
    SAMPLING_RTOL,
    RecordingError,
    load_recording,
)
from rocketroll.cli import main

N_ROWS = 60
DT = 0.1
STEP_ROW = 30
META = ["# name: t", "# source: wind-tunnel"]
HEADER = ["time_s", "fin_cmd_deg", "roll_deg"]
HEADER_LINE = len(META) + 1

Lines = list[str]
Mutator = Callable[[Lines], Lines]


# --------------------------------------------------------------------------- helpers


def row_line(k: int) -> int:
    """1-based file line of data row ``k`` (0-based) of the valid recording."""
    return HEADER_LINE + 1 + k


def fmt_time(t: float) -> str:
    return f"{t:.6f}".rstrip("0").rstrip(".") or "0"


def valid_lines() -> Lines:
    """The valid recording, one string per file line."""
    lines = [*META, ",".join(HEADER)]
    for k in range(N_ROWS):
        fin = 0.0 if k < STEP_ROW else 10.0
        roll = 0.0 if k < STEP_ROW else 0.25 * (k - STEP_ROW) ** 2
        lines.append(f"{fmt_time(k * DT)},{fin:g},{roll:g}")
    return lines


def write_lines(path: Path, lines: Sequence[str]) -> Path:
    path.write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    return path


def set_cell(row: int, column: str, value: str) -> Mutator:
    """Replace one cell of data row ``row``."""

    def mutate(lines: Lines) -> Lines:
        out = list(lines)
        index = row_line(row) - 1
        cells = out[index].split(",")
        cells[HEADER.index(column)] = value
        out[index] = ",".join(cells)
        return out

    return mutate


def set_column(column: str, value: Callable[[int], str]) -> Mutator:
    """Replace every cell of ``column``; ``value(k)`` gives row ``k``'s text."""

    def mutate(lines: Lines) -> Lines:
        out = list(lines)
        for k in range(N_ROWS):
            out = set_cell(k, column, value(k))(out)
        return out

    return mutate


def drop_column(column: str) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        j = HEADER.index(column)
        out = list(lines[: HEADER_LINE - 1])
        for line in lines[HEADER_LINE - 1 :]:
            cells = line.split(",")
            del cells[j]
            out.append(",".join(cells))
        return out

    return mutate


def add_column(column: str, value: str) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        header = lines[HEADER_LINE - 1] + "," + column
        rows = [line + "," + value for line in lines[HEADER_LINE:]]
        return [*lines[: HEADER_LINE - 1], header, *rows]

    return mutate


def rename_header(old: str, new: str) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        out = list(lines)
        out[HEADER_LINE - 1] = ",".join(new if c == old else c for c in HEADER)
        return out

    return mutate


def insert_line(index: int, text: str) -> Mutator:
    """Insert ``text`` so that it becomes 1-based line ``index + 1``."""

    def mutate(lines: Lines) -> Lines:
        return [*lines[:index], text, *lines[index:]]

    return mutate


def replace_line(number: int, text: str) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        out = list(lines)
        out[number - 1] = text
        return out

    return mutate


def delete_line(number: int) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        return [*lines[: number - 1], *lines[number:]]

    return mutate


def keep_rows(n: int) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        return lines[: row_line(n - 1)]

    return mutate


def chain(*mutators: Mutator) -> Mutator:
    def mutate(lines: Lines) -> Lines:
        for m in mutators:
            lines = m(lines)
        return lines

    return mutate


def run_cli(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str, str]:
    """Run ``rocketroll`` in-process; returns (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def run_subprocess(cwd: Path, *argv: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "rocketroll.cli", *[str(a) for a in argv]],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def assert_one_line_error(
    err: str, command: str, path: Path | str, line: int | None, keywords: Sequence[str]
) -> None:
    """``err`` is exactly one line naming ``path`` (and ``line``) and the problem."""
    assert err.endswith("\n"), repr(err)
    assert err.count("\n") == 1, f"expected one line on stderr, got:\n{err}"
    where = f"{path}:{line}" if line is not None else f"{path}"
    prefix = f"rocketroll {command}: error: {where}: "
    assert err.startswith(prefix), f"expected prefix {prefix!r}, got {err!r}"
    for keyword in keywords:
        assert keyword in err, f"{keyword!r} not in {err!r}"


def files_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# --------------------------------------------------------------------------- fixtures


@pytest.fixture
def good_lines() -> Lines:
    return valid_lines()


def test_fixture_recording_is_valid(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Positive control: the base file passes, and ``info`` writes both outputs."""
    good = write_lines(tmp_path / "good.csv", valid_lines())
    js, png = tmp_path / "out.json", tmp_path / "out.png"
    code, out, err = run_cli(capsys, "info", good, "--json", js, "--plot", png)
    assert (code, err) == (0, "")
    assert "recording      t  (wind-tunnel)" in out
    summary = json.loads(js.read_text(encoding="utf-8"))
    assert summary["n_samples"] == N_ROWS
    assert summary["dt_s"] == pytest.approx(DT)
    assert summary["fin_changes"] == 1
    assert png.read_bytes().startswith(b"\x89PNG")


# --------------------------------------------------------------------------- info: bad files

# (mutator, 1-based line or None, key words of the problem)
BAD_RECORDINGS = [
    # columns
    pytest.param(
        drop_column("roll_deg"),
        HEADER_LINE,
        ["missing column roll_deg or roll_rate_dps"],
        id="missing-roll-column",
    ),
    pytest.param(
        drop_column("fin_cmd_deg"),
        HEADER_LINE,
        ["missing column fin_cmd_deg or fin_deg"],
        id="missing-fin-column",
    ),
    pytest.param(
        drop_column("time_s"), HEADER_LINE, ["missing column time_s"], id="missing-time-column"
    ),
    pytest.param(
        add_column("temperature_c", "21.5"),
        HEADER_LINE,
        ["unknown column 'temperature_c'", "allowed columns: time_s"],
        id="unknown-column",
    ),
    pytest.param(
        rename_header("roll_deg", "roll"),
        HEADER_LINE,
        ["unknown column 'roll'"],
        id="misspelt-column",
    ),
    pytest.param(
        add_column("roll_deg", "1"),
        HEADER_LINE,
        ["duplicate column 'roll_deg'"],
        id="duplicate-column",
    ),
    pytest.param(
        add_column("ud_true_deg", "0.5"),
        HEADER_LINE,
        ["'ud_true_deg'", "only allowed when source is synthetic", "not 'wind-tunnel'"],
        id="ud-true-not-synthetic",
    ),
    # cells
    pytest.param(
        set_cell(10, "roll_deg", "abc"),
        row_line(10),
        ["roll_deg is 'abc', not a number"],
        id="non-numeric-cell",
    ),
    pytest.param(
        set_cell(10, "fin_cmd_deg", ""),
        row_line(10),
        ["fin_cmd_deg is '', not a number"],
        id="empty-cell",
    ),
    pytest.param(
        set_cell(11, "roll_deg", "nan"),
        row_line(11),
        ["roll_deg is nan", "not finite"],
        id="nan-cell",
    ),
    pytest.param(
        set_cell(11, "roll_deg", "NaN"),
        row_line(11),
        ["roll_deg is NaN", "not finite"],
        id="NaN-cell",
    ),
    pytest.param(
        set_cell(12, "fin_cmd_deg", "inf"),
        row_line(12),
        ["fin_cmd_deg is inf", "not finite"],
        id="inf-cell",
    ),
    pytest.param(
        set_cell(13, "time_s", "-inf"),
        row_line(13),
        ["time_s is -inf", "not finite"],
        id="minus-inf-cell",
    ),
    pytest.param(
        set_cell(14, "roll_deg", "1e999"),
        row_line(14),
        ["roll_deg is 1e999", "not finite"],
        id="overflow-cell",
    ),
    pytest.param(
        set_cell(20, "roll_deg", "0,7"),
        row_line(20),
        ["expected 3 cells (time_s,fin_cmd_deg,roll_deg), got 4"],
        id="too-many-cells",
    ),
    pytest.param(
        replace_line(row_line(21), "2.1,0"),
        row_line(21),
        ["expected 3 cells (time_s,fin_cmd_deg,roll_deg), got 2"],
        id="too-few-cells",
    ),
    # time
    pytest.param(
        set_cell(25, "time_s", "2.4"),
        row_line(25),
        ["time_s is not strictly increasing", "2.4 s follows 2.4 s"],
        id="time-equal",
    ),
    pytest.param(
        set_cell(25, "time_s", "2.3"),
        row_line(25),
        ["time_s is not strictly increasing", "2.3 s follows 2.4 s"],
        id="time-decreasing",
    ),
    pytest.param(
        set_cell(40, "time_s", fmt_time(40 * DT + 1.5 * SAMPLING_RTOL * DT)),
        row_line(40),
        ["irregular sampling", "to 4.0015 s", "median interval 0.1 s", "more than 1%"],
        id="jitter-1.5-percent",
    ),
    pytest.param(
        delete_line(row_line(40)),
        row_line(40),  # row 41 moves up onto row 40's line
        ["irregular sampling", "interval 0.2 s", "from 3.9 s to 4.1 s"],
        id="dropped-sample",
    ),
    # sizes
    pytest.param(
        keep_rows(MIN_SAMPLES - 1),
        None,
        [f"too few samples: {MIN_SAMPLES - 1}", f"at least {MIN_SAMPLES}"],
        id="49-samples",
    ),
    pytest.param(keep_rows(0), None, ["too few samples: 0"], id="header-but-no-samples"),
    pytest.param(
        set_column("fin_cmd_deg", lambda k: "10"),
        None,
        ["fin angle (fin_cmd_deg) never changes", f"{MIN_FIN_CHANGE_DEG}°", "nothing to identify"],
        id="fin-constant",
    ),
    pytest.param(
        set_column("fin_cmd_deg", lambda k: "0" if k < STEP_ROW else "0.05"),
        None,
        ["fin angle (fin_cmd_deg) never changes"],
        id="fin-change-too-small",
    ),
    # metadata
    pytest.param(
        delete_line(2),
        None,
        ["missing metadata '# source: ...'", "synthetic, wind-tunnel, flight"],
        id="missing-source",
    ),
    pytest.param(
        replace_line(2, "# source: lab"),
        2,
        ["source must be one of synthetic, wind-tunnel, flight, not 'lab'"],
        id="invalid-source",
    ),
    pytest.param(
        replace_line(2, "# source: Wind-Tunnel"),
        2,
        ["source must be one of", "not 'Wind-Tunnel'"],
        id="source-wrong-case",
    ),
    pytest.param(
        insert_line(1, "# a free comment"),
        2,
        ["metadata line must read '# key: value'", "a free comment"],
        id="malformed-metadata-no-colon",
    ),
    pytest.param(
        insert_line(1, "# bad key: x"),
        2,
        ["metadata line must read '# key: value'", "'# bad key: x'"],
        id="malformed-metadata-key",
    ),
    pytest.param(
        insert_line(2, "# name: u"),
        3,
        ["duplicate metadata key 'name'", "first on line 1"],
        id="duplicate-metadata-key",
    ),
    pytest.param(
        insert_line(row_line(10) - 1, "# notes: late"),
        row_line(10),
        ["metadata lines must come before the header row"],
        id="metadata-after-header",
    ),
    pytest.param(
        insert_line(0, "# format: rocketroll-recording/2"),
        1,
        ["unsupported format 'rocketroll-recording/2'", "rocketroll-recording/1"],
        id="unsupported-format",
    ),
    # degenerate files
    pytest.param(lambda lines: [], None, ["no header row"], id="empty-file"),
    pytest.param(lambda lines: ["", "   ", ""], None, ["no header row"], id="blank-file"),
    pytest.param(lambda lines: list(META), None, ["no header row"], id="metadata-only"),
]


@pytest.mark.parametrize(("mutate", "line", "keywords"), BAD_RECORDINGS)
def test_info_rejects_bad_recording(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    mutate: Mutator,
    line: int | None,
    keywords: list[str],
) -> None:
    bad = write_lines(tmp_path / "bad.csv", mutate(valid_lines()))
    js, png = tmp_path / "out.json", tmp_path / "out.png"

    code, out, err = run_cli(capsys, "info", bad, "--json", js, "--plot", png)

    assert code == 2
    assert_one_line_error(err, "info", bad, line, keywords)
    assert out == ""
    assert not js.exists()
    assert not png.exists()
    assert files_in(tmp_path) == ["bad.csv"]  # no temporary files left behind either
    # The library raises the same error, with the line as an attribute.
    with pytest.raises(RecordingError) as caught:
        load_recording(bad)
    assert caught.value.line == line
    assert caught.value.path == str(bad)


def test_info_rejects_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nowhere" / "missing.csv"
    js, png = tmp_path / "out.json", tmp_path / "out.png"
    code, out, err = run_cli(capsys, "info", missing, "--json", js, "--plot", png)
    assert code == 2
    assert_one_line_error(err, "info", missing, None, ["cannot read", "No such file"])
    assert out == ""
    assert files_in(tmp_path) == []


def test_info_rejects_non_utf8_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "latin1.csv"
    bad.write_bytes(
        "\n".join(valid_lines()).replace("# name: t", "# name: t\xe9").encode("latin-1")
    )
    code, out, err = run_cli(capsys, "info", bad, "--json", tmp_path / "o.json")
    assert code == 2
    assert_one_line_error(err, "info", bad, 1, ["byte 0xe9 is not UTF-8", "save the file as"])
    assert out == ""
    assert files_in(tmp_path) == ["latin1.csv"]


# --------------------------------------------------------------------------- info: good edge cases


def _sawtooth(k: int) -> str:
    # odd rows late by 0.25 % of dt: intervals alternate +-0.5 % around each other
    return fmt_time(k * DT + (0.0025 * DT if k % 2 else 0.0))


GOOD_VARIANTS = [
    pytest.param(
        set_cell(40, "time_s", fmt_time(40 * DT + 0.5 * SAMPLING_RTOL * DT)),
        N_ROWS,
        id="jitter-0.5-percent",
    ),
    pytest.param(set_column("time_s", _sawtooth), N_ROWS, id="sawtooth-jitter-0.5-percent"),
    pytest.param(keep_rows(MIN_SAMPLES), MIN_SAMPLES, id="50-samples"),
    pytest.param(
        set_column("fin_cmd_deg", lambda k: "0" if k < STEP_ROW else str(MIN_FIN_CHANGE_DEG)),
        N_ROWS,
        id="fin-change-exactly-minimum",
    ),
    pytest.param(
        chain(replace_line(2, "# source: synthetic"), add_column("ud_true_deg", "0.5")),
        N_ROWS,
        id="ud-true-synthetic",
    ),
    pytest.param(
        chain(rename_header("fin_cmd_deg", "fin_deg"), rename_header("roll_deg", "roll_rate_dps")),
        N_ROWS,
        id="measured-fin-and-gyro",
    ),
    pytest.param(
        chain(
            insert_line(0, "# format: rocketroll-recording/1"),
            insert_line(3, ""),
            insert_line(4, "# notes: a: b"),
        ),
        N_ROWS,
        id="explicit-format-blank-line-colon-in-value",
    ),
]


@pytest.mark.parametrize(("mutate", "n_samples"), GOOD_VARIANTS)
def test_info_accepts_edge_cases(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], mutate: Mutator, n_samples: int
) -> None:
    good = write_lines(tmp_path / "good.csv", mutate(valid_lines()))
    js = tmp_path / "out.json"
    code, _, err = run_cli(capsys, "info", good, "--json", js)
    assert (code, err) == (0, "")
    assert json.loads(js.read_text(encoding="utf-8"))["n_samples"] == n_samples


# --------------------------------------------------------------------------- info: real process


def test_info_subprocess_exit_code(tmp_path: Path) -> None:
    bad = write_lines(tmp_path / "bad.csv", set_cell(10, "roll_deg", "abc")(valid_lines()))
    js, png = tmp_path / "out.json", tmp_path / "out.png"
    proc = run_subprocess(tmp_path, "info", bad, "--json", js, "--plot", png)
    assert proc.returncode == 2
    assert_one_line_error(proc.stderr, "info", bad, row_line(10), ["roll_deg is 'abc'"])
    assert proc.stdout == ""
    assert files_in(tmp_path) == ["bad.csv"]


def test_info_subprocess_success(tmp_path: Path) -> None:
    """Positive control for the real exit code."""
    good = write_lines(tmp_path / "good.csv", valid_lines())
    proc = run_subprocess(tmp_path, "info", good)
    assert (proc.returncode, proc.stderr) == (0, "")
    assert "samples        60 every 0.1 s" in proc.stdout


# --------------------------------------------------------------------------- import-csv

INPUT_COMMENT_LINES = ["# exported by the tunnel DAQ", ""]
INPUT_FIRST = len(INPUT_COMMENT_LINES) + 1  # line of the first data row (headerless input)


def input_line(k: int) -> int:
    """1-based line of data row ``k`` of the headerless input."""
    return INPUT_FIRST + k


def foreign_rows(n: int = N_ROWS) -> Lines:
    """Rows ``fin,roll`` in degrees, with a fin step at row 30."""
    rows = []
    for k in range(n):
        fin = 0.0 if k < STEP_ROW else 12.5
        roll = 0.0 if k < STEP_ROW else 0.3 * (k - STEP_ROW) ** 2
        rows.append(f"{fin:g},{roll:g}")
    return rows


def headerless_input() -> Lines:
    return [*INPUT_COMMENT_LINES, *foreign_rows()]


def headed_input() -> Lines:
    """``t,fin,roll`` with a header on line 2."""
    rows = [f"{fmt_time(k * DT)},{row}" for k, row in enumerate(foreign_rows())]
    return ["# exported by the tunnel DAQ", "t,fin,roll", *rows]


def edit_input_row(k: int, text: str) -> Callable[[], Lines]:
    def build() -> Lines:
        lines = headerless_input()
        lines[input_line(k) - 1] = text
        return lines

    return build


HEADERLESS = ["--columns", "fin,roll", "--no-header", "--rate", "10"]

# (input builder, CLI arguments after IN --out OUT, line or None, key words)
BAD_IMPORTS = [
    pytest.param(
        headerless_input,
        ["--columns", "fin,rol", "--no-header", "--rate", "10"],
        None,
        [
            "unknown column role 'rol' in --columns",
            "time, fin_cmd, fin, roll, roll_rate, airspeed, altitude, skip",
        ],
        id="unknown-role",
    ),
    pytest.param(
        headerless_input,
        ["--columns", "fin,fin", "--no-header", "--rate", "10"],
        None,
        ["column role 'fin' appears more than once"],
        id="duplicate-role",
    ),
    pytest.param(
        edit_input_row(7, "12.5,3,4"),
        HEADERLESS,
        input_line(7),
        ["3 cells but --columns names 2 (fin,roll)"],
        id="too-many-cells",
    ),
    pytest.param(
        edit_input_row(8, "12.5"),
        HEADERLESS,
        input_line(8),
        ["1 cells but --columns names 2"],
        id="too-few-cells",
    ),
    pytest.param(
        edit_input_row(12, "0,n/a"),
        HEADERLESS,
        input_line(12),
        ["roll is 'n/a', not a number"],
        id="non-numeric-cell",
    ),
    pytest.param(
        edit_input_row(13, "nan,0"),
        HEADERLESS,
        input_line(13),
        ["fin_deg is nan (not finite)"],
        id="nan-cell",
    ),
    pytest.param(
        headerless_input,
        ["--columns", "fin,roll", "--no-header"],
        None,
        ["give time exactly one way", "--rate HZ", "--time-column NAME"],
        id="no-time-source",
    ),
    pytest.param(
        headed_input,
        ["--columns", "time,fin,roll", "--rate", "10"],
        None,
        ["give time exactly one way"],
        id="two-time-sources",
    ),
    pytest.param(
        headed_input,
        ["--columns", "skip,fin,roll", "--time-column", "time"],
        2,
        ["--time-column 'time' is not in the header (t, fin, roll)"],
        id="time-column-not-in-header",
    ),
    pytest.param(
        headed_input,
        ["--columns", "skip,fin,roll", "--time-column", "fin"],
        None,
        ["--time-column 'fin' is also given the role 'fin'"],
        id="time-column-has-other-role",
    ),
    pytest.param(
        headerless_input,
        ["--columns", "fin,roll", "--no-header", "--time-column", "4"],
        None,
        ["--time-column 4 is outside columns 1..2"],
        id="time-column-number-out-of-range",
    ),
    pytest.param(
        lambda: [
            line.replace("0.2,", "0.25,") if line.startswith("0.2,") else line
            for line in headed_input()
        ],
        ["--columns", "time,fin,roll"],
        2 + 3,  # header on line 2, row 2 (t = 0.2 s) on line 5
        ["irregular sampling", "from 0.1 s to 0.25 s"],
        id="irregular-time-column",
    ),
    pytest.param(
        lambda: headerless_input()[: input_line(MIN_SAMPLES - 1) - 1],
        HEADERLESS,
        None,
        [f"too few samples: {MIN_SAMPLES - 1}"],
        id="too-few-samples",
    ),
    pytest.param(
        lambda: [*INPUT_COMMENT_LINES, *[f"3,{k}" for k in range(N_ROWS)]],
        HEADERLESS,
        None,
        ["fin angle (fin_deg) never changes"],
        id="fin-constant",
    ),
    pytest.param(
        lambda: headed_input()[:2],
        ["--columns", "time,fin,roll"],
        None,
        ["no data rows"],
        id="header-only",
    ),
    pytest.param(lambda: [], HEADERLESS, None, ["no data rows"], id="empty-input"),
]


@pytest.mark.parametrize("preexisting", [False, True], ids=["no-out", "existing-out"])
@pytest.mark.parametrize(("build", "args", "line", "keywords"), BAD_IMPORTS)
def test_import_csv_rejects_bad_input(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    build: Callable[[], Lines],
    args: list[str],
    line: int | None,
    keywords: list[str],
    preexisting: bool,
) -> None:
    src = write_lines(tmp_path / "run.txt", build())
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    rec = out_dir / "rec.csv"
    old = b"# format: rocketroll-recording/1\n# an earlier recording, not to be touched\n"
    if preexisting:
        rec.write_bytes(old)

    code, out, err = run_cli(capsys, "import-csv", src, "--out", rec, *args)

    assert code == 2
    assert_one_line_error(err, "import-csv", src, line, keywords)
    assert out == ""
    if preexisting:
        assert rec.read_bytes() == old
        assert files_in(out_dir) == ["rec.csv"]
    else:
        assert not rec.exists()
        assert files_in(out_dir) == []


def test_import_csv_rejects_a_zero_rate_before_reading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = write_lines(tmp_path / "run.txt", headerless_input())
    rec = tmp_path / "rec.csv"
    code, out, err = run_cli(
        capsys, "import-csv", src, "--out", rec, "--columns", "fin,roll", "--no-header",
        "--rate", "0",
    )  # fmt: skip
    assert (code, out) == (2, "")
    assert err == "rocketroll import-csv: error: --rate: must be in (0, 1e+07] Hz, got 0.0\n"
    assert files_in(tmp_path) == ["run.txt"]
    # The Python API names the file and the setting.
    with pytest.raises(RecordingError, match=r"run.txt: rate_hz: must be in \(0, "):
        import_csv(src, ["fin", "roll"], header=False, rate_hz=0.0)


def test_import_csv_rejects_missing_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "missing.txt"
    rec = tmp_path / "rec.csv"
    code, _, err = run_cli(capsys, "import-csv", src, "--out", rec, *HEADERLESS)
    assert code == 2
    assert_one_line_error(err, "import-csv", src, None, ["cannot read"])
    assert files_in(tmp_path) == []


def test_import_csv_good_input_positive_control(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The inputs the failure cases start from are themselves accepted."""
    for build, args in (
        (headerless_input, HEADERLESS),
        (headed_input, ["--columns", "time,fin,roll"]),
    ):
        src = write_lines(tmp_path / "run.txt", build())
        rec = tmp_path / "rec.csv"
        code, out, err = run_cli(capsys, "import-csv", src, "--out", rec, *args)
        assert (code, err) == (0, "")
        assert out.startswith(f"wrote {rec}: Recording(name='run'")
        loaded = load_recording(rec)
        assert loaded.n_samples == N_ROWS
        assert loaded.dt_s == pytest.approx(DT)
        rec.unlink()


def test_import_csv_subprocess_exit_code(tmp_path: Path) -> None:
    src = write_lines(tmp_path / "run.txt", edit_input_row(7, "12.5,3,4")())
    rec = tmp_path / "rec.csv"
    proc = run_subprocess(tmp_path, "import-csv", src, "--out", rec, *HEADERLESS)
    assert proc.returncode == 2
    assert_one_line_error(
        proc.stderr, "import-csv", src, input_line(7), ["3 cells but --columns names 2"]
    )
    assert proc.stdout == ""
    assert files_in(tmp_path) == ["run.txt"]


# --------------------------------------------------------------------------- tunnel


@pytest.mark.parametrize(
    ("args", "keywords"),
    [
        pytest.param(["--no-encoder"], ["--no-encoder: needs a rate gyro"], id="no-sensor"),
        pytest.param(["--seed", "-1"], ["--seed: must be in [0, ", "got -1"], id="negative-seed"),
        pytest.param(
            ["--fin-range", "50"], ["--fin-range: must be in (2.5, 40] °"], id="fin-range"
        ),
        # Found in review: these reached run_tunnel and ended in a traceback with exit 1.
        pytest.param(["--servo-rate", "-5"], ["--servo-rate: must be in (0, "], id="servo-rate"),
        pytest.param(["--servo-rate", "0"], ["--servo-rate: must be in (0, "], id="servo-rate-0"),
        pytest.param(["--alpha", "0"], ["--alpha: must be at least 0.001 in size"], id="alpha-0"),
        pytest.param(["--log-dt", "inf"], ["--log-dt: must be finite"], id="log-dt-inf"),
        pytest.param(["--log-dt", "-0.1"], ["--log-dt: must be in [0.001, 1] s"], id="log-dt-neg"),
        pytest.param(["--substeps", "0"], ["--substeps: must be in [1, 1000]"], id="substeps-0"),
        pytest.param(
            ["--turbulence-sd", "-1"], ["--turbulence-sd: must be in [0, 45]"], id="sd-negative"
        ),
        pytest.param(
            ["--schedule", "staircase", "--steps", "0"],
            ["--steps: must be in [1, 200]"],
            id="steps-0",
        ),
        pytest.param(
            ["--schedule", "staircase", "--dwell-min", "5", "--dwell-max", "1"],
            ["--dwell-min: must be at least --log-dt"],
            id="dwell-reversed",
        ),
        pytest.param(
            ["--schedule", "staircase", "--dwell-min", "nan"],
            ["--dwell-min: must be finite"],
            id="dwell-nan",
        ),
        pytest.param(
            ["--dwell-min", "0.01", "--dwell-max", "0.01"],
            ["--dwell-min: must be at least --log-dt"],
            id="dwell-below-log-dt",
        ),
        pytest.param(["--fin-range", "1"], ["--fin-range: must be in"], id="fin-range-small"),
        pytest.param(["--fin-range", "nan"], ["--fin-range: must be finite"], id="fin-range-nan"),
    ],
)
def test_tunnel_rejects_bad_spec(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], keywords: list[str]
) -> None:
    rec = tmp_path / "rec.csv"
    code, out, err = run_cli(capsys, "tunnel", "--out", rec, *args)
    assert code == 2
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith("rocketroll tunnel: error: ")
    for keyword in keywords:
        assert keyword in err
    assert out == ""
    assert files_in(tmp_path) == []


def test_tunnel_subprocess_exit_code(tmp_path: Path) -> None:
    rec = tmp_path / "rec.csv"
    proc = run_subprocess(tmp_path, "tunnel", "--out", rec, "--no-encoder")
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1
    assert proc.stderr.startswith("rocketroll tunnel: error: ")
    assert "--no-encoder: needs a rate gyro" in proc.stderr
    assert proc.stdout == ""
    assert files_in(tmp_path) == []


def test_trailing_comma_in_header_is_reported_at_the_header(tmp_path, capsys) -> None:
    bad = tmp_path / "bad.csv"
    lines = valid_lines()
    header = next(i for i, line in enumerate(lines) if line.startswith("time_s"))
    lines[header] += ","
    lines[header + 1 :] = [line + "," for line in lines[header + 1 :]]
    bad.write_text("\n".join(lines) + "\n")
    code, _out, err = run_cli(capsys, "info", bad)
    assert code == 2
    assert f"{bad}:{header + 1}: empty column name" in err


# ------------------------------------------------------------- output paths and strict input


def test_output_that_cannot_be_written_is_one_line_exit_2(tmp_path: Path, capsys) -> None:
    folder = tmp_path / "folder"
    folder.mkdir()
    code, out, err = run_cli(capsys, "tunnel", "--out", folder)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "is a folder" in err and str(folder) in err
    assert list(folder.iterdir()) == []


def test_info_writes_all_outputs_or_none(tmp_path: Path, capsys) -> None:
    good = write_lines(tmp_path / "good.csv", valid_lines())
    summary = tmp_path / "s.json"
    blocked = tmp_path / "blocked.png"
    blocked.mkdir()  # the figure cannot be written: the JSON must not be either
    code, _out, err = run_cli(capsys, "info", good, "--json", summary, "--plot", blocked)
    assert code == 2 and "is a folder" in err and err.count("\n") == 1
    assert not summary.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocked.png", "good.csv"]
    code, _out, err = run_cli(
        capsys, "info", good, "--json", summary, "--plot", tmp_path / "fig.txt"
    )
    assert code == 2 and "ending in .png" in err and not summary.exists()


@pytest.mark.parametrize("cell", ["5_0", "\u0663", "\uff15", "0x10", "1,5"])
def test_cells_must_be_ascii_decimal_numbers(tmp_path: Path, capsys, cell: str) -> None:
    lines = set_cell(40, "fin_cmd_deg", cell)(valid_lines())
    bad = write_lines(tmp_path / "bad.csv", lines)
    code, _out, err = run_cli(capsys, "info", bad)
    assert code == 2 and f"{bad}:{row_line(40)}:" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    ("line", "keyword"),
    [
        ("# seed: abc", "'seed' must be a non-negative integer"),
        ("# truth.alpha: x", "'truth.alpha' must be a number"),
        ("# sensor.encoder_counts: inf", "must be finite"),
    ],
)
def test_typed_metadata_is_checked_at_its_line(tmp_path: Path, capsys, line, keyword) -> None:
    bad = write_lines(tmp_path / "bad.csv", [line, *valid_lines()])
    code, _out, err = run_cli(capsys, "info", bad)
    assert code == 2 and f"{bad}:1: " in err and keyword in err


def test_empty_delimiter_is_a_clear_error(tmp_path: Path, capsys) -> None:
    src = write_lines(tmp_path / "run.txt", headerless_input())
    out = tmp_path / "rec.csv"
    code, _o, err = run_cli(capsys, "import-csv", src, "--out", out, *HEADERLESS, "--delimiter", "")
    assert code == 2 and "--delimiter must be one character" in err and not out.exists()
