"""The default database: built from the bundled recordings, found or built automatically.

The environment and the CLI need no argument on a fresh install.  The default
database lives at

1. ``$ROCKETROLL_DB`` if that variable is set (the CLI's ``--db PATH`` wins
   over both), else
2. ``$XDG_CACHE_HOME/rocketroll/disturbances.sqlite`` (``~/.cache/...``).

It is made from the bundled synthetic recordings
(:data:`identification.instruments.bundled.BUNDLED`): each is identified by the default
methods -- the paper's, the output-error peer and maximum likelihood -- both
models, with :data:`DEFAULT_SURROGATES` IAAFT surrogates of every paper-method
trace and :data:`DEFAULT_POSTERIOR` posterior draws of every maximum-likelihood
trace (what the environment replays by default: ``benchmarks/closed_loop.py``
finds them the most faithful replay).  The
recipe, the package version, the schema and the bundled files' bytes make its
*fingerprint*; a database built this way is marked ``origin: bundled``.  A
default database whose fingerprint differs -- built by another rocketroll
version, or from other bundled data -- is rebuilt, with a notice on stderr;
results of two versions are never mixed in it.  Once a user adds to a
database (``origin: user``) it is never rebuilt silently: opening one that
holds another version's identifications warns instead.

A build runs under the pinned numerics of :mod:`rocketroll_common.numerics`
(a child interpreter with the same BLAS kernels and SIMD loops on every x86-64
machine), so the same recipe and recordings give the same numbers everywhere:
the identified parameters, traces and draws, and so every figure computed by
replaying them.

Builds are atomic: the new database is written beside the target and renamed
into place when complete.  One process at a time builds into a folder (a lock
on the folder itself, so no lock file is left behind); a build that fails or is
interrupted removes its ``.NAME.*.building`` files, and what a build killed
outright leaves is removed by the next build into that folder.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import os
import sqlite3
import sys
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from disturbances.db import BUSY_TIMEOUT_S, DisturbanceDB, package_version
from disturbances.ingest import add_recording
from disturbances.rows import SURROGATE_KINDS
from disturbances.schema import APPLICATION_ID, SCHEMA_VERSION
from disturbances.stores import Store, open_store
from identification.instruments.bundled import bundled_paths
from identification.methods import METHODS, database_methods, has_posterior
from identification.methods.pipeline import IdentifyOptions
from identification.recordings.recording import load_recording
from rocketroll_common.files import created_folders_removed_on_error, file_mode
from rocketroll_common.numerics import call_pinned, is_pinned, pinned_environment

__all__ = [
    "BUILD_RECIPE",
    "DEFAULT_POSTERIOR",
    "DEFAULT_SURROGATES",
    "ENV_VAR",
    "build_database",
    "default_path",
    "expected_fingerprint",
    "fingerprint",
    "open_database",
    "open_default",
]

#: Environment variable naming the default database file.
ENV_VAR = "ROCKETROLL_DB"
#: IAAFT surrogates per paper-method trace in the default database.
DEFAULT_SURROGATES = 2
#: Posterior u_d draws per trace of a method with a posterior (ml) in the default database.
DEFAULT_POSTERIOR = 8
#: Version of the recipe below; bump it when the build changes in any other way (4: built
#: under pinned numerics, the same bits on every machine).
BUILD_RECIPE = 4


def default_path() -> Path:
    """Where the default database is: ``$ROCKETROLL_DB``, else the user's cache folder."""
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env).expanduser()
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "rocketroll" / "disturbances.sqlite"


