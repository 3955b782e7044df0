"""Speed of drawing an episode's ``u_d`` window from the disturbance database.

The environment draws a 60-s window of ``u_d`` at every ``reset``; the need is
one window in at most 100 µs once the traces are loaded (held in memory, no
SQL per episode).  In one run, on the default database (built from the bundled
recordings if missing; ``--db`` for another file), this measures:

* the first load, ``TraceBank.from_db(db, split="train", method="paper",
  model="theta", kind="identified")`` -- one SQL query and every trace's
  checksum verified (reported, not judged);
* ``bank.window(rng, 60.0)``: ``--draws`` draws timed in batches of
  ``--batch``; the per-draw time of each batch (batch time / batch size) gives
  the median, mean and 99th percentile, and the p99 is judged against the
  100 µs target; ``--single`` more draws timed one by one show the tail of
  single draws (p99, max; includes ~0.1 µs of timer overhead);
* the named reference measured in the same run: the same draw done with SQL
  per episode -- the same uniform choice of (trace, offset) from the same
  generator, then ``db.trace(uid)`` (one query, checksum verified) and a
  slice -- ``--sql-draws`` draws timed one by one, interleaved with the bank's
  batches so that a busy spell of a shared machine slows both alike; the
  ``x bank`` column is the ratio of medians.  The first windows of both are
  compared to check that they are the same windows.

With ``--against REF`` the batches, the SQL draws and a load are also timed
in a worktree of ``REF`` on its own default database (``benchmarks/_against.py``),
alternating with this checkout's, and the change is printed.

Wall-clock times by :func:`time.perf_counter`.  The exit status is 0 whatever
the timings unless ``--strict`` is given, when a missed target gives 1.

Run from the repository root::

    .venv/bin/python benchmarks/db_windows.py [--against REF]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from _against import SERVE, Remote, serve, start_against
from _records import emit

from disturbances.bank import TraceBank
from disturbances.db import DatabaseError
from disturbances.default import default_path, open_database

if TYPE_CHECKING:  # older checkouts (--against) have neither module
    from disturbances.rows import TraceRow
    from disturbances.stores import Store

TARGET_US = 100.0
WINDOW_S = 60.0
SELECTION: dict[str, Any] = {
    "split": "train",
    "method": "paper",
    "model": "theta",
    "kind": "identified",
}


@dataclass(frozen=True)
class Timing:
    """Per-draw wall-clock times of one task, µs."""

    name: str
    samples_us: tuple[float, ...]
    draws: int

    @property
    def median_us(self) -> float:
        return float(np.median(self.samples_us))

    @property
    def mean_us(self) -> float:
        return float(np.mean(self.samples_us))

    @property
    def p99_us(self) -> float:
        return float(np.percentile(self.samples_us, 99))

    @property
    def min_us(self) -> float:
        return float(np.min(self.samples_us))

    @property
    def max_us(self) -> float:
        return float(np.max(self.samples_us))


class SqlWindows:
    """The reference: the bank's choice of window, but the trace read by SQL each episode."""

    def __init__(self, db: Store, traces: Sequence[TraceRow], duration_s: float) -> None:
        self.db = db
        infos = [getattr(t, "info", t) for t in traces]  # older checkouts: Trace.info
        self.uids = [i.uid for i in infos]
        sizes = np.array([i.n_samples for i in infos], dtype=np.int64)
        dts = np.array([i.dt_s for i in infos])
        # As TraceBank: whole samples on each trace's grid, uniform over (trace, offset).
        self.lengths = np.ceil(duration_s / dts - 1e-9).astype(np.int64)
        self.cum = np.cumsum(np.maximum(sizes - self.lengths + 1, 0))
        self.total = int(self.cum[-1])

    def window(self, rng: np.random.Generator) -> tuple[str, int, np.ndarray]:
        k = int(rng.integers(self.total))
        i = int(np.searchsorted(self.cum, k, side="right"))
        start = k - (int(self.cum[i - 1]) if i else 0)
        samples = np.asarray(self.db.trace(self.uids[i]).u_d_deg)
        return self.uids[i], start, samples[start : start + int(self.lengths[i])]


