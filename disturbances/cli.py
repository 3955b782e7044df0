"""``rocketroll db ...``: the database's commands, and the database helpers
``rocketroll identify`` (:mod:`disturbances.identify`) shares with them.

Every database command takes ``--db LOCATION``; without it the default
database is used (``$ROCKETROLL_DB``, else the user's cache folder), built
from the bundled recordings the first time it is needed.  A database of an
older schema is upgraded when opened (a copy is kept; ``rocketroll db
migrate`` does it explicitly).  Each command is a settings dataclass and a
function (:mod:`rocketroll_common.settings`); no library module imports this
one (a command module may).
"""

from __future__ import annotations

import json
import sys
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from disturbances.rows import KINDS, SPLITS, SURROGATE_KINDS
from identification.methods import METHODS, default_methods, has_posterior, traits
from identification.methods.pipeline import IdentifyOptions
from identification.model import MODEL_NAMES, QUADRATIC_RATE_DPS
from identification.recordings.recording import SOURCES, Recording
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import Command, check, setting
from rocketroll_common.tables import Column, text_table

if TYPE_CHECKING:
    from disturbances.rows import TraceRow
    from disturbances.stores import Store

__all__ = [
    "COMMANDS",
    "TraceFilters",
    "check_methods",
    "check_posterior_methods",
    "check_quadratic",
    "db_setting",
    "methods_help",
    "new_database",
    "open_store",
]

_DB_HELP = (
    "database: a file, or SCHEME://... of a registered store (default: $ROCKETROLL_DB, else "
    "~/.cache/rocketroll/disturbances.sqlite, built from the bundled recordings when missing)"
)


def db_setting(new: bool = False) -> Any:
    return setting(
        None,
        _DB_HELP + ("; created if missing" if new else ""),
        metavar="DB",
        input=True,
        kind="sqlite",
    )


def methods_help(text: str, flight: bool = False) -> Callable[[], str]:
    """Help listing the registered methods when the parser is made (plugins included);
    ``flight``: the default for a flight is named too."""

    def help_text() -> str:
        flights = [m for m in METHODS.names() if traits(m).flight and traits(m).default]
        default = ", ".join(default_methods())
        if flight and flights:
            default += f" (a flight: {', '.join(flights)})"
        return f"{text} (repeatable; default: {default}; registered: {', '.join(METHODS.names())})"

    return help_text


def _default_methods() -> list[str]:
    return list(default_methods())


def check_quadratic(options: IdentifyOptions, methods: list[str], recording: Recording) -> None:
    """``--fit-quadratic-damping`` where a method runs that searches it: ml, on a tunnel run."""
    if not options.fit_quadratic_damping:
        return
    if recording.is_flight:
        raise UsageError("--fit-quadratic-damping: searched in a tunnel run's ml fit; "
                         f"{recording.name} is a flight")  # fmt: skip
    if "ml" not in methods:
        raise UsageError(
            f"--fit-quadratic-damping: the ml method searches the term; the methods run are "
            f"{', '.join(methods)} (add --method ml)"
        )


def check_posterior_methods(methods: list[str]) -> None:
    """``--posterior`` needs a method with a posterior among ``methods``."""
    if not any(has_posterior(m) for m in methods):
        raise UsageError(
            "--posterior needs a method with a posterior (--method ml, or flight on a flight); "
            f"none of {', '.join(methods)} has one"
        )


def check_methods(methods: list[str]) -> None:
    for method in methods:
        try:
            METHODS.check(method)
        except ValueError as exc:
            raise UsageError(f"--method: {exc}") from None
    repeated = sorted({m for m in methods if methods.count(m) > 1})
    if repeated:
        raise UsageError(f"--method {repeated[0]} is given twice")


def open_store(db: str | None, *, create: bool = False) -> Store:
    """``--db`` (or the default database), with version notices as one stderr line each."""
    from disturbances.default import open_database
    from disturbances.stores import open_store

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        if db is not None and create:
            store = open_store(db, create=True)
            store.check_version()
        else:
            store = open_database(db)
    for warning in caught:
        print(f"rocketroll: warning: {warning.message}", file=sys.stderr)
    return store


@contextmanager
def new_database(db: str | None) -> Iterator[None]:
    """A database file that does not exist yet, with missing folders: if the block fails,
    leave neither the file nor the folders behind."""
    if db is None or "://" in db:
        yield
        return
    from rocketroll_common.files import created_folders_removed_on_error

    path = Path(db)
    new = not path.exists()
    with created_folders_removed_on_error(path):
        try:
            yield
        except BaseException:
            if new:
                for suffix in ("", "-wal", "-shm"):
                    Path(f"{path}{suffix}").unlink(missing_ok=True)
            raise