def fingerprint(
    recordings: Sequence[Path],
    options: IdentifyOptions,
    surrogates: int,
    surrogate_kinds: Sequence[str],
    posterior: int = DEFAULT_POSTERIOR,
    methods: Sequence[str] | None = None,
    *,
    pinned: bool | None = None,
) -> str:
    """What a build depends on, hashed: recipe, versions, settings, the input bytes and
    whether its numerics were pinned (default: whether a build here would be)."""
    methods = database_methods() if methods is None else tuple(methods)
    if pinned is None:
        pinned = is_pinned() or pinned_environment() is not None
    h = hashlib.sha256()
    recipe = {
        "recipe": BUILD_RECIPE,
        "schema": SCHEMA_VERSION,
        "package": package_version(),
        "methods": list(methods),
        "options": dataclasses.asdict(dataclasses.replace(options, progress=False)),
        "surrogates": surrogates,
        "surrogate_kinds": list(surrogate_kinds),
        "posterior": posterior,
        "numerics": "pinned" if pinned else "as found",
    }
    h.update(json.dumps(recipe, sort_keys=True).encode())
    for path in recordings:
        h.update(path.name.encode() + b"\0" + hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def _discard_journal(path: Path) -> None:
    """Fold a leftover WAL into ``path`` before the file is replaced.

    A ``-wal`` file left beside a replaced database would be applied to the
    new one; checkpointing the old database first empties it.
    """
    wal = Path(f"{path}-wal")
    if path.exists() and wal.exists():
        try:  # a plain connection: the old file is checkpointed, not checked or upgraded
            old = sqlite3.connect(path, timeout=BUSY_TIMEOUT_S)
            try:
                old.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            finally:
                old.close()
        except sqlite3.Error:
            pass
    for suffix in ("-wal", "-shm"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)


def build_database(
    path: str | os.PathLike[str],
    recordings: Sequence[str | os.PathLike[str]] | None = None,
    *,
    options: IdentifyOptions | None = None,
    surrogates: int = DEFAULT_SURROGATES,
    surrogate_kinds: Sequence[str] = ("iaaft",),
    posterior: int = DEFAULT_POSTERIOR,
    methods: Sequence[str] | None = None,
    progress: bool = False,
) -> Path:
    """Build a database from recordings (default: the bundled ones), atomically.

    Every recording is identified by ``methods`` (default: the recipe's,
    :func:`identification.methods.database_methods`: the paper's, the
    output-error peer and maximum likelihood), for every model they fit, with
    ``surrogates`` surrogates of each paper-method trace and ``posterior``
    posterior draws of each trace of a method with a posterior.

    Parameters
    ----------
    path : str or PathLike
        The database to (re)place; missing folders are created (and removed
        again if the build fails).
    recordings : sequence of paths, optional
        Recording files; the bundled recordings by default.  Built from the
        bundled ones with the default settings, the database is marked
        ``origin: bundled`` with its fingerprint.
    options : IdentifyOptions, optional
        Identification settings (the paper's).
    surrogates : int
        Surrogates per kind and per paper-method trace.
    surrogate_kinds : sequence of str
        ``iaaft`` and/or ``ar``.
    posterior : int
        Posterior draws per trace of a method with a posterior (``ml``).
    methods : sequence of str, optional
        Identification methods; default: the default database's.
    progress : bool
        Show a progress bar.

    Returns
    -------
    Path
        ``path``.
    """
    target = Path(path)
    with created_folders_removed_on_error(target), _build_lock(target.parent):
        return _build_pinned(
            target,
            recordings,
            options,
            surrogates,
            surrogate_kinds,
            posterior,
            progress,
            methods=methods,
        )


def _build_default(target: Path, progress: bool) -> None:
    """Build the default database at ``target`` (its folder's build lock held)."""
    _build_pinned(target, None, None, DEFAULT_SURROGATES, ("iaaft",), DEFAULT_POSTERIOR, progress)


def _build_pinned(target: Path, *args: Any, methods: Sequence[str] | None = None) -> Path:
    """:func:`_build` (``target``, then ``args``, its other arguments in its order, and
    ``methods``) under the pinned numerics, its folder's build lock held.  A build that
    does not finish (the pinned process killed after an interrupt's grace, before it
    could clean up) leaves no ``.building`` file: they are removed here, where no other
    build of the folder can be running (the lock)."""
    try:
        return call_pinned(_build_registered, _registered(methods), target, *args, methods)
    except BaseException:
        _remove_stale_builds(target)
        raise


def _registered(methods: Sequence[str] | None) -> list[tuple[str, Any, str, dict[str, Any]]]:
    """The registry a build needs, as :meth:`Registry.snapshot` gives it: the methods it
    runs and those of the default recipe (its fingerprint names them), in their order."""
    needed = set(database_methods() if methods is None else methods) | set(database_methods())
    return METHODS.snapshot([name for name in METHODS.names() if name in needed])


def _build_registered(methods: list[tuple[str, Any, str, dict[str, Any]]], *args: Any) -> Path:
    """:func:`_build` with the identification methods of ``methods`` (a snapshot of the
    calling process's registry, the methods the build runs: the pinned process knows what
    that process registered, and nothing unpicklable it does not run)."""
    METHODS.merge(methods)  # in this process (a fallback): the same entries again
    return _build(*args)


def _build(
    target: Path,
    recordings: Sequence[str | os.PathLike[str]] | None,
    options: IdentifyOptions | None,
    surrogates: int,
    surrogate_kinds: Sequence[str],
    posterior: int,
    progress: bool,
    methods: Sequence[str] | None = None,
) -> Path:
    """:func:`build_database` with the folder's build lock held, in this process."""
    from tqdm.auto import tqdm

    bundled = recordings is None
    files = bundled_paths() if recordings is None else [Path(p) for p in recordings]
    unknown = [k for k in surrogate_kinds if k not in SURROGATE_KINDS]
    if unknown:
        raise ValueError(f"unknown surrogate kind(s) {unknown}; use {', '.join(SURROGATE_KINDS)}")
    opts = IdentifyOptions() if options is None else options
    chosen = database_methods() if methods is None else tuple(methods)
    if not any(has_posterior(m) for m in chosen):
        posterior = 0  # nothing to draw from
    loaded = [load_recording(f) for f in files]  # every file is validated before any work
    _remove_stale_builds(target)
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=".building", dir=target.parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        with DisturbanceDB(tmp) as db:
            for recording in tqdm(
                loaded, desc="building disturbance database", unit="recording", disable=not progress
            ):
                add_recording(
                    db,
                    recording,
                    opts,
                    surrogates=surrogates,
                    surrogate_kinds=surrogate_kinds,
                    posterior=posterior,
                    methods=chosen,
                )
            made = fingerprint(
                files, opts, surrogates, surrogate_kinds, posterior, chosen, pinned=is_pinned()
            )
            # Only the default recipe on the bundled data may be rebuilt automatically.
            default = bundled and made == expected_fingerprint()
            db.set_info(
                {
                    "origin": "bundled" if default else "user",
                    "fingerprint": made,
                    "recordings": json.dumps([f.name for f in files]),
                }
            )
        os.chmod(tmp, file_mode())  # mkstemp made it private
        _discard_journal(target)
        os.replace(tmp, target)
    finally:
        for leftover in (tmp, Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
            leftover.unlink(missing_ok=True)
    return target


def _remove_stale_builds(target: Path) -> None:
    """Remove what a killed build of ``target`` left (only one build runs: the lock)."""
    for suffix in ("", "-wal", "-shm"):
        for leftover in target.parent.glob(f".{glob.escape(target.name)}.*.building{suffix}"):
            leftover.unlink(missing_ok=True)


def expected_fingerprint() -> str:
    return fingerprint(
        bundled_paths(), IdentifyOptions(), DEFAULT_SURROGATES, ("iaaft",), DEFAULT_POSTERIOR
    )


def open_default(*, progress: bool | None = None) -> DisturbanceDB:
    """The default database (:func:`default_path`), built or rebuilt when needed.

    Missing: built from the bundled recordings (about half a minute, once).
    Built by another package version or from other bundled data
    (``origin: bundled`` with a different fingerprint): rebuilt, with a
    notice on stderr.  A database the user has added to is opened as it is.
    """
    path = default_path()
    show = sys.stderr.isatty() if progress is None else progress
    path.parent.mkdir(parents=True, exist_ok=True)
    with _build_lock(path.parent):
        return _open_or_build(path, show)


@contextmanager
def _build_lock(folder: Path) -> Iterator[None]:
    """One process at a time checks, builds or replaces a database in ``folder``.

    Others wait, then find it built.  The lock is on the folder itself (POSIX
    ``flock``), so it leaves no file behind; elsewhere there is no lock.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def peek(path: Path) -> tuple[int, dict[str, str]] | None:
    """Schema version and ``info`` table of a rocketroll database file, read only and
    without upgrading it; None if it is not one (opening it then says why)."""
    if not path.is_file() or path.stat().st_size == 0:
        return None
    try:
        conn = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True)
        try:
            version = int(conn.execute("PRAGMA user_version").fetchone()[0])
            app = int(conn.execute("PRAGMA application_id").fetchone()[0])
            rows = conn.execute("SELECT key, value FROM info").fetchall()
        finally:
            conn.close()
    except sqlite3.Error:
        return None
    if app != APPLICATION_ID:
        return None
    return version, {str(k): str(v) for k, v in rows}


def _open_or_build(path: Path, show: bool) -> DisturbanceDB:
    found = peek(path)
    version, origin = (-1, None) if found is None else (found[0], found[1].get("origin"))
    if 0 < version < SCHEMA_VERSION and origin == "bundled":
        # A default build by an older rocketroll: rebuilt below, not upgraded.
        print(
            f"rocketroll: the default disturbance database {path} has schema version "
            f"{version}; rebuilding it with schema {SCHEMA_VERSION}",
            file=sys.stderr,
        )
        _build_default(path, show)
        return DisturbanceDB(path, create=False)
    if not path.exists() or path.stat().st_size == 0:
        print(
            f"rocketroll: building the default disturbance database at {path} "
            "from the bundled recordings (once)",
            file=sys.stderr,
        )
        _build_default(path, show)
        return DisturbanceDB(path, create=False)
    db = DisturbanceDB(path, create=False)
    info = db.info()
    if info.get("origin") == "bundled" and info.get("fingerprint") != expected_fingerprint():
        db.close()
        built_by = info.get("created_by", "?")
        why = (
            f"was built by rocketroll {built_by}; this is {package_version()}"
            if built_by != package_version()
            else "was built from other bundled recordings or settings"
        )
        print(
            f"rocketroll: the default disturbance database {path} {why}; rebuilding it",
            file=sys.stderr,
        )
        _build_default(path, show)
        return DisturbanceDB(path, create=False)
    db.check_version()
    return db


def open_database(location: str | os.PathLike[str] | None = None) -> Store:
    """The store at ``location`` if given (it must exist), else :func:`open_default`.

    ``location`` is an SQLite file or ``scheme://...`` of a registered back end
    (:mod:`disturbances.stores`).
    """
    if location is None:
        return open_default()
    db = open_store(location, create=False)
    db.check_version()
    return db