def check_same_windows(bank: TraceBank, sql: SqlWindows, seed: int, n: int = 20) -> None:
    """Both draw the same windows from the same seed (else the comparison is unfair)."""
    a, b = np.random.default_rng(seed), np.random.default_rng(seed)
    for _ in range(n):
        w = bank.window(a, WINDOW_S)
        uid, start, values = sql.window(b)
        if (w.uid, w.start) != (uid, start) or not np.array_equal(w.u_d_deg, values):
            raise SystemExit("the SQL reference drew other windows than the bank; fix the script")


def verdict(p99_us: float) -> str:
    return "PASS" if p99_us <= TARGET_US else "FAIL"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="benchmarks/db_windows.py",
        description=(
            f"Time TraceBank.window(rng, {WINDOW_S:g}) on the default disturbance database "
            f"against a {TARGET_US:g} µs target, with the same draw done by SQL per episode "
            "beside it."
        ),
    )
    parser.add_argument(
        "--draws", type=int, default=100_000, help="bank draws timed in batches (default 100000)"
    )
    parser.add_argument("--batch", type=int, default=1000, help="draws per batch (default 1000)")
    parser.add_argument(
        "--single", type=int, default=10_000, help="bank draws timed one by one (default 10000)"
    )
    parser.add_argument(
        "--sql-draws", type=int, default=200, help="SQL-per-episode draws (default 200)"
    )
    parser.add_argument("--seed", type=int, default=0, help="generator seed (default 0)")
    parser.add_argument(
        "--db",
        type=Path,
        help="database file (default: the default database, built from the bundled recordings "
        "if missing)",
    )
    parser.add_argument("--against", metavar="REF", help="also time the draws in a checkout of REF")
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 when the target is missed"
    )
    return parser


def _serve(ns: argparse.Namespace) -> int:
    """The other checkout's side of --against: a batch, an SQL draw, a load, on request."""
    db = open_database(ns.db)
    bank = TraceBank.from_db(db, **SELECTION)
    sql = SqlWindows(db, list(bank.traces), WINDOW_S)
    rng, sql_rng = np.random.default_rng(ns.seed), np.random.default_rng(ns.seed + 1)
    bank.window(rng, WINDOW_S)
    sql.window(sql_rng)

    def batch() -> float:
        t0 = time.perf_counter()
        for _ in range(ns.batch):
            bank.window(rng, WINDOW_S)
        return time.perf_counter() - t0

    def one_sql() -> float:
        t0 = time.perf_counter()
        sql.window(sql_rng)
        return time.perf_counter() - t0

    def load() -> float:
        t0 = time.perf_counter()
        TraceBank.from_db(db, **SELECTION)
        return time.perf_counter() - t0

    return serve({"batch": batch, "sql": one_sql, "load": load})


def _parse(argv: Sequence[str] | None) -> tuple[argparse.Namespace, list[str], bool]:
    """The options, the command-line words (less --serve-blocks) and whether to serve blocks."""
    words = list(sys.argv[1:] if argv is None else argv)
    serving = SERVE in words
    if serving:
        words.remove(SERVE)
    ns = build_parser().parse_args(words)
    for name in ("draws", "batch", "single", "sql_draws"):
        if getattr(ns, name) < 1:
            raise SystemExit(f"--{name.replace('_', '-')} must be >= 1")
    if ns.draws < ns.batch:
        raise SystemExit(f"--draws ({ns.draws}) must be at least --batch ({ns.batch})")
    return ns, words, serving


def _open(location: Path | None) -> tuple[Store, bool, float]:
    """The database, whether it was built now (the default, missing), and ms to open it."""
    path = location if location is not None else default_path()
    built = location is None and not path.exists()
    start = time.perf_counter()
    try:
        db = open_database(location)
    except DatabaseError as exc:
        raise SystemExit(f"benchmarks/db_windows.py: {exc}") from None
    open_ms = (time.perf_counter() - start) * 1e3
    return db, built, open_ms


