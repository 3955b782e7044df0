"""Do the oracle and the causal limit bound every deployable controller?  Per task.

The five tasks (angle with setpoint steps and held at zero, rate with setpoint steps in
the tunnel; angle and rate in flight), each deployable controller the registry runs there
by default (PID -- scheduled in flight --, the tunnel-gain PID in flight, the observer,
the MPC, the committed PPO where there is one), the oracle (perfect preview of ``u_d``,
the true rocket) and the causal oracle (the true rocket and state, the samples of
``u_d`` so far, its future predicted by the design split's turbulence model:
:mod:`agents.oracle`) on the protocol's episodes (test split, ``--episodes``,
``--seed``): each one's headline (regulation RMS, mean over the episodes), the bounds'
ratios to it, and how much of the way from the PID to the causal limit it goes.  Verdict:
both bounds at or below every deployable controller within ``--tolerance`` (their plans
are the best of a grid, not proven optima); the test suite checks the same on three
episodes per task (``tests/agents/test_oracle_bound.py``).

Run from the repository root::

    .venv/bin/python benchmarks/oracle_bound.py                 # 20 episodes per task
    .venv/bin/python benchmarks/oracle_bound.py --episodes 5 --task flight-angle
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

from _records import emit
from tqdm.auto import tqdm

from agents.bounds import TASKS, bound_rows
from rocketroll_common.tables import Column, text_table

#: Per task: the oracle's and the causal oracle's headlines (the first three columns), then
#: each deployable controller's, the bounds' ratios to it and its share of PID->limit.
COLUMNS = (
    Column("task", 14, "<"),
    Column("controller", 14, "<", " "),
    Column("headline", 9, ">", " "),
    Column("oracle/it", 10, ">", " "),
    Column("causal/it", 10, ">", " "),
    Column("it/causal", 10, ">", " "),
    Column("PID->limit", 11, ">", " "),
)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="benchmarks/oracle_bound.py",
        description="The oracle's headline against every deployable controller's, per task.",
    )
    parser.add_argument("--episodes", type=int, default=20, help="protocol episodes (20)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--task", action="append", choices=list(TASKS), help="a task (repeat; default: all)"
    )
    parser.add_argument(
        "--tolerance", type=float, default=0.05, help="the oracle's allowed excess (0.05)"
    )
    parser.add_argument("--strict", action="store_true", help="exit 1 if the bound fails")
    ns = parser.parse_args(argv)
    if ns.episodes < 1 or not 0.0 <= ns.tolerance < 1.0:
        parser.error("--episodes must be >= 1 and --tolerance in [0, 1)")
    tasks = ns.task or list(TASKS)
    began = time.perf_counter()
    with tqdm(desc="controllers", unit="run", leave=False) as bar:

        def tick(what: str) -> None:
            bar.set_postfix_str(what)
            bar.update()

        rows = bound_rows(tasks, ns.episodes, ns.seed, progress=tick)
    print(f"{len(tasks)} tasks, {ns.episodes} episodes each, seed {ns.seed}: "
          f"{time.perf_counter() - began:.0f} s\n")  # fmt: skip
    print(text_table(COLUMNS, [])[0])
    failed = []
    for row in rows:
        print(text_table(COLUMNS[:3], [[row.task, "oracle", f"{row.oracle:.3f}"]])[1])
        emit(f"{row.task}: oracle headline", row.oracle, "")
        emit(f"{row.task}: causal oracle headline", row.causal, "")
        print(text_table(COLUMNS[:3], [["", "causal oracle", f"{row.causal:.3f}"]])[1])
        for name, value in row.others.items():
            ratio, causal = row.ratios[name], row.causal_ratios[name]
            closed = "" if name == "pid" else f"{100 * row.gap_closed(name):.0f}%"
            cells = [f"{value:.3f}", f"{ratio:.3f}", f"{causal:.3f}", f"{1.0 / causal:.2f}"]
            print(text_table(COLUMNS, [["", name, *cells, closed]])[1])
            emit(
                f"{row.task}: causal oracle's headline / {name}'s",
                causal,
                "",
                at_most=1.0 + ns.tolerance,
                note=f"headline {value:.3f}"
                + ("" if name == "pid" else f"; {100 * row.gap_closed(name):.0f} % PID->limit"),
            )
            for bound, r in (("oracle", ratio), ("causal oracle", causal)):
                if r > 1.0 + ns.tolerance:
                    failed.append(f"{row.task}/{bound}/{name}")
    print(
        "\nPID->limit: how much of the way from the PID's headline to the causal limit's a "
        "controller goes (100 %: the limit; below 0: worse than the PID)"
    )
    print(
        f"verdict: the oracle and the causal oracle at or below every deployable controller "
        f"within {100 * ns.tolerance:g} % on every task: "
        + ("PASS" if not failed else f"FAIL ({', '.join(failed)})")
    )
    return 1 if ns.strict and failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