# --------------------------------------------------------------------------- db
def _key_value(text: str) -> tuple[str, str]:
    import argparse

    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"--meta {text!r}: give KEY=VALUE")
    return key, value


@dataclass(frozen=True)
class TraceFilters:
    """Which traces a listing or an export selects."""

    split: Literal["train", "test"] | None = setting(None, "train or test", choices=SPLITS)
    model: str | None = setting(None, "damping model of the identification", choices=MODEL_NAMES)
    method: str | None = setting(None, "identification method")
    kind: str | None = setting(
        None, "identified trace or a surrogate kind", choices=(*KINDS, "surrogate")
    )
    source: str | None = setting(None, "where the recording came from", choices=SOURCES)
    recording: str | None = setting(None, "recording name")
    verdict: str | None = setting(
        None, "the identification's fit adequacy", choices=("good", "weak", "unreliable")
    )
    meta: dict[str, str] = setting(
        default_factory=dict,
        help="recording metadata must have KEY equal to VALUE (repeatable)",
        metavar="KEY=VALUE",
        parse=_key_value,
    )

    def query(self) -> dict[str, Any]:
        """The filters of :meth:`disturbances.db.DisturbanceDB.traces`."""
        out: dict[str, Any] = {
            name: getattr(self, name)
            for name in ("split", "model", "method", "kind", "source", "recording", "verdict")
            if getattr(self, name) is not None
        }
        if self.meta:
            out["metadata"] = dict(self.meta)
        return out


@dataclass(frozen=True)
class BuildArgs:
    """``rocketroll db build``."""

    db: str | None = db_setting()
    force: bool = setting(False, "rebuild even if up to date")
    surrogates: int = setting(2, "IAAFT surrogates per paper-method trace", ge=0, le=1000)
    posterior: int = setting(
        8,  # disturbances.default.DEFAULT_POSTERIOR (not imported at start-up)
        "posterior u_d draws per trace of a method with a posterior (ml)",
        ge=0,
        le=1000,
    )
    recordings: list[Path] = setting(
        default_factory=list,
        help="recording files (default: the bundled ones)",
        positional=True,
        metavar="RECORDING",
        input=True,
    )


def build(args: BuildArgs) -> int:
    """Build a database from the bundled (or given) recordings."""
    for recording in args.recordings:  # before the build's process starts
        if not Path(recording).is_file():
            raise UsageError(f"RECORDING {recording}: no such file")
    from disturbances.db import DatabaseError, DisturbanceDB
    from disturbances.default import (
        DEFAULT_POSTERIOR,
        DEFAULT_SURROGATES,
        build_database,
        default_path,
        expected_fingerprint,
        peek,
    )
    from disturbances.schema import SCHEMA_VERSION

    path = Path(args.db) if args.db is not None else default_path()
    default_recipe = (
        not args.recordings
        and args.surrogates == DEFAULT_SURROGATES
        and args.posterior == DEFAULT_POSTERIOR
    )
    if path.exists() and not args.force:
        found = peek(path)
        if found is None:  # not a readable database: say why
            try:
                DisturbanceDB(path, create=False, upgrade=False).close()
            except DatabaseError as exc:
                raise UsageError(f"{exc}; give --force to replace it") from None
            raise UsageError(f"{path}: not a rocketroll database; give --force to replace it")
        version, info = found
        if info.get("origin") != "bundled":
            raise UsageError(
                f"{path}: exists and is not a default build (it holds data added by hand or "
                "built with other settings); give --force to replace it"
            )
        if (
            default_recipe
            and version == SCHEMA_VERSION
            and info.get("fingerprint") == expected_fingerprint()
        ):
            print(f"{path}: up to date (built by rocketroll {info.get('created_by')})")
            return 0
    build_database(
        path,
        args.recordings or None,
        surrogates=args.surrogates,
        posterior=args.posterior,
        progress=True,
    )
    with DisturbanceDB(path, create=False) as db:
        counts = db.counts()
    print(
        f"built {path}: {counts['recordings']} recordings, {counts['identifications']} "
        f"identifications, {counts['traces']} traces, {counts['surrogates']} surrogates, "
        f"{counts['posterior']} posterior draws"
    )
    return 0