def _load_and_describe(
    db: Store, built: bool, open_ms: float, remote: Remote | None, before: dict[str, list[float]]
) -> tuple[TraceBank, SqlWindows, float]:
    """The bank, its SQL reference and ms of the first load, with what they hold printed."""
    start = time.perf_counter()
    try:
        bank = TraceBank.from_db(db, **SELECTION)
    except (ValueError, DatabaseError) as exc:
        raise SystemExit(f"benchmarks/db_windows.py: {exc}") from None
    load_ms = (time.perf_counter() - start) * 1e3
    bank.require(WINDOW_S)
    counts = db.counts()
    sql = SqlWindows(db, list(bank.traces), WINDOW_S)

    print(
        f"database {db.path}: {counts['recordings']} recordings, {counts['traces']} traces, "
        f"{counts['surrogates']} surrogates"
        + (f" (built now, {open_ms / 1e3:.1f} s)" if built else "")
    )
    nbytes = sum(t.samples().nbytes for t in bank.traces)
    if remote is not None:
        for _ in range(3):
            start = time.perf_counter()
            TraceBank.from_db(db, **SELECTION)
            before.setdefault("load_here", []).append(time.perf_counter() - start)
            before["load"].append(remote.block("load"))
    print(
        f"selection {', '.join(f'{k}={v}' for k, v in SELECTION.items())}: {len(bank)} traces, "
        f"{bank.total_duration_s:.0f} s, {nbytes / 1e6:.2f} MB in memory; "
        f"{WINDOW_S:g}-s windows of {int(bank.samples_for(WINDOW_S)[0])} samples, "
        f"{sql.total} possible"
    )
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, "
        f"{os.cpu_count()} CPU(s), {platform.machine()}"
    )
    return bank, sql, load_ms


def _first_draws(
    bank: TraceBank, sql: SqlWindows, rng: np.random.Generator, sql_rng: np.random.Generator
) -> tuple[float, float]:
    """µs of the first bank draw and the first SQL draw after the load (untimed below)."""
    # The bank plans the window length once.
    start = time.perf_counter()
    bank.window(rng, WINDOW_S)
    first_draw_us = (time.perf_counter() - start) * 1e6
    start = time.perf_counter()
    sql.window(sql_rng)
    first_sql_us = (time.perf_counter() - start) * 1e6
    return first_draw_us, first_sql_us


def _time_draws(
    ns: argparse.Namespace,
    bank: TraceBank,
    sql: SqlWindows,
    rng: np.random.Generator,
    sql_rng: np.random.Generator,
    remote: Remote | None,
    before: dict[str, list[float]],
) -> tuple[Timing, Timing, Timing]:
    """The bank's batches with the SQL draws between them, then single bank draws, timed."""
    # Bank batches with the SQL draws spread evenly between them.
    n_batches = ns.draws // ns.batch
    window = bank.window
    batch_us: list[float] = []
    sql_us: list[float] = []
    sql_done = 0
    for b in range(n_batches):
        t0 = time.perf_counter()
        for _ in range(ns.batch):
            window(rng, WINDOW_S)
        batch_us.append((time.perf_counter() - t0) * 1e6 / ns.batch)
        if remote is not None:
            before["batch"].append(remote.block("batch") * 1e6 / ns.batch)
        while sql_done < ns.sql_draws * (b + 1) // n_batches:
            t0 = time.perf_counter()
            sql.window(sql_rng)
            sql_us.append((time.perf_counter() - t0) * 1e6)
            sql_done += 1
            if remote is not None:
                before["sql"].append(remote.block("sql") * 1e6)
    single_us: list[float] = []
    for _ in range(ns.single):
        t0 = time.perf_counter()
        window(rng, WINDOW_S)
        single_us.append((time.perf_counter() - t0) * 1e6)

    batches = Timing(f"bank.window, batches of {ns.batch}", tuple(batch_us), n_batches * ns.batch)
    singles = Timing("bank.window, one at a time", tuple(single_us), ns.single)
    reference = Timing("db.trace(uid) + slice (SQL)", tuple(sql_us), len(sql_us))
    return batches, singles, reference


