"""Shared fixtures: every test runs with its own default disturbance database.

``ROCKETROLL_DB`` points into the session's temporary folder, so no test reads
or writes the user's cache, and the default database is built at most once
per test session (by the first test that needs it).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture(scope="session", autouse=True)
def _private_default_database(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    path = tmp_path_factory.mktemp("default-db") / "disturbances.sqlite"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ROCKETROLL_DB", str(path))
        yield path


@pytest.fixture(scope="session")
def default_db(_private_default_database: Path) -> Path:
    """The session's default database, built once (about 15 s; once per pytest-xdist
    worker, each in its own temporary folder); its path."""
    from disturbances.default import open_default

    with open_default(progress=False):
        pass
    return _private_default_database
