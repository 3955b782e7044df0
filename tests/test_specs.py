"""The declarative specs: one-line errors naming file, line, key and problem, and the JSON
Schemas kept in docs/schemas/ equal to the models' (``make schemas`` writes them)."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import pytest
from pydantic import BaseModel, Field

from rocketroll.cli import SCHEMAS
from rocketroll_common.errors import UsageError
from rocketroll_common.specs import SCHEMAS_DIR, load_yaml, schema_text, validated


@pytest.mark.parametrize("stem", sorted(SCHEMAS))
def test_the_kept_schemas_are_current(stem: str) -> None:
    module, _, name = SCHEMAS[stem].partition(":")
    model = getattr(importlib.import_module(module), name)
    kept = SCHEMAS_DIR / f"{stem}.schema.json"
    assert kept.is_file(), f"{kept} missing: run make schemas"
    assert kept.read_text(encoding="utf-8") == schema_text(model), f"{kept}: run make schemas"
    assert json.loads(kept.read_text())["$schema"].endswith("2020-12/schema")


class _Inner(BaseModel):
    model_config = {"extra": "forbid"}
    steps: int = Field(1, ge=1, strict=True)


class _Outer(BaseModel):
    model_config = {"extra": "forbid"}
    name: str
    items: list[_Inner] = []


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "name: a\nitems:\n  - {steps: 2}\n  - {steps: 0}\n",
            "f.yml:4: items[1].steps: Input should",
        ),
        (
            "name: a\nitems:\n  - steps: 2\n    extra: 1\n",
            "f.yml:4: items[0].extra: unknown key 'extra'",
        ),
        ("name: a\ncolour: red\n", "f.yml:2: colour: unknown key 'colour'; known: name, items"),
        ("items: []\n", "f.yml: name: is missing"),
        ("- 1\n- 2\n", "f.yml: expected a mapping (name, items)"),
        ("name: [a\n", "f.yml: not a YAML file"),
    ],
)
def test_a_bad_spec_is_one_line_naming_file_line_and_key(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str, message: str
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("f.yml").write_text(text, encoding="utf-8")
    with pytest.raises(UsageError) as info:
        document, lines = load_yaml("f.yml")
        validated(_Outer, document, "f.yml", lines)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("stem", "folder", "bad"),
    [
        ("sweep", "agents/sweeps", {"name": "x", "env_ids": "RocketRoll-v0", "controllers": []}),
        ("hyperparams", "agents/hyperparams", {"RocketRoll-v0": {"n_envs": 0}}),
        ("ascent", "identification/data", {"dry_mass_kg": 1.0}),
    ],
)
def test_the_shipped_specs_pass_their_schema(stem: str, folder: str, bad: object) -> None:
    """What an editor would check: every shipped file against the kept JSON Schema, which
    refuses a bad one."""
    import jsonschema
    import yaml

    schema = json.loads((SCHEMAS_DIR / f"{stem}.schema.json").read_text(encoding="utf-8"))
    shipped = sorted((Path(__file__).resolve().parents[1] / folder).glob("*.yml"))
    assert shipped
    for path in shipped:
        jsonschema.validate(yaml.safe_load(path.read_text(encoding="utf-8")), schema)
        assert f"$schema=../../docs/schemas/{stem}.schema.json" in path.read_text().split("\n")[0]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)
