"""Export a database selection to a folder other tools can read, and import it back.

Layout of an export folder::

    manifest.json      format, samples format, schema and package version, the
                       filters used, counts, and the SHA-256 of every other file
    parameters.json    recordings (name, source, metadata, hash, split),
                       identifications (method, model, α, θ̄, β̄, ᾱ, metrics,
                       options, versions) and traces (uid, provenance, Δt, t0,
                       checksum, statistics, surrogate validation)
    samples, by format:
      csv      recordings/<hash16>.csv (one column per recording column)
               traces/<uid>.csv        (one column, u_d_deg; time = t0 + k·Δt)
      npz      recordings.npz (one (n, k) array per recording hash)
               traces.npz     (one array per uid)
      parquet  recordings.parquet (recording hash, column, values list)
               traces.parquet     (uid, u_d_deg list)     [optional extra]

Numbers are written so that reading them back gives the same float64 bits
(shortest round-trip text in CSV and JSON, raw float64 in npz and parquet), and
nothing depends on when the export ran, so export -> import -> export gives
byte-identical files.  An import checks every file's SHA-256, every recording's
content hash and every trace's checksum before it writes anything, and then
adds everything in one transaction, recognising what the database already has.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from disturbances.db import SCHEMA_VERSION, Dump, StoreResult
from disturbances.rows import IdentificationRow, RecordingRow, TraceRow
from disturbances.stores import Store, check_filters, store_rows
from identification.model import RollParams
from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import RocketrollError

__all__ = [
    "EXPORT_FORMAT",
    "FORMATS",
    "ExchangeError",
    "export_dump",
    "import_export",
    "read_export",
    "write_export",
]

EXPORT_FORMAT = "rocketroll-disturbances-export/1"
FORMATS = ("csv", "npz", "parquet")
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


class ExchangeError(RocketrollError):
    """An export folder cannot be written or read; the message names the file."""


def _json(value: Any) -> str:
    return json.dumps(value, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# --------------------------------------------------------------------------- parameters


def _parameters(dump: Dump) -> dict[str, Any]:
    return {
        "recordings": [
            {
                "content_hash": r.content_hash,
                "name": r.name,
                "source": r.source,
                "split": r.split,
                "columns": list(r.columns),
                "n_samples": r.n_samples,
                "metadata": dict(r.metadata),
                "added_at": r.added_at,
            }
            for r in dump.recordings
        ],
        "identifications": [
            {
                "recording_hash": i.recording_hash,
                "method": i.method,
                "model": i.model,
                "params": dataclasses.asdict(i.params),
                "metrics": dict(i.metrics),
                "options": dict(i.options),
                "package_version": i.package_version,
                "created_at": i.created_at,
            }
            for i in dump.identifications
        ],
        "traces": [
            {
                "uid": t.uid,
                "recording_hash": t.recording_hash,
                "method": t.method,
                "model": t.model,
                "kind": t.kind,
                "source_uid": t.source_uid,
                "seed": t.seed,
                "settings": dict(t.settings),
                "dt_s": t.dt_s,
                "t0_s": t.t0_s,
                "n_samples": t.n_samples,
                "checksum": t.checksum,
                "statistics": dict(t.statistics),
                "validation": None if t.validation is None else dict(t.validation),
                "created_at": t.created_at,
            }
            for t in dump.traces
        ],
    }


# --------------------------------------------------------------------------- sample files


def _csv_text(header: list[str], columns: list[FloatArray]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    # repr() of a float is the shortest text that reads back to the same bits.
    for row in np.column_stack(columns).tolist():
        writer.writerow([repr(x) for x in row])
    return buf.getvalue()


def _npz_bytes(arrays: Mapping[str, FloatArray]) -> bytes:
    """An ``.npz`` archive with fixed timestamps (``np.savez`` stamps the current time)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for key, value in arrays.items():
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_TIME)
            info.external_attr = 0o644 << 16
            member = io.BytesIO()
            np.lib.format.write_array(member, np.ascontiguousarray(value, dtype="<f8"))
            zf.writestr(info, member.getvalue())
    return buf.getvalue()


