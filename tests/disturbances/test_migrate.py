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
import json
import os
import shutil
import signal
import sqlite3
import stat
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from disturbances.db import DatabaseError, DisturbanceDB
from disturbances.schema import SCHEMA_VERSION, backup_path
from disturbances.stores import store_rows
from identification.methods import METHODS, register_method
from rocketroll.cli import main as rocketroll

REPO = Path(__file__).resolve().parents[2]
V1 = Path(__file__).resolve().parent / "data" / "schema-v1.sqlite"


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


TABLES = ("info", "recordings", "identifications", "traces")


def raw(path: Path, *, immutable: bool = False) -> dict[str, Any]:
    """Schema version, every row of every table and the shape of each table (columns,
    foreign keys, indexes), read without rocketroll and read-only (``immutable``: not even
    a ``-shm`` file is made, for the committed fixture)."""
    flags = "mode=ro&immutable=1" if immutable else "mode=ro"
    conn = sqlite3.connect(f"{path.absolute().as_uri()}?{flags}", uri=True)
    try:
        out: dict[str, Any] = {"version": conn.execute("PRAGMA user_version").fetchone()[0]}
        for table in TABLES:
            out[table] = conn.execute(f"SELECT * FROM {table} ORDER BY 1").fetchall()
        out["integrity"] = conn.execute("PRAGMA integrity_check").fetchone()[0]
        out["checks"] = [  # (a renamed table's name comes back quoted)
            r[0].replace('"', "")
            for r in conn.execute("SELECT sql FROM sqlite_master WHERE type = 'table'")
            if " IN (" in r[0]
        ]
        out["shape"] = {
            table: (
                conn.execute(f"PRAGMA table_info({table})").fetchall(),
                conn.execute(f"PRAGMA foreign_key_list({table})").fetchall(),
                sorted(r[1:] for r in conn.execute(f"PRAGMA index_list({table})")),
            )
            for table in TABLES
        }
        out["indexes"] = sorted(
            r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'index'")
        )
    finally:
        conn.close()
    return out


def rows(snapshot: dict[str, Any]) -> dict[str, Any]:
    return {table: snapshot[table] for table in TABLES}


@pytest.fixture
def v1(tmp_path: Path) -> Path:
    """A private copy of the version-1 fixture."""
    target = tmp_path / "old.sqlite"
    shutil.copyfile(V1, target)
    return target


def test_the_fixture_is_a_version_1_database() -> None:
    before = raw(V1, immutable=True)
    assert before["version"] == 1 and before["integrity"] == "ok"
    assert any("method IN" in sql for sql in before["checks"])  # names checked by SQL
    assert len(before["recordings"]) == 2 and len(before["traces"]) == 12


