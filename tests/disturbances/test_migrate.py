"""Schema migrations: a version-1 database written by the first release is upgraded in place.

``data/schema-v1.sqlite`` was built by the landed code of commit 18bcb80 (schema
1, with ``CHECK`` constraints on method and model names)::

    rocketroll tunnel --seed 1 --schedule staircase --steps 4 --dwell-min 25 \\
        --dwell-max 30 --out stair1.csv
    rocketroll tunnel --seed 7 --schedule staircase --steps 4 --dwell-min 25 \\
        --dwell-max 30 --split test --turbulence laplace --out stair7.csv
    rocketroll db add stair1.csv --db schema-v1.sqlite --surrogates 1 --mc-runs 0
    rocketroll db add stair7.csv --db schema-v1.sqlite --mc-runs 0 --surrogates 1 \\
        --surrogate-kind ar
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from disturbances.db import DatabaseError, DisturbanceDB
from disturbances.schema import SCHEMA_VERSION, backup_path
from identification.methods import METHODS, register_method
from rocketroll.cli import main as rocketroll

REPO = Path(__file__).resolve().parents[2]
V1 = Path(__file__).resolve().parent / "data" / "schema-v1.sqlite"


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def raw(path: Path) -> dict[str, Any]:
    """Schema version and every row of every table, read without rocketroll (read-only)."""
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        out: dict[str, Any] = {"version": conn.execute("PRAGMA user_version").fetchone()[0]}
        for table in ("info", "recordings", "identifications", "traces"):
            out[table] = conn.execute(f"SELECT * FROM {table} ORDER BY 1").fetchall()
        out["integrity"] = conn.execute("PRAGMA integrity_check").fetchone()[0]
        out["checks"] = [
            r[0]
            for r in conn.execute("SELECT sql FROM sqlite_master WHERE type = 'table'")
            if "method IN" in r[0] or "model IN" in r[0]
        ]
    finally:
        conn.close()
    return out


@pytest.fixture
def v1(tmp_path: Path) -> Path:
    """A private copy of the version-1 fixture."""
    target = tmp_path / "old.sqlite"
    shutil.copyfile(V1, target)
    return target


def test_the_fixture_is_a_version_1_database() -> None:
    before = raw(V1)
    assert before["version"] == 1 and before["integrity"] == "ok"
    assert len(before["checks"]) == 1  # the identifications table's CHECK on names
    assert len(before["recordings"]) == 2 and len(before["traces"]) == 12


def test_opening_upgrades_in_place_keeping_every_row_and_a_backup(
    v1: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    before, original = raw(v1), digest(v1)
    with DisturbanceDB(v1, create=False) as db:
        assert db.schema_version == SCHEMA_VERSION == 2
        listed = db.traces()
        for row in listed:
            db.trace(row.uid)  # every checksum still holds
    err = capfd.readouterr().err
    backup = Path(f"{v1}.schema1.bak")
    assert err.count("\n") == 1
    assert f"upgraded {v1} from schema 1 to 2" in err and str(backup) in err
    assert digest(v1) != original
    assert raw(backup) == before  # the old database, kept as it was (SQLite's online backup)
    after = raw(v1)
    assert after["version"] == 2 and after["integrity"] == "ok" and after["checks"] == []
    for table in ("info", "recordings", "identifications", "traces"):
        assert after[table] == before[table], table  # same rows, same row ids
    assert [r.uid for r in listed] == [r[1] for r in before["traces"]]
    with DisturbanceDB(v1, create=False):
        pass
    assert capfd.readouterr().err == ""  # upgraded once: no second notice, no second backup
    assert backup_path(v1, 1) == Path(f"{v1}.schema1.2.bak")


def test_after_the_upgrade_any_registered_method_is_accepted(v1: Path) -> None:
    register_method("schema-test", "identification.methods:paper_method", summary="test")
    try:
        with DisturbanceDB(v1, create=False) as db:
            (ident,) = db.identifications(
                recording="tunnel-staircase-seed1", method="paper", model="theta"
            )
            added = db.store(identifications=[dataclasses.replace(ident, method="schema-test")])
            assert added.identifications == 1 and "schema-test" in db.methods()
    finally:
        METHODS.unregister("schema-test")


def test_rocketroll_db_migrate_and_commands_on_an_old_file(
    v1: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert rocketroll(["db", "migrate", "--db", str(v1)]) == 0
    out, err = capsys.readouterr()
    assert "upgraded" in err and "schema version 2" in out
    assert rocketroll(["db", "migrate", "--db", str(v1)]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "up to date" in out
    # Any command opening an old file upgrades it first, with a one-line notice.
    other = tmp_path / "other.sqlite"
    shutil.copyfile(V1, other)
    assert rocketroll(["db", "list", "--db", str(other), "--method", "output-error"]) == 0
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and "upgraded" in err
    assert "4 shown" in out


def test_without_upgrade_an_old_file_is_refused_by_name(v1: Path) -> None:
    with pytest.raises(DatabaseError, match=r"schema version 1 is older .* db migrate --db"):
        DisturbanceDB(v1, create=False, upgrade=False)
    assert raw(v1)["version"] == 1


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write to read-only files")
def test_a_read_only_old_file_is_not_half_upgraded(v1: Path) -> None:
    v1.chmod(0o444)
    v1.parent.chmod(0o555)
    try:
        with pytest.raises(DatabaseError, match="cannot be upgraded here"):
            DisturbanceDB(v1, create=False)
    finally:
        v1.parent.chmod(0o755)
        v1.chmod(0o644)
    assert raw(v1)["version"] == 1


def test_an_old_file_it_may_not_write_is_refused_not_half_upgraded(
    v1: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As the test above, for a user who may not write (root may, so the test asks os.access)."""
    monkeypatch.setattr("disturbances.db.os.access", lambda path, mode: False)
    with pytest.raises(DatabaseError, match=r"cannot be upgraded here .* db migrate --db"):
        DisturbanceDB(v1, create=False)
    assert raw(v1)["version"] == 1 and not Path(f"{v1}.schema1.bak").exists()


MIGRATOR = textwrap.dedent(
    """
    import sys, time
    from disturbances import schema
    from disturbances.db import DisturbanceDB

    original = schema._rebuild

    def slow(conn, table, create):
        original(conn, table, create)
        print("inside", table, flush=True)
        time.sleep(60)

    schema._rebuild = slow
    DisturbanceDB(sys.argv[1], create=False)
    print("finished", flush=True)
    """
)


def test_a_migration_killed_half_way_leaves_the_old_file(v1: Path) -> None:
    before = raw(v1)
    proc = subprocess.Popen(
        [sys.executable, "-c", MIGRATOR, str(v1)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        cwd=REPO,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()
        assert line == "inside recordings"  # one table rebuilt, two to go, not committed
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=30)
        if proc.stdout is not None:
            proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    assert Path(f"{v1}.schema1.bak").is_file()  # the backup was made first
    after = raw(v1)  # SQLite rolls the unfinished transaction back on the next open
    assert after == before
    with DisturbanceDB(v1, create=False) as db:  # and the next open migrates it
        assert db.schema_version == 2
        assert len(db.traces()) == 12
    assert raw(v1)["integrity"] == "ok"