def _parquet_module() -> Any:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ExchangeError(
            "parquet needs pyarrow: pip install 'rocketroll[parquet]' (or use csv or npz)"
        ) from None
    return pa, pq


def _parquet_bytes(columns: Mapping[str, list[Any]]) -> bytes:
    pa, pq = _parquet_module()
    table = pa.table(
        {
            name: pa.array(values, type=pa.list_(pa.float64()))
            if values and isinstance(values[0], list)
            else pa.array(values, type=pa.string())
            for name, values in columns.items()
        }
    )
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    return bytes(sink.getvalue().to_pybytes())


def _sample_files(dump: Dump, fmt: str) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    if fmt == "csv":
        for r in dump.recordings:
            text = _csv_text(list(r.columns), list(r.column_dict().values()))
            files[f"recordings/{r.content_hash[:16]}.csv"] = text.encode()
        for t in dump.traces:
            files[f"traces/{t.uid}.csv"] = _csv_text(["u_d_deg"], [t.samples()]).encode()
    elif fmt == "npz":
        files["recordings.npz"] = _npz_bytes(
            {r.content_hash: r.sample_array() for r in dump.recordings}
        )
        files["traces.npz"] = _npz_bytes({t.uid: t.samples() for t in dump.traces})
    elif fmt == "parquet":
        hashes, names, values = [], [], []
        for r in dump.recordings:
            for k, column in enumerate(r.columns):
                hashes.append(r.content_hash)
                names.append(column)
                values.append(r.sample_array()[:, k].tolist())
        files["recordings.parquet"] = _parquet_bytes(
            {"content_hash": hashes, "column": names, "values": values}
        )
        files["traces.parquet"] = _parquet_bytes(
            {
                "uid": [t.uid for t in dump.traces],
                "u_d_deg": [t.samples().tolist() for t in dump.traces],
            }
        )
    else:
        raise ExchangeError(f"format must be one of {', '.join(FORMATS)}, not {fmt!r}")
    return files


# --------------------------------------------------------------------------- export


def export_dump(dump: Dump, fmt: str, filters: Mapping[str, Any] | None = None) -> dict[str, bytes]:
    """The files of an export folder, name -> bytes (nothing is written)."""
    if fmt not in FORMATS:
        raise ExchangeError(f"format must be one of {', '.join(FORMATS)}, not {fmt!r}")
    from disturbances.db import package_version

    files = {"parameters.json": _json(_parameters(dump)).encode()}
    files.update(_sample_files(dump, fmt))
    manifest = {
        "format": EXPORT_FORMAT,
        "samples_format": fmt,
        "schema_version": SCHEMA_VERSION,
        "package_version": package_version(),
        "filters": {k: v for k, v in (filters or {}).items() if v is not None},
        "counts": {
            "recordings": len(dump.recordings),
            "identifications": len(dump.identifications),
            "traces": len(dump.traces),
        },
        "files": {name: _sha256(data) for name, data in sorted(files.items())},
    }
    files["manifest.json"] = _json(manifest).encode()
    return files


def write_export(
    db: Store, out: str | os.PathLike[str], fmt: str, **filters: Any
) -> dict[str, int]:
    """Export the traces matching ``filters`` (with what they depend on) into ``out``.

    ``out`` must not exist or be empty.  The folder is written in full beside
    its target and renamed into place, so it appears complete or not at all.
    Returns the counts.
    """
    target = Path(out)
    if target.exists() and (not target.is_dir() or any(target.iterdir())):
        raise ExchangeError(f"{target}: exists and is not an empty folder")
    check_filters(db, filters)
    dump = db.dump(**filters)
    if not dump.traces:
        raise ExchangeError(f"{db.path}: no traces match the filters; nothing to export")
    files = export_dump(dump, fmt, filters)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        for name, data in files.items():
            path = staging / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        staging.chmod(0o755)
        if target.exists():
            target.rmdir()
        os.replace(staging, target)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
    return {
        "recordings": len(dump.recordings),
        "identifications": len(dump.identifications),
        "traces": len(dump.traces),
    }


# --------------------------------------------------------------------------- import


