"""``DisturbanceDB``: the SQLite store of recordings, identifications and ``u_d`` traces.

A store only stores: this module holds all the project's SQL and nothing of
the domain.  It writes and reads the rows of :mod:`disturbances.rows`;
identifying a recording and making surrogates happen above it, in
:mod:`disturbances.ingest`, which hands the rows to :meth:`DisturbanceDB.store`.

Schema (:mod:`disturbances.schema`, version in ``PRAGMA user_version``)::

    info             key -> value: created_by (package version), created_at,
                     origin (bundled | user), fingerprint (of a bundled build)
    recordings       name, source, metadata (JSON), columns, the raw samples
                     (float64 blob), content_hash (UNIQUE), split, added_at
    identifications  recording -> method, model, α, θ̄, β̄, ᾱ, metrics (JSON),
                     options (JSON), package_version, created_at;
                     UNIQUE (recording, method, model)
    traces           uid (UNIQUE), identification, kind (identified | iaaft |
                     ar), source trace (surrogates), seed, settings (JSON), Δt,
                     t0, the u_d samples (float64 blob), their SHA-256, mean, SD,
                     5 % and 95 % quantiles, normality p, validation (JSON)

Names -- models, kinds, sources, verdicts -- are checked in Python by the rows
themselves (:data:`disturbances.rows.NAMES`), not by ``CHECK`` constraints.  A
method name is any string to the store: whether it is registered is the
domain's question, asked above every back end (:func:`disturbances.stores.store_rows`,
:func:`disturbances.stores.check_filters`).  A
file of an older schema is upgraded when it is opened (a copy is kept beside
it; :func:`disturbances.schema.migrate`), with a one-line notice.

Foreign keys are on, the journal is in WAL mode (readers never wait for a
writer), and every change is one transaction (``BEGIN IMMEDIATE`` ...
``COMMIT``): a failed or killed writer leaves the database as it was before
that change.  A trace's samples are checked against their SHA-256 whenever
they are read.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sqlite3
import sys
import warnings
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from disturbances.rows import (
    NAMES,
    POSTERIOR_KIND,
    SURROGATE_KINDS,
    ChecksumError,
    IdentificationRow,
    RecordingRow,
    TraceRow,
    params_from_columns,
    rig_from_json,
)
from disturbances.schema import (
    APPLICATION_ID,
    SCHEMA,
    SCHEMA_VERSION,
    TABLES,
    migrate,
    write_transaction,
)
from rocketroll_common import __version__
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import RocketrollError
from rocketroll_physics.scaling import AirspeedScaling, FlightReference

if TYPE_CHECKING:
    from identification.recordings.recording import Recording

__all__ = [
    "APPLICATION_ID",
    "SCHEMA_VERSION",
    "TRACE_FILTERS",
    "DatabaseError",
    "DisturbanceDB",
    "Dump",
    "StoreResult",
    "now",
    "package_version",
]

#: Seconds a writer waits for another writer before giving up.
BUSY_TIMEOUT_S = 30.0

_SQLITE_MAGIC = b"SQLite format 3\x00"


class DatabaseError(RocketrollError):
    """A database cannot be opened, read or changed; the message names the file."""


def package_version() -> str:
    """The installed rocketroll version (``0+unknown`` from an uninstalled tree)."""
    return __version__


def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def _f64(blob: bytes) -> FloatArray:
    return np.frombuffer(blob, dtype="<f8").astype(float)


def _blob(values: FloatArray) -> bytes:
    return np.ascontiguousarray(values, dtype="<f8").tobytes()


def _nan_to_none(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


@dataclass(frozen=True)
class StoreResult:
    """What one change added (and what it found already there).

    Attributes
    ----------
    recording_id : int or None
        Row id of the first recording given (``None`` when none was).
    recordings, identifications, traces : int
        Rows added.
    skipped : int
        Rows already present (recognised by content), not duplicated.
    trace_ids : tuple of int
        Ids of the traces added.
    """

    recording_id: int | None
    recordings: int
    identifications: int
    traces: int
    skipped: int
    trace_ids: tuple[int, ...]


@dataclass(frozen=True, eq=False)
class Dump:
    """Rows selected for export, with everything they depend on (samples included)."""

    recordings: tuple[RecordingRow, ...]
    identifications: tuple[IdentificationRow, ...]
    traces: tuple[TraceRow, ...]


#: Filters of :meth:`DisturbanceDB.traces`.
TRACE_FILTERS = (
    "split",
    "model",
    "method",
    "kind",
    "source",
    "recording",
    "metadata",
    "min_duration_s",
    "validated",
    "verdict",
)


# --------------------------------------------------------------------------- opening


def _header_problem(path: Path) -> str | None:
    """Why ``path`` is not a whole SQLite file, judged from its 100-byte header."""
    size = path.stat().st_size
    if size == 0:
        return None  # SQLite makes an empty file a new database
    with path.open("rb") as handle:
        header = handle.read(100)
    if len(header) < 100 or not header.startswith(_SQLITE_MAGIC):
        return "not an SQLite database"
    page_size = int.from_bytes(header[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = int.from_bytes(header[28:32], "big")
    # The in-header size is valid when the change counter matches version-valid-for.
    if header[24:28] == header[92:96] and pages * page_size > size:
        return f"truncated: its header says {pages * page_size} bytes, the file has {size}"
    return None


class DisturbanceDB:
    """A disturbance database: recordings, identified parameters and ``u_d`` traces.

    Parameters
    ----------
    path : str or PathLike
        The SQLite file.
    create : bool
        Make a new database when ``path`` does not exist (default); otherwise
        a missing file is an error.  The folder must exist.
    upgrade : bool
        Upgrade a file of an older schema in place (default), after copying it
        to a backup beside it, with a one-line notice on stderr; otherwise an
        older schema is an error.

    Raises
    ------
    DatabaseError
        If the file is not a rocketroll database, is truncated or damaged,
        has a newer schema than this package, or an older one that cannot
        be upgraded here.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from disturbances.ingest import add_recording
    >>> from identification.instruments.bundled import load_bundled
    >>> from identification.methods.pipeline import IdentifyOptions
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with DisturbanceDB(pathlib.Path(tmp) / "db.sqlite") as db:
    ...         added = add_recording(db, load_bundled("tunnel-paper-seed0"),
    ...                               IdentifyOptions(noise_runs=0))
    ...         trace = db.trace(db.traces(method="paper", model="theta")[0].uid)
    ...         print(added.traces, trace.kind, trace.u_d_deg.shape, trace.dt_s)
    4 identified (5730,) 0.1
    """

    def __init__(
        self, path: str | os.PathLike[str], *, create: bool = True, upgrade: bool = True
    ) -> None:
        self.path = Path(path)
        self._upgrade = upgrade
        self._conn = self._connect(create)

    # ----------------------------------------------------------------- lifecycle

    def _fail(self, problem: str) -> DatabaseError:
        return DatabaseError(f"{self.path}: {problem}")

    def _connect(self, create: bool) -> sqlite3.Connection:
        path = self.path
        if path.exists():
            if not path.is_file():
                raise self._fail("is not a file")
            if not create and path.stat().st_size == 0:
                raise self._fail("is empty, not a database (build one with `rocketroll db build`)")
            problem = _header_problem(path)
            if problem:
                raise self._fail(f"{problem}; not a usable rocketroll disturbance database")
        elif not create:
            raise self._fail("no such database (build one with `rocketroll db build`)")
        elif not path.parent.is_dir():
            raise self._fail(f"the folder {path.parent} does not exist")
        try:
            conn = sqlite3.connect(path, timeout=BUSY_TIMEOUT_S, isolation_level=None)
        except sqlite3.Error as exc:
            raise self._fail(f"cannot open: {exc}") from None
        try:
            self._configure(conn)
        except sqlite3.DatabaseError as exc:
            conn.close()
            raise self._fail(f"damaged or not a database ({exc})") from None
        except BaseException:
            conn.close()
            raise
        return conn

    @staticmethod
    def _tables(conn: sqlite3.Connection) -> set[str]:
        rows = conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
        return {r[0] for r in rows}

    @staticmethod
    def _version(conn: sqlite3.Connection) -> tuple[int, int]:
        version = int(conn.execute("PRAGMA user_version").fetchone()[0])
        app = int(conn.execute("PRAGMA application_id").fetchone()[0])
        return version, app

    def _configure(self, conn: sqlite3.Connection) -> None:
        conn.execute("PRAGMA foreign_keys = ON")
        version, app = self._version(conn)
        tables = self._tables(conn)
        if version == 0 and app == 0 and not tables:
            # A new file.  Another process may be creating it too: decide under the
            # write lock, and only one of them makes the schema.
            with write_transaction(conn):
                version, app = self._version(conn)
                tables = self._tables(conn)
                if version == 0 and app == 0 and not tables:
                    for statement in SCHEMA:
                        conn.execute(statement)
                    conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                    conn.executemany(
                        "INSERT INTO info (key, value) VALUES (?, ?)",
                        [
                            ("created_by", package_version()),
                            ("created_at", now()),
                            ("origin", "user"),
                        ],
                    )
                    version, app, tables = SCHEMA_VERSION, APPLICATION_ID, set(TABLES)
        if app != APPLICATION_ID:
            raise self._fail(
                "an SQLite database, but not a rocketroll disturbance database "
                f"(tables: {', '.join(sorted(tables)) or 'none'})"
            )
        if version > SCHEMA_VERSION:
            raise self._fail(
                f"schema version {version} is newer than this rocketroll's "
                f"({SCHEMA_VERSION}, package {package_version()}); upgrade rocketroll to read it"
            )
        missing = set(TABLES) - tables
        if missing:
            raise self._fail(f"damaged: missing table(s) {', '.join(sorted(missing))}")
        if version < SCHEMA_VERSION:
            self._migrate(conn, version)
        conn.execute("PRAGMA journal_mode = WAL")

    def _migrate(self, conn: sqlite3.Connection, version: int) -> None:
        """Upgrade an older schema in place (a backup is kept), or say why not."""
        how = f"`rocketroll db migrate --db {self.path}`"
        if not self._upgrade:
            raise self._fail(
                f"schema version {version} is older than this rocketroll's ({SCHEMA_VERSION}); "
                f"upgrade it with {how}"
            )
        if not os.access(self.path, os.W_OK) or not os.access(self.path.parent, os.W_OK):
            raise self._fail(
                f"schema version {version} is older than this rocketroll's ({SCHEMA_VERSION}) "
                f"and cannot be upgraded here (the file or its folder is read-only); run {how} "
                "where it can be written"
            )
        try:
            backup = migrate(conn, self.path, version)
        except ValueError as exc:
            raise self._fail(f"cannot be upgraded: {exc}") from None
        except sqlite3.IntegrityError as exc:
            raise self._fail(f"cannot be upgraded from schema {version}: {exc}") from None
        except sqlite3.OperationalError as exc:
            raise self._fail(
                f"upgrading schema {version} to {SCHEMA_VERSION} failed: {exc}"
            ) from None
        except OSError as exc:
            raise self._fail(
                f"upgrading schema {version} to {SCHEMA_VERSION} failed: cannot write the "
                f"backup ({exc.strerror or exc})"
            ) from None
        if backup is not None:  # None: another process upgraded it first
            print(
                f"rocketroll: upgraded {self.path} from schema {version} to {SCHEMA_VERSION} "
                f"(the old file is kept as {backup})",
                file=sys.stderr,
            )

    @property
    def schema_version(self) -> int:
        """The schema version of the open file (:data:`SCHEMA_VERSION` once opened)."""
        return self._version(self._conn)[0]

    def close(self) -> None:
        """Close the connection (idempotent)."""
        self._conn.close()

    def __enter__(self) -> DisturbanceDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"DisturbanceDB({str(self.path)!r})"

    @contextmanager
    def _errors(self) -> Iterator[None]:
        """Turn SQLite's errors into a :class:`DatabaseError` naming the file."""
        try:
            yield
        except sqlite3.OperationalError as exc:
            text = str(exc)
            if "locked" in text or "busy" in text:
                raise self._fail(
                    f"busy: another process kept it locked for {BUSY_TIMEOUT_S:g} s ({text})"
                ) from None
            if "readonly" in text:
                raise self._fail(f"cannot write: {text}") from None
            raise self._fail(f"damaged or unreadable ({text})") from None
        except sqlite3.IntegrityError as exc:
            raise self._fail(f"refused by the schema's constraints ({exc})") from None
        except sqlite3.DatabaseError as exc:
            raise self._fail(f"damaged or unreadable ({exc})") from None
        except sqlite3.Error as exc:
            raise self._fail(str(exc)) from None

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """One write transaction: all of it is committed, or none of it."""
        with self._errors(), write_transaction(self._conn) as conn:
            yield conn

    def _query(self, sql: str, params: Sequence[Any] = ()) -> list[sqlite3.Row]:
        with self._errors():
            cur = self._conn.execute(sql, params)
            cur.row_factory = sqlite3.Row
            return list(cur.fetchall())

    # ----------------------------------------------------------------- info

    def info(self) -> dict[str, str]:
        """The database's ``info`` table (created_by, created_at, origin, ...)."""
        return {r["key"]: r["value"] for r in self._query("SELECT key, value FROM info")}

    def set_info(self, values: Mapping[str, str]) -> None:
        """Set ``info`` entries (one transaction)."""
        with self._transaction() as conn:
            conn.executemany(
                "INSERT INTO info (key, value) VALUES (?, ?) "
                "ON CONFLICT (key) DO UPDATE SET value = excluded.value",
                list(values.items()),
            )

    @property
    def created_by(self) -> str:
        """The package version that created this database."""
        return self.info().get("created_by", "unknown")

    def versions(self) -> list[str]:
        """Package versions whose identifications are stored, sorted."""
        rows = self._query("SELECT DISTINCT package_version FROM identifications ORDER BY 1")
        return [r[0] for r in rows]

    def check_version(self, *, writing: bool = False) -> None:
        """Say so when this database holds identifications of another rocketroll version.

        Reading warns (``UserWarning``); ``writing=True`` raises
        :class:`DatabaseError`, since adding would mix results of two versions.
        """
        others = [v for v in self.versions() if v != package_version()]
        if not others:
            return
        message = (
            f"{self.path}: holds identifications made by rocketroll {', '.join(others)}; "
            f"this is {package_version()}"
        )
        if writing:
            raise DatabaseError(
                f"{message}: adding to it would mix two versions' results; add to a new "
                "database file instead (`--db NEW.sqlite`)"
            )
        warnings.warn(message, UserWarning, stacklevel=2)

    # ----------------------------------------------------------------- writing

    def store(
        self,
        recordings: Sequence[RecordingRow] = (),
        identifications: Sequence[IdentificationRow] = (),
        traces: Sequence[TraceRow] = (),
    ) -> StoreResult:
        """Insert rows in one transaction; rows already present are recognised and skipped.

        Recordings are matched by content hash, identifications by
        ``(recording, method, model)``, traces by uid.  A surrogate's source
        must be stored already or come earlier in ``traces``.  The rows have
        checked their names; a method is stored under any name
        (:func:`disturbances.stores.store_rows` refuses one that is not
        registered, for every back end).

        Returns
        -------
        StoreResult
            Counts; ``recording_id`` is the first recording's row id.
        """
        added_r = added_i = added_t = skipped = 0
        trace_ids: list[int] = []
        with self._transaction() as conn:
            rec_ids: dict[str, int] = {}
            for row in recordings:
                rid = self._recording_id(row.content_hash)
                if rid is None:
                    rid = self._insert_recording(conn, row)
                    added_r += 1
                else:
                    skipped += 1
                rec_ids[row.content_hash] = rid
            ident_ids: dict[tuple[str, str, str], int] = {}
            for ident in identifications:
                rid = rec_ids.get(ident.recording_hash) or self._recording_id(ident.recording_hash)
                if rid is None:
                    raise self._fail(
                        f"identification {ident.method}/{ident.model} refers to recording "
                        f"{ident.recording_hash[:12]}…, which is not stored"
                    )
                found = conn.execute(
                    "SELECT id FROM identifications WHERE recording_id = ? AND method = ? "
                    "AND model = ?",
                    (rid, ident.method, ident.model),
                ).fetchone()
                if found is None:
                    ident_ids[ident.key] = self._insert_identification(conn, rid, ident)
                    added_i += 1
                else:
                    ident_ids[ident.key] = int(found[0])
                    skipped += 1
            for trace in traces:
                if self._trace_id(trace.uid) is not None:
                    skipped += 1
                    continue
                iid = ident_ids.get(trace.identification_key)
                if iid is None:
                    iid = self._identification_id(*trace.identification_key)
                if iid is None:
                    raise self._fail(
                        f"trace {trace.uid} refers to identification "
                        f"{trace.method}/{trace.model} of recording {trace.recording_hash[:12]}…, "
                        "which is not stored"
                    )
                source_id = None
                if trace.source_uid is not None:
                    source_id = self._trace_id(trace.source_uid)
                    if source_id is None:
                        raise self._fail(
                            f"surrogate {trace.uid} refers to trace {trace.source_uid}, "
                            "which is not stored"
                        )
                trace_ids.append(self._insert_trace(conn, iid, source_id, trace))
                added_t += 1
            if added_r or added_i or added_t:
                # Anything added by hand makes the file the user's: never rebuilt silently.
                conn.execute("UPDATE info SET value = 'user' WHERE key = 'origin'")
        first = None if not recordings else self._recording_id(recordings[0].content_hash)
        return StoreResult(first, added_r, added_i, added_t, skipped, tuple(trace_ids))

    def _insert_recording(self, conn: sqlite3.Connection, row: RecordingRow) -> int:
        if row.samples is None:
            raise ValueError(f"recording {row.name}: a row to store needs its samples")
        cur = conn.execute(
            "INSERT INTO recordings (content_hash, name, source, metadata, columns, n_samples, "
            "dt_s, duration_s, samples, split, added_at) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
            (
                row.content_hash,
                row.name,
                row.source,
                json.dumps(dict(row.metadata)),
                ",".join(row.columns),
                row.n_samples,
                row.dt_s,
                row.duration_s,
                _blob(row.samples),
                row.split,
                row.added_at,
            ),
        )
        return int(cur.lastrowid or 0)

    def _insert_identification(
        self, conn: sqlite3.Connection, recording_id: int, row: IdentificationRow
    ) -> int:
        p = row.params
        cur = conn.execute(
            "INSERT INTO identifications (recording_id, method, model, alpha, theta_bar_deg, "
            "beta_bar_per_s, alpha_bar_per_deg_s, quadratic_damping, metrics, options, "
            "package_version, created_at, verdict, v_ref_mps, rho_ref_kgm3, torque_exponent, "
            "damping_exponent) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                recording_id,
                row.method,
                row.model,
                p.alpha,
                p.theta_bar_deg,
                p.beta_bar_per_s,
                p.alpha_bar_per_deg_s,
                p.quadratic_damping,
                json.dumps(dict(row.metrics), allow_nan=False),
                json.dumps(dict(row.options), allow_nan=False),
                row.package_version,
                row.created_at,
                row.verdict,
                *_reference_columns(row.flight_reference),
            ),
        )
        return int(cur.lastrowid or 0)

    def _insert_trace(
        self, conn: sqlite3.Connection, identification_id: int, source_id: int | None, t: TraceRow
    ) -> int:
        if t.u_d_deg is None:
            raise ValueError(f"trace {t.uid}: a row to store needs its samples")
        s = t.statistics
        cur = conn.execute(
            "INSERT INTO traces (uid, identification_id, kind, source_trace_id, seed, settings, "
            "dt_s, t0_s, n_samples, samples, checksum, mean_deg, sd_deg, q05_deg, q95_deg, "
            "normality_p, validation, created_at) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (
                t.uid,
                identification_id,
                t.kind,
                source_id,
                t.seed,
                json.dumps(dict(t.settings), allow_nan=False),
                t.dt_s,
                t.t0_s,
                int(t.u_d_deg.size),
                _blob(t.u_d_deg),
                t.checksum,
                s["mean_deg"],
                s["sd_deg"],
                s["q05_deg"],
                s["q95_deg"],
                _nan_to_none(s.get("normality_p")),
                None if t.validation is None else json.dumps(dict(t.validation), allow_nan=False),
                t.created_at or now(),
            ),
        )
        return int(cur.lastrowid or 0)

    # ----------------------------------------------------------------- lookup

    def _recording_id(self, recording_hash: str) -> int | None:
        rows = self._query("SELECT id FROM recordings WHERE content_hash = ?", (recording_hash,))
        return int(rows[0][0]) if rows else None

    def _identification_id(self, recording_hash: str, method: str, model: str) -> int | None:
        rows = self._query(
            "SELECT i.id FROM identifications i JOIN recordings r ON r.id = i.recording_id "
            "WHERE r.content_hash = ? AND i.method = ? AND i.model = ?",
            (recording_hash, method, model),
        )
        return int(rows[0][0]) if rows else None

    def _trace_id(self, uid: str) -> int | None:
        rows = self._query("SELECT id FROM traces WHERE uid = ?", (uid,))
        return int(rows[0][0]) if rows else None

    def has_recording(self, recording_hash: str) -> bool:
        """Whether a recording with these samples is stored."""
        return self._recording_id(recording_hash) is not None

    def has_identification(self, recording_hash: str, method: str, model: str) -> bool:
        """Whether ``method``/``model`` of that recording is stored."""
        return self._identification_id(recording_hash, method, model) is not None

    def has_trace(self, uid: str) -> bool:
        """Whether a trace with this uid is stored."""
        return self._trace_id(uid) is not None

    # ----------------------------------------------------------------- reading

    _RECORDING_COLUMNS = (
        "id, name, source, content_hash, split, n_samples, dt_s, duration_s, columns, "
        "metadata, added_at"
    )

    def _recording_row(self, r: sqlite3.Row, samples: FloatArray | None) -> RecordingRow:
        columns = tuple(r["columns"].split(","))
        try:
            return RecordingRow(
                content_hash=r["content_hash"],
                name=r["name"],
                source=r["source"],
                metadata=json.loads(r["metadata"]),
                columns=columns,
                samples=None if samples is None else samples.reshape(r["n_samples"], len(columns)),
                added_at=r["added_at"],
                n_samples=r["n_samples"],
                dt_s=r["dt_s"],
                duration_s=r["duration_s"],
                split=r["split"],
                id=r["id"],
            )
        except ValueError as exc:
            raise self._fail(f"corrupt recording: {exc}") from None

    def recordings(self) -> list[RecordingRow]:
        """Every stored recording (without its samples), oldest first."""
        rows = self._query(f"SELECT {self._RECORDING_COLUMNS} FROM recordings ORDER BY id")
        return [self._recording_row(r, None) for r in rows]

    def recording_row(self, key: int | str) -> RecordingRow:
        """A stored recording with its samples, by row id, name or content hash."""
        if isinstance(key, int):
            rows = self._query("SELECT * FROM recordings WHERE id = ?", (key,))
        else:
            rows = self._query(
                "SELECT * FROM recordings WHERE content_hash = ? OR name = ? ORDER BY id",
                (key, key),
            )
        if not rows:
            raise DatabaseError(f"{self.path}: no recording {key!r}")
        if len(rows) > 1:
            raise DatabaseError(
                f"{self.path}: {len(rows)} recordings are named {key!r}; give the id or hash"
            )
        r = rows[0]
        samples = _f64(r["samples"])
        if samples.size != r["n_samples"] * len(r["columns"].split(",")):
            raise self._fail(f"recording {r['name']}: stored samples have the wrong length")
        return self._recording_row(r, samples)

    def recording(self, key: int | str) -> Recording:
        """A stored recording by row id, name or content hash, exactly as added."""
        return self.recording_row(key).recording()

    def identifications(self, **filters: Any) -> list[IdentificationRow]:
        """Stored identifications; filters ``method``, ``model``, ``recording`` (name),
        ``recording_hash``, ``verdict``."""
        where, params = self._where(
            filters, allowed=("method", "model", "recording", "recording_hash", "verdict")
        )
        rows = self._query(
            "SELECT i.*, r.name AS recording_name, r.content_hash AS recording_hash "
            f"FROM identifications i JOIN recordings r ON r.id = i.recording_id {where} "
            "ORDER BY i.id",
            params,
        )
        return [
            IdentificationRow(
                recording_hash=r["recording_hash"],
                method=r["method"],
                model=r["model"],
                params=params_from_columns(r),
                metrics=json.loads(r["metrics"]),
                options=json.loads(r["options"]),
                package_version=r["package_version"],
                created_at=r["created_at"],
                recording=r["recording_name"],
                id=r["id"],
            )
            for r in rows
        ]

    _TRACE_SELECT = (
        "SELECT t.id, t.uid, t.kind, s.uid AS source_uid, t.seed, t.settings, "
        "r.id AS recording_id, r.name AS recording, r.content_hash AS recording_hash, r.source, "
        "r.split, i.method, "
        "i.model, i.alpha, i.theta_bar_deg, i.beta_bar_per_s, i.alpha_bar_per_deg_s, "
        "i.quadratic_damping, t.dt_s, "
        "t.t0_s, t.n_samples, t.checksum, t.mean_deg, t.sd_deg, t.q05_deg, t.q95_deg, "
        "t.normality_p, i.package_version, i.verdict, t.created_at, t.validation, "
        "i.v_ref_mps, i.rho_ref_kgm3, i.torque_exponent, i.damping_exponent, "
        "i.options, i.metrics AS fit_metrics, r.metadata AS recording_metadata "
        "FROM traces t JOIN identifications i ON i.id = t.identification_id "
        "JOIN recordings r ON r.id = i.recording_id LEFT JOIN traces s ON s.id = t.source_trace_id"
    )

    def _trace_row(self, r: sqlite3.Row, samples: FloatArray | None = None) -> TraceRow:
        try:
            return TraceRow(
                uid=r["uid"],
                recording_hash=r["recording_hash"],
                method=r["method"],
                model=r["model"],
                kind=r["kind"],
                source_uid=r["source_uid"],
                seed=r["seed"],
                settings=json.loads(r["settings"]),
                dt_s=r["dt_s"],
                t0_s=r["t0_s"],
                checksum=r["checksum"],
                statistics={
                    "mean_deg": r["mean_deg"],
                    "sd_deg": r["sd_deg"],
                    "q05_deg": r["q05_deg"],
                    "q95_deg": r["q95_deg"],
                    "normality_p": r["normality_p"],
                },
                validation=None if r["validation"] is None else json.loads(r["validation"]),
                created_at=r["created_at"],
                u_d_deg=samples,
                n_samples=r["n_samples"],
                params=params_from_columns(r),
                recording=r["recording"],
                source=r["source"],
                split=r["split"],
                package_version=r["package_version"],
                verdict=r["verdict"],
                id=r["id"],
                recording_id=r["recording_id"],
                flight_reference=_reference(r),
                rig=rig_from_json(r["options"], r["recording_metadata"], r["fit_metrics"]),
            )
        except ChecksumError:
            raise self._corrupt(r["uid"]) from None
        except ValueError as exc:
            raise self._fail(f"corrupt trace {r['uid']}: {exc}") from None

    _FILTERS: Mapping[str, str] = {
        "split": "r.split",
        "model": "i.model",
        "method": "i.method",
        "kind": "t.kind",
        "source": "r.source",
        "recording": "r.name",
        "recording_hash": "r.content_hash",
        "verdict": "i.verdict",
    }

    def methods(self) -> list[str]:
        """Identification methods of the stored identifications, in order of appearance."""
        rows = self._query("SELECT method FROM identifications GROUP BY method ORDER BY MIN(id)")
        return [r[0] for r in rows]

    def _where(self, filters: Mapping[str, Any], allowed: Sequence[str]) -> tuple[str, list[Any]]:
        clauses: list[str] = []
        params: list[Any] = []
        for key, value in filters.items():
            if value is None:
                continue
            if key == "metadata":
                if "metadata" not in allowed:
                    raise ValueError("unknown filter 'metadata'")
                for mkey, mvalue in dict(value).items():
                    clauses.append("json_extract(r.metadata, ?) = ?")
                    params += [f'$."{mkey}"', str(mvalue)]
                continue
            if key == "validated":
                if key not in allowed:
                    raise ValueError(f"unknown filter {key!r}")
                passed = "(t.validation IS NULL OR json_extract(t.validation, '$.passed') = 1)"
                clauses.append(passed if value else f"NOT {passed}")
                continue
            if key == "min_duration_s":
                if key not in allowed:
                    raise ValueError(f"unknown filter {key!r}")
                clauses.append("t.n_samples * t.dt_s >= ?")
                params.append(float(value))
                continue
            if key not in allowed or key not in self._FILTERS:
                raise ValueError(f"unknown filter {key!r}; use {', '.join(sorted(allowed))}")
            column, choices = self._FILTERS[key], NAMES.get(key)
            values = [value] if isinstance(value, str) else list(value)
            for v in values:
                if choices is not None and v not in choices:
                    raise ValueError(f"filter {key}={v!r}: must be one of {', '.join(choices)}")
            if key == "kind" and "surrogate" in values:
                values = [v for v in values if v != "surrogate"] + list(SURROGATE_KINDS)
            clauses.append(f"{column} IN ({','.join('?' * len(values))})")
            params += values
        return ("WHERE " + " AND ".join(clauses)) if clauses else "", params

    def traces(self, **filters: Any) -> list[TraceRow]:
        """Stored traces (without their samples) matching every filter given, in insertion order.

        Filters (each a value or a list of values): ``split`` (train, test),
        ``model`` (constant, theta), ``method`` (any name: one that is not
        stored matches nothing; :func:`disturbances.stores.check_filters`
        refuses one that is neither registered nor stored), ``kind`` (identified, iaaft, ar,
        ``surrogate`` for both, or posterior), ``source`` (synthetic, wind-tunnel,
        flight), ``recording`` (name); ``metadata`` (a mapping of the
        recording's metadata keys to required values), ``min_duration_s``,
        ``validated`` (``True``: identified traces and surrogates that
        passed their check; ``False``: surrogates that failed), and ``verdict``
        (the identification's adequacy: good, weak, unreliable).  An unknown
        filter or value is a ``ValueError``.
        """
        where, params = self._where(filters, allowed=TRACE_FILTERS)
        rows = self._query(f"{self._TRACE_SELECT} {where} ORDER BY t.id", params)
        return [self._trace_row(r) for r in rows]

    def trace(self, key: int | str) -> TraceRow:
        """One trace with its samples, by row id or uid, verified against its checksum."""
        column = "t.id" if isinstance(key, int) else "t.uid"
        rows = self._query(
            f"{self._TRACE_SELECT.replace('SELECT ', 'SELECT t.samples, ', 1)} WHERE {column} = ?",
            (key,),
        )
        if not rows:
            raise DatabaseError(f"{self.path}: no trace {key!r}")
        r = rows[0]
        return self._trace_row(r, self._samples(r))

    def _samples(self, r: sqlite3.Row) -> FloatArray:
        """A trace's stored samples (the row type checks them against the checksum)."""
        values = readonly_array(_f64(r["samples"]))
        if values.size != r["n_samples"]:
            raise self._corrupt(r["uid"])
        return values

    def _corrupt(self, uid: str) -> DatabaseError:
        return self._fail(
            f"trace {uid} is corrupt: its stored samples do not match their checksum (the "
            "file was altered or damaged)"
        )

    def load_traces(self, rows: Iterable[TraceRow]) -> list[TraceRow]:
        """The given listed traces with their samples (verified), in the order given."""
        rows = list(rows)
        if not rows:
            return []
        ids = [row.id for row in rows]
        found: dict[int, FloatArray] = {}
        for start in range(0, len(ids), 500):
            chunk = ids[start : start + 500]
            got = self._query(
                "SELECT id, uid, samples, checksum, n_samples FROM traces "
                f"WHERE id IN ({','.join('?' * len(chunk))})",
                chunk,
            )
            for r in got:
                found[int(r["id"])] = self._samples(r)
        missing = [row.uid for row in rows if row.id not in found]
        if missing:
            raise DatabaseError(f"{self.path}: trace(s) {', '.join(missing)} no longer stored")
        out = []
        for row in rows:
            try:  # the row verifies its samples against its checksum
                out.append(dataclasses.replace(row, u_d_deg=found[int(row.id or 0)]))
            except ChecksumError:
                raise self._corrupt(row.uid) from None
        return out

    def counts(self) -> dict[str, int]:
        """Number of recordings, identifications and traces (identified, surrogate, posterior)."""
        rows = self._query(
            "SELECT (SELECT COUNT(*) FROM recordings), (SELECT COUNT(*) FROM identifications), "
            "(SELECT COUNT(*) FROM traces WHERE kind = 'identified'), "
            "(SELECT COUNT(*) FROM traces WHERE kind = ?), "
            f"(SELECT COUNT(*) FROM traces WHERE kind IN ({','.join('?' * len(SURROGATE_KINDS))}))",
            (POSTERIOR_KIND, *SURROGATE_KINDS),
        )
        r = rows[0]
        return {
            "recordings": r[0],
            "identifications": r[1],
            "traces": r[2],
            "surrogates": r[4],
            "posterior": r[3],
        }

    def traces_by_uid(self, uids: Sequence[str]) -> list[TraceRow]:
        """The listed trace of each uid, in order (an unknown uid is an error)."""
        out = []
        for uid in uids:
            rows = self._query(f"{self._TRACE_SELECT} WHERE t.uid = ?", (uid,))
            if not rows:
                raise DatabaseError(f"{self.path}: no trace {uid!r}")
            out.append(self._trace_row(rows[0]))
        return out

    # ----------------------------------------------------------------- export

    def dump(self, **filters: Any) -> Dump:
        """The traces matching ``filters`` (see :meth:`traces`) with their samples,
        identifications, recordings and surrogate sources, for export."""
        return self.dump_rows(self.traces(**filters))

    def dump_rows(self, listed: Sequence[TraceRow]) -> Dump:
        """:meth:`dump` of given listed traces."""
        # A surrogate needs its source; add sources that the filters left out.
        by_uid = {i.uid: i for i in listed}
        pending = [i.source_uid for i in listed if i.source_uid and i.source_uid not in by_uid]
        while pending:
            for row in self.traces_by_uid(sorted(set(pending))):
                by_uid[row.uid] = row
            pending = [
                i.source_uid for i in by_uid.values() if i.source_uid and i.source_uid not in by_uid
            ]
        # By uid, sources first: the same selection exports the same bytes from any database.
        ordered = sorted(by_uid.values(), key=lambda i: (i.source_uid is not None, i.uid))
        recordings: dict[str, RecordingRow] = {}
        idents: dict[tuple[str, str, str], IdentificationRow] = {}
        for trace in ordered:
            if trace.recording_hash not in recordings:
                recordings[trace.recording_hash] = self.recording_row(trace.recording_hash)
            if trace.identification_key not in idents:
                (ident,) = self.identifications(
                    recording_hash=trace.recording_hash, method=trace.method, model=trace.model
                )
                idents[trace.identification_key] = ident
        return Dump(
            recordings=tuple(sorted(recordings.values(), key=lambda r: r.content_hash)),
            identifications=tuple(sorted(idents.values(), key=lambda i: i.key)),
            traces=tuple(self.load_traces(ordered)),
        )


def _reference_columns(
    reference: FlightReference | None,
) -> tuple[float | None, float | None, float | None, float | None]:
    """An identification's flight-reference columns (NULL for a tunnel fit)."""
    if reference is None:
        return (None, None, None, None)
    return (
        reference.v_ref_mps,
        reference.rho_ref_kgm3,
        reference.scaling.torque_exponent,
        reference.scaling.damping_exponent,
    )


def _reference(r: sqlite3.Row) -> FlightReference | None:
    """The flight reference a row's columns hold (None for a tunnel fit)."""
    if r["v_ref_mps"] is None:
        return None
    return FlightReference(
        r["v_ref_mps"],
        r["rho_ref_kgm3"],
        AirspeedScaling(r["torque_exponent"], r["damping_exponent"]),
    )
