"""``DisturbanceDB``: the SQLite store of recordings, identifications and ``u_d`` traces.

All the SQL of the project lives in this module; callers use the methods.

Schema (version :data:`SCHEMA_VERSION`, in ``PRAGMA user_version``; the file is
marked with ``PRAGMA application_id`` :data:`APPLICATION_ID`)::

    info             key -> value: created_by (package version), created_at,
                     origin (bundled | user), fingerprint (of a bundled build)
    recordings       name, source, metadata (JSON), columns, the raw samples
                     (float64 blob), content_hash (UNIQUE), split, added_at
    identifications  recording -> method (paper | output-error), model
                     (constant | theta), α, θ̄, β̄, ᾱ, metrics (JSON), options
                     (JSON), package_version, created_at;
                     UNIQUE (recording, method, model)
    traces           uid (UNIQUE), identification, kind (identified | iaaft |
                     ar), source trace (surrogates), seed, settings (JSON), Δt,
                     t0, the u_d samples (float64 blob), their SHA-256, mean, SD,
                     5 % and 95 % quantiles, normality p, validation (JSON)

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
import warnings
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from disturbances.rows import (
    KINDS,
    METHODS,
    MODELS,
    SPLITS,
    SURROGATE_KINDS,
    IdentificationRow,
    RecordingRow,
    TraceRow,
    checksum,
    content_hash,
    identified_uid,
)
from identification.model import RollParams
from identification.recording import Recording
from rocketroll_common import __version__
from rocketroll_common.arrays import FloatArray, readonly_array
from rocketroll_common.errors import RocketrollError

__all__ = [
    "APPLICATION_ID",
    "SCHEMA_VERSION",
    "DatabaseError",
    "DisturbanceDB",
    "Dump",
    "IdentificationInfo",
    "RecordingInfo",
    "StoreResult",
    "Trace",
    "TraceInfo",
    "now",
    "package_version",
]

#: Version of the schema this package writes and reads.
SCHEMA_VERSION = 1
#: ``PRAGMA application_id`` of a rocketroll disturbance database ("RRDB").
APPLICATION_ID = 0x52524442
#: Seconds a writer waits for another writer before giving up.
BUSY_TIMEOUT_S = 30.0

_SQLITE_MAGIC = b"SQLite format 3\x00"

_SCHEMA = """
CREATE TABLE info (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE recordings (
    id           INTEGER PRIMARY KEY,
    content_hash TEXT NOT NULL UNIQUE,
    name         TEXT NOT NULL,
    source       TEXT NOT NULL CHECK (source IN ('synthetic', 'wind-tunnel', 'flight')),
    metadata     TEXT NOT NULL,
    columns      TEXT NOT NULL,
    n_samples    INTEGER NOT NULL CHECK (n_samples > 0),
    dt_s         REAL NOT NULL,
    duration_s   REAL NOT NULL,
    samples      BLOB NOT NULL,
    split        TEXT NOT NULL CHECK (split IN ('train', 'test')),
    added_at     TEXT NOT NULL
);
CREATE TABLE identifications (
    id                  INTEGER PRIMARY KEY,
    recording_id        INTEGER NOT NULL REFERENCES recordings(id) ON DELETE CASCADE,
    method              TEXT NOT NULL CHECK (method IN ('paper', 'output-error')),
    model               TEXT NOT NULL CHECK (model IN ('constant', 'theta')),
    alpha               REAL NOT NULL,
    theta_bar_deg       REAL NOT NULL,
    beta_bar_per_s      REAL NOT NULL,
    alpha_bar_per_deg_s REAL NOT NULL,
    metrics             TEXT NOT NULL,
    options             TEXT NOT NULL,
    package_version     TEXT NOT NULL,
    created_at          TEXT NOT NULL,
    UNIQUE (recording_id, method, model)
);
CREATE TABLE traces (
    id                INTEGER PRIMARY KEY,
    uid               TEXT NOT NULL UNIQUE,
    identification_id INTEGER NOT NULL REFERENCES identifications(id) ON DELETE CASCADE,
    kind              TEXT NOT NULL CHECK (kind IN ('identified', 'iaaft', 'ar')),
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
);
CREATE INDEX traces_by_identification ON traces (identification_id);
CREATE INDEX traces_by_source ON traces (source_trace_id);
CREATE INDEX identifications_by_recording ON identifications (recording_id);
"""

_TABLES = ("identifications", "info", "recordings", "traces")


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


def _params(row: sqlite3.Row) -> RollParams:
    """The roll parameters of an ``identifications`` row (or a join holding its columns)."""
    return RollParams(
        row["alpha"], row["theta_bar_deg"], row["beta_bar_per_s"], row["alpha_bar_per_deg_s"]
    )


def _nan_to_none(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class RecordingInfo:
    """A stored recording, without its samples."""

    id: int
    name: str
    source: str
    content_hash: str
    split: str
    n_samples: int
    dt_s: float
    duration_s: float
    columns: tuple[str, ...]
    metadata: Mapping[str, str]
    added_at: str


@dataclass(frozen=True)
class IdentificationInfo:
    """A stored identification."""

    id: int
    recording_id: int
    recording: str
    method: str
    model: str
    params: RollParams
    metrics: Mapping[str, Any]
    options: Mapping[str, Any]
    package_version: str
    created_at: str


@dataclass(frozen=True)
class TraceInfo:
    """A stored ``u_d`` trace, without its samples.

    Attributes
    ----------
    id : int
        Row id in this database (use ``uid`` across databases).
    uid : str
        Stable identity, the same in every database and export.
    kind : str
        ``identified``, ``iaaft`` or ``ar``.
    source_uid : str or None
        The trace a surrogate was made from.
    seed : int or None
        The surrogate's seed.
    recording, recording_id, source, split
        The recording it comes from (for a surrogate: its source's), its
        ``source`` (synthetic, wind-tunnel, flight) and its split.
    method, model : str
        The identification whose parameters go with it.
    params : RollParams
        Those parameters.
    dt_s, t0_s : float
        Δt of each held sample and the start time, s.
    n_samples : int
        Length.
    mean_deg, sd_deg, q05_deg, q95_deg : float
        Summary statistics, °.
    normality_p : float or None
        Lilliefors p-value on the thinned trace.
    package_version : str
        The rocketroll version that identified it.
    created_at : str
        UTC, ISO 8601.
    validation : mapping or None
        A surrogate's check against its source (KS p-value, PSD
        log-distance, ``passed``); ``None`` for an identified trace.
    """

    id: int
    uid: str
    kind: str
    source_uid: str | None
    seed: int | None
    recording: str
    recording_id: int
    source: str
    split: str
    method: str
    model: str
    params: RollParams
    dt_s: float
    t0_s: float
    n_samples: int
    mean_deg: float
    sd_deg: float
    q05_deg: float
    q95_deg: float
    normality_p: float | None
    package_version: str
    created_at: str
    validation: Mapping[str, Any] | None = None

    @property
    def duration_s(self) -> float:
        """Length of the trace, s."""
        return self.n_samples * self.dt_s


@dataclass(frozen=True, eq=False)
class Trace:
    """A ``u_d`` trace with the parameters it was identified with.

    Attributes
    ----------
    info : TraceInfo
        Provenance, parameters and statistics.
    u_d_deg : ndarray, shape (n,)
        The trace, ° of equivalent fin angle, each sample held for ``dt_s``
        (read-only; verified against its checksum when read).
    """

    info: TraceInfo
    u_d_deg: FloatArray

    @property
    def params(self) -> RollParams:
        """The roll parameters identified together with this trace."""
        return self.info.params

    @property
    def dt_s(self) -> float:
        """Δt of each sample, s."""
        return self.info.dt_s

    def __repr__(self) -> str:
        i = self.info
        return (
            f"Trace(uid={i.uid!r}, kind={i.kind}, {i.method}/{i.model}, split={i.split}, "
            f"n={i.n_samples}, dt={i.dt_s:g} s)"
        )


@dataclass(frozen=True)
class StoreResult:
    """What one change added (and what it found already there).

    Attributes
    ----------
    recording_id : int or None
        The recording the change was about (``None`` for an import).
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
    """Rows selected for export, with everything they depend on."""

    recordings: tuple[RecordingRow, ...]
    identifications: tuple[IdentificationRow, ...]
    traces: tuple[TraceRow, ...]


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
        a missing file is an error.

    Raises
    ------
    DatabaseError
        If the file is not a rocketroll database, is truncated or damaged,
        or has a newer schema than this package.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from identification.bundled import load_bundled
    >>> from identification.pipeline import IdentifyOptions
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with DisturbanceDB(pathlib.Path(tmp) / "db.sqlite") as db:
    ...         added = db.add_recording(load_bundled("tunnel-paper-seed0"),
    ...                                  IdentifyOptions(noise_runs=0))
    ...         trace = db.trace(db.traces(method="paper", model="theta")[0].uid)
    ...         print(added.traces, trace.info.kind, trace.u_d_deg.shape, trace.dt_s)
    4 identified (5730,) 0.1
    """

    def __init__(self, path: str | os.PathLike[str], *, create: bool = True) -> None:
        self.path = Path(path)
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
        except DatabaseError:
            conn.close()
            raise
        return conn

    @staticmethod
    def _tables(conn: sqlite3.Connection) -> set[str]:
        rows = conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
        return {r[0] for r in rows}

    def _configure(self, conn: sqlite3.Connection) -> None:
        conn.execute("PRAGMA foreign_keys = ON")
        version = int(conn.execute("PRAGMA user_version").fetchone()[0])
        app = int(conn.execute("PRAGMA application_id").fetchone()[0])
        tables = self._tables(conn)
        if version == 0 and app == 0 and not tables:
            # A new file.  Another process may be creating it too: decide under the
            # write lock, and only one of them makes the schema.
            conn.execute("BEGIN IMMEDIATE")
            try:
                version = int(conn.execute("PRAGMA user_version").fetchone()[0])
                app = int(conn.execute("PRAGMA application_id").fetchone()[0])
                tables = self._tables(conn)
                if version == 0 and app == 0 and not tables:
                    for statement in _SCHEMA.split(";"):
                        if statement.strip():
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
                    version, app, tables = SCHEMA_VERSION, APPLICATION_ID, set(_TABLES)
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
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
        if version < SCHEMA_VERSION:
            raise self._fail(
                f"schema version {version} is older than this rocketroll's ({SCHEMA_VERSION}); "
                f"rebuild it (`rocketroll db build --db {self.path} --force` for a bundled "
                "build) or export it with the older rocketroll and import it into a new file"
            )
        missing = set(_TABLES) - tables
        if missing:
            raise self._fail(f"damaged: missing table(s) {', '.join(sorted(missing))}")
        conn.execute("PRAGMA journal_mode = WAL")

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
        with self._errors():
            self._conn.execute("BEGIN IMMEDIATE")
            try:
                yield self._conn
            except BaseException:
                if self._conn.in_transaction:  # SQLite may have rolled back already
                    self._conn.execute("ROLLBACK")
                raise
            self._conn.execute("COMMIT")

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

    def add_recording(
        self,
        recording: Recording,
        options: Any = None,
        *,
        methods: Sequence[str] = METHODS,
        surrogates: int = 0,
        surrogate_kinds: Sequence[str] = ("iaaft",),
        surrogate_seed: int = 0,
    ) -> StoreResult:
        """Identify a recording and store it with all its results, in one transaction.

        The recording is identified by every method in ``methods`` (the
        paper's and the output-error peer) for both models; each gives its
        parameters, fit metrics and ``u_d`` trace.  ``surrogates`` surrogate
        traces of each kind in ``surrogate_kinds`` are made from each trace
        identified by the paper's method.  Nothing is written unless all of
        it succeeds.  A recording whose samples are already stored is
        recognised (``StoreResult.recordings == 0``): it is not stored twice,
        and identified again only for methods it lacks (e.g. the
        output-error peer after an add with ``methods=("paper",)``).

        Parameters
        ----------
        recording : Recording
            Any recording the pipeline accepts.
        options : IdentifyOptions, optional
            Identification settings (the paper's by default).
        methods : sequence of str
            Subset of ``("paper", "output-error")``; ``paper`` is required.
        surrogates : int
            Surrogates per kind and per paper-method trace.
        surrogate_kinds : sequence of str
            ``iaaft`` and/or ``ar``.
        surrogate_seed : int
            Seed of the first surrogate (the next ones count up).
        """
        recording_hash = content_hash(recording.columns())
        existing = self._recording_id(recording_hash)
        if existing is not None and all(
            self._identification_id(recording_hash, method, model) is not None
            for method in methods
            for model in MODELS
        ):
            if surrogates == 0:
                return StoreResult(existing, 0, 0, 0, 1, ())
            # Everything identified already: only the surrogates asked for are new.
            from disturbances.ingest import surrogate_rows

            self.check_version(writing=True)
            made: list[TraceRow] = []
            for model in MODELS:
                source = self.dump_trace(identified_uid(recording_hash, "paper", model))
                made += surrogate_rows(source, surrogate_kinds, surrogates, surrogate_seed)
            stored = self.store(None, [], made)
            return dataclasses.replace(stored, recording_id=existing, skipped=stored.skipped + 1)
        from identification.pipeline import identify

        result = identify(recording, options)
        return self.add_identification(
            result,
            methods=methods,
            surrogates=surrogates,
            surrogate_kinds=surrogate_kinds,
            surrogate_seed=surrogate_seed,
        )

    def add_identification(
        self,
        result: Any,
        *,
        methods: Sequence[str] = METHODS,
        surrogates: int = 0,
        surrogate_kinds: Sequence[str] = ("iaaft",),
        surrogate_seed: int = 0,
    ) -> StoreResult:
        """Store an :class:`~identification.pipeline.Identification` (see :meth:`add_recording`)."""
        from disturbances.ingest import identification_rows, surrogate_rows

        self.check_version(writing=True)
        recording, identifications, traces = identification_rows(result, methods)
        if self._recording_id(recording.content_hash) is not None:
            # Partly stored already: new identifications must be made like the stored
            # ones, and surrogates come from the stored traces, never from new twins.
            stored_options = {
                json.dumps(dict(i.options), sort_keys=True)
                for i in self.identifications(recording_hash=recording.content_hash)
            }
            options = json.dumps(dict(identifications[0].options), sort_keys=True)
            if stored_options and stored_options != {options}:
                raise self._fail(
                    f"recording {recording.name} is stored with other identification options; "
                    "add it to a new database to identify it differently"
                )
        made: list[TraceRow] = []
        for trace in traces:
            if trace.method == "paper":
                stored_uid = self._trace_id(trace.uid)
                source = trace if stored_uid is None else self.dump_trace(trace.uid)
                made += surrogate_rows(source, surrogate_kinds, surrogates, surrogate_seed)
        return self.store(recording, identifications, [*traces, *made])

    def add_surrogates(
        self, uid: str, kind: str = "iaaft", count: int = 1, seed: int = 0
    ) -> StoreResult:
        """Make ``count`` surrogates of a stored trace and store them (one transaction)."""
        from disturbances.ingest import surrogate_rows

        if kind not in SURROGATE_KINDS:
            raise ValueError(f"kind must be one of {', '.join(SURROGATE_KINDS)}, not {kind!r}")
        source = self.dump_trace(uid)
        if source.kind != "identified":
            raise DatabaseError(f"{self.path}: trace {uid} is itself a surrogate; use its source")
        self.check_version(writing=True)
        rows = surrogate_rows(source, (kind,), count, seed)
        return self.store(None, [], rows)

    def store(
        self,
        recording: RecordingRow | None,
        identifications: Sequence[IdentificationRow],
        traces: Sequence[TraceRow],
        *,
        recordings: Sequence[RecordingRow] = (),
    ) -> StoreResult:
        """Insert rows in one transaction; rows already present are recognised and skipped.

        Recordings are matched by content hash, identifications by
        ``(recording, method, model)``, traces by uid.  A surrogate's source
        must be stored already or come earlier in ``traces``.
        """
        all_recordings = [*([recording] if recording is not None else []), *recordings]
        added_r = added_i = added_t = skipped = 0
        trace_ids: list[int] = []
        with self._transaction() as conn:
            rec_ids: dict[str, int] = {}
            for row in all_recordings:
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
        rec_id = None if recording is None else self._recording_id(recording.content_hash)
        return StoreResult(rec_id, added_r, added_i, added_t, skipped, tuple(trace_ids))

    def _insert_recording(self, conn: sqlite3.Connection, row: RecordingRow) -> int:
        time = row.samples[:, 0]
        cur = conn.execute(
            "INSERT INTO recordings (content_hash, name, source, metadata, columns, n_samples, "
            "dt_s, duration_s, samples, split, added_at) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
            (
                row.content_hash,
                row.name,
                row.source,
                json.dumps(dict(row.metadata)),
                ",".join(row.columns),
                int(row.samples.shape[0]),
                float(np.median(np.diff(time))),
                float(time[-1] - time[0]),
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
            "beta_bar_per_s, alpha_bar_per_deg_s, metrics, options, package_version, created_at) "
            "VALUES (?,?,?,?,?,?,?,?,?,?,?)",
            (
                recording_id,
                row.method,
                row.model,
                p.alpha,
                p.theta_bar_deg,
                p.beta_bar_per_s,
                p.alpha_bar_per_deg_s,
                json.dumps(dict(row.metrics), allow_nan=False),
                json.dumps(dict(row.options), allow_nan=False),
                row.package_version,
                row.created_at,
            ),
        )
        return int(cur.lastrowid or 0)

    def _insert_trace(
        self, conn: sqlite3.Connection, identification_id: int, source_id: int | None, t: TraceRow
    ) -> int:
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

    # ----------------------------------------------------------------- reading

    def recordings(self) -> list[RecordingInfo]:
        """Every stored recording, oldest first."""
        rows = self._query(
            "SELECT id, name, source, content_hash, split, n_samples, dt_s, duration_s, columns, "
            "metadata, added_at FROM recordings ORDER BY id"
        )
        return [
            RecordingInfo(
                id=r["id"],
                name=r["name"],
                source=r["source"],
                content_hash=r["content_hash"],
                split=r["split"],
                n_samples=r["n_samples"],
                dt_s=r["dt_s"],
                duration_s=r["duration_s"],
                columns=tuple(r["columns"].split(",")),
                metadata=MappingProxyType(json.loads(r["metadata"])),
                added_at=r["added_at"],
            )
            for r in rows
        ]

    def recording(self, key: int | str) -> Recording:
        """A stored recording by row id, name or content hash, exactly as added."""
        return self._recording_row(key).recording()

    def _recording_row(self, key: int | str) -> RecordingRow:
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
        columns = tuple(r["columns"].split(","))
        samples = _f64(r["samples"])
        if samples.size != r["n_samples"] * len(columns):
            raise self._fail(f"recording {r['name']}: stored samples have the wrong length")
        try:
            return RecordingRow(
                content_hash=r["content_hash"],
                name=r["name"],
                source=r["source"],
                metadata=json.loads(r["metadata"]),
                columns=columns,
                samples=samples.reshape(r["n_samples"], len(columns)),
                added_at=r["added_at"],
            )
        except ValueError as exc:
            raise self._fail(f"corrupt recording: {exc}") from None

    def identifications(self, **filters: Any) -> list[IdentificationInfo]:
        """Stored identifications; filters ``method``, ``model``, ``recording`` (name)."""
        where, params = self._where(
            filters, allowed=("method", "model", "recording", "recording_hash")
        )
        rows = self._query(
            "SELECT i.*, r.name AS recording_name FROM identifications i "
            f"JOIN recordings r ON r.id = i.recording_id {where} ORDER BY i.id",
            params,
        )
        return [
            IdentificationInfo(
                id=r["id"],
                recording_id=r["recording_id"],
                recording=r["recording_name"],
                method=r["method"],
                model=r["model"],
                params=_params(r),
                metrics=MappingProxyType(json.loads(r["metrics"])),
                options=MappingProxyType(json.loads(r["options"])),
                package_version=r["package_version"],
                created_at=r["created_at"],
            )
            for r in rows
        ]

    _TRACE_SELECT = (
        "SELECT t.id, t.uid, t.kind, s.uid AS source_uid, t.seed, r.name AS recording, "
        "r.id AS recording_id, r.source, r.split, i.method, i.model, i.alpha, i.theta_bar_deg, "
        "i.beta_bar_per_s, i.alpha_bar_per_deg_s, t.dt_s, t.t0_s, t.n_samples, t.mean_deg, "
        "t.sd_deg, t.q05_deg, t.q95_deg, t.normality_p, i.package_version, t.created_at, "
        "t.validation "
        "FROM traces t JOIN identifications i ON i.id = t.identification_id "
        "JOIN recordings r ON r.id = i.recording_id LEFT JOIN traces s ON s.id = t.source_trace_id"
    )

    @staticmethod
    def _trace_info(r: sqlite3.Row) -> TraceInfo:
        return TraceInfo(
            id=r["id"],
            uid=r["uid"],
            kind=r["kind"],
            source_uid=r["source_uid"],
            seed=r["seed"],
            recording=r["recording"],
            recording_id=r["recording_id"],
            source=r["source"],
            split=r["split"],
            method=r["method"],
            model=r["model"],
            params=_params(r),
            dt_s=r["dt_s"],
            t0_s=r["t0_s"],
            n_samples=r["n_samples"],
            mean_deg=r["mean_deg"],
            sd_deg=r["sd_deg"],
            q05_deg=r["q05_deg"],
            q95_deg=r["q95_deg"],
            normality_p=r["normality_p"],
            package_version=r["package_version"],
            created_at=r["created_at"],
            validation=None if r["validation"] is None else json.loads(r["validation"]),
        )

    _FILTERS: Mapping[str, tuple[str, tuple[str, ...] | None]] = {
        "split": ("r.split", SPLITS),
        "model": ("i.model", MODELS),
        "method": ("i.method", METHODS),
        "kind": ("t.kind", (*KINDS, "surrogate")),
        "source": ("r.source", ("synthetic", "wind-tunnel", "flight")),
        "recording": ("r.name", None),
        "recording_hash": ("r.content_hash", None),
    }

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
            column, choices = self._FILTERS[key]
            values = [value] if isinstance(value, str) else list(value)
            for v in values:
                if choices is not None and v not in choices:
                    raise ValueError(f"filter {key}={v!r}: must be one of {', '.join(choices)}")
            if key == "kind" and "surrogate" in values:
                values = [v for v in values if v != "surrogate"] + list(SURROGATE_KINDS)
            clauses.append(f"{column} IN ({','.join('?' * len(values))})")
            params += values
        return ("WHERE " + " AND ".join(clauses)) if clauses else "", params

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
    )

    def traces(self, **filters: Any) -> list[TraceInfo]:
        """Stored traces matching every filter given, in insertion order.

        Filters (each a value or a list of values): ``split`` (train, test),
        ``model`` (constant, theta), ``method`` (paper, output-error),
        ``kind`` (identified, iaaft, ar, or ``surrogate`` for both), ``source``
        (synthetic, wind-tunnel, flight), ``recording`` (name); ``metadata``
        (a mapping of the recording's metadata keys to required values),
        ``min_duration_s``, and ``validated`` (``True``: identified traces and
        surrogates that passed their check; ``False``: surrogates that failed).
        An unknown filter or value is a ``ValueError``.
        """
        where, params = self._where(filters, allowed=self.TRACE_FILTERS)
        rows = self._query(f"{self._TRACE_SELECT} {where} ORDER BY t.id", params)
        return [self._trace_info(r) for r in rows]

    def trace(self, key: int | str) -> Trace:
        """One trace by row id or uid, its samples verified against their checksum."""
        column = "t.id" if isinstance(key, int) else "t.uid"
        rows = self._query(
            f"{self._TRACE_SELECT.replace('SELECT ', 'SELECT t.samples, t.checksum, ', 1)} "
            f"WHERE {column} = ?",
            (key,),
        )
        if not rows:
            raise DatabaseError(f"{self.path}: no trace {key!r}")
        r = rows[0]
        return Trace(info=self._trace_info(r), u_d_deg=self._verified(r))

    def _verified(self, r: sqlite3.Row) -> FloatArray:
        blob = r["samples"]
        values = readonly_array(_f64(blob))
        if checksum(values) != r["checksum"] or values.size != r["n_samples"]:
            raise self._fail(
                f"trace {r['uid']} is corrupt: its stored samples do not match their "
                "checksum (the file was altered or damaged)"
            )
        return values

    def load_traces(self, infos: Iterable[TraceInfo]) -> list[Trace]:
        """Several traces at once (verified), in the order given."""
        infos = list(infos)
        if not infos:
            return []
        ids = [i.id for i in infos]
        found: dict[int, FloatArray] = {}
        for start in range(0, len(ids), 500):
            chunk = ids[start : start + 500]
            rows = self._query(
                "SELECT id, uid, samples, checksum, n_samples FROM traces "
                f"WHERE id IN ({','.join('?' * len(chunk))})",
                chunk,
            )
            for r in rows:
                found[int(r["id"])] = self._verified(r)
        missing = [i.uid for i in infos if i.id not in found]
        if missing:
            raise DatabaseError(f"{self.path}: trace(s) {', '.join(missing)} no longer stored")
        return [Trace(info=i, u_d_deg=found[i.id]) for i in infos]

    def counts(self) -> dict[str, int]:
        """Number of recordings, identifications and traces (identified and surrogate)."""
        rows = self._query(
            "SELECT (SELECT COUNT(*) FROM recordings), (SELECT COUNT(*) FROM identifications), "
            "(SELECT COUNT(*) FROM traces WHERE kind = 'identified'), "
            "(SELECT COUNT(*) FROM traces WHERE kind != 'identified')"
        )
        r = rows[0]
        return {
            "recordings": r[0],
            "identifications": r[1],
            "traces": r[2],
            "surrogates": r[3],
        }

    # ----------------------------------------------------------------- export

    def dump_trace(self, uid: str) -> TraceRow:
        """One stored trace as a :class:`~disturbances.rows.TraceRow` (verified)."""
        rows = self._dump_rows(self.traces_by_uid([uid]))
        return next(t for t in rows.traces if t.uid == uid)

    def traces_by_uid(self, uids: Sequence[str]) -> list[TraceInfo]:
        """:class:`TraceInfo` of each uid, in order (an unknown uid is an error)."""
        out = []
        for uid in uids:
            rows = self._query(f"{self._TRACE_SELECT} WHERE t.uid = ?", (uid,))
            if not rows:
                raise DatabaseError(f"{self.path}: no trace {uid!r}")
            out.append(self._trace_info(rows[0]))
        return out

    def dump(self, **filters: Any) -> Dump:
        """The traces matching ``filters`` (see :meth:`traces`) with their
        identifications, recordings and surrogate sources, as rows for export."""
        return self._dump_rows(self.traces(**filters))

    def _dump_rows(self, infos: Sequence[TraceInfo]) -> Dump:
        # A surrogate needs its source; add sources that the filters left out.
        by_uid = {i.uid: i for i in infos}
        pending = [i.source_uid for i in infos if i.source_uid and i.source_uid not in by_uid]
        while pending:
            for info in self.traces_by_uid(sorted(set(pending))):
                by_uid[info.uid] = info
            pending = [
                i.source_uid for i in by_uid.values() if i.source_uid and i.source_uid not in by_uid
            ]
        # By uid, sources first: the same selection exports the same bytes from any database.
        ordered = sorted(by_uid.values(), key=lambda i: (i.source_uid is not None, i.uid))
        recordings: dict[int, RecordingRow] = {}
        idents: dict[tuple[int, str, str], IdentificationRow] = {}
        traces: list[TraceRow] = []
        for trace in self.load_traces(ordered):
            info = trace.info
            if info.recording_id not in recordings:
                recordings[info.recording_id] = self._recording_row(info.recording_id)
            rec = recordings[info.recording_id]
            ikey = (info.recording_id, info.method, info.model)
            if ikey not in idents:
                idents[ikey] = self._identification_row(rec.content_hash, *ikey)
            extra = self._query("SELECT settings, checksum FROM traces WHERE id = ?", (info.id,))[0]
            traces.append(
                TraceRow(
                    uid=info.uid,
                    recording_hash=rec.content_hash,
                    method=info.method,
                    model=info.model,
                    kind=info.kind,
                    source_uid=info.source_uid,
                    seed=info.seed,
                    settings=json.loads(extra["settings"]),
                    dt_s=info.dt_s,
                    t0_s=info.t0_s,
                    u_d_deg=trace.u_d_deg,
                    checksum=extra["checksum"],
                    statistics={
                        "mean_deg": info.mean_deg,
                        "sd_deg": info.sd_deg,
                        "q05_deg": info.q05_deg,
                        "q95_deg": info.q95_deg,
                        "normality_p": info.normality_p,
                    },
                    validation=None if info.validation is None else dict(info.validation),
                    created_at=info.created_at,
                )
            )
        return Dump(
            recordings=tuple(sorted(recordings.values(), key=lambda r: r.content_hash)),
            identifications=tuple(sorted(idents.values(), key=lambda i: i.key)),
            traces=tuple(traces),
        )

    def _identification_row(
        self, recording_hash: str, recording_id: int, method: str, model: str
    ) -> IdentificationRow:
        r = self._query(
            "SELECT * FROM identifications WHERE recording_id = ? AND method = ? AND model = ?",
            (recording_id, method, model),
        )[0]
        return IdentificationRow(
            recording_hash=recording_hash,
            method=method,
            model=model,
            params=_params(r),
            metrics=json.loads(r["metrics"]),
            options=json.loads(r["options"]),
            package_version=r["package_version"],
            created_at=r["created_at"],
        )
