"""The benchmark suite: run a script and keep its figures as records; write the page's tables.

    .venv/bin/python benchmarks/suite.py list              # the scripts: timings, studies, tools
    .venv/bin/python benchmarks/suite.py run speed.py --repeats 10
    .venv/bin/python benchmarks/suite.py tables            # the page's tables, from the records
    .venv/bin/python benchmarks/suite.py tables --check    # exit 1 if the page differs

``run`` runs one script as ``python benchmarks/SCRIPT ARGS`` would, its output as always,
and keeps every figure it states (``benchmarks/_records.py``: one record per figure, with
its target and verdict) stamped with the command, the commit, the machine and the day in
``benchmarks/records.jsonl``.  A run that fails keeps nothing.  Records are never
rewritten: a figure measured again is a new record, and the page shows each script's
latest run beside the count of earlier ones.  Figures measured before the suite existed
are records of the commit that first quoted them.

The scripts compare against their reference *in the same run* (``--against REF`` times a
checkout of REF block by block with this one), because this machine's speed drifts by
more than the changes measured; a harness that compares runs taken at different times
(asv, pytest-benchmark's saved runs) would compare the drift, so the suite keeps the
scripts' own protocol and only gives them one result format.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import tomllib
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

from _records import ENV, Record
from pydantic import BaseModel, ConfigDict, ValidationError

from rocketroll_common.tables import markdown_table

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
RECORDS = HERE / "records.jsonl"
INDEX = HERE / "scripts.toml"
PAGE = HERE / "README.md"
KINDS = ("timing", "study", "tool")


class Script(BaseModel):
    """One script of the index (``benchmarks/scripts.toml``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["timing", "study", "tool"]
    question: str
    runtime: str


def scripts() -> dict[str, Script]:
    """The index, checked against the scripts in the folder (each listed, none extra)."""
    with INDEX.open("rb") as f:
        raw = tomllib.load(f)
    try:
        index = {name: Script.model_validate(entry) for name, entry in raw.items()}
    except ValidationError as exc:
        raise SystemExit(f"{INDEX}: {exc}") from None
    present = {p.stem for p in HERE.glob("[a-z]*.py")}
    if set(index) != present:
        missing, extra = sorted(present - set(index)), sorted(set(index) - present)
        raise SystemExit(f"{INDEX}: scripts not listed {missing}; listed but absent {extra}")
    return index


def read_records(path: Path = RECORDS) -> list[Record]:
    """Every record kept, oldest first (a malformed line is named and refused)."""
    if not path.exists():
        return []
    out = []
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            out.append(Record.model_validate_json(line))
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"])
            raise SystemExit(f"{path}:{number}: {where}: {first['msg']}") from None
    return out


def commit() -> str:
    """The commit checked out, ``+dirty`` when tracked files (other than the records and
    the page the suite writes) have changes."""
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.strip()
    changed = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.splitlines()
    own = {str(RECORDS.relative_to(REPO)), str(PAGE.relative_to(REPO))}
    dirty = [line for line in changed if line[3:] not in own]
    return head + ("+dirty" if dirty else "")


def machine() -> str:
    """The CPU model, its cores, Python and numpy: what a timing depends on."""
    import numpy as np

    model = platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{model}, {os.cpu_count()} CPU(s), Python {platform.python_version()}, "
        f"numpy {np.__version__}"
    )


def run(script: str, args: Sequence[str], keep: Path) -> int:
    """Run ``script`` with ``args``; on success append its figures to ``keep``."""
    name = script.removesuffix(".py")
    index = scripts()
    if name not in index:
        raise SystemExit(f"suite run: no script {script!r}; the scripts: {', '.join(index)}")
    command = shlex.join([".venv/bin/python", f"benchmarks/{name}.py", *args])
    stamp = {
        "script": f"{name}.py",
        "kind": "timing" if index[name].kind == "timing" else "study",
        "command": command,
        "commit": commit(),
        "machine": machine(),
        "date": datetime.now(UTC).date().isoformat(),
    }
    with tempfile.TemporaryDirectory() as tmp:
        figures = Path(tmp) / "figures.jsonl"
        done = subprocess.run(
            [sys.executable, str(HERE / f"{name}.py"), *args],
            cwd=REPO,
            env={**os.environ, ENV: str(figures)},
            check=False,
        )
        lines = figures.read_text(encoding="utf-8").splitlines() if figures.exists() else []
    records = [Record.model_validate({**json.loads(line), **stamp}) for line in lines]
    # Exit status 1 with a figure that missed its target is a study's verdict, not a failure.
    judged = done.returncode == 1 and any(r.verdict == "FAIL" for r in records)
    if done.returncode != 0 and not judged:
        print(f"suite: {name}.py exited {done.returncode}; its figures are not kept")
        return done.returncode
    if not records:
        print(f"suite: {name}.py stated no figures; nothing kept")
        return 0
    with keep.open("a", encoding="utf-8") as out:
        for record in records:
            out.write(record.model_dump_json() + "\n")
    print(f"\nsuite: kept {len(records)} figures of {name}.py in {keep}")
    print(records_table(records))
    if keep.resolve() == RECORDS.resolve():  # the page shows the records it was given
        write_page()
    return done.returncode


def _value(record: Record) -> str:
    v = record.value
    if v is None:
        return "not finite"
    number = f"{int(v):,}" if v.is_integer() and abs(v) < 1e15 else f"{v:.4g}"
    return f"{number} {record.unit}".strip()


def records_table(records: Sequence[Record]) -> str:
    """One run's figures."""
    rows = [
        [
            r.figure,
            _value(r),
            "" if r.target is None else f"{r.target} {r.unit}".strip(),
            r.verdict or "",
            r.note,
        ]
        for r in records
    ]
    return "\n".join(markdown_table(("figure", "value", "target", "verdict", "note"), rows))


