"""What a new user hit, one test (or a few) per case.

Each case was found by installing the wheel into a fresh environment and
running every documented command from another folder; each test here fails on the
code before the fix.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import tarfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import rollenv  # noqa: F401  (registers the environments)
from identification.instruments.bundled import bundled_path
from identification.instruments.tunnel import TunnelSpec
from identification.methods.pipeline import IdentifyOptions
from identification.recordings.recording import RecordingError, load_recording
from rocketroll.cli import main as rocketroll
from rocketroll_common.files import write_all_atomic, write_atomic
from rocketroll_common.settings import _fields
from tests.rollenv.conftest import array_bank

REPO = Path(__file__).resolve().parents[1]
FAST = IdentifyOptions(noise_runs=0)


def cli(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str, str]:
    code = rocketroll([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> bool:
    return err.count("\n") == 1 and "Traceback" not in err


def with_cell(source: Path, target: Path, row: int, column: str, value: str) -> int:
    """Copy a recording with one cell replaced; the file line of that row."""
    lines = source.read_text(encoding="utf-8").splitlines()
    header = next(k for k, line in enumerate(lines) if not line.startswith("#"))
    names = lines[header].split(",")
    if row < 0:  # from the end, as for a list
        row += len(lines) - header - 1
    cells = lines[header + 1 + row].split(",")
    cells[names.index(column)] = value
    lines[header + 1 + row] = ",".join(cells)
    target.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return header + 2 + row


# ------------------------------------------------------------------ 1. absurd finite values
@pytest.mark.parametrize(
    ("column", "value", "problem"),
    [
        ("roll_deg", "1e308", "roll_deg is 1e+308: implausible"),
        ("roll_deg", "1e30", "roll_deg is 1e+30: implausible"),
        ("roll_deg", "5e6", "roll_deg jumps from"),
        ("fin_cmd_deg", "1e30", "fin_cmd_deg is 1e+30: implausible"),
        ("ud_true_deg", "1e30", "ud_true_deg is 1e+30: implausible"),
        ("fin_deg", "91", "fin_deg is 91: implausible"),
        ("roll_rate_dps", "-3e4", "roll_rate_dps is -30000: implausible"),
        ("time_s", "1e13", "time_s is 1e+13: implausible"),
    ],
)
def test_an_absurd_value_is_refused_naming_its_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], column: str, value: str, problem: str
) -> None:
    bad = tmp_path / "bad.csv"
    # seed 4 has the gyro and the measured fin; its last row for time (still increasing)
    source = bundled_path("tunnel-paper-seed4" if column != "roll_deg" else "tunnel-paper-seed0")
    row = -1 if column == "time_s" else 3000
    line = with_cell(source, bad, row, column, value)
    for argv in (["identify", bad, "--mc-runs", "0"], ["db", "add", bad, "--db", tmp_path / "d"]):
        code, out, err = cli(capsys, *argv)
        assert code == 2 and out == "" and one_line(err), err
        assert f"{bad}:{line}: " in err and problem in err
    assert not (tmp_path / "d").exists()
    with pytest.raises(RecordingError, match="implausible"):
        load_recording(bad)


# ------------------------------------------------------------------ 2. tunnel options bounded
@pytest.mark.parametrize(
    "argv",
    [
        ["--turbulence-sd", "1e200"],
        ["--turbulence-sd", "1e308"],
        ["--gyro-noise", "1e308"],
        ["--correlation-time", "1e9"],
        ["--encoder-counts", "99999999999"],
        ["--beta-bar", "0"],
        ["--alpha-bar", "-0.5"],  # a(θ) would not be a damping within the fin range
    ],
)
def test_every_tunnel_number_is_bounded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    out = tmp_path / "rec.csv"
    code, printed, err = cli(capsys, "tunnel", "--out", out, *argv)
    assert code == 2 and printed == "" and one_line(err), err
    assert err.startswith(f"rocketroll tunnel: error: {argv[0]}: "), err
    assert not out.exists()


def test_every_numeric_option_of_every_command_declares_its_range() -> None:
    """Not only the tunnel's: each number a command takes has a physical or sane range."""
    from rocketroll.cli import COMMANDS, command

    def leaves(cls: type) -> list[Any]:
        out: list[Any] = []
        for f in _fields(cls):
            out += leaves(f.base) if f.spec.flatten else [f]
        return out

    checked = 0
    for name in COMMANDS:
        stack = [command(name)]
        while stack:
            cmd = stack.pop()
            stack += cmd.subcommands
            if cmd.args is None:
                continue
            for f in leaves(cmd.args):
                kind = f.item if f.base is tuple else f.base
                if kind in (int, float) and f.spec.cli:
                    spec = f.spec
                    low = spec.ge is not None or spec.gt is not None
                    high = spec.le is not None or spec.lt is not None
                    assert low and high, f"rocketroll {name}: {f.flag} has no range"
                    checked += 1
    assert checked > 40


