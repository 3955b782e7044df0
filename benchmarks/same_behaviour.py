"""The same behaviour before and after a restructuring: snapshots of what the commands
compute, and their comparison.

A restructuring of the identification (one estimation core under ``ml`` and
``flight``, modules moved into sub-packages) must leave every result as it was.
``snapshot OUT`` runs, in this checkout, the commands whose results say so and
keeps what they wrote in ``OUT`` (a new folder):

* ``rocketroll identify --json`` by the paper's method, output error and ml on
  every bundled recording (``--quick``: the first one only);
* five virtual flights (``record-flight --seed 0..4``) identified by the flight
  method, and the first two fitted together (``--together``);
* a 100-Hz virtual-tunnel log with a measured fin and a linkage, a latency and
  a quadratic damping outside the model, through every tunnel method with
  ``--actuation --fit-quadratic-damping``;
* the default database built from the bundled recordings: the SHA-256 of its
  content, every row of every table but the times it was made (``info``'s
  ``created_at`` and the rows' ``*_at`` columns: two builds of one commit
  differ in those alone).

``compare A B`` reads two snapshots (say, one of ``main`` and one of a branch)
and compares every JSON file leaf by leaf: the same keys and strings, the same
integers, and every other number within ``--rtol`` (default 1e-9) relative; the
databases' content digests equal.  It prints each difference and a summary, and exits
0 when the two are the same, 1 when they differ, 2 on bad input.

Run from the repository root::

    .venv/bin/python benchmarks/same_behaviour.py snapshot runs/before
    git switch my-branch
    .venv/bin/python benchmarks/same_behaviour.py snapshot runs/after
    .venv/bin/python benchmarks/same_behaviour.py compare runs/before runs/after
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
BUNDLED = REPO / "identification" / "data"
TUNNEL_METHODS = ("paper", "output-error", "ml")
FLIGHT_SEEDS = range(5)
MANIFEST = "snapshot.json"


def _refuse(message: str) -> None:
    print(f"same_behaviour.py: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _git_commit() -> str:
    done = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True, check=False
    )
    return done.stdout.strip() or "unknown"


class _Runner:
    """Runs ``python -m rocketroll`` in ``out`` with the default database there."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.env = {**os.environ, "ROCKETROLL_DB": str(out / "default.sqlite")}
        self.commands: list[list[str]] = []

    def __call__(self, *argv: str | Path) -> None:
        words = [str(a) for a in argv]
        began = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "rocketroll", *words],
            cwd=self.out,
            env=self.env,
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:] or ["(no message)"]
            _refuse(f"`rocketroll {' '.join(words)}` failed ({done.returncode}): {tail[0]}")
        self.commands.append(words)
        print(f"  {time.perf_counter() - began:6.1f} s  rocketroll {' '.join(words)}", flush=True)


def snapshot(out: Path, quick: bool) -> None:
    """Run the commands in ``out`` (a new folder) and write its manifest."""
    if out.exists():
        _refuse(f"{out}: exists; a snapshot goes into a new folder")
    recordings = sorted(BUNDLED.glob("*.csv"))
    if not recordings:
        _refuse(f"{BUNDLED}: no bundled recordings")
    if quick:
        recordings = recordings[:1]
    out.mkdir(parents=True)
    run = _Runner(out.resolve())
    print(f"snapshot of {_git_commit()[:12]} into {out}:", flush=True)
    methods = [f"--method={m}" for m in TUNNEL_METHODS]
    for recording in recordings:
        run("identify", recording, *methods, "--json", f"identify-{recording.stem}.json")
    seeds = FLIGHT_SEEDS[:1] if quick else FLIGHT_SEEDS
    for seed in seeds:
        run("record-flight", "--seed", str(seed), "--out", f"flight-seed{seed}.csv")
        run("identify", f"flight-seed{seed}.csv", "--json", f"flight-seed{seed}.json")
    if not quick:
        together = ["--together", "flight-seed1.csv", "--json", "flight-together.json"]
        run("identify", "flight-seed0.csv", *together)
    run(
        "tunnel",
        "--seed=7",
        "--schedule=staircase",
        "--log-dt=0.01",
        "--measured-fin",
        "--servo-lag=0.03",
        "--backlash=0.4",
        "--sensor-latency=0.02",
        "--quadratic-damping=0.5",
        "--out=log-100hz.csv",
    )
    run(
        "identify",
        "log-100hz.csv",
        *methods,
        "--actuation",
        "--fit-quadratic-damping",
        "--json",
        "log-100hz.json",
    )
    run("db", "list")  # builds the default database
    manifest = {
        "commit": _git_commit(),
        "quick": quick,
        "commands": run.commands,
        "default_database_content_sha256": content_digest(out / "default.sqlite"),
    }
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {out / MANIFEST}")


