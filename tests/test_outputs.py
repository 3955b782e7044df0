"""No command destroys a file it did not make.

Before any work, every command refuses an output that is one of its inputs (the same
file, links included) and an existing output that holds another kind of content than it
writes (read from the file's first bytes); writing again over its own earlier output is
allowed.  Each refusal is one line, exit 2, and leaves every file as it was.
"""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import pytest

from identification.instruments.bundled import bundled_path
from rocketroll.cli import main as rocketroll
from rocketroll_common.files import MANIFEST, content_kind
from tests.agents.test_sweep import TINY_PPO
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


# ------------------------------------------------------------------------ output folders
EVAL = ["eval", "--policy", "pid", "--episodes", "1"]


def _users_folder(folder: Path, names: dict[str, bytes]) -> dict[Path, bytes]:
    """``folder`` holding the user's own files (and a note no command names)."""
    folder.mkdir()
    made = {folder / name: data for name, data in {**names, "notes.txt": b"mine\n"}.items()}
    for path, data in made.items():
        path.write_bytes(data)
    return made


def _manifest(folder: Path) -> dict[str, str]:
    record = json.loads((folder / MANIFEST).read_text("utf-8"))
    files: dict[str, str] = record["files"]
    return files


def _train(tmp_path: Path, out: Path, *more: str) -> list[str]:
    recipe = tmp_path / "tiny-ppo.yml"
    recipe.write_text(TINY_PPO, encoding="utf-8")
    return ["train", "ppo", "--hyperparams", str(recipe), "--out", str(out), "--no-progress-bar",
            "--eval-freq", "0", "--eval-episodes", "1", *more]  # fmt: skip


def test_eval_into_a_folder_of_the_users_files_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`eval --out myfolder` replaced the user's table.md, results.json and a recording
    saved as episode.png."""
    folder = tmp_path / "myfolder"
    mine = _users_folder(
        folder,
        {
            "table.md": b"# my table\n",
            "results.json": b'{"mine": 1}\n',
            "episode.png": RECORDING.read_bytes(),
        },
    )
    err = refused(capsys, [*EVAL, "--out", str(folder)], f"--out {folder}: table.md exists")
    assert "rocketroll did not write it there; give another folder, or --force" in err
    assert {p: p.read_bytes() for p in folder.iterdir()} == mine  # nothing added either


def test_identify_report_over_the_users_report_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`identify rec.csv --report rep3` replaced a recording saved as rep3/report.md."""
    folder = tmp_path / "rep3"
    mine = _users_folder(folder, {"report.md": RECORDING.read_bytes()})
    argv = ["identify", str(RECORDING), "--method", "paper", "--report", str(folder)]
    refused(capsys, argv, f"--report {folder}: report.md exists", "--force")
    # The figures are named before the fits too.
    (folder / "report.md").unlink()
    (folder / "fit-paper.png").write_bytes(PNG)
    mine = {
        **{p: d for p, d in mine.items() if p.name != "report.md"},
        folder / "fit-paper.png": PNG,
    }
    refused(capsys, argv, f"--report {folder}: fit-paper.png exists")
    assert {p: p.read_bytes() for p in folder.iterdir()} == mine


def test_train_into_a_folder_of_the_users_files_is_refused_before_training(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`train ppo --out tr3` replaced the user's settings.json and normalize.json."""
    folder = tmp_path / "tr3"
    mine = _users_folder(folder, {"settings.json": b'{"mine": 1}\n', "normalize.json": b"{}\n"})
    refused(capsys, _train(tmp_path, folder), f"--out {folder}: ", "normalize.json", "--force")
    assert {p: p.read_bytes() for p in folder.iterdir()} == mine
    # A checkpoint SB3 would save over (64 env-steps, one every 32) is named before too.
    (folder / "settings.json").unlink()
    (folder / "normalize.json").unlink()
    (folder / "checkpoints").mkdir()
    (folder / "checkpoints" / "ppo_64_steps.zip").write_bytes(b"mine")
    argv = _train(tmp_path, folder, "--checkpoint-freq", "32")
    refused(capsys, argv, "checkpoints/ppo_64_steps.zip exists")
    assert (folder / "checkpoints" / "ppo_64_steps.zip").read_bytes() == b"mine"
    assert sorted(p.name for p in folder.iterdir()) == ["checkpoints", "notes.txt"]


def test_train_twice_into_one_folder_and_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "run"
    argv = _train(tmp_path, folder, "--checkpoint-freq", "32")
    for _ in range(2):
        assert rocketroll(argv) == 0, capsys.readouterr().err
    capsys.readouterr()
    listed = _manifest(folder)
    for name in ("model.zip", "settings.json", "normalize.json", "vecnormalize.pkl",
                 "checkpoints/ppo_64_steps.zip", "checkpoints/ppo_vecnormalize_64_steps.pkl",
                 "logs/progress.csv"):  # fmt: skip
        assert name in listed, name
    assert MANIFEST not in listed
    (folder / "settings.json").write_text("{}\n")  # the user's now
    capsys.readouterr()
    refused(capsys, argv, "settings.json was changed since rocketroll wrote it")
    assert (folder / "settings.json").read_text() == "{}\n"
    assert rocketroll([*argv, "--force"]) == 0
    assert json.loads((folder / "settings.json").read_text())["algorithm"] == "ppo"
    capsys.readouterr()


def test_the_same_command_twice_into_one_folder_and_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "eval"
    for _ in range(2):
        assert rocketroll([*EVAL, "--out", str(folder)]) == 0
    out = capsys.readouterr().out
    written = {"table.md", "results.json", "episode.png", "errors.png"}
    assert set(_manifest(folder)) == written  # the manifest does not list itself
    assert sorted(p.name for p in folder.iterdir()) == sorted([*written, MANIFEST])
    assert MANIFEST not in out
    # --force replaces what the user put there, and from then on it is rocketroll's.
    (folder / "table.md").write_text("# my own notes\n")
    capsys.readouterr()
    refused(capsys, [*EVAL, "--out", str(folder)], "table.md was changed since")
    assert (folder / "table.md").read_text() == "# my own notes\n"
    assert rocketroll([*EVAL, "--out", str(folder), "--force"]) == 0
    assert (folder / "table.md").read_text().startswith("|")
    assert rocketroll([*EVAL, "--out", str(folder)]) == 0
    # A file of the manifest's name that is not one is the user's.
    (folder / MANIFEST).write_text("my notes\n")
    capsys.readouterr()
    refused(capsys, [*EVAL, "--out", str(folder)], f"{MANIFEST} exists and is not rocketroll's")
    assert (folder / MANIFEST).read_text() == "my notes\n"
    capsys.readouterr()


def test_an_empty_or_new_folder_and_a_folder_of_other_files_are_fine(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    other = tmp_path / "other"
    mine = _users_folder(other, {"my-table.md": b"mine\n"})
    for folder in (empty, tmp_path / "new" / "deeper", other):
        assert rocketroll([*EVAL, "--out", str(folder)]) == 0
    assert all(p.read_bytes() == data for p, data in mine.items())
    capsys.readouterr()


def test_a_resume_that_is_not_a_model_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`train ppo --resume some.csv` ended in Stable-Baselines3's ValueError traceback."""
    refused(capsys, ["train", "ppo", "--resume", str(RECORDING)], "--resume", "not a")
    archive = tmp_path / "other.zip"
    with zipfile.ZipFile(archive, "w") as handle:
        handle.writestr("notes.txt", "mine")
    refused(
        capsys,
        ["train", "ppo", "--resume", str(archive)],
        f"--resume: {archive}: a zip archive, but not a Stable-Baselines3 model",
    )
