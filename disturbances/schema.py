"""The database's schema, and the migrations that bring an older file up to it.

Version :data:`SCHEMA_VERSION` is written to ``PRAGMA user_version``; the
file is marked with ``PRAGMA application_id`` :data:`APPLICATION_ID`.

Version 5 (this one) stores each identification's ``quadratic_damping``: the growth of its
damping with the roll rate (:attr:`identification.model.RollParams.quadratic_damping`; 0,
the paper's linear roll, for every identification before and every one that does not
search the term).  Version 4 stores flights: a flight method's identification holds its
parameters at a reference airspeed and density with the airspeed scaling it measured
(``v_ref_mps``, ``rho_ref_kgm3``, ``torque_exponent``, ``damping_exponent``:
:class:`rocketroll_physics.scaling.FlightReference`; NULL for the tunnel's, which hold at
the tunnel's airspeed).  Version 3 adds each identification's adequacy ``verdict`` (good, weak or
unreliable: :mod:`identification.methods.adequacy`; NULL where it was not assessed -- a flight
fit, or one stored before version 3 without it in its metrics).  Version 2 validates
method, model, kind and source names in Python -- against the registries of identification methods
(:data:`identification.methods.METHODS`), damping models
(:data:`identification.model.MODELS`), surrogate kinds and recording sources
-- instead of in ``CHECK`` constraints, so a new identification method needs
no new schema.  Version 1 (the first release) had those ``CHECK``\\ s.

:func:`migrate` upgrades an older file in place, in one transaction, after
copying it to a backup beside it: a migration that fails or is killed leaves
the file as it was (SQLite rolls the transaction back), and the backup is
kept either way.
"""

from __future__ import annotations

import os
import sqlite3
import stat
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = [
    "APPLICATION_ID",
    "SCHEMA",
    "SCHEMA_VERSION",
    "TABLES",
    "backup_path",
    "migrate",
    "write_transaction",
]

#: Version of the schema this package writes and reads.
SCHEMA_VERSION = 5
#: ``PRAGMA application_id`` of a rocketroll disturbance database ("RRDB").
APPLICATION_ID = 0x52524442

_RECORDINGS = """
CREATE TABLE recordings (
    id           INTEGER PRIMARY KEY,
    content_hash TEXT NOT NULL UNIQUE,
    name         TEXT NOT NULL,
    source       TEXT NOT NULL,
    metadata     TEXT NOT NULL,
    columns      TEXT NOT NULL,
    n_samples    INTEGER NOT NULL CHECK (n_samples > 0),
    dt_s         REAL NOT NULL,
    duration_s   REAL NOT NULL,
    samples      BLOB NOT NULL,
    split        TEXT NOT NULL CHECK (split IN ('train', 'test')),
    added_at     TEXT NOT NULL
)"""
_IDENTIFICATIONS = """
CREATE TABLE identifications (
    id                  INTEGER PRIMARY KEY,
    recording_id        INTEGER NOT NULL REFERENCES recordings(id) ON DELETE CASCADE,
    method              TEXT NOT NULL,
    model               TEXT NOT NULL,
    alpha               REAL NOT NULL,
    theta_bar_deg       REAL NOT NULL,
    beta_bar_per_s      REAL NOT NULL,
    alpha_bar_per_deg_s REAL NOT NULL,
    quadratic_damping   REAL NOT NULL DEFAULT 0,
    metrics             TEXT NOT NULL,
    options             TEXT NOT NULL,
    package_version     TEXT NOT NULL,
    created_at          TEXT NOT NULL,
    verdict             TEXT,
    v_ref_mps           REAL CHECK (v_ref_mps > 0),
    rho_ref_kgm3        REAL CHECK (rho_ref_kgm3 > 0),
    torque_exponent     REAL,
    damping_exponent    REAL,
    CHECK ((v_ref_mps IS NULL) = (torque_exponent IS NULL)),
    UNIQUE (recording_id, method, model)
)"""
#: The flight reference's lines of the identifications table (version 4).
_FLIGHT_COLUMNS = (
    "    v_ref_mps           REAL CHECK (v_ref_mps > 0),\n"
    "    rho_ref_kgm3        REAL CHECK (rho_ref_kgm3 > 0),\n"
    "    torque_exponent     REAL,\n"
    "    damping_exponent    REAL,\n"
    "    CHECK ((v_ref_mps IS NULL) = (torque_exponent IS NULL)),\n"
)
#: The quadratic damping's line of the identifications table (version 5).
_QUADRATIC_COLUMN = "    quadratic_damping   REAL NOT NULL DEFAULT 0,\n"
#: The identifications table of version 4 (before its quadratic damping), what 3 -> 4 makes.
_IDENTIFICATIONS_V4 = _IDENTIFICATIONS.replace(_QUADRATIC_COLUMN, "")
#: The identifications table of version 2 (before its ``verdict``), what 1 -> 2 makes.
_IDENTIFICATIONS_V2 = _IDENTIFICATIONS_V4.replace(_FLIGHT_COLUMNS, "").replace(
    "    verdict             TEXT,\n", ""
)
_TRACES = """
CREATE TABLE traces (
    id                INTEGER PRIMARY KEY,
    uid               TEXT NOT NULL UNIQUE,
    identification_id INTEGER NOT NULL REFERENCES identifications(id) ON DELETE CASCADE,
    kind              TEXT NOT NULL,
    source_trace_id   INTEGER REFERENCES traces(id) ON DELETE CASCADE,
    seed              INTEGER,
    settings          TEXT NOT NULL,
    dt_s              REAL NOT NULL CHECK (dt_s > 0),
    t0_s              REAL NOT NULL,
    n_samples         INTEGER NOT NULL CHECK (n_samples > 1),
    samples           BLOB NOT NULL,
    checksum          TEXT NOT NULL,
    mean_deg          REAL NOT NULL,
    sd_deg            REAL NOT NULL,
    q05_deg           REAL NOT NULL,
    q95_deg           REAL NOT NULL,
    normality_p       REAL,
    validation        TEXT,
    created_at        TEXT NOT NULL,
    CHECK ((kind = 'identified') = (source_trace_id IS NULL))
)"""
_INDEXES = (
    "CREATE INDEX traces_by_identification ON traces (identification_id)",
    "CREATE INDEX traces_by_source ON traces (source_trace_id)",
    "CREATE INDEX identifications_by_recording ON identifications (recording_id)",
)
_INFO = "CREATE TABLE info (\n    key   TEXT PRIMARY KEY,\n    value TEXT NOT NULL\n)"