@dataclass(frozen=True)
class ListArgs:
    """``rocketroll db list``."""

    db: str | None = db_setting()
    filters: TraceFilters = setting(default_factory=TraceFilters, flatten=True)
    json: bool = setting(False, "print JSON instead of a table")


def _trace_table(rows: list[TraceRow], accepted: set[tuple[str, str, str]]) -> str:
    """The listing; a trace whose identification is among ``accepted`` (its recording stored
    although every fit of it is judged unreliable) has its verdict marked."""
    cells = [
        [
            str(i.id),
            i.uid,
            i.kind,
            i.split,
            i.method,
            i.model,
            f"{i.duration_s:.0f}",
            f"{i.mean_deg:.2f}",
            f"{i.sd_deg:.2f}",
            f"[{i.q05_deg:>6.2f}, {i.q95_deg:>6.2f}]",
            "" if i.normality_p is None else f"{i.normality_p:.3f}",
            (i.verdict or "-")
            + (ACCEPTED_MARK if (i.recording_hash, i.method, i.model) in accepted else ""),
        ]
        for i in rows
    ]
    lines = text_table(_TRACE_COLUMNS, cells)
    if any((i.recording_hash, i.method, i.model) in accepted for i in rows):
        lines.append(
            "accepted: stored with db add --accept-unreliable, although every fit of its "
            "recording is judged unreliable"
        )
    return "\n".join(lines)


#: How ``db list`` marks the verdict of a fit stored with ``db add --accept-unreliable``.
ACCEPTED_MARK = ", accepted"
#: ``db list``'s columns (the interval's title is as wide as its cells and a space).
_TRACE_COLUMNS = (
    Column("id", 4),
    Column("uid", 40, "<", "  "),
    Column("kind", 10, "<", " "),
    Column("split", 5, "<", " "),
    Column("method", 12, "<", " "),
    Column("model", 8, "<", " "),
    Column("dur s", 6, ">", " "),
    Column("mean °", 7, ">", " "),
    Column("SD °", 6, ">", " "),
    Column("  90 % interval °", 16, ">", " "),
    Column("normal p", 8, ">", " "),
    Column("fit", gap="  "),
)


def _row_json(row: TraceRow) -> dict[str, Any]:
    """A listed trace as JSON-ready values."""
    out: dict[str, Any] = {
        "id": row.id,
        "uid": row.uid,
        "kind": row.kind,
        "source_uid": row.source_uid,
        "seed": row.seed,
        "recording": row.recording,
        "recording_id": row.recording_id,
        "source": row.source,
        "split": row.split,
        "method": row.method,
        "model": row.model,
        "params": None if row.params is None else asdict(row.params),
        "dt_s": row.dt_s,
        "t0_s": row.t0_s,
        "n_samples": row.n_samples,
        **{key: row.statistics.get(key) for key in row.statistics},
        "package_version": row.package_version,
        "created_at": row.created_at,
        "validation": None if row.validation is None else dict(row.validation),
        "verdict": row.verdict,
        "duration_s": row.duration_s,
        "recording_hash": row.recording_hash,  # (new: the recording across databases)
    }
    return out


def list_traces(args: ListArgs) -> int:
    """List traces."""
    with open_store(args.db) as db:
        try:
            from disturbances.stores import check_filters

            query = args.filters.query()
            check_filters(db, query)
            rows = db.traces(**query)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if args.json:
            print(json.dumps([_row_json(r) for r in rows], indent=2, allow_nan=False))
            return 0
        counts = db.counts()
        drawn = f", {counts['posterior']} posterior draws" if counts["posterior"] else ""
        print(
            f"{db.path}: {counts['recordings']} recordings, {counts['traces']} traces, "
            f"{counts['surrogates']} surrogates{drawn}; {len(rows)} shown"
        )
        accepted = {
            i.key for i in db.identifications(verdict="unreliable") if i.accepted_unreliable
        }
        print(_trace_table(rows, accepted))
    return 0


def _key(text: str) -> int | str:
    return int(text) if text.isdigit() else text


@dataclass(frozen=True)
class ShowArgs:
    """``rocketroll db show``."""

    trace: str = setting(help="trace id or uid", positional=True)
    db: str | None = db_setting()
    json: bool = setting(False, "print JSON")
    plot: Path | None = setting(
        None, "write a PNG: the trace, its histogram and PSD", output="file", kind="png"
    )