def test_opening_upgrades_in_place_keeping_every_row_and_a_backup(
    v1: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    before, original = raw(v1), digest(v1)
    with DisturbanceDB(v1, create=False) as db:
        assert db.schema_version == SCHEMA_VERSION == 5
        listed = db.traces()
        for row in listed:
            db.trace(row.uid)  # every checksum still holds
    err = capfd.readouterr().err
    backup = Path(f"{v1}.schema1.bak")
    assert err.count("\n") == 1
    assert f"upgraded {v1} from schema 1 to 5" in err and str(backup) in err
    assert digest(v1) != original
    assert raw(backup) == before  # the old database, kept as it was (SQLite's online backup)
    after = raw(v1)
    assert after["version"] == 5 and after["integrity"] == "ok"
    assert not any("method IN" in sql or "model IN" in sql for sql in after["checks"])
    for table in ("info", "recordings", "traces"):
        assert after[table] == before[table], table  # same rows, same row ids
    # the fits of version 1 searched no quadratic damping (0, after ᾱ), were not assessed
    # (their verdict is NULL) and are the tunnel's (no flight reference: v_ref, ρ_ref, n, m NULL)
    nulls = (None,) * 5
    assert after["identifications"] == [
        (*r[:8], 0.0, *r[8:], *nulls) for r in before["identifications"]
    ]
    # The upgraded file has exactly the tables, columns, keys and indexes of a new one.
    with DisturbanceDB(v1.parent / "fresh.sqlite"):
        pass
    fresh = raw(v1.parent / "fresh.sqlite")
    assert after["shape"] == fresh["shape"] and after["indexes"] == fresh["indexes"]
    assert after["checks"] == fresh["checks"]
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
            added = store_rows(db, [], [dataclasses.replace(ident, method="schema-test")])
            assert added.identifications == 1 and "schema-test" in db.methods()
    finally:
        METHODS.unregister("schema-test")


def test_rocketroll_db_migrate_and_commands_on_an_old_file(
    v1: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert rocketroll(["db", "migrate", "--db", str(v1)]) == 0
    out, err = capsys.readouterr()
    assert "upgraded" in err and "schema version 5" in out
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


def test_a_migration_that_fails_half_way_is_one_error_and_leaves_the_old_file(
    v1: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from disturbances import schema

    before, rebuild = raw(v1), schema._rebuild

    def full_disk(conn: sqlite3.Connection, table: str, create: str) -> None:
        rebuild(conn, table, create)
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(schema, "_rebuild", full_disk)
    with pytest.raises(DatabaseError, match=rf"{v1}: upgrading schema 1 to 5 failed: .*full"):
        DisturbanceDB(v1, create=False)
    assert rows(raw(v1)) == rows(before) and raw(v1)["version"] == 1
    assert Path(f"{v1}.schema1.bak").is_file()  # kept, as the message's notice would say


def test_the_backup_keeps_the_files_permissions(v1: Path) -> None:
    v1.chmod(0o600)
    with DisturbanceDB(v1, create=False):
        pass
    assert stat.S_IMODE(Path(f"{v1}.schema1.bak").stat().st_mode) == 0o600


def test_db_migrate_without_db_upgrades_the_default_database_a_user_added_to(
    v1: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("ROCKETROLL_DB", str(v1))  # origin "user": upgraded, never rebuilt
    assert rocketroll(["db", "migrate"]) == 0
    out, err = capsys.readouterr()
    assert "upgraded" in err and f"{v1}: schema version 5" in out
    assert len(raw(v1)["traces"]) == 12


OPENER = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from disturbances.db import DisturbanceDB

    go = Path(sys.argv[2])
    while not go.exists():
        pass
    with DisturbanceDB(sys.argv[1], create=False) as db:
        print(db.schema_version, len(db.traces()))
    """
)


def test_processes_opening_an_old_file_at_once_upgrade_it_once(v1: Path, tmp_path: Path) -> None:
    go = tmp_path / "go"
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", OPENER, str(v1), str(go)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(REPO)},
            cwd=REPO,
        )
        for _ in range(4)
    ]
    time.sleep(3.0)  # let every one of them import and wait
    go.touch()
    results = [proc.communicate(timeout=120) for proc in procs]
    assert [proc.returncode for proc in procs] == [0, 0, 0, 0], results
    assert [out for out, _ in results] == ["5 12\n"] * 4
    notices = [err for _, err in results if "upgraded" in err]
    assert len(notices) == 1, results  # one process upgraded it; the others found it done
    assert sorted(p.name for p in tmp_path.glob("*.bak")) == ["old.sqlite.schema1.bak"]
    assert not list(tmp_path.glob(".*.tmp"))


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
        assert db.schema_version == 5
        assert len(db.traces()) == 12
    assert raw(v1)["integrity"] == "ok"


def test_a_version_2_file_gets_the_verdicts_its_fits_were_stored_with(v1: Path) -> None:
    from disturbances import schema

    conn = sqlite3.connect(v1)
    with conn:
        schema.MIGRATIONS[1](conn)  # the file as version 2 left it
        (ident_id, metrics), *_ = conn.execute("SELECT id, metrics FROM identifications")
        assessed = {**json.loads(metrics), "adequacy": {"verdict": "weak", "reasons": ["x"]}}
        conn.execute(
            "UPDATE identifications SET metrics = ? WHERE id = ?", (json.dumps(assessed), ident_id)
        )
        conn.execute("PRAGMA user_version = 2")
    conn.close()
    with DisturbanceDB(v1, create=False) as db:
        verdicts = {row.id: row.verdict for row in db.identifications()}
        assert verdicts[ident_id] == "weak"
        assert set(verdicts.values()) == {"weak", None}
        weak = db.traces(verdict="weak")
        assert weak and {t.verdict for t in weak} == {"weak"}
        assert len(db.traces(verdict="good")) == 0
    stored = raw(v1)["identifications"]
    assert sorted(r[-5] or "" for r in stored) == [""] * (len(stored) - 1) + ["weak"]
