"""``rocketroll COMMAND --help`` from rocketroll/help.json: current, the same text as the
command's own parser at any width, and without importing the command's module."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator

import pytest

from rocketroll import help as kept
from rocketroll.cli import COMMANDS, command
from rocketroll_common.settings import run_command


def _words() -> Iterator[list[str]]:
    """Every command and every subcommand, as the words before ``--help``."""
    for name in COMMANDS:
        yield [name]
        for sub in command(name).subcommands:
            yield [name, sub.name]
            for alias in sub.aliases:
                yield [name, alias]


WORDS = list(_words())


def test_the_kept_help_is_current() -> None:
    cache = json.loads(kept.CACHE.read_text(encoding="utf-8"))
    assert cache["digest"] == kept.source_digest(), (
        "rocketroll/help.json was written from other sources: run `make help`"
    )
    assert sorted(cache["commands"]) == sorted(COMMANDS)
    # Nothing of this machine in it (a default path is shown relative to the packages).
    text = kept.CACHE.read_text(encoding="utf-8")
    assert str(kept.ROOT) not in text and os.path.expanduser("~") + "/" not in text


@pytest.mark.parametrize("columns", ["60", "100", "200"])
@pytest.mark.parametrize("words", WORDS, ids=" ".join)
def test_the_kept_help_is_what_the_command_prints(
    words: list[str],
    columns: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setenv("COLUMNS", columns)
    prog = f"rocketroll {words[0]}"
    with pytest.raises(SystemExit) as stop:
        run_command(command(words[0]), [*words[1:], "--help"], prog)
    assert stop.value.code == 0
    live = capsys.readouterr().out
    assert kept.cached_help(words[0], [*words[1:], "--help"], prog) == live
    assert kept.cached_help(words[0], [*words[1:], "-h"], prog) == live


def test_a_renamed_command_runs_under_its_former_name_and_says_the_new_one(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A renamed command keeps its old name for a release: it is not listed, it runs, and
    it says the new name on stderr (the top level's and a group's)."""
    from rocketroll.cli import ALIASES, build_parser, main

    listed = build_parser().format_help()
    for old, new in ALIASES.items():
        assert new in COMMANDS and old not in COMMANDS and f"    {old} " not in listed
    assert "ascent" in [c.name for c in command("env").subcommands]
    assert main(["env", "flight"]) == 0
    captured = capsys.readouterr()
    assert "episode:" in captured.out
    assert "rocketroll env flight: renamed 'rocketroll env ascent'" in captured.err
    out = tmp_path / "log.csv"
    assert main(["flight", "--out", str(out), "--seed", "1", "--log-dt", "0.05"]) == 0
    captured = capsys.readouterr()
    assert out.is_file() and "wrote" in captured.out
    assert "rocketroll flight: renamed 'rocketroll record-flight'" in captured.err
    try:  # from help.json, or, where the sources were edited since, argparse's exit
        code = main(["flight", "--help"])
    except SystemExit as stop:
        code = int(stop.code or 0)
    assert code == 0 and "usage: rocketroll record-flight" in capsys.readouterr().out


def test_only_a_bare_help_is_answered_from_the_file(monkeypatch: pytest.MonkeyPatch) -> None:
    assert kept.cached_help("eval", ["--episodes", "3", "--help"], "rocketroll eval") is None
    assert kept.cached_help("db", ["no-such", "--help"], "rocketroll db") is None
    assert kept.cached_help("eval", ["--help", "x"], "rocketroll eval") is None
    assert kept.cached_help("eval", [], "rocketroll eval") is None
    monkeypatch.setenv("ROCKETROLL_PLUGINS", "a_plugin")  # its entries belong in the help
    assert kept.cached_help("eval", ["--help"], "rocketroll eval") is None
    monkeypatch.delenv("ROCKETROLL_PLUGINS")
    assert kept.cached_help("eval", ["--help"], "rocketroll eval") is not None
    monkeypatch.setattr(kept, "source_digest", lambda: "edited sources")
    assert kept.cached_help("eval", ["--help"], "rocketroll eval") is None  # the slow way


def test_command_help_imports_nothing_heavy() -> None:
    code = (
        "import sys, contextlib, io\n"
        "from rocketroll.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    for words in (['eval', '--help'], ['tunnel', '--help'], ['db', 'add', '-h']):\n"
        "        assert main(words) == 0\n"
        "assert 'usage: rocketroll db add' in out.getvalue()\n"
        "heavy = {'numpy', 'scipy', 'numba', 'torch', 'gymnasium'} & set(sys.modules)\n"
        "print(sorted(heavy))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stderr
