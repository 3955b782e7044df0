"""Start-up time of the command line: ``rocketroll --help`` against a bare Python.

``rocketroll --help`` must answer at once (target: under 0.3 s on this
machine).  Each run is a fresh process, as a user's is; in one run this
times, interleaved so that a busy spell slows all alike:

* ``python -m rocketroll --help`` (the top-level list of commands);
* ``python -m rocketroll tunnel --help`` (one command's options: its layer is
  imported, numpy and scipy with it; reported, not judged);
* the named reference, ``python -c pass``: the interpreter's own start-up,
  which no command can beat.

With ``--against REF`` the first two are also timed with a worktree of
``REF`` first on ``PYTHONPATH`` (``benchmarks/_against.py``), alternating with
this checkout's, and the change is printed.  The exit status is 0 whatever the
timings unless ``--strict`` is given, when a missed target gives 1.

Run from the repository root::

    .venv/bin/python benchmarks/cli_startup.py [--runs 15] [--against REF]
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

TARGET_S = 0.3

#: Name -> the command's arguments after ``python``.
TASKS: dict[str, list[str]] = {
    "rocketroll --help": ["-m", "rocketroll", "--help"],
    "rocketroll tunnel --help": ["-m", "rocketroll", "tunnel", "--help"],
    "python -c pass (reference)": ["-c", "pass"],
}


def _time(argv: list[str], tree: Path) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    start = time.perf_counter()
    subprocess.run([sys.executable, *argv], cwd=tree, env=env, capture_output=True, check=True)
    return time.perf_counter() - start


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=15, help="processes per task (default 15)")
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
    for tree in trees.values():  # warm the file cache and __pycache__ once
        for args in TASKS.values():
            _time(args, tree)
    times: dict[tuple[str, str], list[float]] = {}
    for _ in range(ns.runs):
        for name, args in TASKS.items():
            for side, tree in trees.items():
                if side == "against" and "reference" in name:
                    continue
                times.setdefault((name, side), []).append(_time(args, tree))
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPU(s); {ns.runs} processes each")
    print(f"\n{'task':<30} {'median s':>9} {'min s':>7} {'target s':>9}  verdict")
    missed = False
    for name in TASKS:
        runs = times[(name, "here")]
        median = statistics.median(runs)
        judged = name == "rocketroll --help"
        target = f"{TARGET_S:.1f}" if judged else ""
        verdict = ("PASS" if median < TARGET_S else "FAIL") if judged else "(reference)"
        if not judged and "reference" not in name:
            verdict = "-"
        missed |= verdict == "FAIL"
        print(f"{name:<30} {median:>9.3f} {min(runs):>7.3f} {target:>9}  {verdict}")
    if "against" in trees:
        print(f"\nthis checkout against {ns.against}, the same processes alternating:")
        for name in TASKS:
            if (name, "against") not in times:
                continue
            ours = statistics.median(times[(name, "here")])
            theirs = statistics.median(times[(name, "against")])
            print(f"{name:<30} {theirs:>7.3f} s -> {ours:.3f} s ({ours / theirs - 1:+.0%})")
    return 1 if missed and ns.strict else 0


if __name__ == "__main__":
    sys.exit(main())
