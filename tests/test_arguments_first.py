"""Every argument of every command is checked before any work.

The work a bad argument must never reach -- building the default database, an
identification fit, training, running the virtual tunnel or the flight recorder -- is
replaced by a function that raises; then every command of the ``rocketroll`` tree is run
with each of its checked arguments wrong: each must exit 2 with one line on stderr.  The
cases come from the settings' declarations (bounds and choices, :func:`setting`), plus
hand-written ones for what is parsed later (policy specs, ``--resume``, recording names,
hyperparameter recipes, ...).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from identification.instruments.bundled import bundled_path
from rocketroll.cli import COMMANDS, command
from rocketroll.cli import main as rocketroll
from rocketroll_common.settings import Command, _Field, _leaves

REPO = Path(__file__).resolve().parents[1]
RECORDING = str(bundled_path("tunnel-paper-seed0"))
#: Two seeds of a learner, as ``rocketroll seeds --run`` takes them (shipped with the package).
RUNS = [f"--run=ppo:agents/policies/seeds/RocketRoll-v0/ppo-residual/seed{n}" for n in (0, 1)]


class Reached(AssertionError):
    """Work a refused argument must not reach (not a user error: it keeps its traceback)."""


#: What must not run, as ``module:attribute``: the default database's build, the
#: identification fits, training, the tunnel and the flight recorder.
WORK = (
    "disturbances.default:open_default",
    "disturbances.default:_build_default",
    "disturbances.default:build_database",
    "disturbances:open_default",
    "identification.methods:fit",
    "disturbances.ingest:fit",
    "identification.methods.pipeline:identify",
    "agents.train.run:make_env",
    "agents.cli:run_sweep",
    "identification.instruments.tunnel:run_tunnel",
    "identification.instruments.flightlog:run_flight",
)


@pytest.fixture
def no_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A fresh ``ROCKETROLL_DB`` (none built) and every kind of work raising
    :class:`Reached`; the folder to run in."""
    import importlib

    monkeypatch.setenv("ROCKETROLL_DB", str(tmp_path / "fresh" / "disturbances.sqlite"))
    for target in WORK:
        module, _, name = target.partition(":")
        loaded = importlib.import_module(module)
        if not hasattr(loaded, name):
            continue

        def refuse(*args: Any, _what: str = target, **kwargs: Any) -> Any:
            raise Reached(f"{_what} was reached")

        monkeypatch.setattr(loaded, name, refuse)
    monkeypatch.chdir(tmp_path)
    yield tmp_path


def leaf_commands() -> list[tuple[list[str], Command]]:
    """Every runnable command: its words and its :class:`Command`."""
    found: list[tuple[list[str], Command]] = []

    def walk(cmd: Command, words: list[str]) -> None:
        if cmd.subcommands:
            for child in cmd.subcommands:
                walk(child, [*words, child.name])
        elif cmd.args is not None:
            found.append((words, cmd))

    for name in COMMANDS:
        walk(command(name), [name])
    return found


#: Values that make a command's required arguments valid, by how the user names them.
REQUIRED = {
    "RECORDING": RECORDING,
    "INPUT": RECORDING,
    "TRACE": "no-such-trace",
    "FOLDER": "folder",
    "SPEC": str(REPO / "agents" / "sweeps" / "pid-ppo-seeds.yml"),
    "DIR": "sweep",
    "--out": "out/result",
    "--format": "csv",
}


def required(cls: type) -> list[str]:
    """Valid words for the arguments of ``cls`` that have no default."""
    words: list[str] = []
    for f in _leaves(cls):
        if not f.spec.cli or f.default is not dataclasses.MISSING or f.base is list:
            continue
        value = REQUIRED[f.shown]
        words += [value] if f.spec.positional else [f.flag, value]
    return words


def _outside(f: _Field) -> list[str]:
    """Values just outside the field's declared bounds."""
    spec, integer = f.spec, (f.item if f.base is tuple else f.base) is int
    values: list[float] = []
    for edge, step in ((spec.ge, -1), (spec.gt, 0), (spec.le, 1), (spec.lt, 0)):
        if edge is not None:
            values.append(edge + step if integer or step == 0 else edge + step * max(1, abs(edge)))
    return [str(int(v)) if integer else repr(float(v)) for v in values]


def declared_cases() -> Iterator[Any]:
    """From the settings' declarations: each bounded number just outside its bounds and each
    choice not among its choices, with the command's required arguments valid."""
    for words, cmd in leaf_commands():
        assert cmd.args is not None
        base = required(cmd.args)
        for f in _leaves(cmd.args):
            if not f.spec.cli or f.base is bool:
                continue
            bad: list[str] = []
            kind = f.item if f.base in (tuple, list) else f.base
            if kind in (int, float):
                bad += _outside(f)
            if f.choices is not None:
                bad.append("no-such-choice")
            for value in bad:
                argv = [*words, *base]
                if f.spec.positional:
                    argv = [*words, *[w for w in base if w != REQUIRED.get(f.shown)], value]
                else:
                    argv += [f.flag, value]
                yield pytest.param(argv, f.shown, id=" ".join([*words, f.shown, value]))


def refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run ``argv``: exit 2 and one line on stderr, nothing on stdout; that line."""
    code = rocketroll(argv)
    out, err = capsys.readouterr()
    assert code == 2, (code, err[-2000:])
    assert out == "", out
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err.strip()


@pytest.mark.parametrize(("argv", "named"), list(declared_cases()))
def test_a_declared_bound_or_choice_is_refused_first(
    argv: list[str], named: str, no_work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    err = refused(argv, capsys)
    assert named in err, err


@pytest.fixture
def empty_db(tmp_path: Path) -> Path:
    """A database with no recordings (opening it is not building the default one)."""
    from disturbances.db import DisturbanceDB

    path = tmp_path / "empty.sqlite"
    with DisturbanceDB(path):
        pass
    return path


#: Arguments parsed after the settings' own checks: each with what its one line names.
LATER = [
    (["eval", "--policy", "mpc:100000"], "mpc:HORIZON"),
    (["eval", "--policy", "mpc:x"], "mpc:HORIZON"),
    (["eval", "--policy", "pid:fast"], "pid:OMEGA"),
    (["eval", "--policy", "pid-tunnel:fast"], "pid-tunnel:OMEGA"),
    (["eval", "--policy", "no-such-controller"], "no-such-controller"),
    (["eval", "--policy", "trim:3"], "trim takes no argument"),
    (["eval", "--policy", "oracle:3"], "oracle takes no argument"),
    (["eval", "--policy", "ppo:no/such/run"], "no/such/run"),
    (["eval", "--policy", "sac"], "sac:DIR"),
    (["eval", "--policy", "td3:no/such/run"], "no/such/run"),
    (["eval", "--set", "no_such_key=1"], "no_such_key"),
    (["eval", "--set", "method=no-such-method"], "no-such-method"),
    (["eval", "--minari", "not a name!"], "--minari"),
    (["eval", "--db", "no-such.sqlite"], "no-such.sqlite"),
    (["robustness", "--policy", "mpc:100000"], "mpc:HORIZON"),
    (["robustness", "--condition", "no-such-condition"], "no-such-condition"),
    (["seeds", "--run", "ppo:no/such/run", "--run", "ppo:no/such/run2"], "no/such/run"),
    (["seeds", "--run", "sac:no/such/run", "--run", "sac:no/such/run2"], "no/such/run"),
    (["seeds", *RUNS, "--reference", "mpc:100000"], "mpc:HORIZON"),
    (["tune", "pid", "--set", "no_such_key=1"], "no_such_key"),
    (["env", "rollout", "--set", "no_such_key=1"], "no_such_key"),
    (["env", "ascent", "--flight", "no-such-flight"], "no-such-flight"),
    (["record-flight", "--out", "f.csv", "--ascent", "no-such-ascent"], "no-such-ascent"),
    (["identify", RECORDING, "--method", "no-such-method"], "no-such-method"),
    (["identify", RECORDING, "--together", "no-such.csv"], "no-such.csv"),
    (["db", "add", RECORDING, "--db", "new.sqlite", "--method", "no-such-method"], "no-such"),
    (["db", "add", RECORDING, "--db", "new.sqlite", "--surrogate-kind", "nope"], "nope"),
    (["db", "build", "--db", "new.sqlite", "no-such.csv"], "no-such.csv"),
    (["import-csv", RECORDING, "--out", "a.csv", "--columns", "time,nope"], "nope"),
    (["train", "ppo", "--hyperparams", "no-such-recipe"], "no-such-recipe"),
    (["train", "sac", "--hyperparams", "ppo-history"], "ppo-history"),
    (["train", "ppo", "--resume", "no-such.zip"], "no-such.zip"),
    (["train", "recipe", "no-such-recipe"], "no-such-recipe"),
    (["train", "recipe", "--out", "copy.yml"], "--out"),
    (["train", "ppo", "--timesteps", "1"], "--timesteps 1"),
    (["train", "ppo", "--set", "no_such_key=1"], "no_such_key"),
    (["sweep", "run", "no-such-spec.yml"], "no-such-spec.yml"),
]


@pytest.mark.parametrize(("argv", "named"), LATER, ids=[" ".join(a) for a, _ in LATER])
def test_an_argument_parsed_later_is_refused_before_the_work(
    argv: list[str], named: str, no_work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    err = refused(argv, capsys)
    assert named in err, err


def test_a_checkpoint_that_is_not_one_is_refused_before_the_work(
    no_work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = no_work / "notes.zip"
    text.write_text("not a checkpoint\n", encoding="utf-8")
    err = refused(["train", "ppo", "--resume", str(text)], capsys)
    assert f"--resume: {text}: not a checkpoint" in err, err


#: Names looked up in the database (an empty one: opening it builds nothing).
DATABASE_NAMES = [
    ["eval", "--recording", "no-such-run"],
    ["train", "ppo", "--recording", "no-such-run"],
    ["tune", "pid", "--recording", "no-such-run"],
    ["seeds", *RUNS, "--recording", "no-such-run"],
    ["robustness", "--recording", "no-such-run"],
    ["db", "show", "no-such-trace"],
    ["db", "surrogate", "no-such-trace"],
]


@pytest.mark.parametrize("argv", DATABASE_NAMES, ids=lambda argv: " ".join(argv))
def test_a_name_the_database_lacks_is_refused_before_the_work(
    argv: list[str], no_work: Path, empty_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    err = refused([*argv, "--db", str(empty_db)], capsys)
    assert "no-such" in err or str(empty_db) in err, err  # the name, or what the db lacks


#: Commands with no argument to get wrong but a file's name (checked by the file's reader).
ONLY_FILES = {"info", "db import", "db migrate"}


def test_the_cases_cover_every_command() -> None:
    argvs = [p.values[0] for p in declared_cases()]
    argvs += [argv for argv, _ in LATER] + DATABASE_NAMES
    for words, _ in leaf_commands():
        name = " ".join(words)
        hit = any(" ".join(argv[: len(words)]) == name for argv in argvs)
        assert hit or name in ONLY_FILES, name
    assert len(argvs) > 250
