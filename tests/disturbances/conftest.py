"""Fixtures of the disturbance-database tests.

``small_db`` is built once per session from two bundled recordings (one in
each split) without the Monte Carlo noise study, by the paper's method and the
output-error peer (the methods ``db add`` runs by default), with one IAAFT
surrogate per paper trace; tests that change a database work on a copy
(``db_copy``).  The default database's recipe (with maximum likelihood and its
posterior draws) is tested on the session's default database.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from disturbances.default import build_database
from identification.instruments.bundled import bundled_path
from identification.methods.pipeline import IdentifyOptions

FAST = IdentifyOptions(noise_runs=0)
#: One recording of each split (seed 4 is in the test split by hash, seed 0 in train).
SMALL = ("tunnel-paper-seed0", "tunnel-paper-seed4")


@pytest.fixture(scope="session")
def small_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A database file of :data:`SMALL` (do not modify; use ``db_copy``)."""
    path = tmp_path_factory.mktemp("small-db") / "small.sqlite"
    build_database(
        path,
        [bundled_path(n) for n in SMALL],
        options=FAST,
        surrogates=1,
        methods=("paper", "output-error"),
    )
    return path


@pytest.fixture
def db_copy(small_db: Path, tmp_path: Path) -> Path:
    """A private copy of ``small_db``."""
    target = tmp_path / "copy.sqlite"
    shutil.copyfile(small_db, target)
    return target