def show(args: ShowArgs) -> int:
    """Show one trace: provenance, parameters, statistics."""
    with open_store(args.db) as db:
        trace = db.trace(_key(args.trace))
        (ident,) = db.identifications(
            recording_hash=trace.recording_hash, method=trace.method, model=trace.model
        )
        if args.plot is not None:
            from disturbances.plots import plot_trace
            from rocketroll_common.files import write_atomic

            source = None if trace.source_uid is None else db.trace(trace.source_uid)
            write_atomic(args.plot, plot_trace(trace, source))
    if args.json:
        d = _row_json(trace)
        d["metrics"] = dict(ident.metrics)
        print(json.dumps(d, indent=2, allow_nan=False))
        return 0
    p = trace.rocket()
    lines = [
        f"trace {trace.id}  {trace.uid}",
        f"  kind         {trace.kind}"
        + (f" of {trace.source_uid} (seed {trace.seed})" if trace.source_uid else ""),
        f"  recording    {trace.recording} ({trace.source}), split {trace.split}",
        f"  identified   {trace.method} method, {trace.model} damping, rocketroll "
        f"{trace.package_version}, {ident.created_at}",
        f"  samples      {trace.n_samples} every {trace.dt_s:g} s ({trace.duration_s:g} s) from "
        f"t0 = {trace.t0_s:g} s; checksum verified",
        f"  u_d          mean {trace.mean_deg:.3f}°, SD {trace.sd_deg:.3f}°, 90 % interval "
        f"[{trace.q05_deg:.2f}, {trace.q95_deg:.2f}]°, normality p "
        + ("n/a" if trace.normality_p is None else f"{trace.normality_p:.3g}"),
        f"  parameters   α = {p.alpha:.4f} (°/s)/°, θ̄ = {p.theta_bar_deg:.3f}°, "
        + (
            f"a = {p.beta_bar_per_s:.4f} 1/s"
            if p.is_constant_damping
            else f"ᾱ = {p.alpha_bar_per_deg_s:.4f} 1/(s·°), β̄ = {p.beta_bar_per_s:.4f} 1/s"
        )
        + (
            f", quadratic damping q = {p.quadratic_damping:.3g} (× a(θ) at "
            f"{QUADRATIC_RATE_DPS:g} °/s)"
            if p.quadratic_damping
            else ""
        ),
    ]
    if trace.validation is not None:
        v = trace.validation
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
    figures = m.get("adequacy")
    if isinstance(figures, dict):
        r2, share = figures.get("rate_r2"), figures.get("fin_share")
        detail = [
            *([f"rate R² without u_d {r2:.3f}"] if r2 is not None else []),
            *([f"the fin explains {100 * share:.0f} % of u_d"] if share is not None else []),
            *(figures.get("reasons") or ()),
        ]
        lines.append(f"  fit          {figures['verdict']}: " + "; ".join(detail))
    print("\n".join(lines))
    if args.plot is not None:
        print(f"wrote {args.plot}")
    return 0


@dataclass(frozen=True)
class AddArgs:
    """``rocketroll db add``."""

    recording: Path = setting(help="recording file (CSV, format v1)", positional=True, input=True)
    db: str | None = db_setting(new=True)
    method: list[str] = setting(
        default_factory=list,
        help=methods_help("identification method to store", flight=True),
        metavar="METHOD",
    )
    surrogates: int = setting(
        0, "surrogates per trace of the paper's method (or the first method)", ge=0, le=1000
    )
    surrogate_kind: list[str] = setting(
        default_factory=list, help="surrogate kind (repeatable; default iaaft)", metavar="KIND"
    )
    posterior: int = setting(
        0,
        "posterior u_d draws per trace of a method with a posterior (--method ml)",
        ge=0,
        le=1000,
    )
    posterior_seed: int = setting(0, "seed of the first posterior draw", ge=0, le=2**63 - 1)
    split: Literal["train", "test"] | None = setting(
        None,
        "store the recording in this split (default: its metadata's split, else chosen by "
        "its samples, a quarter of recordings test)",
    )
    holdout: float | None = setting(
        None,
        "hold out this share of the run's end for evaluation: its earlier part goes to the "
        "train split (identified alone: what designs see), the whole run to the test split "
        "(identified on all of it) with its traces cut to the held-out end; both under the "
        "run's name, for eval/tune/... --recording NAME",
        ge=0.1,
        le=0.8,
        metavar="SHARE",
    )
    accept_unreliable: bool = setting(
        False,
        "store the recording even where every fit of it is judged unreliable (refused "
        "without this), marked: db list and the evaluations that replay it say so",
    )
    options: IdentifyOptions = setting(default_factory=IdentifyOptions, flatten=True)

    def __post_init__(self) -> None:
        check(self)
        check_methods(self.method)
        if self.holdout is not None and (self.split is not None or self.surrogates):
            raise UsageError(
                "--holdout splits the run between the train and test splits itself, without "
                "surrogates: drop " + ("--split" if self.split is not None else "--surrogates")
            )
        if self.posterior and self.method:
            check_posterior_methods(self.method)
        for kind in self.surrogate_kind:
            if kind not in SURROGATE_KINDS:
                raise UsageError(
                    f"--surrogate-kind must be one of {', '.join(SURROGATE_KINDS)}, not {kind!r}"
                )
        if self.surrogate_kind and self.surrogates == 0:
            raise UsageError("--surrogate-kind needs --surrogates N (how many of each kind)")