def _print_table(batches: Timing, singles: Timing, reference: Timing) -> None:
    """One line per task: its per-draw statistics, its ratio to the batches, the verdict."""
    from rocketroll_common.tables import Column, text_table  # this checkout's (not older ones')

    columns = (  # one task per line: its per-draw statistics, the target and the verdict
        Column("task", 34, "<"),
        Column("draws", 7, ">", " "),
        Column("median µs", 10, ">", " "),
        Column("mean µs", 9, ">", " "),
        Column("p99 µs", 9, ">", " "),
        Column("min µs", 8, ">", " "),
        Column("max µs", 9, ">", " "),
        Column("target µs", 10, ">", " "),
        Column("x bank", 8, ">", " "),
        Column("verdict", 0, "<", "  "),
    )
    header = text_table(columns, [])[0]
    print()
    print(header)
    print("-" * len(header))

    def row(t: Timing, judged: bool, note: str = "") -> None:
        ratio = t.median_us / batches.median_us
        target = f"{TARGET_US:.0f}" if judged else "-"
        mark = f"{verdict(t.p99_us)} (p99)" if judged else note
        cells = [
            t.name,
            str(t.draws),
            f"{t.median_us:.2f}",
            f"{t.mean_us:.2f}",
            f"{t.p99_us:.2f}",
            f"{t.min_us:.2f}",
            f"{t.max_us:.2f}",
            target,
            f"{ratio:.2f}",
            mark,
        ]
        print(text_table(columns, [cells])[1])
        emit(
            f"{t.name}: p99" if judged else f"{t.name}: median",
            t.p99_us if judged else t.median_us,
            "µs",
            at_most=TARGET_US if judged else None,
            note=f"median {t.median_us:.2f} µs, p99 {t.p99_us:.2f} µs over {t.draws} draws; "
            f"{ratio:.2f}x the bank",
        )

    row(batches, True)
    row(singles, False, "(tail; not judged)")
    row(reference, False, "(reference)")


def _print_against(
    ref: str, commit: str, batches: Timing, reference: Timing, before: dict[str, list[float]]
) -> None:
    """This checkout's medians of the batches, the SQL draws and a load against REF's."""
    from rocketroll_common.tables import Column, text_table  # this checkout's (not older ones')

    print(f"\nthis checkout against {ref} ({commit[:12]}), the same work alternating:")
    pairs = (
        (batches.name + " (µs/draw)", batches.median_us, before["batch"]),
        (reference.name + " (µs)", reference.median_us, before["sql"]),
        (
            "TraceBank.from_db (ms)",
            1e3 * float(np.median(before["load_here"])),
            [1e3 * x for x in before["load"]],
        ),
    )
    against = (
        Column("task", 34, "<"),
        Column("this median", 12, ">", " "),
        Column("REF median", 12, ">", " "),
        Column("change", 8, ">", " "),
    )
    rows = []
    for name, here, there in pairs:
        old = float(np.median(there))
        rows.append([name, f"{here:.2f}", f"{old:.2f}", f"{here / old - 1:+.1%}"])
    print("\n".join(text_table(against, rows)))


def main(argv: Sequence[str] | None = None) -> int:
    """Time the draws, print the table and the verdict; 1 with --strict if the target is missed."""
    ns, words, serving = _parse(argv)
    if serving:
        return _serve(ns)

    remote, commit = start_against(__file__, words, ns.against)
    before: dict[str, list[float]] = {"batch": [], "sql": [], "load": []}
    db, built, open_ms = _open(ns.db)
    with db:
        bank, sql, load_ms = _load_and_describe(db, built, open_ms, remote, before)
        check_same_windows(bank, sql, ns.seed)
        rng = np.random.default_rng(ns.seed)
        sql_rng = np.random.default_rng(ns.seed + 1)
        first_draw_us, first_sql_us = _first_draws(bank, sql, rng, sql_rng)
        batches, singles, reference = _time_draws(ns, bank, sql, rng, sql_rng, remote, before)

    print()
    print(
        f"first load TraceBank.from_db: {load_ms:.1f} ms (open: {open_ms:.1f} ms); "
        f"first draw after it: bank {first_draw_us:.1f} µs, SQL {first_sql_us:.0f} µs (untimed "
        "below)"
    )
    _print_table(batches, singles, reference)
    print()
    print(
        f"SQL per episode / bank: {reference.median_us / batches.median_us:.0f}x slower "
        f"(medians); the bank's p99 is {batches.p99_us / TARGET_US:.1%} of the "
        f"{TARGET_US:g} µs budget"
    )
    print(
        "batch rows: statistics over the per-draw time of each batch; single and SQL rows: "
        "over individually timed draws; SQL draws interleaved with the batches; same windows "
        "checked for both on 20 draws"
    )
    missed = batches.p99_us > TARGET_US
    print(f"missed target: {batches.name}" if missed else "target met")
    if remote is not None:
        remote.close()
        _print_against(ns.against, commit, batches, reference, before)
    return 1 if ns.strict and missed else 0


if __name__ == "__main__":
    sys.exit(main())
