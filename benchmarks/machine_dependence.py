"""Which figures move between machines, and why: the default database and the site's
tables under the numerical settings that differ between x86-64 machines of one kind.

Machines differ in OpenBLAS's kernel (chosen by processor, or by
``OPENBLAS_CORETYPE``), numpy's SIMD level (AVX-512 or AVX2), the code numba
generates for the processor, torch's kernels (ATen's SIMD level, MKL's code
path) and thread counts.  Each setting below imitates one such difference on
this machine.  Under each, this builds the default database twice -- in the
process as it is (``ROCKETROLL_NUMERICS=pinned`` keeps the build in it: how
every build ran before the numerics were pinned) and pinned, as
``rocketroll db build`` does (:mod:`rocketroll_common.numerics`) -- and
compares every identification's parameters and every trace's checksum with the
first setting's; then evaluates the site's three tables on each database,
under the setting, and compares them with the first setting's pinned ones.

Run from the repository root (about 2 minutes per setting)::

    .venv/bin/python benchmarks/machine_dependence.py [--setting NAME ...]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from _records import emit

from rocketroll_common.numerics import MACHINE_SETTINGS, MARKER, with_settings
from rocketroll_common.tables import markdown_table

REPO = Path(__file__).resolve().parents[1]

#: The site's evaluation tables: ``rocketroll eval`` arguments.
TABLES: dict[str, list[str]] = {
    "angle": ["--env-id", "RocketRoll-v0"],
    "rate": ["--env-id", "RocketRollRate-v0"],
    "flight": ["--env-id", "RocketRollFlight-v0"]
    + [f"--policy={p}" for p in ("trim", "pid", "pid-tunnel", "observer", "mpc", "oracle")],
}

#: Prints the default database's parameters and trace checksums as JSON.
_DIGEST = """
import json, os, sqlite3
from disturbances.default import open_default
with open_default(progress=False):
    pass