def add(args: AddArgs) -> int:
    """Identify a recording and store everything (one transaction)."""
    import dataclasses

    from disturbances.ingest import add_recording
    from identification.recordings.recording import load_recording

    options = dataclasses.replace(args.options, progress=sys.stderr.isatty())
    recording = load_recording(args.recording)
    methods = args.method or list(default_methods(recording))
    check_quadratic(options, methods, recording)
    if args.posterior:
        check_posterior_methods(methods)
    if args.split is not None:
        recording = dataclasses.replace(
            recording, metadata={**recording.metadata, "split": args.split}
        )
    with new_database(args.db), open_store(args.db, create=True) as db:
        result = add_recording(
            db,
            recording,
            options,
            methods=methods,
            surrogates=args.surrogates,
            surrogate_kinds=tuple(args.surrogate_kind or ["iaaft"]),
            posterior=args.posterior,
            posterior_seed=args.posterior_seed,
            holdout=args.holdout or 0.0,
            unreliable="accept" if args.accept_unreliable else "refuse",
        )
        if result.recordings == 0 and result.traces == 0:
            print(f"{db.path}: {recording.name} is already stored (same samples); nothing added")
            return 0
        print(
            f"{db.path}: added {recording.name}: {result.identifications} identifications, "
            f"{result.traces} traces (ids {', '.join(map(str, result.trace_ids))})"
        )
        if args.accept_unreliable and any(
            i.accepted_unreliable for i in db.identifications(recording=recording.name)
        ):
            print(
                f"  every fit of {recording.name} is judged unreliable: stored with "
                "--accept-unreliable, marked (db list; the evaluations that replay it say so)"
            )
        if args.holdout:
            from disturbances.ingest import split_parts

            for row in split_parts(db, recording.name):
                verdicts = sorted(
                    {
                        i.verdict or "not assessed"
                        for i in db.identifications(recording_hash=row.content_hash)
                    }
                )
                span = (
                    f"to {row.metadata['part.to_s']} s"
                    if row.metadata["part"] == "design"
                    else f"from {row.metadata['part.from_s']} s"
                )
                print(
                    f"  {row.metadata['part']} part ({span}): {row.split} split, fits "
                    f"{', '.join(verdicts)}"
                )
            print(f"  evaluate on it: rocketroll eval --db {db.path} --recording {recording.name}")

    return 0


@dataclass(frozen=True)
class SurrogateArgs:
    """``rocketroll db surrogate``."""

    trace: str = setting(help="trace id or uid (an identified trace)", positional=True)
    db: str | None = db_setting()
    kind: Literal["iaaft", "ar"] = setting("iaaft", "surrogate method")
    count: int = setting(1, "how many", ge=1, le=10_000)
    seed: int = setting(0, "seed of the first", ge=0, le=2**63 - 1)


def surrogate(args: SurrogateArgs) -> int:
    """Make and store surrogates of a stored trace."""
    from disturbances.ingest import add_surrogates

    with open_store(args.db) as db:
        uid = db.trace(_key(args.trace)).uid
        result = add_surrogates(db, uid, args.kind, args.count, args.seed)
        added = db.traces_by_uid([db.trace(i).uid for i in result.trace_ids])
    print(f"added {result.traces} {args.kind} surrogate(s) of {uid} ({result.skipped} existed)")
    for row in added:
        v = row.validation or {}
        verdict = (
            "check passed"
            if v.get("passed")
            else f"check FAILED (KS p {v.get('ks_p', float('nan')):.3g}, PSD log-distance "
            f"{v.get('psd_log_distance', float('nan')):.3f}); left out of banks by default"
        )
        print(f"  {row.id:>4}  {row.uid}  {verdict}")
    return 0


