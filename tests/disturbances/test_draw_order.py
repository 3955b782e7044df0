"""Episodes are drawn by what each trace is, not by where the database stored it.

A trace bank orders its traces by :func:`disturbances.bank.draw_order` (recording name
and content hash, method, model, kind, seed, uid), so a database exported and imported
back -- whose rows come in the export's uid order -- and a database whose rows were
added in any other order evaluate to the same bits; and an import holds every row of
the export as the database it came from held it.

``order_db`` holds two test-split recordings whose uid order is the reverse of the
order they were added in (``tunnel-paper-seed5`` is ``d476…``, ``tunnel-staircase-seed12``
is ``71cd…``), so an evaluation that followed row order would draw other episodes from
the import.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from disturbances.bank import TraceBank, draw_order
from disturbances.db import DisturbanceDB
from disturbances.exchange import FORMATS, import_export, write_export
from disturbances.ingest import add_recording
from identification.instruments.bundled import load_bundled
from identification.methods.pipeline import IdentifyOptions
from rocketroll.cli import main

FAST = IdentifyOptions(noise_runs=0)
#: Added in this order: one train recording (the observer's design), then two test ones
#: in name order, which is not their uid order.
RECORDINGS = ("tunnel-paper-seed0", "tunnel-paper-seed5", "tunnel-staircase-seed12")
#: The banks of every kind the database holds: (method, kind).
BANKS = (("paper", "identified"), ("paper", "surrogate"), ("ml", "identified"), ("ml", "posterior"))


def _format(fmt: str) -> str:
    if fmt == "parquet":
        pytest.importorskip(
            "pyarrow", reason="the parquet export needs pyarrow (pip install 'rocketroll[parquet]')"
        )
    return fmt


@pytest.fixture(scope="module")
def order_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Paper and maximum-likelihood fits of :data:`RECORDINGS`, one IAAFT surrogate per
    paper trace and two posterior draws per ML trace (do not modify)."""
    path = tmp_path_factory.mktemp("order") / "order.sqlite"
    with DisturbanceDB(path, create=True) as db:
        for name in RECORDINGS:
            add_recording(
                db, load_bundled(name), FAST, methods=("paper", "ml"), surrogates=1, posterior=2
            )
    return path


def evaluation(db: Path, out: Path) -> dict[str, Any]:
    """``rocketroll eval`` of the PID and the observer, 4 episodes, seed 0 (the default
    replay: ML posterior draws) on ``db``: its results.json and table, less what
    depends on the run rather than the database (the command line, the seconds)."""
    argv = ["eval", "--db", str(db), "--out", str(out), "--episodes", "4", "--seed", "0"]
    assert main([*argv, "--policy", "pid", "--policy", "observer"]) == 0
    results = json.loads((out / "results.json").read_text(encoding="utf-8"))
    del results["protocol"]["command"]
    for controller in results["controllers"].values():
        del controller["seconds"]
    results["table"] = (out / "table.md").read_text(encoding="utf-8")
    return results


def in_row_order(path: Path) -> list[str]:
    """The test recordings of ``path``'s default replay (ML posterior draws of the
    θ model, two per recording), in the database's row order."""
    with DisturbanceDB(path, create=False) as db:
        rows = db.traces(split="test", method="ml", model="theta", kind="posterior")
    return [t.recording for t in rows][::2]


def test_the_fixture_adds_its_rows_in_another_order_than_their_uids(order_db: Path) -> None:
    """What makes the tests below able to fail: row order and uid order differ."""
    assert in_row_order(order_db) == ["tunnel-paper-seed5", "tunnel-staircase-seed12"]


