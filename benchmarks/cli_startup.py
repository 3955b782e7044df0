"""Start-up time of the command line: ``rocketroll --help`` and every ``rocketroll
COMMAND --help``, against a bare Python.

A command's help must answer at once (target: under 0.3 s on this machine).
Each run is a fresh process, as a user's is; in one run this times,
interleaved so that a busy spell slows all alike:

* ``python -m rocketroll --help`` (the top-level list of commands);
* ``python -m rocketroll COMMAND --help`` for every command, and ``rocketroll
  COMMAND SUB --help`` for every subcommand (from ``rocketroll/help.json``
  while it is current: ``rocketroll.help``);
* ``python -m rocketroll tunnel --help`` through the command's own parser
  (``ROCKETROLL_HELP_FROM_SOURCE=1``: its layer imported, numpy and scipy with
  it), for comparison; reported, not judged;
* the named reference, ``python -c pass``: the interpreter's own start-up,
  which no command can beat.

With ``--against REF`` the same tasks are also timed with a worktree of
``REF`` first on ``PYTHONPATH`` (``benchmarks/_against.py``), alternating with
this checkout's, and the change is printed.  The exit status is 0 whatever the
timings unless ``--strict`` is given, when a missed target gives 1.

Run from the repository root::

    .venv/bin/python benchmarks/cli_startup.py [--runs 5] [--against REF]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from _against import REPO, checkout
from _records import emit

from rocketroll_common.tables import Column, text_table

TARGET_S = 0.3
REFERENCE = "python -c pass (reference)"
FROM_SOURCE = "tunnel --help, its own parser"


def _tasks() -> dict[str, list[str]]:
    """Name -> the command's arguments after ``python``."""
    sys.path.insert(0, str(REPO))
    from rocketroll.cli import COMMANDS, command

    tasks = {"rocketroll --help": ["-m", "rocketroll", "--help"]}
    for name in COMMANDS:
        tasks[f"rocketroll {name} --help"] = ["-m", "rocketroll", name, "--help"]
        for sub in command(name).subcommands:
            tasks[f"rocketroll {name} {sub.name} --help"] = [
                "-m", "rocketroll", name, sub.name, "--help",
            ]  # fmt: skip
    tasks[FROM_SOURCE] = ["-m", "rocketroll", "tunnel", "--help"]
    tasks[REFERENCE] = ["-c", "pass"]
    return tasks


def _time(name: str, argv: list[str], tree: Path) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    if name == FROM_SOURCE:
        env["ROCKETROLL_HELP_FROM_SOURCE"] = "1"
    start = time.perf_counter()
    subprocess.run([sys.executable, *argv], cwd=tree, env=env, capture_output=True, check=True)
    return time.perf_counter() - start


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5, help="processes per task (default 5)")
    parser.add_argument("--against", metavar="REF", help="also time a checkout of REF")
    parser.add_argument("--strict", action="store_true", help="exit 1 when a target is missed")
    ns = parser.parse_args(argv)
    if ns.runs < 1:
        raise SystemExit("--runs must be >= 1")
    trees = {"here": REPO}
    if ns.against:
        tree, commit = checkout(ns.against)
        print(f"against {ns.against} ({commit[:12]}), checked out at {tree}")
        trees["against"] = tree
    tasks = _tasks()
    for tree in trees.values():  # warm the file cache and __pycache__ once
        for name, args in tasks.items():
            _time(name, args, tree)
    times: dict[tuple[str, str], list[float]] = {}
    for _ in range(ns.runs):
        for name, args in tasks.items():
            for side, tree in trees.items():
                if side == "against" and name == REFERENCE:
                    continue
                try:
                    took = _time(name, args, tree)
                except subprocess.CalledProcessError:  # a command REF does not have
                    continue
                times.setdefault((name, side), []).append(took)
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPU(s); {ns.runs} processes each")
    width = max(map(len, tasks)) + 1
    rows = []
    missed = False
    for name in tasks:
        runs = times[(name, "here")]
        median = statistics.median(runs)
        judged = name not in (REFERENCE, FROM_SOURCE)
        target = f"{TARGET_S:.1f}" if judged else ""
        verdict = ("PASS" if median < TARGET_S else "FAIL") if judged else "(reference)"
        if name == FROM_SOURCE:
            verdict = "-"
        missed |= verdict == "FAIL"
        rows.append([name, f"{median:.3f}", f"{min(runs):.3f}", target, verdict])
        emit(
            f"{name}: median",
            median,
            "s",
            at_most=TARGET_S if judged else None,
            note=f"min {min(runs):.3f} s over {len(runs)} processes",
        )
    columns = (
        Column("task", width, "<"),
        Column("median s", 9, gap=" "),
        Column("min s", 7, gap=" "),
        Column("target s", 9, gap=" "),
        Column("verdict", gap="  "),
    )
    print("\n" + "\n".join(text_table(columns, rows)))
    if "against" in trees:
        print(f"\nthis checkout against {ns.against}, the same processes alternating:")
        for name in tasks:
            if (name, "against") not in times:
                continue
            ours = statistics.median(times[(name, "here")])
            theirs = statistics.median(times[(name, "against")])
            print(f"{name:<{width}} {theirs:>7.3f} s -> {ours:.3f} s ({ours / theirs - 1:+.0%})")
    return 1 if missed and ns.strict else 0


if __name__ == "__main__":
    sys.exit(main())