def _read_csv(path: Path, data: bytes) -> tuple[list[str], FloatArray]:
    rows = list(csv.reader(io.StringIO(data.decode("utf-8"))))
    if not rows:
        raise ExchangeError(f"{path}: empty")
    header, body = rows[0], rows[1:]
    try:
        values = np.array([[float(x) for x in row] for row in body], dtype=float)
    except ValueError as exc:
        raise ExchangeError(f"{path}: {exc}") from None
    if values.ndim != 2 or values.shape[1] != len(header):
        raise ExchangeError(f"{path}: rows do not match the header's {len(header)} columns")
    return header, values


def _read_npz(path: Path, data: bytes) -> dict[str, FloatArray]:
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            return {key: np.asarray(archive[key], dtype=float) for key in archive.files}
    except (ValueError, OSError, zipfile.BadZipFile) as exc:
        raise ExchangeError(f"{path}: not a readable npz archive ({exc})") from None


def _read_parquet(path: Path, data: bytes) -> dict[str, list[Any]]:
    pa, pq = _parquet_module()
    try:
        table = pq.read_table(pa.BufferReader(data))
    except Exception as exc:  # pyarrow raises its own error types
        raise ExchangeError(f"{path}: not a readable parquet file ({exc})") from None
    return {name: table.column(name).to_pylist() for name in table.column_names}