def test_the_largest_turbulence_allowed_writes_ordinary_cells() -> None:
    from identification.instruments.tunnel import run_tunnel
    from identification.recordings.recording import recording_text

    spec = TunnelSpec(turbulence_sd=45.0, turbulence="student-t", dof=2.1, seed=3, steps=3)
    text = recording_text(run_tunnel(dataclasses.replace(spec, schedule="staircase")))
    rows = [line for line in text.splitlines() if not line.startswith("#")][1:]
    assert max(len(cell) for row in rows for cell in row.split(",")) < 20


# ------------------------------------------------------------------ 3. a YAML that is not UTF-8
def test_a_hyperparameter_file_that_is_not_utf8_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "hp.yml"
    bad.write_bytes("RocketRoll-v0:\n  n_envs: 2  # réglage\n".encode("latin-1"))
    code, _, err = cli(capsys, "train", "ppo", "--hyperparams", bad, "--out", tmp_path / "run")
    assert code == 2 and one_line(err), err
    assert f"{bad}: not UTF-8 text (byte" in err
    assert not (tmp_path / "run").exists()


# ------------------------------------------------------------------ 4. outputs checked first
def test_eval_checks_its_output_folder_before_it_evaluates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], default_db: Path
) -> None:
    taken = tmp_path / "taken"
    taken.write_text("mine\n", encoding="utf-8")
    start = time.perf_counter()
    code, out, err = cli(capsys, "eval", "--policy", "trim", "--episodes", "2", "--out", taken)
    assert code == 2 and out == "" and one_line(err), err  # nothing evaluated, nothing printed
    assert f"--out {taken}: exists and is not a folder" in err
    assert taken.read_text(encoding="utf-8") == "mine\n"
    assert time.perf_counter() - start < 60  # (a sanity bound, not a timing claim)


def test_an_output_that_cannot_be_written_is_refused_before_the_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("rocketroll_common.files.os.access", lambda path, mode: False)
    code, out, err = cli(capsys, "tunnel", "--out", tmp_path / "rec.csv")
    assert code == 2 and out == "" and one_line(err)
    assert f"--out {tmp_path / 'rec.csv'}: cannot write in {tmp_path}" in err


def test_a_failing_write_names_the_users_path_not_the_staging_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "table.md"

    def refuse(src: str, dst: object) -> None:
        raise PermissionError(13, "Permission denied", src)

    monkeypatch.setattr("rocketroll_common.files.os.replace", refuse)
    with pytest.raises(PermissionError) as caught:
        write_all_atomic({target: "x"})
    assert caught.value.filename == str(target)
    assert list(tmp_path.iterdir()) == []  # the staged file is gone too


def test_written_files_get_the_permissions_of_open_and_keep_their_own(tmp_path: Path) -> None:
    """mkstemp stages private (0600) files: a new output gets what open() would give, a
    replaced one keeps its mode (the landed evaluation once left 0600 tables)."""
    old = os.umask(0o022)
    try:
        new, kept = tmp_path / "new.md", tmp_path / "kept.md"
        kept.write_text("before")
        kept.chmod(0o640)
        write_all_atomic({new: "x", kept: "y"})
        assert stat.S_IMODE(new.stat().st_mode) == 0o644
        assert stat.S_IMODE(kept.stat().st_mode) == 0o640 and kept.read_text() == "y"
        os.umask(0o077)
        write_atomic(tmp_path / "private.md", "z")
        assert stat.S_IMODE((tmp_path / "private.md").stat().st_mode) == 0o600
    finally:
        os.umask(old)


