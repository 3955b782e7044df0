"""A sweep's results store: one row per trial in one SQLite file (``OUT/results.sqlite``),
written in one transaction when the trial ends."""

from __future__ import annotations

import json
import os
import sqlite3
import time
from pathlib import Path
from typing import Any

from rocketroll_common.arrays import nan_to_none
from rocketroll_common.errors import UsageError

#: The results store's schema version (``PRAGMA user_version``).
SCHEMA_VERSION = 1
_SCHEMA = """
CREATE TABLE IF NOT EXISTS trials (
    id TEXT PRIMARY KEY,
    sweep TEXT NOT NULL,
    env_id TEXT NOT NULL,
    controller TEXT NOT NULL,
    seed INTEGER,
    spec TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('done', 'failed')),
    error TEXT,
    headline TEXT,
    headline_mean REAL,
    metrics TEXT,
    episode_headline TEXT,
    wall_s REAL NOT NULL,
    train_s REAL,
    env_steps_per_s REAL,
    artifacts TEXT,
    version TEXT NOT NULL,
    git_revision TEXT,
    finished_at TEXT NOT NULL
);
"""


# ----------------------------------------------------------------------------- the store
class ResultStore:
    """The sweep's results: ``trials`` in one SQLite file (schema :data:`_SCHEMA`).

    Each record is written in one transaction (``INSERT OR REPLACE``: a
    failed trial run again replaces its failure).  Query it with any SQLite
    client, :meth:`rows`, or :meth:`export_parquet`.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(self.path)
        version = self._db.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:
            raise UsageError(
                f"{self.path}: results store of schema {version}, newer than this rocketroll's "
                f"{SCHEMA_VERSION}"
            )
        with self._db:
            self._db.executescript(_SCHEMA)
            self._db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def done(self) -> set[str]:
        """Ids of the trials finished without error."""
        return {r[0] for r in self._db.execute("SELECT id FROM trials WHERE status = 'done'")}

    def record(self, record: dict[str, Any]) -> None:
        """Store one trial's record (one transaction)."""

        def text(key: str) -> str | None:
            value = record.get(key)
            return None if value is None else json.dumps(nan_to_none(value), allow_nan=False)

        row = (
            record["id"],
            record["sweep"],
            record["env_id"],
            record["controller"],
            record.get("seed"),
            json.dumps(record["spec"], sort_keys=True, default=str),
            record["status"],
            record.get("error"),
            record.get("headline"),
            record.get("headline_mean"),
            text("metrics"),
            text("episode_headline"),
            float(record["wall_s"]),
            record.get("train_s"),
            record.get("env_steps_per_s"),
            text("artifacts"),
            record["version"],
            record.get("git_revision"),
            time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        )
        with self._db:
            self._db.execute(f"INSERT OR REPLACE INTO trials VALUES ({', '.join('?' * 19)})", row)

    def rows(self, sweep: str | None = None) -> list[dict[str, Any]]:
        """Every trial (of ``sweep``) as a dict, JSON columns decoded, in id order."""
        self._db.row_factory = sqlite3.Row
        try:
            query = "SELECT * FROM trials" + (" WHERE sweep = ?" if sweep else "") + " ORDER BY id"
            found = self._db.execute(query, (sweep,) if sweep else ()).fetchall()
        finally:
            self._db.row_factory = None
        rows = []
        for r in found:
            row = dict(r)
            for key in ("spec", "metrics", "episode_headline", "artifacts"):
                if row[key] is not None:
                    row[key] = json.loads(row[key])
            rows.append(row)
        return rows

    def export_parquet(self, path: str | os.PathLike[str]) -> Path:
        """Every row into a Parquet file (needs pyarrow: ``pip install 'rocketroll[parquet]'``);
        the JSON columns stay JSON text."""
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise UsageError(
                "Parquet export needs pyarrow: pip install 'rocketroll[parquet]'"
            ) from exc
        cursor = self._db.execute("SELECT * FROM trials ORDER BY id")
        names = [d[0] for d in cursor.description]
        found = cursor.fetchall()
        table = pa.table({n: [row[i] for row in found] for i, n in enumerate(names)})
        target = Path(path)
        pq.write_table(table, target)
        return target