def latest_runs(records: Sequence[Record]) -> dict[str, tuple[list[Record], int]]:
    """Per script, the figures of its latest run (command, commit and day) and how many
    earlier runs are on record."""
    runs: dict[str, dict[tuple[str, str, str], list[Record]]] = {}
    for record in records:
        key = (record.command, record.commit, record.date)
        runs.setdefault(record.script, {}).setdefault(key, []).append(record)
    latest = {}
    for script, by_run in runs.items():
        keys = list(by_run)
        # the last day's last run (figures measured earlier may be recorded later)
        last = max(range(len(keys)), key=lambda i: (keys[i][2], i))
        latest[script] = (by_run[keys[last]], len(keys) - 1)
    return latest


def index_section(index: dict[str, Script]) -> str:
    parts = []
    titles = {
        "timing": "Timings (the figures depend on the machine)",
        "study": "Studies",
        "tool": "Tools",
    }
    for kind in KINDS:
        rows = [
            [f"`benchmarks/{name}.py`", s.question, s.runtime]
            for name, s in index.items()
            if s.kind == kind
        ]
        table = "\n".join(markdown_table(("script", "what it answers", "runtime"), rows))
        parts.append(f"**{titles[kind]}**\n\n{table}")
    return "\n\n".join(parts)


def records_section(records: Sequence[Record]) -> str:
    if not records:
        return "No figures are on record yet."
    parts = []
    latest = latest_runs(records)
    machines: list[str] = []
    for kind in ("timing", "study"):
        scripts_of_kind = [s for s, (run_, _) in latest.items() if run_[0].kind == kind]
        if not scripts_of_kind:
            continue
        parts.append(f"**{'Timings' if kind == 'timing' else 'Studies'}**")
        for script in scripts_of_kind:
            run_, earlier = latest[script]
            first = run_[0]
            if first.machine not in machines:
                machines.append(first.machine)
            more = f"; {earlier} earlier run(s) on record" if earlier else ""
            parts.append(
                f"`{script}`, `{first.command}` at {first.commit[:12]}, {first.date}, "
                f"machine {machines.index(first.machine) + 1}{more}:\n\n{records_table(run_)}"
            )
    listed = "\n".join(f"{i}. {m}" for i, m in enumerate(machines, 1))
    parts.append(f"Machines:\n\n{listed}")
    return "\n\n".join(parts)


def run_section(records: Sequence[Record], script: str, commit: str) -> str:
    """The figures of ``script``'s runs at ``commit`` (a prefix), a table per command."""
    runs: dict[str, list[Record]] = {}
    for record in records:
        if record.script == script and record.commit.startswith(commit):
            runs.setdefault(record.command, []).append(record)
    if not runs:
        raise SystemExit(f"{PAGE}: no records of {script} at {commit}")
    parts = []
    for command, figures in runs.items():
        first = figures[0]
        parts.append(
            f"`{command}` at {first.commit[:12]}, {first.date} ({first.machine}):\n\n"
            + records_table(figures)
        )
    return "\n\n".join(parts)


RUN_MARKER = re.compile(r"<!-- suite:run (\S+) ([0-9a-f]+) -->\n.*?<!-- /suite:run -->", re.S)


def _between(text: str, name: str, body: str) -> str:
    begin, end = f"<!-- suite:{name} -->", f"<!-- /suite:{name} -->"
    if begin not in text or end not in text:
        raise SystemExit(f"{PAGE}: the markers {begin} ... {end} are missing")
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{begin}\n{body}\n{end}{tail}"


def page(text: str) -> str:
    """The benchmark page with its generated sections written from the index and records."""
    records = read_records()
    text = _between(text, "index", index_section(scripts()))
    text = _between(text, "records", records_section(records))
    return RUN_MARKER.sub(
        lambda m: (
            f"<!-- suite:run {m[1]} {m[2]} -->\n{run_section(records, m[1], m[2])}\n"
            "<!-- /suite:run -->"
        ),
        text,
    )


def write_page() -> None:
    """Rewrite the benchmark page's generated tables (if they changed)."""
    text = PAGE.read_text(encoding="utf-8")
    written = page(text)
    if written != text:
        PAGE.write_text(written, encoding="utf-8")
        print(f"wrote {PAGE}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="the scripts, by kind")
    runner = sub.add_parser("run", help="run a script and keep its figures")
    runner.add_argument(
        "--records",
        type=Path,
        default=RECORDS,
        help=f"where to keep them (default {RECORDS}; given before the script)",
    )
    runner.add_argument("script", help="e.g. speed.py")
    runner.add_argument("args", nargs=argparse.REMAINDER, help="the script's own options")
    tables = sub.add_parser("tables", help="write the benchmark page's tables from the records")
    tables.add_argument("--check", action="store_true", help="exit 1 if the page differs")
    ns = parser.parse_args(argv)
    if ns.command == "list":
        for name, s in sorted(scripts().items(), key=lambda item: KINDS.index(item[1].kind)):
            print(f"{s.kind:7s} {name + '.py':24s} {s.runtime}")
        return 0
    if ns.command == "run":
        args = ns.args[1:] if ns.args[:1] == ["--"] else ns.args
        return run(ns.script, args, ns.records)
    if ns.check:
        text = PAGE.read_text(encoding="utf-8")
        if page(text) != text:
            print(f"{PAGE}: not what the index and records give; run benchmarks/suite.py tables")
            return 1
        print(f"{PAGE}: up to date")
        return 0
    write_page()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
