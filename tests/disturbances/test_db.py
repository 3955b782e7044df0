"""``DisturbanceDB``: what it stores, atomicity, concurrency, damage and versions."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from disturbances import default as default_db
from disturbances.db import DatabaseError, DisturbanceDB
from disturbances.ingest import add_recording
from disturbances.rows import TEST_FRACTION, RecordingRow, checksum, content_hash, split_of
from identification.instruments.bundled import bundled_path, load_bundled
from identification.methods import METHODS, register_method
from identification.methods.pipeline import identify
from identification.methods.steps import IdentificationError
from identification.recordings.recording import Recording
from rocketroll_common import numerics
from tests.disturbances.conftest import FAST, SMALL

REPO = Path(__file__).resolve().parents[2]


def file_digest(path: Path) -> str:
    """SHA-256 of a database file once every connection is closed (WAL folded in)."""
    assert not Path(f"{path}-wal").exists(), "a connection is still open"
    return hashlib.sha256(path.read_bytes()).hexdigest()


def one_step_recording() -> Recording:
    """Valid as a recording, but with a single fin step: identification must fail."""
    t = np.arange(0, 60, 0.1)
    fin = np.where(t < 30, 0.0, 10.0)
    return Recording(
        name="one-step", source="wind-tunnel", time_s=t, fin_cmd_deg=fin, roll_deg=3.0 * t
    )


# --------------------------------------------------------------------------- contents


def test_add_recording_stores_every_result(tmp_path: Path) -> None:
    rec = load_bundled("tunnel-paper-seed0")
    with DisturbanceDB(tmp_path / "db.sqlite") as db:
        added = add_recording(db, rec, FAST)
        assert (added.recordings, added.identifications, added.traces) == (1, 4, 4)
        expected = identify(rec, FAST)
        for model in ("constant", "theta"):
            (info,) = db.traces(method="paper", model=model)
            trace = db.trace(info.uid)
            # Stored exactly: same bits as the pipeline's trace and parameters.
            np.testing.assert_array_equal(trace.u_d_deg, expected.disturbances[model].u_d_deg)
            assert trace.params == expected.model(model)
            assert trace.dt_s == 0.1 and info.t0_s == 0.0
            assert info.kind == "identified" and info.source_uid is None
            assert info.mean_deg == pytest.approx(float(np.mean(trace.samples())))
            assert info.q05_deg < 0 < info.q95_deg
            assert 0 <= (info.normality_p or 0) <= 1
        (oe,) = db.traces(method="output-error", model="theta")
        assert oe.params != expected.theta_model  # the peer's own fit
        idents = {(i.method, i.model): i for i in db.identifications()}
        assert set(idents) == {
            (m, k) for m in ("paper", "output-error") for k in ("constant", "theta")
        }
        paper = idents["paper", "theta"]
        assert paper.metrics["steady_state_r2"] == pytest.approx(expected.steady.r_squared)
        assert paper.metrics["resim_angle_mae_deg"] < 0.5
        assert idents["output-error", "constant"].metrics["converged"] is True
        assert paper.options["noise_runs"] == 0
        assert paper.package_version == db.created_by
        # The raw samples come back exactly, with name, source and metadata.
        back = db.recording("tunnel-paper-seed0")
        for column, values in rec.columns().items():
            np.testing.assert_array_equal(back.columns()[column], values)
        assert dict(back.metadata) == dict(rec.metadata)


def test_same_samples_are_recognised_not_duplicated(tmp_path: Path) -> None:
    rec = load_bundled("tunnel-paper-seed0")
    renamed = dataclasses.replace(rec, name="same-data-other-name")
    with DisturbanceDB(tmp_path / "db.sqlite") as db:
        add_recording(db, rec, FAST)
        before = db.counts()
        again = add_recording(db, renamed, FAST)
        assert (again.recordings, again.traces, again.skipped) == (0, 0, 1)
        assert db.counts() == before


def test_surrogates_are_linked_to_their_source_and_validated(small_db: Path) -> None:
    with DisturbanceDB(small_db, create=False) as db:
        surrogates = db.traces(kind="surrogate")
        assert surrogates and all(s.kind == "iaaft" for s in surrogates)
        for s in surrogates:
            source = db.trace(s.source_uid or "")
            assert source.kind == "identified" and source.method == "paper"
            assert (s.split, s.model, s.params) == (
                source.split,
                source.model,
                source.params,
            )
            trace = db.trace(s.uid)
            # IAAFT keeps the amplitude distribution exactly.
            np.testing.assert_array_equal(np.sort(trace.samples()), np.sort(source.samples()))
            assert not np.array_equal(trace.samples(), source.samples())
        row = db.trace(surrogates[0].uid)
        assert row.validation is not None and row.validation["passed"] is True


def test_adding_again_fills_in_only_the_missing_methods(tmp_path: Path) -> None:
    rec = load_bundled("tunnel-paper-seed0")
    with DisturbanceDB(tmp_path / "db.sqlite") as db:
        add_recording(db, rec, FAST, methods=("paper",))
        paper = [t.uid for t in db.traces()]
        more = add_recording(db, rec, FAST)  # now with the output-error peer too
        assert (more.recordings, more.identifications, more.traces) == (0, 2, 2)
        assert [t.uid for t in db.traces(method="paper")] == paper
        assert len(db.recordings()) == 1
        assert add_recording(db, rec, FAST).skipped == 1


# --------------------------------------------------------------------------- split


def test_split_is_a_function_of_content_and_declared_split_wins(tmp_path: Path) -> None:
    rec = load_bundled("tunnel-paper-seed1")
    h = content_hash(rec.columns())
    assert split_of(h) == split_of(h)
    hashes = [f"{i:064x}" for i in range(4000)]
    share = np.mean([split_of(x) == "test" for x in hashes])
    assert share == pytest.approx(TEST_FRACTION, abs=0.03)
    declared = dataclasses.replace(rec, metadata={**rec.metadata, "split": "test"})
    assert RecordingRow.of(declared, "").split == "test"
    assert RecordingRow.of(rec, "").split == split_of(h)
    # A recording keeps its split whatever else the database holds.
    with DisturbanceDB(tmp_path / "a.sqlite") as a, DisturbanceDB(tmp_path / "b.sqlite") as b:
        add_recording(a, rec, FAST, methods=("paper",))
        add_recording(b, load_bundled("tunnel-paper-seed4"), FAST, methods=("paper",))
        add_recording(b, rec, FAST, methods=("paper",))
        split_a = {t.split for t in a.traces()}
        split_b = {t.split for t in b.traces(recording=rec.name)}
        assert len(split_a) == 1 and split_a == split_b


def test_every_trace_of_a_recording_shares_its_split(small_db: Path) -> None:
    with DisturbanceDB(small_db, create=False) as db:
        by_recording: dict[str, set[str]] = {}
        for info in db.traces():
            by_recording.setdefault(info.recording_hash, set()).add(info.split)
        assert all(len(s) == 1 for s in by_recording.values())
        assert {s for v in by_recording.values() for s in v} == {"train", "test"}


# --------------------------------------------------------------------------- queries


def test_queries_filter_and_reject_unknown_filters(small_db: Path) -> None:
    with DisturbanceDB(small_db, create=False) as db:
        test = db.traces(split="test", method="paper", model="theta", kind="identified")
        assert len(test) == 1 and test[0].recording == "tunnel-paper-seed4"
        assert {t.kind for t in db.traces(kind="surrogate")} == {"iaaft"}
        assert db.traces(kind=["identified", "iaaft"]) == db.traces()
        assert len(db.traces(metadata={"seed": "0"})) == len(
            db.traces(recording="tunnel-paper-seed0")
        )
        assert db.traces(metadata={"seed": "999"}) == []
        assert db.traces(source="flight") == []
        assert len(db.traces(min_duration_s=500)) == len(db.traces())
        with pytest.raises(ValueError, match="unknown filter 'colour'"):
            db.traces(colour="red")
        with pytest.raises(ValueError, match="split='validation'"):
            db.traces(split="validation")
        with pytest.raises(DatabaseError, match="no trace 'nope'"):
            db.trace("nope")


# --------------------------------------------------------------------------- atomicity


def test_failed_identification_leaves_the_file_byte_for_byte(db_copy: Path) -> None:
    before = file_digest(db_copy)
    with DisturbanceDB(db_copy, create=False) as db, pytest.raises(IdentificationError):
        add_recording(db, one_step_recording(), FAST)
    assert file_digest(db_copy) == before


def test_failure_inside_the_transaction_rolls_everything_back(
    db_copy: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = file_digest(db_copy)
    original = DisturbanceDB._insert_trace
    calls = []

    def fail_on_third(self: DisturbanceDB, *args: object) -> int:
        calls.append(1)
        if len(calls) == 3:
            raise OSError("disk full (simulated)")
        return original(self, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(DisturbanceDB, "_insert_trace", fail_on_third)
    with DisturbanceDB(db_copy, create=False) as db:
        with pytest.raises(OSError, match="simulated"):
            add_recording(db, load_bundled("tunnel-paper-seed1"), FAST)
        # Rows of the recording and its identifications went with the rollback.
        assert [r.name for r in db.recordings()] == list(SMALL)
    assert len(calls) == 3
    assert file_digest(db_copy) == before


WRITER = textwrap.dedent(
    """
    import sys, time
    from disturbances.db import DisturbanceDB
    from disturbances.ingest import add_recording
    from identification.instruments.bundled import load_bundled
    from identification.methods.pipeline import IdentifyOptions

    fast = IdentifyOptions(noise_runs=0)
    db = DisturbanceDB(sys.argv[1], create=False)
    add_recording(db, load_bundled("tunnel-paper-seed1"), fast, methods=("paper",))
    print("committed", flush=True)
    original = DisturbanceDB._insert_trace

    def slow(self, *args):
        result = original(self, *args)
        print("inside", flush=True)
        time.sleep(60)
        return result

    DisturbanceDB._insert_trace = slow
    add_recording(db, load_bundled("tunnel-paper-seed2"), fast, methods=("paper",))
    print("finished", flush=True)
    """
)


def start_writer(path: Path) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
    )


def stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=30)
    if proc.stdout is not None:
        proc.stdout.close()


def wait_for(proc: subprocess.Popen[str], word: str) -> None:
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()
    assert line == word, f"writer said {line!r}, expected {word!r}"


def test_killed_writer_loses_nothing_committed(db_copy: Path) -> None:
    proc = start_writer(db_copy)
    try:
        wait_for(proc, "committed")
        wait_for(proc, "inside")  # mid-transaction, one trace row written
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        stop(proc)
    assert proc.returncode == -signal.SIGKILL
    with DisturbanceDB(db_copy, create=False) as db:
        names = [r.name for r in db.recordings()]
        assert names == [*SMALL, "tunnel-paper-seed1"]  # committed one kept, killed one gone
        assert len(db.traces(recording="tunnel-paper-seed1")) == 2
        assert db.traces(recording="tunnel-paper-seed2") == []
        with db._errors():
            assert db._conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        for info in db.traces():
            db.trace(info.uid)  # every checksum still holds


def test_a_reader_queries_while_another_process_writes(db_copy: Path) -> None:
    with DisturbanceDB(db_copy, create=False) as db:
        n_before = len(db.traces())
    proc = start_writer(db_copy)
    try:
        wait_for(proc, "committed")
        wait_for(proc, "inside")  # the writer now holds an open write transaction
        start = time.perf_counter()
        with DisturbanceDB(db_copy, create=False) as reader:
            infos = reader.traces()
            arrays = reader.load_traces(infos)
        waited = time.perf_counter() - start
        # The reader sees the committed recording, not the one being written, and is
        # not blocked by the writer (which sleeps for a minute inside its transaction).
        assert len(infos) == n_before + 2
        assert {i.recording for i in infos} == {*SMALL, "tunnel-paper-seed1"}
        assert len(arrays) == len(infos)
        assert waited < 30
        assert proc.poll() is None  # the writer was still inside its transaction
    finally:
        stop(proc)


# --------------------------------------------------------------------------- bad files


def test_newer_schema_is_refused_with_a_clear_error(db_copy: Path) -> None:
    conn = sqlite3.connect(db_copy)
    conn.execute("PRAGMA user_version = 7")
    conn.close()
    with pytest.raises(DatabaseError, match=r"schema version 7 is newer .* upgrade rocketroll"):
        DisturbanceDB(db_copy, create=False)


def test_a_file_that_is_not_a_database(tmp_path: Path) -> None:
    path = tmp_path / "notes.sqlite"
    path.write_text("time_s,fin_cmd_deg\n0,1\n" * 20)
    with pytest.raises(DatabaseError, match=f"{path.name}: not an SQLite database"):
        DisturbanceDB(path)
    assert path.read_text().startswith("time_s")  # untouched


def test_another_applications_sqlite_file(tmp_path: Path) -> None:
    path = tmp_path / "other.sqlite"
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE things (x)")
    conn.commit()
    conn.close()
    with pytest.raises(DatabaseError, match=r"not a rocketroll disturbance database.*things"):
        DisturbanceDB(path)


def test_a_truncated_database(db_copy: Path) -> None:
    data = db_copy.read_bytes()
    assert len(data) > 8192
    db_copy.write_bytes(data[: len(data) // 2])
    with pytest.raises(DatabaseError, match="truncated"):
        DisturbanceDB(db_copy, create=False)


def test_a_missing_database_is_not_created_when_reading(tmp_path: Path) -> None:
    with pytest.raises(DatabaseError, match="no such database"):
        DisturbanceDB(tmp_path / "missing.sqlite", create=False)
    assert not (tmp_path / "missing.sqlite").exists()


def test_altered_trace_bytes_are_caught_by_the_checksum(db_copy: Path) -> None:
    with DisturbanceDB(db_copy, create=False) as db:
        info = db.traces(method="paper", model="theta", split="train", kind="identified")[0]
    conn = sqlite3.connect(db_copy)
    (blob,) = conn.execute("SELECT samples FROM traces WHERE id = ?", (info.id,)).fetchone()
    altered = bytearray(blob)
    altered[800] ^= 0x01  # one bit of one sample
    conn.execute("UPDATE traces SET samples = ? WHERE id = ?", (bytes(altered), info.id))
    conn.commit()
    conn.close()
    with DisturbanceDB(db_copy, create=False) as db:
        with pytest.raises(DatabaseError, match=f"trace {info.uid} is corrupt"):
            db.trace(info.uid)
        with pytest.raises(DatabaseError, match="corrupt"):
            db.load_traces(db.traces(split="train"))
        other = db.traces(split="test")[0]
        assert checksum(db.trace(other.uid).samples())  # the others still read


# --------------------------------------------------------------------------- versions


def mark_old(path: Path, version: str = "0.0.1") -> None:
    conn = sqlite3.connect(path)
    conn.execute("UPDATE identifications SET package_version = ?", (version,))
    conn.execute("UPDATE info SET value = ? WHERE key = 'created_by'", (version,))
    conn.commit()
    conn.close()


def test_another_versions_database_is_said_so_and_never_mixed(db_copy: Path) -> None:
    mark_old(db_copy)
    before = file_digest(db_copy)
    with DisturbanceDB(db_copy, create=False) as db:
        with pytest.warns(UserWarning, match=r"rocketroll 0\.0\.1; this is"):
            db.check_version()
        with pytest.raises(DatabaseError, match="would mix two versions"):
            add_recording(db, load_bundled("tunnel-paper-seed1"), FAST)
    assert file_digest(db_copy) == before


def test_default_database_is_rebuilt_when_built_by_another_version(
    db_copy: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = tmp_path / "default.sqlite"
    db_copy.rename(path)
    mark_old(path)
    with DisturbanceDB(path, create=False) as db:
        db.set_info({"origin": "bundled", "fingerprint": "made-by-an-old-version"})
    monkeypatch.setenv("ROCKETROLL_DB", str(path))
    built: list[Path] = []

    def fake_build(target: Path, progress: bool) -> None:
        # What open_default runs under the folder's build lock, here in this process.
        built.append(Path(target))
        default_db._build(
            target, [bundled_path("tunnel-paper-seed0")], FAST, 0, ("iaaft",), 0, False
        )

    monkeypatch.setattr(default_db, "_build_default", fake_build)
    with default_db.open_default(progress=False) as db:
        assert db.versions() == [db.created_by]  # nothing of 0.0.1 left
    assert built == [path]
    assert "built by rocketroll 0.0.1" in capsys.readouterr().err

    # A database a user added to is not rebuilt; it says so instead.
    mark_old(path)
    with DisturbanceDB(path, create=False) as db:
        assert db.info()["origin"] == "user"
    with pytest.warns(UserWarning, match="0.0.1"):
        default_db.open_default(progress=False).close()
    assert built == [path]


def test_a_build_is_pinned_and_its_fingerprint_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A database built as before (in the caller's process, its numerics as the machine has
    them) is not the default recipe: an old default database is rebuilt, not trusted."""
    if numerics.pinned_environment() is None:
        pytest.skip(
            "the numerics are pinned only on x86-64 Linux with AVX2 and FMA, and not with "
            "ROCKETROLL_NUMERICS=unpinned"
        )
    files = [bundled_path("tunnel-paper-seed0")]
    pinned = default_db.fingerprint(files, FAST, 0, ("iaaft",), 0, ["paper"], pinned=True)
    found = default_db.fingerprint(files, FAST, 0, ("iaaft",), 0, ["paper"], pinned=False)
    assert pinned != found
    assert default_db.fingerprint(files, FAST, 0, ("iaaft",), 0, ["paper"]) == pinned
    # A method registered here that the build does not run, and that no new process could
    # be given (a lambda), does not keep the build from its pinned process.
    register_method("local", lambda context, models: [], summary="not picklable")
    try:
        path = default_db.build_database(
            tmp_path / "db.sqlite", files, options=FAST, surrogates=0, methods=["paper"]
        )
    finally:
        METHODS.unregister("local")
    with DisturbanceDB(path, create=False) as db:
        assert db.info()["fingerprint"] == pinned
    # Built in this process instead, its fingerprint says that.
    monkeypatch.setattr(default_db, "call_pinned", lambda f, *args: f(*args))
    path = default_db.build_database(
        tmp_path / "here.sqlite", files, options=FAST, surrogates=0, methods=["paper"]
    )
    with DisturbanceDB(path, create=False) as db:
        assert db.info()["fingerprint"] == found
    assert "flight" in METHODS  # the build's registry merged, nothing of this one lost


