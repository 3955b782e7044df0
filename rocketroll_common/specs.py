"""Declarative specs read from YAML files: a pydantic model checks the document.

A spec's structure (its keys, their types and ranges, which keys go together) is a
pydantic model; :func:`load_yaml` reads the file and :func:`validated` checks it, and a
bad key or value is one :class:`~rocketroll_common.errors.UsageError` line naming the file,
the line, the key and the problem (``sweep.yml:7: controllers[1].timesteps: Input should be
greater than or equal to 1``).  What needs the rest of the toolkit (an environment id that
is registered, a file that exists) the loader checks after.  Each model's JSON Schema
(:func:`json_schema`, written under ``docs/schemas/`` by ``make schemas``:
:func:`rocketroll.cli.write_schemas`) lets an
editor check a spec as it is typed.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, BeforeValidator, Field, ValidationError

from rocketroll_common.errors import UsageError

__all__ = [
    "SCHEMAS_DIR",
    "Count",
    "Whole",
    "as_whole",
    "json_schema",
    "load_yaml",
    "place",
    "schema_text",
    "validated",
]

Model = TypeVar("Model", bound=BaseModel)

#: Where the JSON Schemas of the shipped spec models are kept (``make schemas``).
SCHEMAS_DIR = Path(__file__).resolve().parents[1] / "docs" / "schemas"


def as_whole(value: Any) -> Any:
    """``1e6`` is the whole number YAML reads as a float: take it as one (not a bool, not
    ``2.5``, which a strict integer then refuses)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


# Whole numbers: an integer, or a float with no fraction (``1e6``); not a bool.  (The
# bound before the validator, so that the JSON Schema carries it as ``minimum``.)
#: A whole number from 0.
Whole = Annotated[int, Field(strict=True, ge=0), BeforeValidator(as_whole)]
#: A whole number from 1.
Count = Annotated[int, Field(strict=True, ge=1), BeforeValidator(as_whole)]

#: A key path in a document: mapping keys and list indices.
Location = tuple[str | int, ...]


def load_yaml(path: str | os.PathLike[str]) -> tuple[Any, dict[Location, int]]:
    """The YAML document of ``path`` and the line (1-based) of every key and list item in
    it, by its path (``("controllers", 1, "timesteps")``); ``UsageError`` naming the file
    where it cannot be read or is not YAML."""
    import yaml

    where = os.fspath(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise UsageError(
            f"{where}: not UTF-8 text (byte {exc.start} is 0x{exc.object[exc.start]:02x})"
        ) from None
    except OSError as exc:
        raise UsageError(f"{where}: cannot read: {exc}") from None
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        document = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise UsageError(f"{where}: not a YAML file ({exc})".replace("\n", " ")) from None
    lines: dict[Location, int] = {}

    def walk(found: Any, at: Location) -> None:
        if isinstance(found, yaml.MappingNode):
            for key, value in found.value:
                if isinstance(key, yaml.ScalarNode):
                    lines[(*at, str(key.value))] = int(key.start_mark.line) + 1
                    walk(value, (*at, str(key.value)))
        elif isinstance(found, yaml.SequenceNode):
            for index, item in enumerate(found.value):
                lines[(*at, index)] = int(item.start_mark.line) + 1
                walk(item, (*at, index))

    walk(node, ())
    return document, lines


def place(where: str, lines: Mapping[Location, int] | None, loc: Location) -> str:
    """``WHERE:LINE`` of the key at ``loc`` in a document :func:`load_yaml` read (of the
    nearest key above it where ``loc`` has no line of its own), or ``WHERE`` alone."""
    known = lines or {}
    line = next((known[loc[:k]] for k in range(len(loc), 0, -1) if loc[:k] in known), None)
    return f"{where}:{line}" if line is not None else where


def _dotted(loc: Location) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def validated(
    model: type[Model],
    document: Any,
    where: str,
    lines: Mapping[Location, int] | None = None,
    at: Location = (),
) -> Model:
    """``document`` checked as ``model``; the first problem as one ``UsageError`` line,
    ``WHERE:LINE: KEY: PROBLEM`` (the line of the key, or of the nearest key above it).
    ``at`` is where ``document`` sits in its file (``("RocketRoll-v0",)``: an entry)."""
    if not isinstance(document, dict):
        keys = ", ".join(model.model_fields)
        key = f" {_dotted(at)}:" if at else ""
        raise UsageError(f"{place(where, lines, at)}:{key} expected a mapping ({keys})")
    try:
        return model.model_validate(document)
    except ValidationError as exc:
        error = exc.errors()[0]
        inner: Location = tuple(p for p in error["loc"] if isinstance(p, str | int))
        loc: Location = (*at, *inner)
        problem = str(error["msg"])
        if error["type"] == "extra_forbidden":
            problem = f"unknown key {loc[-1]!r}" if loc else "unknown key"
            if len(inner) == 1:
                problem += f"; known: {', '.join(model.model_fields)}"
        elif error["type"] == "missing":
            problem = "is missing"
        elif error["type"].endswith("_type") or error["type"] in ("literal_error", "enum"):
            shown = repr(error.get("input"))
            problem += f", got {shown}" if len(shown) <= 60 else ""
        problem = problem.removeprefix("Value error, ")
        key = _dotted(loc)
        found = place(where, lines, loc)
        raise UsageError(f"{found}: {key}: {problem}" if key else f"{found}: {problem}") from None


def json_schema(model: type[BaseModel]) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of ``model``, as an editor reads it."""
    schema = model.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def schema_text(model: type[BaseModel]) -> str:
    """:func:`json_schema` as the text kept in :data:`SCHEMAS_DIR`."""
    return json.dumps(json_schema(model), indent=2, ensure_ascii=False, sort_keys=True) + "\n"
