"""One record per measured figure: the schema every benchmark script's results share.

A script states each figure it measures with :func:`emit` (a name, the value, its unit
and, where the figure has one, its target).  Run through ``benchmarks/suite.py run``,
the figures are stamped with the command, the commit, the machine and the date and kept
in ``benchmarks/records.jsonl``; run by hand, :func:`emit` does nothing and the script
prints what it always printed.  ``benchmarks/suite.py tables`` writes the benchmark
page's tables from the records.
"""

from __future__ import annotations

import json
import math
import os
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["ENV", "Record", "Target", "emit"]

#: Where a script run by the suite writes its figures (a JSON line each).
ENV = "ROCKETROLL_BENCH_RECORDS"

Kind = Literal["timing", "study"]
Verdict = Literal["PASS", "FAIL"]


class Target(BaseModel):
    """A figure's target: ``value op bound`` (``<=``: at most, ``>=``: at least)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    op: Literal["<=", ">="]
    bound: float

    def verdict(self, value: float) -> Verdict:
        met = value <= self.bound if self.op == "<=" else value >= self.bound
        return "PASS" if met and math.isfinite(value) else "FAIL"

    def __str__(self) -> str:
        return f"{'≤' if self.op == '<=' else '≥'} {self.bound:g}"


class Record(BaseModel):
    """One figure as measured: what, by which command, at which commit, on which machine."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    figure: str = Field(description="what was measured, unique within its script")
    script: str = Field(description="the benchmark script, e.g. speed.py")
    kind: Kind = Field(description="a timing (machine-dependent) or a study (a result)")
    value: float
    unit: str
    target: Target | None = None
    verdict: Verdict | None = None
    note: str = ""
    command: str = Field(description="the command that measured it, as run")
    commit: str = Field(description="the commit measured (+dirty: with changes)")
    machine: str = Field(description="CPU, cores, Python and numpy of the machine")
    date: str = Field(description="the day measured, YYYY-MM-DD")


def emit(
    figure: str,
    value: float,
    unit: str,
    *,
    target: tuple[Literal["<=", ">="], float] | None = None,
    note: str = "",
) -> None:
    """State one measured figure (kept when the suite runs the script; else nothing)."""
    path = os.environ.get(ENV)
    if not path:
        return
    goal = None if target is None else Target(op=target[0], bound=target[1])
    line = {
        "figure": figure,
        "value": float(value),
        "unit": unit,
        "target": None if goal is None else goal.model_dump(),
        "verdict": None if goal is None else goal.verdict(float(value)),
        "note": note,
    }
    with open(path, "a", encoding="utf-8") as out:
        out.write(json.dumps(line, allow_nan=True) + "\n")