def content_digest(database: Path) -> str:
    """SHA-256 of a database's content: every table's columns and rows (in key order),
    less the times of creation (``info.created_at``, the ``*_at`` columns)."""
    digest = hashlib.sha256()
    connection = sqlite3.connect(f"{database.resolve().as_uri()}?mode=ro", uri=True)
    try:
        tables = connection.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name"
        ).fetchall()
        for (table,) in tables:
            info = connection.execute(f"PRAGMA table_info({table})").fetchall()
            columns = [row[1] for row in info if not row[1].endswith("_at")]
            keys = [row[1] for row in sorted(info, key=lambda r: r[5]) if row[5]] or columns
            rows = connection.execute(
                f"SELECT {', '.join(columns)} FROM {table} ORDER BY {', '.join(keys)}"
            ).fetchall()
            if table == "info":
                rows = [row for row in rows if row[0] != "created_at"]
            digest.update(repr((table, columns, rows)).encode())
    finally:
        connection.close()
    return digest.hexdigest()


def leaves(value: Any, where: str = "") -> Iterator[tuple[str, Any]]:
    """Every leaf of a JSON value with its path (``a.b[3]``)."""
    if isinstance(value, dict):
        for key in sorted(value):
            yield from leaves(value[key], f"{where}.{key}" if where else str(key))
    elif isinstance(value, list):
        for k, item in enumerate(value):
            yield from leaves(item, f"{where}[{k}]")
    else:
        yield where, value


def differences(a: Any, b: Any, rtol: float) -> tuple[list[str], int, float]:
    """The differences between two JSON values, leaf by leaf: the paths only one has, and
    the leaves whose values differ (integers, strings, booleans and nulls exactly; other
    numbers beyond ``rtol`` relative, NaN equal to NaN); the number of numbers compared
    and the largest relative difference among them."""
    mine, theirs = dict(leaves(a)), dict(leaves(b))
    found = [f"{path}: only in the first" for path in sorted(mine.keys() - theirs.keys())]
    found += [f"{path}: only in the second" for path in sorted(theirs.keys() - mine.keys())]
    numbers, largest = 0, 0.0
    for path in sorted(mine.keys() & theirs.keys()):
        x, y = mine[path], theirs[path]
        floats = isinstance(x, float) or isinstance(y, float)
        if floats and all(isinstance(v, int | float) and not isinstance(v, bool) for v in (x, y)):
            numbers += 1
            if math.isnan(x) and math.isnan(y):
                continue
            scale = max(abs(x), abs(y))
            relative = 0.0 if x == y else abs(x - y) / scale
            largest = max(largest, relative)
            if relative > rtol or math.isnan(relative):
                found.append(f"{path}: {x!r} against {y!r} ({relative:.2g} relative)")
        elif type(x) is not type(y) or x != y:
            found.append(f"{path}: {x!r} against {y!r}")
    return found, numbers, largest


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        _refuse(f"{path}: not readable JSON ({exc})")


def compare(first: Path, second: Path, rtol: float) -> int:
    """Print the differences between two snapshots; 0 when the same, 1 when not."""
    manifests = [_read_json(folder / MANIFEST) for folder in (first, second)]
    names = sorted({p.name for folder in (first, second) for p in folder.glob("*.json")})
    names.remove(MANIFEST)
    report: list[str] = []
    numbers, largest = 0, 0.0
    for name in names:
        there = [folder / name for folder in (first, second)]
        if not all(p.is_file() for p in there):
            report.append(f"{name}: only in {there[0].parent if there[0].is_file() else second}")
            continue
        found, counted, worst = differences(_read_json(there[0]), _read_json(there[1]), rtol)
        report += [f"{name}: {line}" for line in found]
        numbers, largest = numbers + counted, max(largest, worst)
    digests = [m.get("default_database_content_sha256") for m in manifests]
    if digests[0] != digests[1]:
        report.append(f"default database: content SHA-256 {digests[0]} against {digests[1]}")
    commits = " and ".join(str(m.get("commit", "?"))[:12] for m in manifests)
    for line in report:
        print(line)
    same = "the same" if not report else f"{len(report)} difference(s)"
    print(
        f"{commits}: {len(names)} JSON files, {numbers} numbers compared (largest relative "
        f"difference {largest:.2g}, tolerance {rtol:g}), default database "
        f"content {'identical' if digests[0] == digests[1] else 'different'}: {same}"
    )
    return 0 if not report else 1


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    take = sub.add_parser("snapshot", help="run the commands and keep their results in OUT")
    take.add_argument("out", type=Path, help="a new folder for the snapshot")
    take.add_argument(
        "--quick", action="store_true", help="one bundled recording and one flight (a smoke run)"
    )
    check = sub.add_parser("compare", help="compare two snapshots")
    check.add_argument("first", type=Path)
    check.add_argument("second", type=Path)
    check.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance of numbers")
    args = parser.parse_args(argv)
    if args.command == "snapshot":
        snapshot(args.out, args.quick)
        return 0
    for folder in (args.first, args.second):
        if not (folder / MANIFEST).is_file():
            _refuse(f"{folder}: not a snapshot (no {MANIFEST})")
    if not (0.0 <= args.rtol < 1.0):
        _refuse(f"--rtol: must be in [0, 1), got {args.rtol}")
    return compare(args.first, args.second, args.rtol)


if __name__ == "__main__":
    sys.exit(main())
