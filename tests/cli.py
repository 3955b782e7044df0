"""Running ``rocketroll`` in a test: the exit code and what it printed, checked."""

from __future__ import annotations

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