@dataclass(frozen=True)
class ExportArgs:
    """``rocketroll db export``."""

    format: Literal["csv", "npz", "parquet"] = setting(help="format of the sample files")
    out: Path = setting(help="folder to create (must not exist, or be empty)", output="folder")
    db: str | None = db_setting()
    filters: TraceFilters = setting(default_factory=TraceFilters, flatten=True)

    def __post_init__(self) -> None:
        check(self)
        if self.out.exists() and (not self.out.is_dir() or any(self.out.iterdir())):
            raise UsageError(f"--out {self.out}: exists and is not an empty folder")


def export(args: ExportArgs) -> int:
    """Export traces, parameters and a manifest to a folder."""
    from disturbances.exchange import write_export

    with open_store(args.db) as db:
        try:
            counts = write_export(db, args.out, args.format, **args.filters.query())
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    print(
        f"wrote {args.out}: {counts['traces']} traces, {counts['identifications']} "
        f"identifications, {counts['recordings']} recordings ({args.format})"
    )
    return 0


@dataclass(frozen=True)
class ImportArgs:
    """``rocketroll db import``."""

    folder: Path = setting(
        help="a folder written by `rocketroll db export`", positional=True, input=True
    )
    db: str | None = db_setting(new=True)


def import_(args: ImportArgs) -> int:
    """Import an export folder (one transaction)."""
    from disturbances.exchange import import_export, read_export

    read_export(args.folder)  # every file checked before the database is touched
    with new_database(args.db), open_store(args.db, create=True) as db:
        db.check_version(writing=True)
        result = import_export(db, args.folder)
    print(
        f"imported {args.folder}: {result.recordings} recordings, {result.identifications} "
        f"identifications, {result.traces} traces added; {result.skipped} already present"
    )
    return 0


@dataclass(frozen=True)
class MigrateArgs:
    """``rocketroll db migrate``."""

    db: str | None = db_setting()


def migrate(args: MigrateArgs) -> int:
    """Upgrade a database to this rocketroll's schema (opening it does; say what happened)."""
    from disturbances.schema import SCHEMA_VERSION

    # As every command opens it: the default database by its rules (one built from the
    # bundled recordings by an older rocketroll is rebuilt), any other upgraded in place.
    with open_store(args.db) as db:
        version = db.schema_version
        path = db.path
    print(f"{path}: schema version {version} (this rocketroll's: {SCHEMA_VERSION}), up to date")
    return 0


_DB_COMMANDS = (
    Command(
        "build",
        "build the database from the bundled (or given) recordings",
        BuildArgs,
        build,
        "Identify every bundled recording (every default identification method, both "
        "models), make surrogates, and write the database atomically.",
    ),
    Command("list", "list traces, optionally filtered", ListArgs, list_traces),
    Command("show", "show one trace: provenance, parameters, statistics", ShowArgs, show),
    Command(
        "add",
        "identify a recording and store everything (one transaction)",
        AddArgs,
        add,
        "Run the identification methods on a recording (format v1) and store the "
        "recording, parameters and u_d traces.  Nothing is stored if anything fails.",
    ),
    Command("surrogate", "make and store surrogates of a stored trace", SurrogateArgs, surrogate),
    Command(
        "export",
        "export traces, parameters (JSON) and a manifest to a folder",
        ExportArgs,
        export,
        "Write the selected traces with their parameters, recordings and a manifest into a "
        "new folder; `rocketroll db import` reads it back exactly.",
    ),
    Command("import", "import an export folder (one transaction)", ImportArgs, import_),
    Command(
        "migrate",
        "upgrade a database to this rocketroll's schema (a backup is kept beside it)",
        MigrateArgs,
        migrate,
        "Upgrade a database written by an older rocketroll to this one's schema, in place "
        "and in one transaction, after copying it to NAME.schemaN.bak beside it.  Any "
        "command that opens an old database does the same, with a one-line notice.",
    ),
)

#: The commands of this layer, by name.
COMMANDS: dict[str, Command] = {
    "db": Command(
        "db",
        "the disturbance database: build, list, show, add, surrogate, export, import, migrate",
        description="The disturbance database of recordings, identified parameters and u_d "
        "traces.  Without --db, the default database is used (built from the bundled "
        "recordings when missing).",
        subcommands=_DB_COMMANDS,
    ),
}
