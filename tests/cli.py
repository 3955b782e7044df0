"""Running ``rocketroll`` in a test: the exit code and what it printed, checked."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from rocketroll.cli import main as rocketroll


def ok(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """Run ``argv``: exit 0; its standard output."""
    code = rocketroll(argv)
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


def refused(capsys: pytest.CaptureFixture[str], argv: list[str], *needles: str) -> str:
    """Run ``argv``: exit 2, one line on stderr naming ``needles``; that line."""
    code = rocketroll(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


def python(
    argv: list[str], cwd: Path, env: dict[str, str], *, check: bool = False
) -> subprocess.CompletedProcess[str]:
    """``python ARGV`` in a new process from ``cwd`` with ``env``; its output as text."""
    return subprocess.run(
        [sys.executable, *argv],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=check,
    )
