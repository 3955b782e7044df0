"""Loading the disturbance traces an environment replays (through the database API only)."""

from __future__ import annotations

import dataclasses
import difflib
import os
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from disturbances.bank import TraceBank
from disturbances.default import open_database
from rollenv.config import RollConfig, config_fields
from rollenv.flight import stored_flight_name

__all__ = [
    "find_bank",
    "load_bank",
    "make_config",
    "settings_config",
    "stored_flight_config",
    "variant_config",
]

_CACHE: dict[tuple[Any, ...], TraceBank] = {}
_LOCK = threading.Lock()


def make_config(owner: str, settings: dict[str, Any]) -> RollConfig:
    """``RollConfig(**settings)``, with an unknown name rejected by name (and a suggestion);
    ``owner`` (an environment id or class) starts the message."""
    known = config_fields()
    for name in settings:
        if name not in known:
            close = difflib.get_close_matches(name, known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(
                f"{owner}: unknown option {name!r}{hint}; the options are: "
                f"{', '.join(known)}, and bank, db, render_mode"
            )
    return RollConfig(**settings)


def variant_config(env_id: str, settings: Mapping[str, Any] | None = None) -> RollConfig:
    """The configuration of the registered variant ``env_id`` with ``settings`` on top
    (as ``gym.make(env_id, **settings)`` makes it); a ``task`` other than the
    variant's is a ``ValueError``."""
    from rollenv.variants import variant_options

    try:
        options = variant_options(env_id)
    except ValueError as exc:
        raise ValueError(f"env_id: {exc}") from None
    given = dict(settings or {})
    task = options["task"]
    if given.setdefault("task", task) != task:
        raise ValueError(f"{env_id} is the {task!r} task; task={given['task']!r} conflicts")
    return make_config(env_id, {**options, **given})


def load_bank(config: RollConfig, db: str | os.PathLike[str] | None) -> TraceBank:
    """The traces ``config`` asks for, from ``db`` (default: the default database).

    Identified traces for ``disturbance="replay"`` (and ``"none"``, which
    still takes the rocket's parameters from them), validated surrogates for
    ``"surrogate"``, posterior draws for ``"posterior"`` (a method with a
    posterior, ``method="ml"``); ``config.method`` (the paper's by default);
    ``config.model``; ``config.split``; ``config.recording`` (one recording's
    traces, when given).
    Banks are cached per file state and selection, so a vector of
    environments in one process loads the traces once.  For a flight
    (``config.flight``) the bank holds the flights
    (:meth:`rollenv.config.RollConfig.flights`): one trace per flight, exactly
    one episode long.
    """
    kind = {"surrogate": "surrogate", "posterior": "posterior"}.get(
        str(config.disturbance), "identified"
    )
    database = open_database(None if db is None else Path(db))
    try:
        path = Path(database.path).resolve()
        stat = path.stat()
        key = (
            str(path),
            stat.st_mtime_ns,
            stat.st_size,
            config.split,
            config.method,
            config.model,
            kind,
            config.recording,
        )
        with _LOCK:
            bank = _CACHE.get(key)
            if bank is None:
                only: dict[str, Any] = {}
                if config.recording is not None:
                    only["recording"] = config.recording
                split = config.split
                if config.flies_stored_flight:  # one flight's rocket and u_d, in its split
                    split = _split_of(database, str(config.recording))
                bank = TraceBank.from_db(
                    database,
                    split,
                    method=config.method,
                    model=config.model,
                    kind=kind,
                    **only,
                )
                if len(_CACHE) >= 16:
                    _CACHE.clear()
                _CACHE[key] = bank
            bank = config.flights(bank)  # in flight: one trace per flight (cached there)
    finally:
        database.close()
    return bank


def _split_of(database: Any, recording: str) -> str:
    """The split a stored flight's traces are in (a flight is flown as that rocket, with
    its own u_d: there is no other split to evaluate it on)."""
    splits = {t.split for t in database.traces(recording=recording, method=_flight_methods())}
    return splits.pop() if len(splits) == 1 else "train"


def _flight_methods() -> list[str]:
    from identification.methods import METHODS, traits

    return [m for m in METHODS.names() if traits(m).flight]


def settings_config(
    make: Callable[[dict[str, Any]], RollConfig],
    settings: Mapping[str, Any],
    db: str | os.PathLike[str] | None,
) -> RollConfig:
    """``make(settings)`` (:func:`make_config`, :func:`variant_config`), flying a stored
    flight where ``settings`` name one (:func:`stored_flight_config`): its ``episode_s``,
    where given, is checked against that flight, not against the ascent the variant flies
    by default; without it the episode is the whole stored flight."""
    rest = {name: value for name, value in settings.items() if name != "episode_s"}
    return stored_flight_config(make(rest), db, settings.get("episode_s"))


def stored_flight_config(
    config: RollConfig, db: str | os.PathLike[str] | None, episode_s: float | None = None
) -> RollConfig:
    """``config`` flying the stored flight ``config.recording`` as that rocket, where it
    is a flight environment (``flight`` given) and the database holds that recording's
    flight fit: its profile, its airspeed scaling and its own ``u_d``
    (:func:`rollenv.flight.stored_flight_name`, ``method="flight"``,
    ``flight_turbulence="recorded"``), in an episode ``episode_s`` long (None: the whole
    stored flight from the tunnel's airspeed, as a tunnel episode fits one recording's
    trace); ``config`` itself otherwise, with ``episode_s`` where given.

    Raises
    ------
    ValueError
        Where ``episode_s`` is longer than the flight (the message says what to set).
    """
    if config.flight is None or config.recording is None or config.flies_stored_flight:
        return config if episode_s is None else dataclasses.replace(config, episode_s=episode_s)
    database = open_database(None if db is None else Path(db))
    try:
        path = str(Path(database.path).resolve())
        methods = [
            row.method
            for row in database.identifications(recording=config.recording, model=config.model)
            if row.flight_reference is not None
        ]
    finally:
        database.close()
    if not methods:
        return config if episode_s is None else dataclasses.replace(config, episode_s=episode_s)
    return dataclasses.replace(
        config,
        flight=stored_flight_name(path, config.recording),
        method=methods[-1],
        flight_turbulence="recorded",
        episode_s=episode_s,
    )


def find_bank(config: RollConfig, db: str | os.PathLike[str] | None) -> TraceBank | None:
    """:func:`load_bank`, or None where the database holds no traces of that selection (a
    :class:`~disturbances.bank.BankError`: a recording the split lacks, a method it does
    not hold, ...)."""
    from disturbances.bank import BankError

    try:
        return load_bank(config, db)
    except BankError:
        return None