def test_default_build_is_atomic_and_marked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "db.sqlite"
    path.write_bytes(b"")  # an existing (empty) target is replaced only when the build is done
    monkeypatch.setenv(numerics.MARKER, "pinned")  # built in this process, where the patch is
    monkeypatch.setattr(
        "disturbances.default.add_recording",
        lambda *a, **k: (_ for _ in ()).throw(RuntimeError("interrupted")),
    )
    with pytest.raises(RuntimeError, match="interrupted"):
        default_db.build_database(path, [bundled_path("tunnel-paper-seed0")], options=FAST)
    assert path.read_bytes() == b""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["db.sqlite"]  # no leftovers


def test_info_records_the_recipe(small_db: Path) -> None:
    with DisturbanceDB(small_db, create=False) as db:
        info = db.info()
    assert info["origin"] == "user"  # not the default recipe: never rebuilt silently
    assert json.loads(info["recordings"]) == [f"{n}.csv" for n in SMALL]
    assert len(info["fingerprint"]) == 64


# --------------------------------------------------------------------------- review findings


def test_adding_again_never_pairs_a_surrogate_with_a_new_twin(tmp_path: Path) -> None:
    rec = load_bundled("tunnel-paper-seed0")
    with DisturbanceDB(tmp_path / "db.sqlite") as db:
        add_recording(db, rec, FAST, methods=("paper",))
        before = file_digest_open(db)
        other = dataclasses.replace(FAST, ud_interval_s=0.2)
        with pytest.raises(DatabaseError, match="stored with other identification options"):
            add_recording(db, rec, other, surrogates=1)
        assert file_digest_open(db) == before
        # With the same options, surrogates come from the stored traces.
        added = add_recording(db, rec, FAST, surrogates=1)
        assert added.identifications == 2  # the output-error peer was missing
        for info in db.traces(kind="iaaft"):
            source = db.trace(info.source_uid or "")
            trace = db.trace(info.uid)
            assert trace.dt_s == source.dt_s
            np.testing.assert_array_equal(np.sort(trace.samples()), np.sort(source.samples()))
        # Everything stored: asking for more surrogates makes only those.
        more = add_recording(db, rec, FAST, surrogates=2)
        assert (more.recordings, more.identifications, more.traces) == (0, 0, 2)