def read_export(folder: str | os.PathLike[str]) -> Dump:
    """Read and verify an export folder into rows (nothing is written)."""
    root = Path(folder)
    manifest_path = root / "manifest.json"
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ExchangeError(f"{manifest_path}: missing; not an export folder") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ExchangeError(f"{manifest_path}: not valid JSON ({exc})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != EXPORT_FORMAT:
        raise ExchangeError(f"{manifest_path}: format is not {EXPORT_FORMAT}")
    if int(manifest.get("schema_version", 0)) > SCHEMA_VERSION:
        raise ExchangeError(
            f"{manifest_path}: schema version {manifest['schema_version']} is newer than this "
            f"rocketroll's ({SCHEMA_VERSION}); upgrade rocketroll"
        )
    fmt = manifest.get("samples_format")
    if fmt not in FORMATS:
        raise ExchangeError(f"{manifest_path}: unknown samples_format {fmt!r}")
    contents: dict[str, bytes] = {}
    for name, digest in dict(manifest.get("files", {})).items():
        path = root / name
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            raise ExchangeError(f"{path}: listed in the manifest but missing") from None
        if _sha256(data) != digest:
            raise ExchangeError(f"{path}: SHA-256 differs from the manifest (altered or damaged)")
        contents[name] = data
    if "parameters.json" not in contents:
        raise ExchangeError(f"{manifest_path}: lists no parameters.json")
    try:
        params = json.loads(contents["parameters.json"])
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ExchangeError(f"{root / 'parameters.json'}: not valid JSON ({exc})") from None

    try:
        dump = _parse(root, fmt, params, contents)
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise ExchangeError(
            f"{root}: parameters.json and the sample files disagree ({type(exc).__name__}: {exc})"
        ) from None
    _check_references(root, dump)
    return dump


def _check_references(root: Path, dump: Dump) -> None:
    """An export is self-contained: everything a row refers to is in it."""
    recordings = {r.content_hash for r in dump.recordings}
    for i in dump.identifications:
        if i.recording_hash not in recordings:
            raise ExchangeError(
                f"{root}: identification {i.method}/{i.model} refers to recording "
                f"{i.recording_hash[:12]}…, which the export does not contain"
            )
    identifications = {i.key for i in dump.identifications}
    uids: set[str] = set()
    for t in dump.traces:
        if t.identification_key not in identifications:
            raise ExchangeError(
                f"{root}: trace {t.uid} refers to an identification the export does not contain"
            )
        if t.source_uid is not None and t.source_uid not in uids:
            raise ExchangeError(
                f"{root}: surrogate {t.uid} refers to trace {t.source_uid}, which does not "
                "come before it in the export"
            )
        uids.add(t.uid)


def _parse(root: Path, fmt: str, params: Any, contents: Mapping[str, bytes]) -> Dump:
    # Samples by recording hash and by trace uid.
    rec_samples: dict[str, FloatArray] = {}
    trace_samples: dict[str, FloatArray] = {}
    if fmt == "csv":
        by_prefix = {r["content_hash"][:16]: r for r in params["recordings"]}
        for name, data in contents.items():
            path = root / name
            if name.startswith("recordings/"):
                rec = by_prefix[Path(name).stem]
                header, values = _read_csv(path, data)
                if header != rec["columns"]:
                    raise ExchangeError(f"{path}: columns {header} differ from parameters.json")
                rec_samples[rec["content_hash"]] = values
            elif name.startswith("traces/"):
                _, values = _read_csv(path, data)
                trace_samples[Path(name).stem] = values[:, 0]
    elif fmt == "npz":
        rec_samples = _read_npz(root / "recordings.npz", contents["recordings.npz"])
        trace_samples = _read_npz(root / "traces.npz", contents["traces.npz"])
    else:
        recs = _read_parquet(root / "recordings.parquet", contents["recordings.parquet"])
        columns: dict[str, dict[str, list[float]]] = {}
        for h, column, values in zip(
            recs["content_hash"], recs["column"], recs["values"], strict=True
        ):
            columns.setdefault(h, {})[column] = values
        for r in params["recordings"]:
            got = columns.get(r["content_hash"], {})
            rec_samples[r["content_hash"]] = np.column_stack(
                [np.asarray(got[c], dtype=float) for c in r["columns"]]
            )
        tr = _read_parquet(root / "traces.parquet", contents["traces.parquet"])
        trace_samples = {
            uid: np.asarray(v, dtype=float) for uid, v in zip(tr["uid"], tr["u_d_deg"], strict=True)
        }

    try:
        recordings = tuple(
            RecordingRow(
                content_hash=r["content_hash"],
                name=r["name"],
                source=r["source"],
                metadata=r["metadata"],
                columns=tuple(r["columns"]),
                samples=rec_samples[r["content_hash"]],
                added_at=r["added_at"],
            )
            for r in params["recordings"]
        )
        identifications = tuple(
            IdentificationRow(
                recording_hash=i["recording_hash"],
                method=i["method"],
                model=i["model"],
                params=RollParams(**i["params"]),
                metrics=i["metrics"],
                options=i["options"],
                package_version=i["package_version"],
                created_at=i["created_at"],
            )
            for i in params["identifications"]
        )
        traces = tuple(
            TraceRow(
                uid=t["uid"],
                recording_hash=t["recording_hash"],
                method=t["method"],
                model=t["model"],
                kind=t["kind"],
                source_uid=t["source_uid"],
                seed=t["seed"],
                settings=t["settings"],
                dt_s=t["dt_s"],
                t0_s=t["t0_s"],
                u_d_deg=trace_samples[t["uid"]],
                checksum=t["checksum"],
                statistics=t["statistics"],
                validation=t["validation"],
                created_at=t["created_at"],
            )
            for t in params["traces"]
        )
    except KeyError as exc:
        raise ExchangeError(
            f"{root}: parameters.json and the sample files disagree: {exc}"
        ) from None
    except (ValueError, TypeError) as exc:
        raise ExchangeError(f"{root}: {exc}") from None
    for r in recordings:
        if r.split != next(
            p["split"] for p in params["recordings"] if p["content_hash"] == r.content_hash
        ):
            raise ExchangeError(
                f"{root}: recording {r.name} was exported in another split; the split rule differs"
            )
    return Dump(recordings=recordings, identifications=identifications, traces=traces)


def import_export(db: Store, folder: str | os.PathLike[str]) -> StoreResult:
    """Import an export folder into ``db`` in one transaction (present rows are skipped)."""
    dump = read_export(folder)
    versions = set(db.versions()) | {i.package_version for i in dump.identifications}
    if len(versions) > 1:
        raise ExchangeError(
            f"{folder}: holds identifications of rocketroll "
            f"{', '.join(sorted({i.package_version for i in dump.identifications}))}; importing "
            f"into {db.path} would mix versions {', '.join(sorted(versions))}; import into a new "
            "database file instead"
        )
    try:
        return store_rows(db, dump.recordings, dump.identifications, dump.traces)
    except ValueError as exc:  # a name this rocketroll does not know (a method not registered)
        raise ExchangeError(f"{folder}: {exc}") from None
