"""Shared fixtures: every test runs with its own default disturbance database.

``ROCKETROLL_DB`` points into the session's temporary folder, so no test reads
or writes the user's cache, and the default database is built at most once
per test session (by the first test that needs it).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from rocketroll_common.numerics import one_blas_thread

# One OpenBLAS thread, as the `rocketroll` command runs (before anything imports numpy):
# beside pytest-xdist's workers, which hold every core, OpenBLAS's own threads only wait
# for each other (a maximum-likelihood module took 56 CPU-s with them, 32 without).
one_blas_thread()


@pytest.fixture(scope="session", autouse=True)
def _private_default_database(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    path = tmp_path_factory.mktemp("default-db") / "disturbances.sqlite"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ROCKETROLL_DB", str(path))
        yield path


@pytest.fixture(scope="session")
def default_db(_private_default_database: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The session's default database, built once (about 35 s of CPU) for all pytest-xdist
    workers and copied into each worker's own folder, so no test sees another's changes;
    its path."""
    from disturbances.default import open_default

    if not _private_default_database.exists():
        shutil.copyfile(_shared_default_database(tmp_path_factory), _private_default_database)
    with open_default(progress=False):  # checks the copy (and rebuilds one that is not right)
        pass
    return _private_default_database


def _shared_default_database(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default database in the folder the workers share (the parent of each worker's
    base folder; this session's own under one process), built by the first worker to ask:
    the build's lock on its folder makes the others wait and then find it built."""
    from disturbances.default import open_default

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    path = root / "shared-default-db" / "disturbances.sqlite"
    path.parent.mkdir(exist_ok=True)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ROCKETROLL_DB", str(path))
        with open_default(progress=False):
            pass
    return path


#: The modules that take longest (minutes of CPU each in the parallel run), in that order.
#: pytest-xdist's --dist loadfile hands modules out in collection order (with
#: --no-loadscope-reorder, as `make pytest` runs it), so these go first and the short ones
#: fill in after: otherwise the last heavy module (collected last, being top-level) runs
#: alone while the other workers have finished.  The second needs no default database:
#: its worker identifies flights while the first worker builds the database (about 40 s),
#: where it would otherwise wait for that build.
SLOWEST_MODULES = (
    "tests/test_benchmarks.py",
    "tests/identification/test_flightfit.py",
    "tests/test_figures.py",
    "tests/test_new_user.py",
    "tests/agents/test_sweep.py",
    "tests/rollenv/test_env.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The slowest modules first, every module's tests in their own order."""
    root = config.rootpath

    def rank(item: pytest.Item) -> int:
        module = item.path.relative_to(root).as_posix() if item.path.is_relative_to(root) else ""
        return SLOWEST_MODULES.index(module) if module in SLOWEST_MODULES else len(SLOWEST_MODULES)

    items.sort(key=rank)  # stable