# ------------------------------------------------------------------ 5. Ctrl-C
_STARTED: list[subprocess.Popen[str]] = []


@pytest.fixture(autouse=True)
def _no_process_outlives_its_test() -> Iterator[None]:
    yield
    while _STARTED:
        proc = _STARTED.pop()
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def _sigint_as_from_a_terminal() -> None:
    # A shell starts background jobs with SIGINT ignored, and a child inherits that; a
    # Python started so never raises KeyboardInterrupt. Ctrl-C is what is under test.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(argv: Sequence[object], cwd: Path, **env: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "rocketroll", *[str(a) for a in argv]],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1", **env},
        preexec_fn=_sigint_as_from_a_terminal,
    )
    _STARTED.append(proc)
    return proc


def interrupt(proc: subprocess.Popen[str], ready: str, *, stream: str = "stdout") -> str:
    """Wait for ``ready`` on ``stream``, send SIGINT, return all of stderr."""
    pipe = proc.stdout if stream == "stdout" else proc.stderr
    assert pipe is not None
    seen = ""
    while ready not in seen:
        chunk = pipe.read(1)
        assert chunk, f"ended before saying {ready!r}: {seen[-500:]}"
        seen += chunk
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    return (seen + err) if stream == "stderr" else err


def assert_interrupted(proc: subprocess.Popen[str], err: str, command: str) -> None:
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"rocketroll {command}: interrupted"), err


def test_ctrl_c_during_eval(tmp_path: Path, default_db: Path) -> None:
    # One quick controller (the others' designs and torch only delay "policies:") and
    # more episodes than it runs before the Ctrl-C arrives, whatever the machine's load.
    out = tmp_path / "eval"
    argv = ["eval", "--policy", "pid", "--episodes", "1000", "--out", out]
    proc = start(argv, tmp_path, ROCKETROLL_DB=str(default_db))
    err = interrupt(proc, "policies:")
    assert_interrupted(proc, err, "eval")
    assert not out.exists()  # nothing half-made


def test_ctrl_c_during_db_build(tmp_path: Path) -> None:
    target = tmp_path / "db" / "new.sqlite"
    proc = start(["db", "build", "--db", target], tmp_path)
    err = interrupt(proc, "building disturbance database", stream="stderr")
    assert_interrupted(proc, err, "db")
    assert not (tmp_path / "db").exists()  # no database, no leftovers, no folder


def test_a_ctrl_c_while_a_checkpoint_is_written_waits_for_it() -> None:
    """A Ctrl-C inside a checkpoint's write (torch's zip writer) is held until the files
    are whole, then raised: never a file cut short and a traceback."""
    from rocketroll_common.settings import interrupts_held

    before = signal.getsignal(signal.SIGINT)
    written = []
    with pytest.raises(KeyboardInterrupt), interrupts_held():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
        written.append("whole")
    assert written == ["whole"]
    assert signal.getsignal(signal.SIGINT) is before
    with interrupts_held():  # no Ctrl-C: nothing raised
        written.append("again")
    assert written == ["whole", "again"]


