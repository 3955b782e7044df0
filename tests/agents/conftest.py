"""Fixtures of the agents tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _sb3_logs_in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SB3 makes a log folder for every ``learn()`` (``/tmp/SB3-<date>`` by default);
    keep the test runs' in the test's own temporary folder."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path / "sb3-logs"))