#: The statements that make a new, empty database of :data:`SCHEMA_VERSION`.
SCHEMA: tuple[str, ...] = (_INFO, _RECORDINGS, _IDENTIFICATIONS, _TRACES, *_INDEXES)
#: The tables a database of this schema has.
TABLES = ("identifications", "info", "recordings", "traces")


def _rebuild(conn: sqlite3.Connection, table: str, create: str) -> None:
    """Replace ``table`` by one made with ``create``, keeping every row and row id."""
    conn.execute(create.replace(f"CREATE TABLE {table} (", f"CREATE TABLE {table}_new (", 1))
    columns = [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]
    names = ", ".join(columns)
    conn.execute(f"INSERT INTO {table}_new ({names}) SELECT {names} FROM {table}")
    conn.execute(f"DROP TABLE {table}")
    conn.execute(f"ALTER TABLE {table}_new RENAME TO {table}")


def _migrate_1_to_2(conn: sqlite3.Connection) -> None:
    """Version 1 -> 2: drop the ``CHECK``\\ s on names (method, model, kind, source).

    SQLite cannot drop a constraint, so each table is rebuilt (the
    procedure of SQLite's "ALTER TABLE" page): new table, copy, drop, rename,
    indexes again.  Row ids are kept, so a trace's ``id`` stays what it was.
    """
    for table, create in (
        ("recordings", _RECORDINGS),
        ("identifications", _IDENTIFICATIONS_V2),
        ("traces", _TRACES),
    ):
        _rebuild(conn, table, create)
    for statement in _INDEXES:
        conn.execute(statement)


def _migrate_2_to_3(conn: sqlite3.Connection) -> None:
    """Version 2 -> 3: each identification's adequacy ``verdict``, read from its metrics
    where the fit was assessed when it was stored (NULL where it was not)."""
    conn.execute("ALTER TABLE identifications ADD COLUMN verdict TEXT")
    conn.execute(
        "UPDATE identifications SET verdict = json_extract(metrics, '$.adequacy.verdict') "
        "WHERE json_valid(metrics)"
    )


def _migrate_3_to_4(conn: sqlite3.Connection) -> None:
    """Version 3 -> 4: the flight reference of an identification (none is stored before:
    version 3 refused flights), with its checks, by rebuilding the table."""
    _rebuild(conn, "identifications", _IDENTIFICATIONS_V4)
    conn.execute(_INDEXES[2])


