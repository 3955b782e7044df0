"""No command destroys a file it did not make.

Before any work, every command refuses an output that is one of its inputs (the same
file, links included) and an existing output that holds another kind of content than it
writes (read from the file's first bytes); writing again over its own earlier output is
allowed.  Each refusal is one line, exit 2, and leaves every file as it was.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from identification.bundled import bundled_path
from rocketroll.cli import main as rocketroll
from rocketroll_common.files import content_kind
from tests.cli import refused

RECORDING = bundled_path("tunnel-paper-seed0")
PNG = b"\x89PNG\r\n\x1a\n" + b"\0" * 32


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    """One file of every kind, and a foreign CSV log."""
    made = {
        "recording": tmp_path / "rec.csv",
        "json": tmp_path / "summary.json",
        "png": tmp_path / "figure.png",
        "sqlite": tmp_path / "my.sqlite",
        "log": tmp_path / "log.csv",
    }
    shutil.copy(RECORDING, made["recording"])
    made["json"].write_text('{"a": 1}\n')
    made["png"].write_bytes(PNG)
    made["sqlite"].write_bytes(b"SQLite format 3\x00" + b"\0" * 84)
    made["log"].write_text("t,roll,fin\n0.0,1.0,2.0\n0.1,1.1,2.0\n")
    return made


def _unchanged(files: dict[str, Path], before: dict[str, bytes]) -> None:
    for name, path in files.items():
        assert path.read_bytes() == before[name], name


def test_the_kind_of_a_file_is_read_from_its_first_bytes(files: dict[str, Path]) -> None:
    assert {name: content_kind(path) for name, path in files.items()} == {
        "recording": "recording",
        "json": "json",
        "png": "png",
        "sqlite": "sqlite",
        "log": "other",
    }


def test_an_output_that_is_the_input_is_refused(
    files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = {name: path.read_bytes() for name, path in files.items()}
    rec, log = str(files["recording"]), str(files["log"])
    refused(capsys, ["info", rec, "--json", rec], "--json", f"is the input {rec};")
    refused(capsys, ["identify", rec, "--json", rec], "--json", f"is the input {rec};")
    columns = ["--columns", "time,roll,fin"]
    refused(capsys, ["import-csv", log, "--out", log, *columns], "--out", f"is the input {log};")
    # A link to the input is the input.
    link = tmp_path / "link.csv"
    link.symlink_to(files["recording"])
    refused(capsys, ["info", rec, "--json", str(link)], f"is the input {rec};")
    other = tmp_path / "other.csv"
    shutil.copy(RECORDING, other)
    refused(
        capsys,
        ["identify", rec, "--json", str(other), "--together", str(other)],
        "is the input --together",
    )
    _unchanged(files, before)


@pytest.mark.parametrize(
    ("argv", "output", "kind_there", "needles"),
    [
        (["tunnel", "--out", "{json}"], "json", "JSON", ["--out", "not a rocketroll recording"]),
        (
            ["import-csv", "{log}", "--columns", "time,roll,fin", "--out", "{json}"],
            "json",
            "JSON",
            ["--out"],
        ),
        (["record-flight", "--out", "{log}"], "log", "other content", ["--out"]),
        (
            ["info", "{recording}", "--json", "{sqlite}"],
            "sqlite",
            "an SQLite database",
            ["--json", "not JSON"],
        ),
        (["info", "{recording}", "--plot", "{png}x.png"], None, None, []),
        (
            ["identify", "{recording}", "--json", "{sqlite}"],
            "sqlite",
            "an SQLite database",
            ["--json", "not JSON"],
        ),
        (["env", "rollout", "--frames", "{png}"], None, None, []),
        (["env", "ascent", "--plot", "{png}"], None, None, []),
    ],
    ids=[
        "tunnel",
        "import-csv",
        "record-flight",
        "info",
        "info-plot",
        "identify",
        "rollout",
        "ascent",
    ],
)
def test_an_existing_output_of_another_kind_is_refused(
    argv: list[str],
    output: str | None,
    kind_there: str | None,
    needles: list[str],
    files: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
) -> None:
    before = {name: path.read_bytes() for name, path in files.items()}
    words = [w.format(**{k: str(v) for k, v in files.items()}) for w in argv]
    if output is None:  # a PNG output over a recording given a PNG's name
        target = tmp_path / "looks-like.png"
        shutil.copy(RECORDING, target)
        words = [str(target) if w.startswith(str(files["png"])) else w for w in words]
        kind_there, needles = "a rocketroll recording", ["not a PNG image"]
        before_target = target.read_bytes()
    refused(capsys, words, f"holds {kind_there}", *needles)
    _unchanged(files, before)
    if output is None:
        assert target.read_bytes() == before_target


def test_a_png_is_named_png(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    refused(capsys, ["env", "rollout", "--frames", str(tmp_path / "x.txt")], "ending in .png")
    refused(capsys, ["env", "ascent", "--plot", str(tmp_path / "x.jpg")], "ending in .png")
    assert list(tmp_path.iterdir()) == []


def test_a_database_option_naming_another_kind_of_file_is_refused_before_the_work(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    before = {name: path.read_bytes() for name, path in files.items()}
    rec = str(files["recording"])
    for argv in (
        ["identify", rec, "--db", rec],
        ["db", "add", rec, "--db", str(files["json"])],
        ["db", "list", "--db", str(files["png"])],
        ["eval", "--db", rec],
        ["tune", "pid", "--db", str(files["log"])],
    ):
        refused(capsys, argv, "--db", "not an SQLite database")
    _unchanged(files, before)


def test_writing_again_over_its_own_output_is_allowed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec, summary, figure = tmp_path / "rec.csv", tmp_path / "s.json", tmp_path / "f.png"
    for _ in range(2):
        assert rocketroll(["tunnel", "--seed", "3", "--out", str(rec)]) == 0
        argv = ["info", str(rec), "--json", str(summary), "--plot", str(figure)]
        assert rocketroll(argv) == 0
    assert [content_kind(p) for p in (rec, summary, figure)] == ["recording", "json", "png"]
    empty = tmp_path / "empty.json"
    empty.touch()  # an empty file holds nothing to lose
    assert rocketroll(["info", str(rec), "--json", str(empty)]) == 0
    capsys.readouterr()
