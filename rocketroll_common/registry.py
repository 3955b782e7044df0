"""Registries: one name chooses among alternatives, decided in one place.

Gymnasium's ``register``/``make`` is the model.  A :class:`Registry` maps a
name to an entry -- an object, or a ``"module:attribute"`` string loaded on
first use, so listing the names (for ``--help`` and error messages) imports
nothing heavy.  Identification methods, controllers, environment variants and
storage back ends are each one registry (the two damping models, fixed by the
paper, are one table: ``identification.model.MODELS``); a new one joins by one
``register`` call, and the command line, the database and the evaluation
find it.

Plugins outside this distribution register themselves when they are
imported.  :func:`load_plugins` imports every module named by an entry point
of the group ``rocketroll.plugins`` (``[project.entry-points."rocketroll.plugins"]``
in a plugin's ``pyproject.toml``) and by the environment variable
``ROCKETROLL_PLUGINS`` (comma-separated module names); every registry calls it
before it lists or looks up names.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Generic, TypeVar

from rocketroll_common.errors import UsageError
from rocketroll_common.plugins import PLUGIN_GROUP, PLUGIN_VARIABLE, plugin_modules

__all__ = ["PLUGIN_GROUP", "PLUGIN_VARIABLE", "Entry", "Registry", "load_plugins", "unknown"]

T = TypeVar("T")


_plugins_loaded = False


def load_plugins() -> None:
    """Import every plugin module once (entry points, then ``$ROCKETROLL_PLUGINS``)."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True  # first: a plugin's own registrations come back here
    for what, load in plugin_modules():
        try:
            load()
        except Exception as exc:
            _plugins_loaded = False
            raise UsageError(
                f"rocketroll plugin {what} cannot be loaded: {type(exc).__name__}: {exc}"
            ) from exc


def _load(reference: str) -> Any:
    module, _, attribute = reference.partition(":")
    value: Any = importlib.import_module(module)
    for part in attribute.split(".") if attribute else ():
        value = getattr(value, part)
    return value


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One registered alternative.

    Attributes
    ----------
    name : str
        What users type.
    target : object or str
        The entry, or ``"module:attribute"`` to import on first use.
    summary : str
        One line for ``--help`` and listings.
    info : mapping
        Anything else the registry's users read (e.g. ``usage``, ``default``).
    """

    name: str
    target: T | str
    summary: str = ""
    info: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))

    def load(self) -> T:
        """The entry itself (imported on first use)."""
        if isinstance(self.target, str):
            loaded: T = _load(self.target)
            object.__setattr__(self, "target", loaded)
        return self.target  # type: ignore[return-value]


def unknown(kind: str, name: object, known: Sequence[str]) -> ValueError:
    """The error for ``name``, not among ``known`` names of ``kind``: the nearest known
    name, if one is near, and all of them."""
    close = difflib.get_close_matches(str(name), list(known), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return ValueError(f"unknown {kind} {name!r}{hint}; known: {', '.join(known) or 'none'}")


class Registry(Generic[T]):
    """Names mapped to alternatives of one kind.

    Parameters
    ----------
    kind : str
        What is registered, for messages (``"identification method"``).

    Examples
    --------
    >>> colours = Registry[tuple[int, int, int]]("colour")
    >>> colours.register("red", (255, 0, 0), summary="warm")
    >>> colours.register("blue", "colorsys:ONE_THIRD")  # imported on first use
    >>> colours.get("red"), colours.names()
    ((255, 0, 0), ('red', 'blue'))
    >>> colours.check("rde")
    Traceback (most recent call last):
    ...
    ValueError: unknown colour 'rde' (did you mean 'red'?); known: red, blue
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._entries: dict[str, Entry[T]] = {}

    def register(
        self,
        name: str,
        target: T | str,
        *,
        summary: str = "",
        replace: bool = False,
        **info: Any,
    ) -> None:
        """Add ``name``; registering a taken name needs ``replace=True``."""
        if not isinstance(name, str) or not name or name != name.strip() or "," in name:
            raise ValueError(f"a {self.kind} name must be a non-empty word, got {name!r}")
        if name in self._entries and not replace:
            raise ValueError(f"{self.kind} {name!r} is registered already")
        self._entries[name] = Entry(name, target, summary, MappingProxyType(dict(info)))

    def snapshot(
        self, names: Sequence[str] | None = None
    ) -> list[tuple[str, Any, str, dict[str, Any]]]:
        """The entries of ``names`` (default: every one) as plain values, picklable when
        each target is importable by name, for :meth:`merge` in another process."""
        chosen = self.entries() if names is None else [self.entry(n) for n in names]
        return [(e.name, e.target, e.summary, dict(e.info)) for e in chosen]

    def merge(self, snapshot: list[tuple[str, Any, str, dict[str, Any]]]) -> None:
        """Register every entry of :meth:`snapshot` under its name, replacing what is
        registered under it (after the plugins have registered theirs, so they cannot come
        back over it later); other entries stay."""
        load_plugins()
        for name, target, summary, info in snapshot:
            self._entries[name] = Entry(name, target, summary, MappingProxyType(dict(info)))

    def unregister(self, name: str) -> None:
        """Remove ``name`` (tests and plugins that replace a built-in)."""
        self._entries.pop(name, None)

    def names(self) -> tuple[str, ...]:
        """Every registered name, in registration order."""
        load_plugins()
        return tuple(self._entries)

    def entries(self) -> tuple[Entry[T], ...]:
        """Every entry, in registration order."""
        load_plugins()
        return tuple(self._entries.values())

    def __contains__(self, name: object) -> bool:
        load_plugins()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self.names())

    def check(self, name: str) -> str:
        """``name`` if it is registered; otherwise a ``ValueError`` with suggestions."""
        if name in self:
            return name
        raise unknown(self.kind, name, list(self._entries))

    def entry(self, name: str) -> Entry[T]:
        """The entry of ``name`` (``ValueError`` if unknown)."""
        return self._entries[self.check(name)]

    def get(self, name: str) -> T:
        """The alternative registered as ``name``, imported on first use."""
        return self.entry(name).load()

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"
