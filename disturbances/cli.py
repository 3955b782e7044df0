"""``rocketroll db ...`` and ``rocketroll identify --db``: the disturbance database from the shell.

Every subcommand takes ``--db PATH``; without it the default database is used
(``$ROCKETROLL_DB``, else the user's cache folder), built from the bundled
recordings the first time it is needed.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rocketroll_common.errors import UsageError

if TYPE_CHECKING:
    from disturbances.db import DisturbanceDB, TraceInfo
    from identification.pipeline import Identification

__all__ = ["register"]

_DB_HELP = (
    "database file (default: $ROCKETROLL_DB, else ~/.cache/rocketroll/disturbances.sqlite, "
    "built from the bundled recordings when missing)"
)


def _open(ns: argparse.Namespace, *, create: bool = False) -> DisturbanceDB:
    """``--db`` (or the default database), with a version notice as one stderr line."""
    import warnings

    from disturbances.db import DisturbanceDB
    from disturbances.default import open_database

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        if ns.db is not None and create:
            db = DisturbanceDB(ns.db, create=True)
            db.check_version()
        else:
            db = open_database(ns.db)
    for warning in caught:
        print(f"rocketroll: warning: {warning.message}", file=sys.stderr)
    return db


@contextmanager
def _new_file_removed_on_error(path: Path | None) -> Iterator[None]:
    """If ``path`` does not exist yet and the block fails, leave no database behind."""
    new = path is not None and not path.exists()
    try:
        yield
    except BaseException:
        if new and path is not None:
            for suffix in ("", "-wal", "-shm"):
                Path(f"{path}{suffix}").unlink(missing_ok=True)
        raise


def _add_filters(p: argparse.ArgumentParser) -> None:
    from disturbances.rows import KINDS, METHODS, MODELS, SPLITS

    p.add_argument("--split", choices=SPLITS, help="train or test")
    p.add_argument("--model", choices=MODELS, help="damping model of the identification")
    p.add_argument("--method", choices=METHODS, help="identification method")
    p.add_argument(
        "--kind", choices=(*KINDS, "surrogate"), help="identified trace or a surrogate kind"
    )
    p.add_argument("--source", choices=("synthetic", "wind-tunnel", "flight"))
    p.add_argument("--recording", help="recording name")
    p.add_argument(
        "--meta",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="recording metadata must have KEY equal to VALUE (repeatable)",
    )


def _filters(ns: argparse.Namespace) -> dict[str, Any]:
    meta: dict[str, str] = {}
    for item in ns.meta:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UsageError(f"--meta {item!r}: give KEY=VALUE")
        meta[key] = value
    filters: dict[str, Any] = {
        "split": ns.split,
        "model": ns.model,
        "method": ns.method,
        "kind": ns.kind,
        "source": ns.source,
        "recording": ns.recording,
    }
    if meta:
        filters["metadata"] = meta
    return {k: v for k, v in filters.items() if v is not None}


def _trace_table(infos: list[TraceInfo]) -> str:
    lines = [
        f"{'id':>4}  {'uid':<40} {'kind':<10} {'split':<5} {'method':<12} {'model':<8} "
        f"{'dur s':>6} {'mean °':>7} {'SD °':>6} {'90 % interval °':>17} {'normal p':>8}"
    ]
    for i in infos:
        p = "" if i.normality_p is None else f"{i.normality_p:.3f}"
        lines.append(
            f"{i.id:>4}  {i.uid:<40} {i.kind:<10} {i.split:<5} {i.method:<12} {i.model:<8} "
            f"{i.duration_s:>6.0f} {i.mean_deg:>7.2f} {i.sd_deg:>6.2f} "
            f"[{i.q05_deg:>6.2f}, {i.q95_deg:>6.2f}] {p:>8}"
        )
    return "\n".join(lines)


def _cmd_build(ns: argparse.Namespace) -> int:
    from disturbances.db import DatabaseError, DisturbanceDB
    from disturbances.default import (
        DEFAULT_SURROGATES,
        _expected_fingerprint,
        build_database,
        default_path,
    )

    path = ns.db if ns.db is not None else default_path()
    if ns.surrogates < 0:
        raise UsageError(f"--surrogates must be >= 0, got {ns.surrogates}")
    default_recipe = not ns.recordings and ns.surrogates == DEFAULT_SURROGATES
    if path.exists() and not ns.force:
        try:
            with DisturbanceDB(path, create=False) as db:
                info = db.info()
        except DatabaseError as exc:
            raise UsageError(f"{exc}; give --force to replace it") from None
        if info.get("origin") != "bundled":
            raise UsageError(
                f"{path}: exists and is not a default build (it holds data added by hand or "
                "built with other settings); give --force to replace it"
            )
        if default_recipe and info.get("fingerprint") == _expected_fingerprint():
            print(f"{path}: up to date (built by rocketroll {info.get('created_by')})")
            return 0
    build_database(
        path,
        ns.recordings or None,
        surrogates=ns.surrogates,
        progress=True,
    )
    with DisturbanceDB(path, create=False) as db:
        counts = db.counts()
    print(
        f"built {path}: {counts['recordings']} recordings, {counts['identifications']} "
        f"identifications, {counts['traces']} traces, {counts['surrogates']} surrogates"
    )
    return 0


def _cmd_list(ns: argparse.Namespace) -> int:
    with _open(ns) as db:
        try:
            infos = db.traces(**_filters(ns))
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if ns.json:
            print(json.dumps([_info_json(i) for i in infos], indent=2, allow_nan=False))
            return 0
        counts = db.counts()
        print(
            f"{db.path}: {counts['recordings']} recordings, {counts['traces']} traces, "
            f"{counts['surrogates']} surrogates; {len(infos)} shown"
        )
        print(_trace_table(infos))
    return 0


def _info_json(info: TraceInfo) -> dict[str, Any]:
    """A :class:`TraceInfo` as JSON-ready values."""
    from dataclasses import asdict, fields

    out: dict[str, Any] = {f.name: getattr(info, f.name) for f in fields(info)}
    out["params"] = asdict(info.params)
    out["validation"] = None if info.validation is None else dict(info.validation)
    out["duration_s"] = info.duration_s
    return out


def _key(text: str) -> int | str:
    return int(text) if text.isdigit() else text


def _cmd_show(ns: argparse.Namespace) -> int:
    with _open(ns) as db:
        trace = db.trace(_key(ns.trace))
        info = trace.info
        ident = next(
            i
            for i in db.identifications(recording=info.recording)
            if i.method == info.method
            and i.model == info.model
            and i.recording_id == info.recording_id
        )
        if ns.plot is not None:
            from disturbances.plots import plot_trace
            from rocketroll_common.files import write_atomic

            source = None if info.source_uid is None else db.trace(info.source_uid)
            write_atomic(ns.plot, plot_trace(trace, source))
    if ns.json:
        d = _info_json(info)
        d["metrics"] = dict(ident.metrics)
        print(json.dumps(d, indent=2, allow_nan=False))
        return 0
    p = info.params
    lines = [
        f"trace {info.id}  {info.uid}",
        f"  kind         {info.kind}"
        + (f" of {info.source_uid} (seed {info.seed})" if info.source_uid else ""),
        f"  recording    {info.recording} ({info.source}), split {info.split}",
        f"  identified   {info.method} method, {info.model} damping, rocketroll "
        f"{info.package_version}, {ident.created_at}",
        f"  samples      {info.n_samples} every {info.dt_s:g} s ({info.duration_s:g} s) from "
        f"t0 = {info.t0_s:g} s; checksum verified",
        f"  u_d          mean {info.mean_deg:.3f}°, SD {info.sd_deg:.3f}°, 90 % interval "
        f"[{info.q05_deg:.2f}, {info.q95_deg:.2f}]°, normality p "
        + ("n/a" if info.normality_p is None else f"{info.normality_p:.3g}"),
        f"  parameters   α = {p.alpha:.4f} (°/s)/°, θ̄ = {p.theta_bar_deg:.3f}°, "
        + (
            f"a = {p.beta_bar_per_s:.4f} 1/s"
            if p.is_constant_damping
            else f"ᾱ = {p.alpha_bar_per_deg_s:.4f} 1/(s·°), β̄ = {p.beta_bar_per_s:.4f} 1/s"
        ),
    ]
    if info.validation is not None:
        v = info.validation
        lines.append(
            f"  validation   KS p = {v['ks_p']:.3g} (thinned every {v['stride']}), PSD "
            f"log-distance {v['psd_log_distance']:.3f} decades (limit "
            f"{v['psd_tolerance_decades']:g}): " + ("passed" if v["passed"] else "FAILED")
        )
    m = ident.metrics
    if "resim_angle_mae_deg" in m:
        lines.append(
            f"  re-simulated rate MAE {m['resim_rate_mae_dps']:.3f} °/s, angle MAE "
            f"{m['resim_angle_mae_deg']:.3f}°"
        )
    print("\n".join(lines))
    if ns.plot is not None:
        print(f"wrote {ns.plot}")
    return 0


def _cmd_add(ns: argparse.Namespace) -> int:
    from identification.cli import identify_options
    from identification.recording import load_recording

    if ns.surrogates < 0:
        raise UsageError(f"--surrogates must be >= 0, got {ns.surrogates}")
    if ns.surrogate_kind and ns.surrogates == 0:
        raise UsageError("--surrogate-kind needs --surrogates N (how many of each kind)")
    options = identify_options(ns)
    recording = load_recording(ns.recording)
    methods = ("paper",) if ns.no_output_error else ("paper", "output-error")
    with _new_file_removed_on_error(ns.db), _open(ns, create=True) as db:
        result = db.add_recording(
            recording,
            options,
            methods=methods,
            surrogates=ns.surrogates,
            surrogate_kinds=tuple(ns.surrogate_kind or ["iaaft"]),
        )
        if result.recordings == 0 and result.traces == 0:
            print(f"{db.path}: {recording.name} is already stored (same samples); nothing added")
            return 0
        print(
            f"{db.path}: added {recording.name}: {result.identifications} identifications, "
            f"{result.traces} traces (ids {', '.join(map(str, result.trace_ids))})"
        )
    return 0


def _cmd_surrogate(ns: argparse.Namespace) -> int:
    if ns.count < 1:
        raise UsageError(f"--count must be >= 1, got {ns.count}")
    if ns.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {ns.seed}")
    with _open(ns) as db:
        uid = db.trace(_key(ns.trace)).info.uid
        result = db.add_surrogates(uid, ns.kind, ns.count, ns.seed)
        added = db.traces_by_uid([db.trace(i).info.uid for i in result.trace_ids])
    print(f"added {result.traces} {ns.kind} surrogate(s) of {uid} ({result.skipped} existed)")
    for info in added:
        v = info.validation or {}
        verdict = (
            "check passed"
            if v.get("passed")
            else f"check FAILED (KS p {v.get('ks_p', float('nan')):.3g}, PSD log-distance "
            f"{v.get('psd_log_distance', float('nan')):.3f}); left out of banks by default"
        )
        print(f"  {info.id:>4}  {info.uid}  {verdict}")
    return 0


def _cmd_export(ns: argparse.Namespace) -> int:
    from disturbances.exchange import write_export

    with _open(ns) as db:
        try:
            counts = write_export(db, ns.out, ns.format, **_filters(ns))
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    print(
        f"wrote {ns.out}: {counts['traces']} traces, {counts['identifications']} "
        f"identifications, {counts['recordings']} recordings ({ns.format})"
    )
    return 0


def _cmd_import(ns: argparse.Namespace) -> int:
    from disturbances.exchange import import_export, read_export

    read_export(ns.folder)  # every file checked before the database is touched
    with _new_file_removed_on_error(ns.db), _open(ns, create=True) as db:
        db.check_version(writing=True)
        result = import_export(db, ns.folder)
    print(
        f"imported {ns.folder}: {result.recordings} recordings, {result.identifications} "
        f"identifications, {result.traces} traces added; {result.skipped} already present"
    )
    return 0


def _store_result(ns: argparse.Namespace, result: Identification) -> str | None:
    """``rocketroll identify --db``: keep the result (runs before any file is written)."""
    if ns.db is None:
        return None
    from disturbances.db import DisturbanceDB

    with _new_file_removed_on_error(ns.db), DisturbanceDB(ns.db, create=True) as db:
        stored = db.add_identification(result)
    if stored.recordings == 0 and stored.traces == 0:
        return f"{ns.db}: this recording is already stored (same samples); nothing added"
    return (
        f"stored in {ns.db}: {stored.identifications} identifications, {stored.traces} traces "
        f"(ids {', '.join(map(str, stored.trace_ids))})"
    )


def register(subparsers: Any) -> None:
    """Add ``rocketroll db`` and ``identify --db`` to the ``rocketroll`` parser."""
    from identification.cli import add_identify_options

    identify = subparsers.choices.get("identify")
    if identify is not None:
        identify.add_argument(
            "--db",
            type=Path,
            help="also store the result (both models, and the output-error peer) in this "
            "disturbance database; created if missing",
        )
        identify.set_defaults(store_result=_store_result)

    db = subparsers.add_parser(
        "db",
        help="the disturbance database: build, list, show, add, surrogate, export, import",
        description="The disturbance database of recordings, identified parameters and u_d "
        "traces.  Without --db, the default database is used (built from the bundled "
        "recordings when missing).",
    )
    sub = db.add_subparsers(dest="db_command", required=True, metavar="DB_COMMAND")

    p = sub.add_parser(
        "build",
        help="build the database from the bundled (or given) recordings",
        description="Identify every bundled recording (paper's method and output-error peer, "
        "both models), make surrogates, and write the database atomically.",
    )
    p.add_argument("--db", type=Path, help=_DB_HELP)
    p.add_argument("--force", action="store_true", help="rebuild even if up to date")
    p.add_argument(
        "--surrogates",
        type=int,
        default=2,
        help="IAAFT surrogates per paper-method trace (default 2)",
    )
    p.add_argument(
        "recordings", nargs="*", type=Path, help="recording files (default: the bundled ones)"
    )
    p.set_defaults(handler=_cmd_build)

    p = sub.add_parser("list", help="list traces, optionally filtered")
    p.add_argument("--db", type=Path, help=_DB_HELP)
    _add_filters(p)
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(handler=_cmd_list)

    p = sub.add_parser("show", help="show one trace: provenance, parameters, statistics")
    p.add_argument("trace", help="trace id or uid")
    p.add_argument("--db", type=Path, help=_DB_HELP)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--plot", type=Path, help="write a PNG: the trace, its histogram and PSD")
    p.set_defaults(handler=_cmd_show)

    p = sub.add_parser(
        "add",
        help="identify a recording and store everything (one transaction)",
        description="Run the identification on a recording (format v1) and store the "
        "recording, parameters and u_d traces.  Nothing is stored if anything fails.",
    )
    p.add_argument("recording", type=Path, help="recording file (CSV, format v1)")
    p.add_argument("--db", type=Path, help=_DB_HELP + "; created if missing")
    p.add_argument("--surrogates", type=int, default=0, help="surrogates per paper trace (0)")
    p.add_argument(
        "--surrogate-kind", action="append", choices=("iaaft", "ar"), help="surrogate kind"
    )
    p.add_argument("--no-output-error", action="store_true", help="skip the output-error peer")
    add_identify_options(p)
    p.set_defaults(handler=_cmd_add)

    p = sub.add_parser("surrogate", help="make and store surrogates of a stored trace")
    p.add_argument("trace", help="trace id or uid (an identified trace)")
    p.add_argument("--db", type=Path, help=_DB_HELP)
    p.add_argument("--kind", choices=("iaaft", "ar"), default="iaaft", help="method (iaaft)")
    p.add_argument("--count", type=int, default=1, help="how many (1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first (0)")
    p.set_defaults(handler=_cmd_surrogate)

    p = sub.add_parser(
        "export",
        help="export traces, parameters (JSON) and a manifest to a folder",
        description="Write the selected traces with their parameters, recordings and a "
        "manifest into a new folder; `rocketroll db import` reads it back exactly.",
    )
    p.add_argument("--format", required=True, choices=("csv", "npz", "parquet"))
    p.add_argument("--out", required=True, type=Path, help="folder to create (must be empty)")
    p.add_argument("--db", type=Path, help=_DB_HELP)
    _add_filters(p)
    p.set_defaults(handler=_cmd_export)

    p = sub.add_parser("import", help="import an export folder (one transaction)")
    p.add_argument("folder", type=Path, help="a folder written by `rocketroll db export`")
    p.add_argument("--db", type=Path, help=_DB_HELP + "; created if missing")
    p.set_defaults(handler=_cmd_import)