def file_digest_open(db: DisturbanceDB) -> list[tuple[object, ...]]:
    """The rows of every table (a database that is still open cannot be hashed as a file)."""
    out: list[tuple[object, ...]] = []
    for table in ("recordings", "identifications", "traces", "info"):
        out += [tuple(r) for r in db._query(f"SELECT * FROM {table} ORDER BY 1")]
    return out


CREATOR = textwrap.dedent(
    """
    import sys
    from disturbances.db import DisturbanceDB
    with DisturbanceDB(sys.argv[1]) as db:
        print(db.counts()["recordings"], flush=True)
    """
)


def test_processes_creating_one_new_database_at_once(tmp_path: Path) -> None:
    path = tmp_path / "new.sqlite"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", CREATOR, str(path)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for _ in range(4)
    ]
    results = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0, 0], results
    assert [out.strip() for out, _ in results] == ["0"] * 4
    with DisturbanceDB(path, create=False) as db:
        assert db.counts()["recordings"] == 0


def test_an_empty_file_is_not_taken_for_a_database_when_reading(tmp_path: Path) -> None:
    path = tmp_path / "empty.sqlite"
    path.write_bytes(b"")
    with pytest.raises(DatabaseError, match="is empty, not a database"):
        DisturbanceDB(path, create=False)
    assert path.read_bytes() == b""


