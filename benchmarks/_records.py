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
    """A figure's target: at least ``low`` and/or at most ``high``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    low: float | None = None
    high: float | None = None

    def verdict(self, value: float | None) -> Verdict:
        if value is None or not math.isfinite(value):
            return "FAIL"
        met = (self.low is None or value >= self.low) and (self.high is None or value <= self.high)
        return "PASS" if met else "FAIL"

    def __str__(self) -> str:
        if self.low is not None and self.high is not None:
            return f"{self.low:g} to {self.high:g}"
        return f"≥ {self.low:g}" if self.low is not None else f"≤ {self.high:g}"


class Record(BaseModel):
    """One figure as measured: what, by which command, at which commit, on which machine."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    figure: str = Field(description="what was measured, unique within its script")
    script: str = Field(description="the benchmark script, e.g. speed.py")
    kind: Kind = Field(description="a timing (machine-dependent) or a study (a result)")
    value: float | None = Field(description="None: not finite (the note says what it was)")
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
    at_least: float | None = None,
    at_most: float | None = None,
    note: str = "",
) -> None:
    """State one measured figure and its target if it has one (kept when the suite runs
    the script; else nothing)."""
    path = os.environ.get(ENV)
    if not path:
        return
    has_target = at_least is not None or at_most is not None
    goal = Target(low=at_least, high=at_most) if has_target else None
    number: float | None = float(value)
    if not math.isfinite(float(value)):  # JSON has no NaN: kept as null, said in the note
        number, note = None, f"{float(value)}" + (f"; {note}" if note else "")
    line = {
        "figure": figure,
        "value": number,
        "unit": unit,
        "target": None if goal is None else goal.model_dump(),
        "verdict": None if goal is None else goal.verdict(number),
        "note": note,
    }
    with open(path, "a", encoding="utf-8") as out:
        out.write(json.dumps(line, allow_nan=False) + "\n")
