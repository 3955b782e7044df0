"""``rocketroll db ...`` and ``rocketroll identify --db``: every subcommand and its user errors.

User errors exit with code 2 and print one line on stderr,
``rocketroll db: error: ...``, naming the file or argument, and change nothing.
Tests that change a database work on ``db_copy`` (a private copy of the
session's ``small_db``) or on a new file in ``tmp_path``; only
:func:`test_list_without_db_builds_the_default_database` uses the default
database (``$ROCKETROLL_DB``, a session temporary path set by the root
conftest), and it does not change it once built.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
from contextlib import closing
from pathlib import Path

import pytest

from disturbances.db import DisturbanceDB, package_version
from disturbances.default import default_path
from disturbances.rows import content_hash
from identification.instruments.bundled import BUNDLED, bundled_path, load_bundled
from rocketroll.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SEED0 = "tunnel-paper-seed0"  # in small_db, train split
SEED4 = "tunnel-paper-seed4"  # in small_db, test split
NEW = "tunnel-paper-seed1"  # not in small_db


def ok(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run the CLI, expect success, return stdout."""
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return captured.out


def fails(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """Run the CLI, expect a user error (exit 2, one stderr line), return that line."""
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 2, (captured.out, captured.err)
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert line.startswith(f"rocketroll {argv[0]}: error: "), line
    for needle in needles:
        assert needle in line, line
    return line


def table_rows(out: str) -> list[list[str]]:
    """The rows of a ``db list`` table (after the summary and header lines)."""
    lines = out.splitlines()
    header = next(k for k, line in enumerate(lines) if line.split()[:2] == ["id", "uid"])
    return [line.split() for line in lines[header + 1 :] if line.strip()]


def uid_of(path: Path, **filters: str) -> str:
    with DisturbanceDB(path, create=False) as db:
        (info,) = db.traces(**filters)
        return info.uid


def counts(path: Path) -> dict[str, int]:
    with DisturbanceDB(path, create=False) as db:
        return db.counts()


def broken_recording(path: Path) -> Path:
    """A recording file that fails validation (time goes backwards)."""
    lines = bundled_path(NEW).read_text().splitlines(keepends=True)
    first = next(k for k, line in enumerate(lines) if not line.startswith("#")) + 1
    lines[first + 2], lines[first + 3] = lines[first + 3], lines[first + 2]
    path.write_text("".join(lines))
    return path


def tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root``, relative path -> bytes."""
    return {
        p.relative_to(root).as_posix(): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


# --------------------------------------------------------------------------- build


def test_list_without_db_builds_the_default_database(capsys: pytest.CaptureFixture[str]) -> None:
    path = default_path()
    fresh = not path.exists()  # another test of the session may have built it already
    code = main(["db", "list"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    if fresh:
        assert "building the default disturbance database" in captured.err
    out = captured.out
    assert path.is_file()
    assert out.startswith(f"{path}: {len(BUNDLED)} recordings, ")
    rows = table_rows(out)
    uids = {r[1] for r in rows}
    for name in BUNDLED:
        prefix = content_hash(load_bundled(name).columns())[:12]
        for method in ("paper", "output-error"):
            for model in ("constant", "theta"):
                assert f"{prefix}-{method}-{model}" in uids, name
    splits = [r[3] for r in rows]
    assert splits.count("train") > 0 and splits.count("test") > 0
    assert set(splits) == {"train", "test"}
    with DisturbanceDB(path, create=False) as db:
        assert db.info()["origin"] == "bundled"
        assert len(db.traces(kind="surrogate")) > 0

    # A second build finds it up to date and leaves the file alone.
    before = path.stat().st_mtime_ns, path.read_bytes()
    out = ok(["db", "build"], capsys)
    assert out.strip() == f"{path}: up to date (built by rocketroll {package_version()})"
    assert (path.stat().st_mtime_ns, path.read_bytes()) == before


def short_recording(folder: Path, seed: int) -> Path:
    """A 70-s staircase of the virtual tunnel (a bundled recording is 573 s), written to
    ``folder`` as ``staircase-<seed>.csv``: the methods identify it in a fraction of the
    time, for the tests of what the commands do rather than of what they find."""
    from identification.instruments.tunnel import TunnelSpec, run_tunnel
    from identification.recordings.recording import save_recording

    spec = TunnelSpec(
        seed=seed, schedule="staircase", steps=5, dwell_min=10.0, dwell_max=15.0, lead=5.0
    )
    path = folder / f"staircase-{seed}.csv"
    save_recording(run_tunnel(spec), path)
    return path


def test_build_given_recordings_refuses_plain_rebuild_and_force_replaces(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "given.sqlite"
    recordings = [str(short_recording(tmp_path, seed)) for seed in (0, 4)]
    out = ok(
        ["db", "build", "--db", str(db), *recordings, "--surrogates", "0", "--posterior", "2"],
        capsys,
    )
    # The recipe's three methods (paper, output-error, ml) x two models, 2 draws per ml trace.
    assert out.strip() == (
        f"built {db}: 2 recordings, 12 identifications, 12 traces, 0 surrogates, 8 posterior draws"
    )
    with DisturbanceDB(db, create=False) as d:
        assert [r.name for r in d.recordings()] == [
            "tunnel-staircase-seed0",
            "tunnel-staircase-seed4",
        ]
        assert d.info()["origin"] == "user"
        assert d.counts()["surrogates"] == 0
    before = db.read_bytes()

    # Not a default build: a plain build (bundled recipe) refuses to replace it.
    fails(["db", "build", "--db", str(db)], capsys, str(db), "not a default build", "--force")
    # A recording that fails validation: refused before anything is built.
    bad = broken_recording(tmp_path / "broken.csv")
    fails(["db", "build", "--db", str(db), "--force", str(bad)], capsys, "broken.csv")
    fails(["db", "build", "--db", str(db), "--surrogates", "-1"], capsys, "--surrogates")
    assert db.read_bytes() == before

    # --force replaces it (here with one other recording).
    other = short_recording(tmp_path, 1)
    out = ok(["db", "build", "--db", str(db), "--force", str(other), "--surrogates", "0"], capsys)
    assert out.strip() == (
        f"built {db}: 1 recordings, 6 identifications, 6 traces, 0 surrogates, 16 posterior draws"
    )
    with DisturbanceDB(db, create=False) as d:
        assert [r.name for r in d.recordings()] == ["tunnel-staircase-seed1"]
    # No temporary files of the atomic build are left beside it.
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "broken.csv",
        "given.sqlite",
        *(f"staircase-{seed}.csv" for seed in (0, 1, 4)),
    ]


# --------------------------------------------------------------------------- list


def test_list_filters(small_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = str(small_db)
    rows = table_rows(ok(["db", "list", "--db", db], capsys))
    # 2 recordings x 4 identified traces + 1 IAAFT surrogate per paper trace.
    assert len(rows) == 12
    one = ["--split", "test", "--model", "theta", "--method", "paper", "--kind", "identified"]
    out = ok(["db", "list", "--db", db, *one], capsys)
    assert out.splitlines()[0] == f"{db}: 2 recordings, 8 traces, 4 surrogates; 1 shown"
    (row,) = table_rows(out)
    assert row[1:6] == [
        uid_of(small_db, recording=SEED4, method="paper", model="theta", kind="identified"),
        "identified",
        "test",
        "paper",
        "theta",
    ]

    surrogates = table_rows(ok(["db", "list", "--db", db, "--kind", "surrogate"], capsys))
    assert len(surrogates) == 4 and {r[2] for r in surrogates} == {"iaaft"}
    assert all(r[1].endswith("-iaaft-0") and r[4] == "paper" for r in surrogates)
    oe = table_rows(ok(["db", "list", "--db", db, "--method", "output-error"], capsys))
    assert len(oe) == 4 and {r[4] for r in oe} == {"output-error"}
    by_name = table_rows(ok(["db", "list", "--db", db, "--recording", SEED0], capsys))
    assert len(by_name) == 6 and {r[3] for r in by_name} == {"train"}
    # every fit of the paper's rocket on its own schedule is adequate; a surrogate shows
    # its source's identification's verdict
    good = table_rows(ok(["db", "list", "--db", db, "--verdict", "good"], capsys))
    assert len(good) == 12 and {r[-1] for r in good} == {"good"}
    out = ok(["db", "list", "--db", db, "--verdict", "unreliable"], capsys)
    assert out.splitlines()[0].endswith("; 0 shown")


def test_list_json(small_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = ok(["db", "list", "--db", str(small_db), "--json", "--split", "train"], capsys)
    data = json.loads(out)
    assert len(data) == 6
    fields = {
        "id", "uid", "kind", "source_uid", "seed", "recording", "split", "method", "model",
        "params", "dt_s", "t0_s", "n_samples", "mean_deg", "sd_deg", "q05_deg", "q95_deg",
        "normality_p", "package_version", "created_at",
    }  # fmt: skip
    for item in data:
        assert fields <= set(item)
        assert item["split"] == "train" and item["recording"] == SEED0
        assert set(item["params"]) == {
            "alpha", "theta_bar_deg", "beta_bar_per_s", "alpha_bar_per_deg_s",
            "quadratic_damping",
        }  # fmt: skip
        assert item["dt_s"] == pytest.approx(0.1) and item["n_samples"] > 600
    kinds = sorted(item["kind"] for item in data)
    assert kinds == ["iaaft"] * 2 + ["identified"] * 4
    for item in data:
        if item["kind"] == "iaaft":
            assert item["seed"] == 0 and item["uid"] == f"{item['source_uid']}-iaaft-0"
        else:
            assert item["seed"] is None and item["source_uid"] is None


def test_list_metadata_filter(small_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = str(small_db)
    data = json.loads(ok(["db", "list", "--db", db, "--json", "--meta", "seed=0"], capsys))
    assert len(data) == 6 and {item["recording"] for item in data} == {SEED0}
    both = ["--meta", "seed=4", "--meta", "tunnel.schedule=paper"]
    data = json.loads(ok(["db", "list", "--db", db, "--json", *both], capsys))
    assert {item["recording"] for item in data} == {SEED4}
    assert json.loads(ok(["db", "list", "--db", db, "--json", "--meta", "seed=99"], capsys)) == []
    fails(["db", "list", "--db", db, "--meta", "bad"], capsys, "--meta", "'bad'", "KEY=VALUE")
    fails(["db", "list", "--db", db, "--meta", "=x"], capsys, "--meta")


# --------------------------------------------------------------------------- show


def test_show_by_id_and_uid(small_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = str(small_db)
    with DisturbanceDB(small_db, create=False) as d:
        (info,) = d.traces(recording=SEED0, method="paper", model="theta", kind="identified")
        (ident,) = d.identifications(recording=SEED0, method="paper", model="theta")
    by_id = ok(["db", "show", str(info.id), "--db", db], capsys)
    by_uid = ok(["db", "show", info.uid, "--db", db], capsys)
    assert by_id == by_uid
    assert by_id.startswith(f"trace {info.id}  {info.uid}\n")
    assert f"recording    {SEED0} (synthetic), split train" in by_id
    assert "paper method, theta damping" in by_id
    assert "checksum verified" in by_id
    assert f"α = {ident.params.alpha:.4f}" in by_id and "ᾱ = " in by_id
    assert "re-simulated rate MAE" in by_id
    assert "fit          good: rate R² without u_d 0.9" in by_id

    data = json.loads(ok(["db", "show", info.uid, "--db", db, "--json"], capsys))
    assert data["uid"] == info.uid and data["kind"] == "identified"
    assert data["params"]["alpha"] == ident.params.alpha
    assert data["metrics"]["n_steps"] == ident.metrics["n_steps"]
    assert data["verdict"] == ident.verdict == data["metrics"]["adequacy"]["verdict"] == "good"

    surrogate = f"{info.uid}-iaaft-0"
    out = ok(["db", "show", surrogate, "--db", db], capsys)
    assert f"kind         iaaft of {info.uid} (seed 0)" in out and "checksum verified" in out
    data = json.loads(ok(["db", "show", surrogate, "--db", db, "--json"], capsys))
    assert (data["uid"], data["kind"], data["source_uid"], data["seed"]) == (
        surrogate,
        "iaaft",
        info.uid,
        0,
    )

    fails(["db", "show", "9999", "--db", db], capsys, "no trace 9999")
    fails(["db", "show", "no-such-uid", "--db", db], capsys, "no trace 'no-such-uid'")


@pytest.mark.parametrize("kind", ["identified", "iaaft"])
def test_show_plot(
    kind: str, small_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    uid = uid_of(small_db, recording=SEED4, method="paper", model="constant", kind=kind)
    png = tmp_path / f"{kind}.png"
    out = ok(["db", "show", uid, "--db", str(small_db), "--plot", str(png)], capsys)
    assert out.rstrip().endswith(f"wrote {png}")
    data = png.read_bytes()
    assert data.startswith(PNG_MAGIC) and len(data) > 10_000


# --------------------------------------------------------------------------- add


def test_add_then_add_again(db_copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = counts(db_copy)
    rec = str(bundled_path(NEW))
    out = ok(["db", "add", rec, "--db", str(db_copy), "--mc-runs", "0"], capsys)
    assert out.startswith(f"{db_copy}: added {NEW}: 4 identifications, 4 traces (ids ")
    after = counts(db_copy)
    assert after == {
        "recordings": before["recordings"] + 1,
        "identifications": before["identifications"] + 4,
        "traces": before["traces"] + 4,
        "surrogates": before["surrogates"],
        "posterior": 0,
    }
    with DisturbanceDB(db_copy, create=False) as d:
        idents = d.identifications(recording=NEW)
        assert {(i.method, i.model) for i in idents} == {
            (m, k) for m in ("paper", "output-error") for k in ("constant", "theta")
        }
        assert all(i.options["noise_runs"] == 0 for i in idents)
        assert d.info()["origin"] == "user"

    stored = db_copy.read_bytes()
    out = ok(["db", "add", rec, "--db", str(db_copy), "--mc-runs", "0"], capsys)
    assert "already stored" in out and "nothing added" in out
    assert counts(db_copy) == after
    assert db_copy.read_bytes() == stored


def test_add_invalid_recording_changes_nothing(
    db_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = broken_recording(tmp_path / "broken.csv")
    before = db_copy.read_bytes()
    fails(["db", "add", str(bad), "--db", str(db_copy), "--mc-runs", "0"], capsys, "broken.csv")
    assert db_copy.read_bytes() == before
    # Nor is a missing database created for it.
    new = tmp_path / "new.sqlite"
    fails(["db", "add", str(bad), "--db", str(new)], capsys, "broken.csv")
    assert not new.exists()
    fails(["db", "add", str(tmp_path / "missing.csv"), "--db", str(db_copy)], capsys, "missing.csv")
    assert db_copy.read_bytes() == before


def test_add_with_ar_surrogates(db_copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = str(bundled_path(NEW))
    argv = ["db", "add", rec, "--db", str(db_copy), "--mc-runs", "0", "--method", "paper"]
    out = ok([*argv, "--surrogates", "1", "--surrogate-kind", "ar"], capsys)
    # 2 paper traces and one AR surrogate of each.
    assert f"added {NEW}: 2 identifications, 4 traces" in out
    with DisturbanceDB(db_copy, create=False) as d:
        ar = d.traces(recording=NEW, kind="ar")
        paper = d.traces(recording=NEW, kind="identified")
        assert {i.method for i in paper} == {"paper"}
        assert sorted(i.uid for i in ar) == sorted(f"{i.uid}-ar-0" for i in paper)
        assert all(i.seed == 0 and i.source_uid is not None for i in ar)
        assert d.traces(recording=NEW, kind="iaaft") == []


# --------------------------------------------------------------------------- surrogate


def test_surrogate(db_copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    uid = uid_of(db_copy, recording=SEED0, method="paper", model="theta", kind="identified")
    argv = ["db", "surrogate", uid, "--kind", "iaaft", "--count", "2", "--seed", "5"]
    out = ok([*argv, "--db", str(db_copy)], capsys)
    lines = out.splitlines()
    assert lines[0] == f"added 2 iaaft surrogate(s) of {uid} (0 existed)"
    assert [line.split()[1] for line in lines[1:]] == [f"{uid}-iaaft-5", f"{uid}-iaaft-6"]
    with DisturbanceDB(db_copy, create=False) as d:
        made = d.traces_by_uid([f"{uid}-iaaft-5", f"{uid}-iaaft-6"])
        assert [(i.seed, i.source_uid, i.kind) for i in made] == [
            (5, uid, "iaaft"),
            (6, uid, "iaaft"),
        ]
        stored = d.counts()
    # Again: recognised, nothing duplicated.
    out = ok([*argv, "--db", str(db_copy)], capsys)
    assert out.strip() == f"added 0 iaaft surrogate(s) of {uid} (2 existed)"
    assert counts(db_copy) == stored

    fails(["db", "surrogate", f"{uid}-iaaft-5", "--db", str(db_copy)], capsys, "itself a surrogate")
    fails(["db", "surrogate", uid, "--count", "0", "--db", str(db_copy)], capsys, "--count")
    assert counts(db_copy) == stored


# --------------------------------------------------------------------------- export / import


@pytest.mark.parametrize("fmt", ["csv", "npz", "parquet"])
def test_export_import_export_is_byte_identical(
    fmt: str, db_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    first, second, new = tmp_path / "first", tmp_path / "second", tmp_path / "new.sqlite"
    out = ok(["db", "export", "--format", fmt, "--out", str(first), "--db", str(db_copy)], capsys)
    assert out.strip() == (f"wrote {first}: 12 traces, 8 identifications, 2 recordings ({fmt})")
    out = ok(["db", "import", str(first), "--db", str(new)], capsys)
    assert out.strip() == (
        f"imported {first}: 2 recordings, 8 identifications, 12 traces added; 0 already present"
    )
    assert counts(new) == counts(db_copy)
    ok(["db", "export", "--format", fmt, "--out", str(second), "--db", str(new)], capsys)
    a, b = tree(first), tree(second)
    assert sorted(a) == sorted(b)
    assert "manifest.json" in a and "parameters.json" in a
    for name in a:
        assert a[name] == b[name], name
    # Importing into the database it came from adds nothing.
    out = ok(["db", "import", str(first), "--db", str(db_copy)], capsys)
    assert "0 recordings, 0 identifications, 0 traces added; 22 already present" in out


def test_export_filtered_brings_surrogate_sources(
    db_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = tmp_path / "surrogates"
    argv = ["db", "export", "--format", "npz", "--out", str(out_dir), "--db", str(db_copy)]
    out = ok([*argv, "--split", "test", "--kind", "surrogate"], capsys)
    # 2 surrogates of the test recording, and the 2 traces they were made from.
    assert out.strip() == f"wrote {out_dir}: 4 traces, 2 identifications, 1 recordings (npz)"
    manifest = json.loads((out_dir / "manifest.json").read_text())
    assert manifest["filters"] == {"split": "test", "kind": "surrogate"}
    new = tmp_path / "new.sqlite"
    ok(["db", "import", str(out_dir), "--db", str(new)], capsys)
    assert counts(new) == {
        "recordings": 1,
        "identifications": 2,
        "traces": 2,
        "surrogates": 2,
        "posterior": 0,
    }


def test_export_into_non_empty_folder(
    db_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / "keep.txt").write_text("mine\n")
    argv = ["db", "export", "--format", "csv", "--out", str(out_dir), "--db", str(db_copy)]
    fails(argv, capsys, str(out_dir), "not an empty folder")
    assert tree(out_dir) == {"keep.txt": b"mine\n"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy.sqlite", "out"]
    # No trace matches: nothing is written either.
    empty = tmp_path / "empty"
    argv = ["db", "export", "--format", "csv", "--out", str(empty), "--db", str(db_copy)]
    fails([*argv, "--kind", "ar"], capsys, "no traces match")
    assert not empty.exists()


def _flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def _change_number_keep_manifest(folder: Path, name: str) -> None:
    """Change one sample of a trace CSV and re-sign it in the manifest (a forged export)."""
    path = folder / name
    lines = path.read_text().splitlines(keepends=True)
    lines[5] = repr(float(lines[5]) + 1.0) + "\n"
    path.write_text("".join(lines))
    manifest_path = folder / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["files"][name] = hashlib.sha256(path.read_bytes()).hexdigest()
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")


@pytest.mark.parametrize(
    ("fmt", "tamper"),
    [("csv", "flip"), ("npz", "flip"), ("parquet", "flip"), ("csv", "forge")],
)
def test_import_altered_export_is_refused(
    fmt: str, tamper: str, db_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "export"
    ok(["db", "export", "--format", fmt, "--out", str(folder), "--db", str(db_copy)], capsys)
    uid = uid_of(db_copy, recording=SEED0, method="paper", model="theta", kind="identified")
    name = f"traces/{uid}.csv" if fmt == "csv" else f"traces.{fmt}"
    if tamper == "flip":
        _flip_byte(folder / name)
        needles: tuple[str, ...] = (str(folder / name), "SHA-256")
    else:
        _change_number_keep_manifest(folder, name)
        needles = (str(folder), uid, "checksum")

    new = tmp_path / "new.sqlite"
    fails(["db", "import", str(folder), "--db", str(new)], capsys, *needles)
    assert not new.exists()
    before = db_copy.read_bytes()
    fails(["db", "import", str(folder), "--db", str(db_copy)], capsys, *needles)
    assert db_copy.read_bytes() == before


@pytest.mark.parametrize("fmt", ["csv", "npz"])
def test_import_of_an_export_missing_a_recording_is_refused(
    fmt: str, db_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A consistently re-signed export that leaves out a recording its rows refer to."""
    folder = tmp_path / "export"
    ok(["db", "export", "--format", fmt, "--out", str(folder), "--db", str(db_copy)], capsys)
    params_path = folder / "parameters.json"
    params = json.loads(params_path.read_text())
    dropped = params["recordings"].pop(0)
    params_path.write_text(json.dumps(params, indent=2) + "\n")
    manifest_path = folder / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["files"]["parameters.json"] = hashlib.sha256(params_path.read_bytes()).hexdigest()
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    new = tmp_path / "new.sqlite"
    line = fails(["db", "import", str(folder), "--db", str(new)], capsys, str(folder))
    assert "disagree" in line or dropped["content_hash"][:12] in line
    assert not new.exists()


def test_bad_counts_and_seeds_are_usage_errors(
    db_copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = db_copy.read_bytes()
    rec = str(bundled_path(NEW))
    fails(["db", "add", rec, "--db", str(db_copy), "--surrogates", "-1"], capsys, "--surrogates")
    fails(
        ["db", "add", rec, "--db", str(db_copy), "--surrogate-kind", "ar"],
        capsys,
        "--surrogate-kind needs --surrogates",
    )
    uid = uid_of(db_copy, recording=SEED0, method="paper", model="theta", kind="identified")
    fails(["db", "surrogate", uid, "--db", str(db_copy), "--seed", "-1"], capsys, "--seed")
    assert db_copy.read_bytes() == before


def test_import_not_an_export(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    new = tmp_path / "new.sqlite"
    fails(["db", "import", str(tmp_path), "--db", str(new)], capsys, "manifest.json", "missing")
    assert not new.exists()


# --------------------------------------------------------------------------- identify --db


def test_identify_stores_in_database(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """What identify prints is what it stores: each method runs once, not again to store."""
    import identification.methods as methods

    judged: list[str] = []  # every tunnel fit made is judged once, as it is made
    judge = methods.with_adequacy

    def counted(found: methods.ModelFit, context: methods.Context) -> methods.ModelFit:
        judged.append(found.method)
        return judge(found, context)

    monkeypatch.setattr(methods, "with_adequacy", counted)
    db = tmp_path / "identified.sqlite"
    argv = ["identify", str(bundled_path(NEW)), "--db", str(db), "--mc-runs", "0"]
    out = ok(argv, capsys)
    assert sorted(judged) == ["output-error", "output-error", "paper", "paper"]
    stored_line = f"stored in {db}: 4 identifications, 4 traces (ids 1, 2, 3, 4)"
    assert stored_line in out.splitlines()
    assert out.index("\nparameter") < out.index(stored_line)  # after the usual table
    with DisturbanceDB(db, create=False) as d:
        idents = d.identifications(recording=NEW)
        assert sorted((i.method, i.model) for i in idents) == [
            ("output-error", "constant"),
            ("output-error", "theta"),
            ("paper", "constant"),
            ("paper", "theta"),
        ]
        assert len(d.traces(recording=NEW, kind="identified")) == 4
        stored = d.counts()
    out = ok(argv, capsys)
    assert f"{db}: this recording is already stored" in out and "stored in" not in out
    assert counts(db) == stored


# --------------------------------------------------------------------------- opening errors


def test_opening_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a database at all, but long enough to have a header " * 4)
    fails(["db", "list", "--db", str(text)], capsys, str(text), "not an SQLite database")
    assert text.read_text().startswith("not a database")

    missing = tmp_path / "missing.sqlite"
    fails(["db", "list", "--db", str(missing)], capsys, str(missing), "no such database")
    fails(["db", "show", "1", "--db", str(missing)], capsys, "no such database")
    assert not missing.exists()

    other = tmp_path / "other.sqlite"
    with closing(sqlite3.connect(other)) as conn:
        conn.execute("CREATE TABLE t (x)")
        conn.commit()
    fails(
        ["db", "list", "--db", str(other)],
        capsys,
        str(other),
        "not a rocketroll disturbance database",
    )


def test_failed_identification_into_a_new_database_leaves_no_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import numpy as np

    from identification.recordings.recording import Recording, save_recording

    t = np.arange(0, 60, 0.1)
    one_step = Recording(
        name="one-step",
        source="wind-tunnel",
        time_s=t,
        fin_cmd_deg=np.where(t < 30, 0.0, 10.0),
        roll_deg=3.0 * t,
    )
    rec = tmp_path / "one-step.csv"
    save_recording(one_step, rec)
    new = tmp_path / "new.sqlite"
    fails(["db", "add", str(rec), "--db", str(new), "--mc-runs", "0"], capsys, "fin step")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one-step.csv"]


def test_the_identification_layer_imports_nothing_above_it() -> None:
    import subprocess
    import sys

    code = (
        "import sys, identification.cli, identification.methods.pipeline,"
        " identification.reports.report\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('disturbances', 'rollenv', 'agents', 'rocketroll')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_build_over_a_file_that_is_not_a_database_is_refused_even_with_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "notes.sqlite"
    path.write_text("not a database\n")
    for force in ([], ["--force"]):
        fails(["db", "build", "--db", str(path), *force], capsys, str(path), "not an SQLite")
    assert path.read_text() == "not a database\n"


def test_fit_quadratic_damping_without_ml_is_one_clear_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The term is searched by the ml method only: asked for without it, identify and
    db add say so, and write nothing."""
    path = bundled_path(NEW)
    fails(["identify", str(path), "--method", "paper", "--fit-quadratic-damping"], capsys,
          "--fit-quadratic-damping", "add --method ml")  # fmt: skip
    db = tmp_path / "q.sqlite"
    fails(["db", "add", str(path), "--db", str(db), "--method", "paper",
           "--fit-quadratic-damping"], capsys, "--fit-quadratic-damping")  # fmt: skip
    assert not db.exists()