def test_validated_filter_separates_failed_surrogates(db_copy: Path) -> None:
    with DisturbanceDB(db_copy, create=False) as db:
        (uid,) = [t.uid for t in db.traces(kind="iaaft", split="train", model="theta")]
    conn = sqlite3.connect(db_copy)
    validation = json.loads(
        conn.execute("SELECT validation FROM traces WHERE uid = ?", (uid,)).fetchone()[0]
    )
    validation["passed"] = False
    conn.execute("UPDATE traces SET validation = ? WHERE uid = ?", (json.dumps(validation), uid))
    conn.commit()
    conn.close()
    with DisturbanceDB(db_copy, create=False) as db:
        assert [t.uid for t in db.traces(validated=False)] == [uid]
        good = db.traces(validated=True)
        assert uid not in {t.uid for t in good} and len(good) == len(db.traces()) - 1


def test_import_refuses_to_mix_versions(db_copy: Path, tmp_path: Path) -> None:
    from disturbances.exchange import ExchangeError, import_export, write_export

    with DisturbanceDB(db_copy, create=False) as db:
        write_export(db, tmp_path / "export", "npz", split="test")
    mark_old(db_copy)
    target = tmp_path / "target.sqlite"
    with DisturbanceDB(target) as db:
        add_recording(db, load_bundled("tunnel-paper-seed1"), FAST, methods=("paper",))
        mark_old(target)  # the target now holds 0.0.1 results only
    before = file_digest(target)
    with DisturbanceDB(target, create=False) as db, pytest.raises(ExchangeError, match="mix"):
        import_export(db, tmp_path / "export")
    assert file_digest(target) == before
