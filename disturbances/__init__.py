"""The disturbance database: recordings, identified parameters and ``u_d`` traces.

* :mod:`disturbances.db` -- :class:`DisturbanceDB`, the SQLite store (all SQL lives here).
* :mod:`disturbances.schema` -- its schema and the migrations of older files.
* :mod:`disturbances.rows` -- the stored rows, content hashes, checksums and the split rule.
* :mod:`disturbances.ingest` -- identify and store: the service above the store.
* :mod:`disturbances.default` -- the default database, built from the bundled recordings.
* :mod:`disturbances.bank` -- :class:`TraceBank`, traces in memory for fast episode windows.
* :mod:`disturbances.surrogate` -- IAAFT and AR surrogate traces and their check.
* :mod:`disturbances.exchange` -- export to csv/npz/parquet folders and import.

Heavy modules (surrogates, export, plots) are imported on use.
"""

from disturbances.bank import TraceBank, Window
from disturbances.db import DatabaseError, DisturbanceDB
from disturbances.default import default_path, open_database, open_default
from disturbances.rows import IdentificationRow, RecordingRow, TraceRow

__all__ = [
    "DatabaseError",
    "DisturbanceDB",
    "IdentificationRow",
    "RecordingRow",
    "TraceBank",
    "TraceRow",
    "Window",
    "default_path",
    "open_database",
    "open_default",
]