@pytest.fixture(scope="module")
def small_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A database of two bundled recordings (one in each split) by the method the
    environments replay by default (``ml``, its posterior draws) alone, for the training
    tests (which only read it)."""
    from disturbances.default import build_database

    db = tmp_path_factory.mktemp("small-db") / "small.sqlite"
    recordings = [bundled_path(n) for n in ("tunnel-paper-seed0", "tunnel-paper-seed4")]
    return build_database(db, recordings, options=FAST, surrogates=0, methods=("ml",))


def test_ctrl_c_during_training_leaves_a_resumable_checkpoint(
    tmp_path: Path, small_db: Path
) -> None:
    db = small_db
    hp = tmp_path / "hp.yml"
    hp.write_text(
        # 200 checkpoints (the most a run may write), each rollout slowed by its epochs
        "RocketRoll-v0:\n  n_envs: 2\n  n_timesteps: 12800\n  policy: MlpPolicy\n"
        "  normalize: true\n  n_steps: 32\n  batch_size: 32\n  n_epochs: 50\n"
        "  policy_kwargs: {net_arch: [8]}\n",
        encoding="utf-8",
    )
    run = tmp_path / "run"
    argv = ["train", "ppo", "--db", db, "--hyperparams", hp, "--out", run, "--eval-freq", "0"]
    proc = start([*argv, "--checkpoint-freq", "64", "--eval-episodes", "1"], tmp_path)
    checkpoint = run / "checkpoints" / "ppo_128_steps.zip"
    deadline = time.monotonic() + 300
    while not checkpoint.exists():
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert_interrupted(proc, err, "train")
    assert "resumable checkpoint" in err and "--resume" in err
    assert not (run / "model.zip").exists()  # no half-trained model that looks like a result
    saved = max(run.glob("checkpoints/ppo_*_steps.zip"), key=lambda p: int(p.stem.split("_")[1]))
    assert (
        saved.with_name(saved.name.replace("ppo_", "ppo_vecnormalize_"))
        .with_suffix(".pkl")
        .is_file()
    )
    done_steps = int(saved.stem.split("_")[1])
    # Going on from it finishes the run, in the same folder.
    steps = done_steps + 64
    again = [*map(str, argv), "--resume", str(saved), "--timesteps", str(steps)]
    done = subprocess.run(
        [sys.executable, "-m", "rocketroll", *again, "--no-progress-bar", "--eval-episodes", "1"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert (run / "model.zip").is_file()
    assert f"trained 64 env-steps (resumed at {done_steps:,}: {steps:,} in all)" in done.stdout


# ------------------------------------------------------------------ 6. leftovers and folders
def test_a_killed_builds_leftovers_are_cleaned_by_the_next_build(tmp_path: Path) -> None:
    target = tmp_path / "x.sqlite"
    stale = [tmp_path / f".x.sqlite.abc123.building{s}" for s in ("", "-wal", "-shm")]
    for path in stale:
        path.write_bytes(b"half a database")
    from disturbances.default import build_database

    build_database(target, [bundled_path("tunnel-paper-seed0")], options=FAST, surrogates=0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.sqlite"]


def test_a_build_whose_pinned_process_is_killed_leaves_no_files_and_no_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A pinned build that could not clean up (killed after an interrupt's grace) leaves
    its half-written files; the build that started it removes them, and so the folders it
    made, before the error goes on."""
    import disturbances.default as default

    target = tmp_path / "a" / "b" / "new.sqlite"

    def killed(*args: object, **kwargs: object) -> None:
        for suffix in ("", "-wal", "-shm"):
            (target.parent / f".new.sqlite.k1ll3d.building{suffix}").write_bytes(b"half")
        raise RuntimeError("the pinned computation of _build_registered ended with exit code -9")

    monkeypatch.setattr(default, "call_pinned", killed)
    with pytest.raises(RuntimeError, match="exit code -9"):
        default.build_database(target, [bundled_path("tunnel-paper-seed0")], surrogates=0)
    assert list(tmp_path.iterdir()) == []


def test_opening_a_file_that_is_no_database_leaves_nothing_behind(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    fake = tmp_path / "fake.png"
    fake.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(200))
    monkeypatch.setenv("ROCKETROLL_DB", str(fake))
    code, _, err = cli(capsys, "db", "list")
    assert code == 2 and one_line(err) and "not an SQLite database" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fake.png"]  # no .lock file


