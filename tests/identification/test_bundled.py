"""The bundled synthetic recordings: valid, labelled synthetic, reproducible from their commands."""

from __future__ import annotations

import pytest

from identification.instruments.bundled import BUNDLED, DATA_DIR, bundled_paths, load_bundled, make
from identification.recordings.recording import recording_text


def test_every_bundled_file_is_listed_and_present() -> None:
    on_disk = sorted(p.name for p in DATA_DIR.glob("*.csv"))
    assert on_disk == sorted(BUNDLED)
    assert all(p.is_file() for p in bundled_paths())


@pytest.mark.parametrize("name", list(BUNDLED))
def test_bundled_file_regenerates_byte_for_byte(name: str) -> None:
    rec = load_bundled(name)
    assert rec.source == "synthetic"
    assert rec.metadata["command"] == BUNDLED[name]
    assert recording_text(make(name)) == (DATA_DIR / name).read_text(encoding="utf-8")