def _migrate_4_to_5(conn: sqlite3.Connection) -> None:
    """Version 4 -> 5: each identification's quadratic damping, 0 for every one stored
    before (none searched the term), by rebuilding the table: its columns then stand where
    a new database's do."""
    _rebuild(conn, "identifications", _IDENTIFICATIONS)
    conn.execute(_INDEXES[2])


#: ``version -> migration`` to ``version + 1``, applied in order.
MIGRATIONS: dict[int, Callable[[sqlite3.Connection], None]] = {
    1: _migrate_1_to_2,
    2: _migrate_2_to_3,
    3: _migrate_3_to_4,
    4: _migrate_4_to_5,
}


def backup_path(path: Path, version: int) -> Path:
    """Where the backup of ``path`` at schema ``version`` goes: ``NAME.schemaN.bak``, or
    ``NAME.schemaN.K.bak`` when that is taken (see :func:`migrate` for how it is claimed)."""
    candidate = Path(f"{path}.schema{version}.bak")
    k = 1
    while candidate.exists():
        k += 1
        candidate = Path(f"{path}.schema{version}.{k}.bak")
    return candidate


def _claim(path: Path, version: int) -> Path:
    """A backup name beside ``path`` that no other file has, created empty (``O_EXCL``)."""
    while True:
        target = backup_path(path, version)
        try:
            os.close(os.open(target, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        except FileExistsError:
            continue
        return target


def _backup(path: Path, version: int) -> Path:
    """A consistent copy of the database file (SQLite's online backup, read through a
    connection of its own), with the file's own permissions, under a name of its own."""
    for stale in path.parent.glob(f".{path.name}.schema*.bak.*.tmp"):  # a killed backup's
        stale.unlink(missing_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.name}.schema{version}.bak.", suffix=".tmp", dir=path.parent
    )
    os.close(fd)
    try:
        source = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True, timeout=30.0)
        copy = sqlite3.connect(tmp)
        try:
            source.backup(copy)
        finally:
            copy.close()
            source.close()
        os.chmod(tmp, stat.S_IMODE(path.stat().st_mode))
        target = _claim(path, version)
        os.replace(tmp, target)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return target


@contextmanager
def write_transaction(conn: sqlite3.Connection) -> Iterator[sqlite3.Connection]:
    """One write transaction under the database's write lock (``BEGIN IMMEDIATE``): all of
    it committed, or, on any error (the commit's too), none of it."""
    conn.execute("BEGIN IMMEDIATE")
    try:
        yield conn
        conn.execute("COMMIT")
    except BaseException:
        if conn.in_transaction:  # SQLite may have rolled back already
            conn.execute("ROLLBACK")
        raise


def migrate(conn: sqlite3.Connection, path: Path, version: int) -> Path | None:
    """Upgrade the database on ``conn`` from ``version`` to :data:`SCHEMA_VERSION`.

    Under the write lock (``BEGIN IMMEDIATE``) the version is read again: a
    file another process has upgraded meanwhile is left alone (``None`` is
    returned: no backup, nothing to say).  Otherwise the file is copied to a
    backup beside it (:func:`backup_path`, a name no other file has), every
    migration runs in that one transaction with foreign keys off (as a table
    rebuild needs), the foreign keys are checked, ``user_version`` is set, and
    only then is it committed.  A failure (or a killed process) leaves the
    file at ``version``; the backup is kept either way.

    Returns
    -------
    Path or None
        The backup, or None when there was nothing left to upgrade.

    Raises
    ------
    ValueError
        No migration leads from ``version``.
    """
    if version not in MIGRATIONS and version != SCHEMA_VERSION:
        raise ValueError(f"no migration from schema version {version}")
    conn.execute("PRAGMA foreign_keys = OFF")  # (outside a transaction, or it is ignored)
    try:
        with write_transaction(conn):
            current = int(conn.execute("PRAGMA user_version").fetchone()[0])
            if current >= SCHEMA_VERSION:  # another process upgraded it while this one waited
                return None
            if conn.execute("PRAGMA foreign_key_check").fetchall():
                raise sqlite3.IntegrityError(
                    f"its foreign keys are broken (schema {current}); nothing was changed"
                )
            backup = _backup(path, current)
            while current < SCHEMA_VERSION:
                MIGRATIONS[current](conn)
                current += 1
            bad = conn.execute("PRAGMA foreign_key_check").fetchall()
            if bad:
                raise sqlite3.IntegrityError(f"foreign keys broken by the migration: {bad[:3]}")
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    finally:
        conn.execute("PRAGMA foreign_keys = ON")
    return backup
