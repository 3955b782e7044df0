"""Storage back ends of the disturbance database: what one must do, and where it registers.

Everything above the store -- identifying and ingesting
(:mod:`disturbances.ingest`), trace banks (:mod:`disturbances.bank`), export
and import (:mod:`disturbances.exchange`), the command line -- talks to a
:class:`Store`: rows of :mod:`disturbances.rows` in, rows out.
:class:`~disturbances.db.DisturbanceDB` (SQLite, a file) is the one this
distribution has.  Another back end (a server database, an object store) is
one module with a class that does what :class:`Store` says, registered once::

    from disturbances.stores import register_store

    register_store("postgresql", "my_package.pg:PostgresStore", summary="a PostgreSQL server")

after which ``--db postgresql://host/name`` (or ``open_store(...)``) opens
it: the class is called with the rest of the location and ``create=``.
A location without ``scheme://`` is an SQLite file.

A store holds any method name.  Which methods exist is the domain's to say,
so it is asked here, once for every back end: :func:`store_rows` refuses
rows of a method that is not registered, and :func:`check_filters` refuses a
method filter that is neither registered nor stored.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from disturbances.db import DatabaseError, DisturbanceDB, Dump
from disturbances.rows import IdentificationRow, RecordingRow, TraceRow
from identification.methods import METHODS
from rocketroll_common.registry import Registry

__all__ = ["STORES", "Store", "check_filters", "open_store", "register_store", "store_rows"]


class Store(Protocol):
    """What a disturbance store does (see :class:`disturbances.db.DisturbanceDB`)."""

    path: Path

    @property
    def schema_version(self) -> int:
        """The store's schema version (after any upgrade opening it made)."""

    def store(
        self,
        recordings: Sequence[RecordingRow] = ...,
        identifications: Sequence[IdentificationRow] = ...,
        traces: Sequence[TraceRow] = ...,
    ) -> Any:
        """Insert rows in one transaction, skipping those present."""

    def recordings(self) -> list[RecordingRow]:
        """Every recording, without samples."""

    def methods(self) -> list[str]:
        """Methods of the stored identifications."""

    def recording_row(self, key: int | str) -> RecordingRow:
        """One recording with its samples."""

    def identifications(self, **filters: Any) -> list[IdentificationRow]:
        """Stored identifications."""

    def traces(self, **filters: Any) -> list[TraceRow]:
        """Stored traces, without samples."""

    def trace(self, key: int | str) -> TraceRow:
        """One trace with its samples, verified."""

    def load_traces(self, rows: Iterable[TraceRow]) -> list[TraceRow]:
        """Listed traces with their samples, verified."""

    def has_recording(self, recording_hash: str) -> bool:
        """Whether a recording is stored."""

    def has_identification(self, recording_hash: str, method: str, model: str) -> bool:
        """Whether an identification is stored."""

    def has_trace(self, uid: str) -> bool:
        """Whether a trace is stored."""

    def info(self) -> dict[str, str]:
        """Key/value facts about the store (creator, origin, ...)."""

    def set_info(self, values: Mapping[str, str]) -> None:
        """Set such facts."""

    def check_version(self, *, writing: bool = False) -> None:
        """Warn (or, writing, refuse) when another version's results are stored."""

    def versions(self) -> list[str]:
        """Package versions whose identifications are stored."""

    def counts(self) -> dict[str, int]:
        """Rows stored: recordings, identifications, traces, surrogates."""

    def traces_by_uid(self, uids: Sequence[str]) -> list[TraceRow]:
        """Listed traces by uid, in order."""

    def dump(self, **filters: Any) -> Dump:
        """Traces matching ``filters`` with samples and what they depend on, for export."""

    def close(self) -> None:
        """Release the store."""

    def __enter__(self) -> Store:
        """The store itself (``with open_store(...) as db``)."""

    def __exit__(self, *exc: object) -> None:
        """:meth:`close`."""


#: Storage back ends by URL scheme.
STORES: Registry[Callable[..., Store]] = Registry("storage back end")


def register_store(
    scheme: str, opener: Callable[..., Store] | str, *, summary: str = "", replace: bool = False
) -> None:
    """Register a back end for locations ``SCHEME://...`` (``opener(rest, create=...)``)."""
    STORES.register(scheme, opener, summary=summary, replace=replace)


def open_store(location: str | os.PathLike[str], *, create: bool = False) -> Store:
    """The store at ``location``: ``scheme://rest`` by its back end, else an SQLite file."""
    text = os.fspath(location)
    scheme, sep, rest = text.partition("://")
    if sep and scheme.isidentifier():
        try:
            opener = STORES.get(scheme)
        except ValueError as exc:
            raise DatabaseError(f"{text}: {exc}") from None
        return opener(rest, create=create)
    return STORES.get("sqlite")(Path(text), create=create)


register_store("sqlite", "disturbances.db:DisturbanceDB", summary="an SQLite file (the default)")


def store_rows(
    db: Store,
    recordings: Sequence[RecordingRow] = (),
    identifications: Sequence[IdentificationRow] = (),
    traces: Sequence[TraceRow] = (),
) -> Any:
    """``db.store(...)`` of rows whose methods are registered (``ValueError`` before
    anything is written if one is not)."""
    for method in sorted({i.method for i in identifications} | {t.method for t in traces}):
        try:
            METHODS.check(method)
        except ValueError as exc:
            raise ValueError(
                f"{exc}: register it (identification.methods.register_method) before storing "
                "its results"
            ) from None
    return db.store(recordings, identifications, traces)


def check_filters(db: Store, filters: Mapping[str, Any]) -> None:
    """Refuse a ``method`` filter that is neither registered nor stored in ``db``
    (``ValueError``); a registered method that is not stored matches nothing."""
    value = filters.get("method")
    if value is None:
        return
    registered = METHODS.names()
    known = (*registered, *(m for m in db.methods() if m not in registered))
    for v in [value] if isinstance(value, str) else list(value):
        if v not in known:
            raise ValueError(f"filter method={v!r}: must be one of {', '.join(known)}")


if TYPE_CHECKING:  # the type checker proves the SQLite store is a Store

    def _sqlite_is_a_store(db: DisturbanceDB) -> Store:
        return db