def test_build_and_add_follow_one_folder_rule(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Missing folders above a new database are created, by build and by add alike, and
    removed again when the command fails."""
    from identification.instruments.tunnel import run_tunnel
    from identification.recordings.recording import save_recording

    # a 70-s staircase: what the commands do with folders, not what they identify
    rec = tmp_path / "staircase.csv"
    short = TunnelSpec(schedule="staircase", steps=5, dwell_min=10.0, dwell_max=15.0, lead=5.0)
    save_recording(run_tunnel(short), rec)
    built = tmp_path / "a" / "b" / "built.sqlite"
    assert cli(capsys, "db", "build", "--db", built, rec, "--surrogates", "0")[0] == 0
    added = tmp_path / "c" / "d" / "added.sqlite"
    assert cli(capsys, "db", "add", rec, "--db", added, "--mc-runs", "0")[0] == 0
    assert built.is_file() and added.is_file()
    failed = tmp_path / "e" / "f" / "failed.sqlite"
    bad = tmp_path / "one-step.csv"
    t = np.arange(0.0, 60.0, 0.1)
    bad.write_text(
        "# source: wind-tunnel\ntime_s,fin_cmd_deg,roll_deg\n"
        + "".join(f"{x:.1f},{0 if x < 30 else 10},{3 * x:.3f}\n" for x in t),
        encoding="utf-8",
    )
    code, _, err = cli(capsys, "db", "add", bad, "--db", failed, "--mc-runs", "0")
    assert code == 2 and one_line(err)
    assert not (tmp_path / "e").exists()


# ------------------------------------------------------------------ 7. import-csv by the csv module
def test_import_csv_reads_quoted_cells_and_an_escaped_tab(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = load_recording(bundled_path("tunnel-paper-seed0"))
    assert rec.fin_cmd_deg is not None and rec.roll_deg is not None
    quoted = tmp_path / "quoted.csv"
    with quoted.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, quoting=csv.QUOTE_ALL)
        writer.writerow(["t", "fin", "roll"])
        writer.writerows(zip(rec.time_s, rec.fin_cmd_deg, rec.roll_deg, strict=True))
    out = tmp_path / "a.csv"
    code, _, err = cli(capsys, "import-csv", quoted, "--out", out, "--columns", "time,fin_cmd,roll")
    assert code == 0, err
    np.testing.assert_allclose(np.asarray(load_recording(out).roll_deg), rec.roll_deg, atol=1e-6)
    tabbed = tmp_path / "tabbed.txt"
    rows = zip(rec.fin_cmd_deg, rec.roll_deg, strict=True)
    tabbed.write_text("".join(f"{a}\t{b}\n" for a, b in rows), encoding="utf-8")
    out2 = tmp_path / "b.csv"
    argv = ["import-csv", tabbed, "--out", out2, "--columns", "fin_cmd,roll", "--no-header"]
    code, _, err = cli(capsys, *argv, "--rate", "10", "--delimiter", "\\t")
    assert code == 0, err
    np.testing.assert_allclose(np.asarray(load_recording(out2).fin_cmd_deg), rec.fin_cmd_deg)
    # Errors still name the input's line.
    lines = quoted.read_text(encoding="utf-8").splitlines()
    lines[10] = '"0.9","x","3"'
    quoted.write_text("\n".join(lines) + "\n", encoding="utf-8")
    code, _, err = cli(capsys, "import-csv", quoted, "--out", out, "--columns", "time,fin_cmd,roll")
    assert code == 2 and f"{quoted}:11: fin_cmd is 'x', not a number" in err


# ------------------------------------------------------------------ 8. a fast --help
def test_help_imports_nothing_heavy() -> None:
    """`rocketroll --help` must answer at once (under 0.3 s; timed by
    benchmarks/cli_startup.py): it imports neither numpy nor any domain package."""
    code = (
        "import sys\n"
        "from rocketroll.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('numpy', 'scipy', 'numba', 'torch', 'matplotlib', 'identification', 'disturbances', "
        "'rollenv', 'agents'))\n"
        "print('HEAVY', heavy)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True
    )
    assert "COMMAND" in done.stdout and "HEAVY []" in done.stdout, done.stdout


def test_the_top_level_help_says_what_each_layer_says() -> None:
    """The one-line help in rocketroll.cli (kept there so --help imports no layer) is the
    layer's own."""
    from rocketroll.cli import COMMANDS, command

    for name, (_, text) in COMMANDS.items():
        assert command(name).help == text, name


# ------------------------------------------------------------------ 9. packaging
def test_python_m_rocketroll_runs_the_command_line(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "rocketroll", "--version"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        check=False,
    )
    assert done.returncode == 0 and done.stdout.startswith("rocketroll ")


def test_every_package_is_typed_and_licensed() -> None:
    from tests.import_graph import LAYERS

    for package in LAYERS:
        assert (REPO / package / "py.typed").is_file(), package
    assert "MIT License" in (REPO / "LICENSE").read_text(encoding="utf-8")
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    assert 'license = "MIT"' in text and "license = {" not in text


#: What a build of the source tree leaves out of its copy: environments, outputs, caches.
_NOT_SOURCE = shutil.ignore_patterns(
    ".git", ".venv", "build", "runs", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"
)


def _built(kind: str, folder: Path) -> Path:
    """The package built as ``kind`` (``sdist`` or ``wheel``) into ``folder`` by `build`,
    from a copy of the source tree: setuptools writes ``build/`` and ``*.egg-info`` beside
    the sources, and an ``egg-info`` half written in the repository would be read as the
    installed package's metadata by the tests running beside this one."""
    pytest.importorskip("build", reason=f"the {kind} is built with `build` (dev extra)")
    source = folder / "source"
    shutil.copytree(REPO, source, ignore=_NOT_SOURCE)
    out = folder / "dist"
    done = subprocess.run(
        [sys.executable, "-m", "build", f"--{kind}", "--outdir", str(out), str(source)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "deprecated" not in done.stderr.lower()
    (built,) = out.glob("*.tar.gz" if kind == "sdist" else "*.whl")
    return built


def test_the_sdist_carries_tests_docs_and_license(tmp_path: Path) -> None:
    sdist = _built("sdist", tmp_path)
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    for wanted in (
        "LICENSE",
        "docs/images/tunnel-paper-seed0.png",
        "tests/test_new_user.py",
        "tests/disturbances/data/schema-v1.sqlite",
        "identification/py.typed",
    ):
        assert wanted in names, wanted


def test_the_wheel_carries_what_the_readme_runs_from_an_installed_package(
    tmp_path: Path,
) -> None:
    """`rocketroll sweep run pid-ppo-seeds` and `seeds --run ppo:agents/policies/seeds/...`
    from an installed package: the specs and the seed policies are in the wheel."""
    import zipfile

    wheel = _built("wheel", tmp_path)
    names = set(zipfile.ZipFile(wheel).namelist())
    for wanted in (
        "agents/sweeps/pid-ppo-seeds.yml",
        "agents/hyperparams/ppo-fast.yml",
        "agents/policies/RocketRoll-v0/model.zip",
        "agents/policies/seeds/RocketRoll-v0/ppo-residual/seed4/model.zip",
        "agents/policies/seeds/RocketRollRate-v0/sac/seed0/normalize.json",
        "identification/data/tunnel-paper-seed0.csv",
        "rocketroll/help.json",
    ):
        assert wanted in names, wanted
    # The installed package answers `rocketroll COMMAND --help` from help.json: its sources
    # are those the file was written from.
    from rocketroll import help as kept

    installed = tmp_path / "installed"
    zipfile.ZipFile(wheel).extractall(installed)
    written = json.loads((installed / "rocketroll" / "help.json").read_text(encoding="utf-8"))
    assert written["digest"] == kept.source_digest(installed)
    # The guides name shipped recipes (`--hyperparams ppo-history`, rl-zoo's `-conf "$(rocketroll
    # train recipe ppo)"`): from another folder they are the installed package's files.
    env = {**os.environ, "PYTHONPATH": str(installed)}

    def run(*argv: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "rocketroll", *argv],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )

    done = run("train", "recipe", "ppo")
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()) == installed / "agents" / "hyperparams" / "ppo.yml"
    done = run("train", "ppo", "--hyperparams", "ppo-histroy", "--out", "run")
    assert done.returncode == 2 and one_line(done.stderr), done.stderr
    assert "ppo-histroy: no such file, nor a shipped recipe" in done.stderr
    assert "ppo-history" in done.stderr and not (tmp_path / "run").exists()


# ------------------------------------------------------------------ 10. SB3 keywords and statistics
def test_sb3_keywords_pass_through_and_the_final_statistics_load_in_sb3(
    tmp_path: Path, small_db: Path
) -> None:
    pytest.importorskip("tensorboard", reason="tensorboard_log needs the tensorboard extra")
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.train import VECNORMALIZE_FILE, Args, train
    from agents.vecenv import RollVecEnv

    db = small_db
    tb = tmp_path / "tb"
    hp = tmp_path / "hp.yml"
    hp.write_text(
        "RocketRoll-v0:\n  n_envs: 2\n  n_timesteps: 64\n  policy: MlpPolicy\n"
        "  normalize: true\n  n_steps: 32\n  batch_size: 32\n  n_epochs: 1\n"
        f"  device: cpu\n  tensorboard_log: {tb}\n  stats_window_size: 5\n",
        encoding="utf-8",
    )
    out = tmp_path / "run"
    args = Args(hyperparams=hp, db=str(db), out=out, eval_freq=0, eval_episodes=1)
    train(dataclasses.replace(args, progress_bar=False, checkpoint_freq=0))
    assert list(tb.rglob("events.out.tfevents.*"))  # TensorBoard got the training logs
    venv = RollVecEnv(2, db=str(db), split="train")
    loaded = VecNormalize.load(str(out / VECNORMALIZE_FILE), venv)
    stats: Any = loaded.obs_rms
    assert stats.mean.shape == (4,) and stats.count > 1


def test_keywords_the_command_line_sets_are_refused_in_the_yaml(tmp_path: Path) -> None:
    from agents.train import load_hyperparameters
    from rocketroll_common.errors import UsageError

    hp = tmp_path / "hp.yml"
    hp.write_text("RocketRoll-v0: {n_envs: 2, n_timesteps: 64, policy: MlpPolicy, seed: 3}\n")
    with pytest.raises(UsageError, match="'seed' is set by the command line"):
        load_hyperparameters(hp, "RocketRoll-v0")


# ------------------------------------------------------------------ 11. Gymnasium details
def test_the_spec_reports_the_episode_length_without_a_time_limit() -> None:
    env = gym.make("RocketRoll-v0", bank=array_bank())
    assert env.spec is not None and env.spec.max_episode_steps == 600
    wrappers = []
    inner = env
    while isinstance(inner, gym.Wrapper):
        wrappers.append(type(inner).__name__)
        inner = inner.env
    assert "TimeLimit" not in wrappers
    longer = gym.make("RocketRoll-v0", bank=array_bank(), episode_s=90.0)
    assert longer.spec is not None and longer.spec.max_episode_steps == 900
    vec = gym.make_vec("RocketRoll-v0", num_envs=2, bank=array_bank())
    assert vec.spec is not None and vec.spec.max_episode_steps == 600


def test_the_vector_env_renders_one_frame_per_env() -> None:
    envs = gym.make_vec("RocketRoll-v0", num_envs=2, bank=array_bank(), render_mode="rgb_array")
    assert envs.metadata["render_modes"] == ["rgb_array"]
    envs.reset(seed=0)
    envs.step(np.zeros((2, 1), dtype=np.float32))
    frames: Any = envs.render()
    assert frames is not None and len(frames) == 2
    assert all(f.shape == (480, 720, 3) and f.dtype == np.uint8 for f in frames)
    assert not np.array_equal(frames[0], frames[1])  # two episodes, two pictures
    envs.close()


# ------------------------------------------------------------------ 12. pytest -m slow
def test_the_slow_marker_selects_tests() -> None:
    """`-m slow` selects the committed policies' retraining (collected from their module
    alone: the whole suite's collection imports every package, about 15 s)."""
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "--collect-only",
            "-q",
            "-m",
            "slow",
            "-p",
            "no:cacheprovider",
            "tests/test_figures.py",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    collected = [line for line in done.stdout.splitlines() if "::" in line]
    assert any("test_the_angle_recipe_trains_the_same_bits_twice" in c for c in collected), (
        done.stdout[-2000:]
    )
    assert not any("test_the_evaluation_tables" in c for c in collected), done.stdout[-2000:]


def test_ctrl_c_inside_a_compiled_call_is_an_interrupt_not_a_traceback(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Interrupted inside numba's dispatcher, Python raises SystemError("... returned a
    result with an exception set") from the KeyboardInterrupt (seen once in 12 Ctrl-C's
    during ``db build``); any other SystemError stays a bug."""
    from rocketroll_common.settings import guarded

    def interrupted() -> None:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher returned a result with an exception set") from exc

    assert guarded("rocketroll db", interrupted) == 130
    assert capsys.readouterr().err.strip() == "rocketroll db: interrupted"

    def bug() -> None:
        raise SystemError("a real one")

    with pytest.raises(SystemError, match="a real one"):
        guarded("rocketroll db", bug)