c = sqlite3.connect(os.environ["ROCKETROLL_DB"])
ids = c.execute(
    "SELECT r.name, i.method, i.model, i.alpha, i.theta_bar_deg, i.beta_bar_per_s,"
    " i.alpha_bar_per_deg_s FROM identifications i JOIN recordings r ON r.id = i.recording_id"
).fetchall()
traces = c.execute("SELECT uid, checksum FROM traces").fetchall()
print(json.dumps({"ids": {"/".join(r[:3]): r[3:] for r in ids}, "traces": dict(traces)}))
"""


def _env(changes: dict[str, str | None], **extra: str) -> dict[str, str]:
    return with_settings({**changes, **extra, "PYTHONPATH": str(REPO)})


def _digest(env: dict[str, str]) -> dict[str, dict[str, object]]:
    done = subprocess.run(
        [sys.executable, "-c", _DIGEST], cwd=REPO, env=env, capture_output=True, text=True
    )
    if done.returncode != 0:
        raise SystemExit(f"building the database failed:\n{done.stderr[-3000:]}")
    digest: dict[str, dict[str, object]] = json.loads(done.stdout)
    return digest


def _tables(env: dict[str, str]) -> dict[str, list[str]]:
    tables = {}
    for name, args in TABLES.items():
        done = subprocess.run(
            [sys.executable, "-m", "rocketroll", "eval", *args, "--episodes", "20", "--seed", "0"],
            cwd=REPO,
            env=env,
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            raise SystemExit(f"rocketroll eval {' '.join(args)} failed:\n{done.stderr[-3000:]}")
        tables[name] = [row for row in done.stdout.splitlines() if row.startswith("| ")]
    return tables


def _differences(
    digest: dict[str, dict[str, object]], ref: dict[str, dict[str, object]]
) -> tuple[int, int, float]:
    """Identifications and traces that differ, and the largest relative parameter change."""
    ids = [k for k in ref["ids"] if digest["ids"].get(k) != ref["ids"][k]]
    traces = sum(digest["traces"].get(k) != v for k, v in ref["traces"].items())
    worst = 0.0
    for key in ids:
        for a, b in zip(digest["ids"][key], ref["ids"][key], strict=True):  # type: ignore[call-overload]
            if b:
                worst = max(worst, abs(a / b - 1.0))
    return len(ids), traces, worst


def _compare(digest: dict[str, dict[str, object]], ref: dict[str, dict[str, object]]) -> str:
    ids, traces, worst = _differences(digest, ref)
    return f"{ids}/{len(ref['ids'])} ids, {traces}/{len(ref['traces'])} traces, {worst:.1e}"


def _tunnel_pid(tables: dict[str, list[str]]) -> str:
    row = next(r for r in tables["flight"] if r.startswith("| PID, tunnel gains |"))
    return row.split("|")[2].strip().split()[0]


def _rows_moved(tables: dict[str, list[str]], ref: dict[str, list[str]]) -> int:
    return sum(a != b for name in ref for a, b in zip(tables[name], ref[name], strict=True))


def _moved(tables: dict[str, list[str]], ref: dict[str, list[str]]) -> str:
    rows = _rows_moved(tables, ref)
    return "identical" if rows == 0 else f"{rows} rows differ"


def _emit_setting(
    name: str,
    pinned: bool,
    found: tuple[dict[str, dict[str, object]], dict[str, list[str]]],
    ref: tuple[dict[str, dict[str, object]], dict[str, list[str]]],
) -> None:
    """State one setting's figures, built as it is or pinned, against this machine's (pinned:
    no identification and no table row may differ, the verdict printed at the end)."""
    (digest, tables), (ref_digest, ref_tables) = found, ref
    ids, traces, worst = _differences(digest, ref_digest)
    how = "pinned" if pinned else "built as it is"
    target = 0 if pinned else None
    emit(
        f"{name}, {how}: identifications that differ from this machine's",
        ids,
        f"of {len(ref_digest['ids'])}",
        at_most=target,
        note=f"{traces}/{len(ref_digest['traces'])} traces differ; largest relative change of "
        f"a parameter {worst:.1e}",
    )
    emit(
        f"{name}, {how}: evaluation-table rows that differ from this machine's",
        _rows_moved(tables, ref_tables),
        "rows",
        at_most=target,
        note=f"the {', '.join(TABLES)} tables, 20 episodes, seed 0",
    )
    try:
        pid = float(_tunnel_pid(tables))
    except ValueError:  # not a number: nothing to state
        return
    emit(f"{name}, {how}: flight, tunnel-gain PID headline", pid, "°")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--setting",
        action="append",
        choices=list(MACHINE_SETTINGS),
        help="a setting to run (repeatable; default: all; the first is the reference)",
    )
    ns = parser.parse_args(argv)
    names = ns.setting or list(MACHINE_SETTINGS)
    if names[0] != "this machine":
        names.insert(0, "this machine")
    rows = []
    Found = tuple[dict[str, dict[str, object]], dict[str, list[str]]]
    ref: dict[bool, Found] = {}
    with tempfile.TemporaryDirectory(prefix="rocketroll-machines-") as folder:
        for k, name in enumerate(names):
            started = time.perf_counter()
            found: dict[bool, Found] = {}
            for pinned in (False, True):
                db = Path(folder, f"{k}-{'pinned' if pinned else 'unpinned'}.sqlite")
                extra = {"ROCKETROLL_DB": str(db)}
                if not pinned:
                    extra[MARKER] = "pinned"  # build in the process as it is
                env = _env(MACHINE_SETTINGS[name], **extra)
                digest = _digest(env)
                env.pop(MARKER, None)
                found[pinned] = (digest, _tables(env))
            if not ref:
                ref = dict(found)
            cells = [name]
            for pinned in (False, True):
                digest, tables = found[pinned]
                ref_digest, ref_tables = ref[pinned]
                cells += [
                    _compare(digest, ref_digest),
                    _tunnel_pid(tables),
                    _moved(tables, ref_tables),
                ]
                _emit_setting(name, pinned, found[pinned], ref[pinned])
            rows.append(cells)
            print(f"  {name}: {time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)
    header = [
        "setting",
        "database built as it is: differs from this machine's (identifications, traces, "
        "largest relative change of a parameter)",
        "flight, tunnel-gain PID (°)",
        "tables",
        "database built pinned: differs",
        "flight, tunnel-gain PID (°)",
        "tables",
    ]
    print("\n" + "\n".join(markdown_table(header, rows)))
    same = sum(cells[-1] == "identical" and cells[4].startswith("0/") for cells in rows)
    stable = same == len(rows)
    emit(
        "pinned: settings whose database and tables are this machine's",
        same,
        f"of {len(rows)}",
        at_least=len(rows),
        note=", ".join(names),
    )
    print(
        "\npinned: the database and the tables are the same under every setting"
        if stable
        else "\npinned: SOMETHING MOVED -- see the table"
    )
    return 0 if stable else 1


if __name__ == "__main__":
    sys.exit(main())