@pytest.fixture(scope="module")
def original(order_db: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return evaluation(order_db, tmp_path_factory.mktemp("eval") / "original")


@pytest.mark.parametrize("fmt", FORMATS)
def test_an_export_imported_back_evaluates_to_the_same_bits(
    fmt: str, order_db: Path, original: dict[str, Any], tmp_path: Path
) -> None:
    folder, new = tmp_path / "export", tmp_path / "imported.sqlite"
    with DisturbanceDB(order_db, create=False) as db:
        write_export(db, folder, _format(fmt))
    with DisturbanceDB(new, create=True) as db:
        import_export(db, folder)
    # The import's rows come in the export's uid order.
    assert in_row_order(new) == ["tunnel-staircase-seed12", "tunnel-paper-seed5"]
    imported = evaluation(new, tmp_path / "eval")
    assert imported["protocol"]["episodes"] == original["protocol"]["episodes"]
    assert imported == original  # every metric of every episode, as JSON's exact floats


def _shuffled_copy(source: Path, target: Path, seed: int) -> None:
    """``source``'s rows added to a new ``target`` in a shuffled order (a surrogate or
    draw after the trace it was made from, as a store requires)."""
    rng = np.random.default_rng(seed)
    with DisturbanceDB(source, create=False) as db:
        dump = db.dump()

    def shuffled(rows: tuple[Any, ...]) -> list[Any]:
        return [rows[k] for k in rng.permutation(len(rows))]

    traces = shuffled(dump.traces)
    traces.sort(key=lambda t: t.source_uid is not None)  # stable: shuffled within each
    with DisturbanceDB(target, create=True) as db:
        db.store(shuffled(dump.recordings), shuffled(dump.identifications), traces)


def test_rows_added_in_a_shuffled_order_draw_the_same_episodes(
    order_db: Path, original: dict[str, Any], tmp_path: Path
) -> None:
    shuffled = tmp_path / "shuffled.sqlite"
    _shuffled_copy(order_db, shuffled, seed=1)
    with DisturbanceDB(order_db, create=False) as a, DisturbanceDB(shuffled) as b:
        for split in ("train", "test"):
            assert [t.uid for t in a.traces(split=split)] != [t.uid for t in b.traces(split=split)]
            for method, kind in BANKS:
                first = TraceBank.from_db(a, split, method=method, kind=kind)
                second = TraceBank.from_db(b, split, method=method, kind=kind)
                assert [t.uid for t in first.traces] == [t.uid for t in second.traces]
                assert list(first.traces) == sorted(first.traces, key=draw_order)
                for x, y in zip(first.traces, second.traces, strict=True):
                    assert x.samples().tobytes() == y.samples().tobytes()
                starts = [first.draw(np.random.default_rng(s), 60.0, 8) for s in range(3)]
                again = [second.draw(np.random.default_rng(s), 60.0, 8) for s in range(3)]
                for (ti, si), (tj, sj) in zip(starts, again, strict=True):
                    np.testing.assert_array_equal(ti, tj)
                    np.testing.assert_array_equal(si, sj)
    assert evaluation(shuffled, tmp_path / "eval") == original


def test_the_draw_order_is_by_recording_then_identified_before_its_draws_by_seed() -> None:
    """Seeds sort as numbers (draw 10 after draw 2), two recordings of one name by their
    content, and the database's row ids play no part."""
    from disturbances.rows import STATISTICS, TraceRow

    def row(recording: str, digest: str, seed: int | None, row_id: int) -> TraceRow:
        uid = f"{digest}-ml-theta" + ("" if seed is None else f"-posterior-{seed}")
        return TraceRow(
            uid=uid,
            recording_hash=digest,
            method="ml",
            model="theta",
            kind="identified" if seed is None else "posterior",
            source_uid=None if seed is None else f"{digest}-ml-theta",
            seed=seed,
            settings={},
            dt_s=0.1,
            t0_s=0.0,
            checksum="0" * 64,
            statistics=dict.fromkeys(STATISTICS, 0.0),
            validation=None,
            recording=recording,
            id=row_id,
        )

    rows = [
        row("b-run", "aaaa", 10, 1),
        row("b-run", "aaaa", None, 2),
        row("a-run", "ffff", 2, 3),
        row("b-run", "aaaa", 2, 4),
        row("a-run", "ffff", None, 5),
        row("a-run", "0000", None, 6),
    ]
    ordered = [r.uid for r in sorted(rows, key=draw_order)]
    assert ordered == [
        "0000-ml-theta",
        "ffff-ml-theta",
        "ffff-ml-theta-posterior-2",
        "aaaa-ml-theta",
        "aaaa-ml-theta-posterior-2",
        "aaaa-ml-theta-posterior-10",
    ]


# --------------------------------------------------------------------------- round trip


def _fields(row: Any) -> dict[str, Any]:
    """A row's fields as another database holds them: without its row ids, with its
    samples as bytes (the same bits, or not)."""
    out = {}
    for f in dataclasses.fields(row):
        if f.name in ("id", "recording_id"):
            continue
        value = getattr(row, f.name)
        if isinstance(value, np.ndarray):
            value = (value.shape, value.dtype.str, value.tobytes())
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            value = dataclasses.asdict(value)
        out[f.name] = value
    return out


def stored_rows(path: Path) -> dict[str, Any]:
    """Every recording (with samples), identification and trace (with samples) of a
    database, by their identity across databases."""
    with DisturbanceDB(path, create=False) as db:
        return {
            "recordings": {
                r.content_hash: _fields(db.recording_row(r.content_hash)) for r in db.recordings()
            },
            "identifications": {i.key: _fields(i) for i in db.identifications()},
            "traces": {t.uid: _fields(t) for t in db.load_traces(db.traces())},
        }


@pytest.mark.parametrize("fmt", FORMATS)
def test_an_import_holds_every_parameter_trace_and_provenance_of_the_export(
    fmt: str, order_db: Path, tmp_path: Path
) -> None:
    """``db export``'s claim, "import reads it back exactly": recordings and their samples,
    identified parameters, metrics, options, versions and times, every trace's samples,
    source, seed, settings, validation and statistics, row for row."""
    folder, new = tmp_path / "export", tmp_path / "imported.sqlite"
    with DisturbanceDB(order_db, create=False) as db:
        write_export(db, folder, _format(fmt))
    with DisturbanceDB(new, create=True) as db:
        import_export(db, folder)
    before, after = stored_rows(order_db), stored_rows(new)
    # Per recording: 4 fits; their 4 identified traces, 2 surrogates and 4 posterior draws.
    assert [len(before[k]) for k in before] == [3, 12, 30]
    for table in before:
        assert after[table].keys() == before[table].keys(), table
        for key, fields in before[table].items():
            assert after[table][key] == fields, (table, key)
