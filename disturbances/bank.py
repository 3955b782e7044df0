"""``TraceBank``: traces held in memory for drawing episode windows without SQL.

The environment draws a window of ``u_d`` at every ``reset``.  A bank loads
the matching traces once (checked against their checksums) and then draws a
window in a few microseconds: one integer from the caller's generator picks a
(trace, offset) pair uniformly among all windows of that length, and the
window is a read-only view, not a copy.  ``benchmarks/db_windows.py`` measures
it against the 100 µs budget.

A bank loaded from a database holds its traces in :func:`draw_order`, a key made
of what each trace is (its recording's name and content hash, its method, model,
kind and seed, its uid), never the store's row order: the same seed draws the
same episodes from a database, from its export imported back, and from one whose
rows were added in any other order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from disturbances.rows import TraceRow
from disturbances.stores import Store, check_filters
from identification.model import Rig, RollParams
from rocketroll_common.arrays import FloatArray
from rocketroll_common.errors import RocketrollError
from rocketroll_physics.flown import interval_means

__all__ = ["REPLAY_OF_KIND", "BankError", "TraceBank", "Window", "draw_order"]

#: The environment's ``disturbance`` option that replays each kind of trace.
REPLAY_OF_KIND = {"identified": "replay", "surrogate": "surrogate", "posterior": "posterior"}


class BankError(RocketrollError, ValueError):
    """A database or bank lacks what a replay needs; the message says what it holds and
    how to get what is missing."""


@dataclass(frozen=True, eq=False)
class Window:
    """A stretch of one trace.

    Attributes
    ----------
    trace : int
        Index of the trace in its bank.
    uid : str
        The trace's uid.
    start : int
        Index of the first sample in the trace.
    u_d_deg : ndarray, shape (n,)
        The samples, ° (a read-only view into the bank).
    dt_s : float
        Δt of each sample, s.
    params : RollParams
        The parameters identified together with the trace.
    """

    trace: int
    uid: str
    start: int
    u_d_deg: FloatArray
    dt_s: float
    params: RollParams

    @property
    def start_s(self) -> float:
        """Offset of the window from the start of the trace, s."""
        return self.start * self.dt_s

    def __repr__(self) -> str:
        return (
            f"Window(uid={self.uid!r}, start={self.start_s:g} s, n={self.u_d_deg.size}, "
            f"dt={self.dt_s:g} s)"
        )


def _lacking(
    db: Store,
    split: str,
    method: str,
    model: str,
    kind: Any,
    described: str,
    recording: str | None = None,
) -> str:
    """Why ``db`` has no traces of a selection: what it holds, and how to replay that or
    add what is missing."""
    rows = db.traces()
    if recording is not None and not any(r.recording == recording for r in rows):
        names = sorted({r.recording for r in rows if r.split == split}) or ["none"]
        return (
            f"{db.path}: no recording named {recording!r} ({described}); its {split} split "
            f"holds {', '.join(names)} (recording=NAME, as `rocketroll db list --db {db.path}` "
            "names them)"
        )
    if recording is not None:
        rows = [r for r in rows if r.recording == recording]
        where = {str(r.split) for r in rows}
        if split not in where:
            return (
                f"{db.path}: recording {recording!r} is in the {', '.join(sorted(where))} split, "
                f"not {split} ({described})"
            )
    held: dict[tuple[str, str, str], int] = {}
    for row in rows:
        if row.model == model:
            key = (str(row.split), row.method, row.kind)
            held[key] = held.get(key, 0) + 1
    kinds = [kind] if isinstance(kind, str) else list(kind)
    want = f"{'/'.join(kinds)} traces of {method}'s {model} model in the {split} split"
    if not any(s == split for s, _, _ in held):
        splits = sorted({s for s, _, _ in held}) or ["none"]
        return (
            f"{db.path}: no {want} ({described}): none of its recordings is in the {split} "
            f"split (it has {', '.join(splits)}); add one there with `rocketroll db add "
            f"RECORDING --db {db.path} --split {split}`"
        )
    have = sorted((m, k, n) for (s, m, k), n in held.items() if s == split)
    if any(m == method and k in kinds for m, k, _ in have):  # other filters left none
        return f"{db.path}: no traces match {described}"
    listed = ", ".join(f"{n} {k} of {m}" for m, k, n in have)
    other_method, other_kind, _ = have[0]
    replay = REPLAY_OF_KIND.get(other_kind, other_kind)
    draws = " --posterior 8" if "posterior" in kinds else ""
    return (
        f"{db.path}: no {want} ({described}); its {split} split holds {listed}: replay those "
        f"(--set method={other_method} --set disturbance={replay}) or add them (`rocketroll "
        f"db add RECORDING --db {db.path} --method {method}{draws}`)"
    )


def draw_order(row: TraceRow) -> tuple[Any, ...]:
    """The key a bank loaded from a database sorts its traces by.

    Intrinsic to the trace, the same in every database and export: its
    recording's name and content hash (two recordings of one name stay apart),
    its identification's method and model, the identified trace before its
    draws, then the draws by source, kind and seed (as a number), and the uid
    last (unique).  A database's row ids or insertion order play no part, so a
    seed draws the same episodes from a database and from its export imported
    back.  The default database's build adds its recordings in name order
    within each split, so there this order is also the row order.
    """
    seed = -1 if row.seed is None else int(row.seed)
    return (
        row.recording,
        row.recording_hash,
        row.method,
        row.model,
        row.source_uid is not None,
        row.source_uid or "",
        row.kind,
        seed,
        row.uid,
    )


def _one(value: Any) -> str | None:
    """A filter's single value (None for none or a list)."""
    return value if isinstance(value, str) else None


class TraceBank:
    """Traces in memory, for fast windows.

    Parameters
    ----------
    traces : sequence of TraceRow
        The traces with their samples and parameters (e.g.
        ``db.load_traces(db.traces(split="train"))``).
    description : str
        What was selected, for error messages (e.g. ``split='train'``).

    Examples
    --------
    >>> import numpy as np
    >>> bank = TraceBank.from_arrays([np.arange(10.0)], dt_s=0.1)
    >>> w = bank.window(np.random.default_rng(0), 0.5)
    >>> w.u_d_deg.size, float(w.u_d_deg[1] - w.u_d_deg[0])
    (5, 1.0)
    """

    def __init__(self, traces: Sequence[TraceRow], description: str = "the selection") -> None:
        if not traces:
            raise ValueError(f"no traces match {description}")
        self.traces = tuple(traces)
        self.description = description
        self._arrays = [t.samples() for t in self.traces]
        self._uids = [t.uid for t in self.traces]
        self._dts = np.array([t.dt_s for t in self.traces])
        self._params = [t.rocket() for t in self.traces]
        self._rigs = tuple(t.rig for t in self.traces)
        self._sizes = np.array([a.size for a in self._arrays], dtype=np.int64)
        self._plans: dict[float, tuple[np.ndarray, np.ndarray, int]] = {}
        self._flat: tuple[FloatArray, np.ndarray] | None = None

    @classmethod
    def from_db(
        cls,
        db: Store,
        split: str,
        *,
        method: str = "paper",
        model: str = "theta",
        kind: str | Sequence[str] = "identified",
        validated: bool = True,
        **filters: Any,
    ) -> TraceBank:
        """Load the traces of one split (see :meth:`disturbances.db.DisturbanceDB.traces`
        for ``filters``).

        ``split`` is required, so a bank never mixes training and evaluation
        disturbances.  The defaults select each recording once: the paper's
        method, the θ-dependent model, identified traces (``kind="surrogate"``
        for surrogates), and only surrogates that passed their check.  The
        traces are in :func:`draw_order`, not the store's row order, so a seed
        draws the same windows from any database holding the same traces.
        """
        if split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', not {split!r}")
        filters = {
            "split": split,
            "method": method,
            "model": model,
            "kind": kind,
            "validated": validated,
            **filters,
        }
        check_filters(db, filters)
        infos = db.traces(**filters)
        described = ", ".join(f"{k}={v!r}" for k, v in filters.items() if v is not None)
        if not infos:
            raise BankError(
                _lacking(db, split, method, model, kind, described, _one(filters.get("recording")))
            )
        return cls(db.load_traces(sorted(infos, key=draw_order)), described or "all traces")

    @classmethod
    def from_arrays(
        cls,
        arrays: Sequence[FloatArray],
        dt_s: float,
        params: RollParams | None = None,
        rig: Rig | None = None,
    ) -> TraceBank:
        """A bank of bare arrays (tests, user-made disturbances), of the rocket ``params``
        (the paper's) on ``rig`` (the model's)."""
        from disturbances.rows import checksum, plain_statistics
        from identification.model import PAPER_THETA, model_of
        from rocketroll_common.arrays import readonly_array

        p = PAPER_THETA if params is None else params
        traces = []
        for k, values in enumerate(arrays):
            u = readonly_array(values)
            digest = checksum(u)
            traces.append(
                TraceRow(
                    uid=f"array-{k}-{digest[:8]}",
                    recording_hash=digest,
                    method="given",
                    model=model_of(p),
                    kind="identified",
                    source_uid=None,
                    seed=None,
                    settings={},
                    dt_s=float(dt_s),
                    t0_s=0.0,
                    checksum=digest,
                    statistics=plain_statistics(u),
                    validation=None,
                    u_d_deg=u,
                    params=p,
                    recording=f"array-{k}",
                    source="synthetic",
                    split="train",
                    id=k,
                    rig=Rig() if rig is None else rig,
                )
            )
        return cls(traces, "the given arrays")

    def __len__(self) -> int:
        return len(self.traces)

    def __repr__(self) -> str:
        return f"TraceBank({len(self)} traces, {self.total_duration_s:g} s, {self.description})"

    @property
    def total_duration_s(self) -> float:
        """Sum of the traces' lengths, s."""
        return float(np.sum(self._sizes * self._dts))

    @property
    def longest_s(self) -> float:
        """The longest trace, s."""
        return float(np.max(self._sizes * self._dts))

    @property
    def params(self) -> tuple[RollParams, ...]:
        """Each trace's parameters, in bank order."""
        return tuple(self._params)

    @property
    def rigs(self) -> tuple[Rig, ...]:
        """Each trace's rig (its identification's linkage and latency), in bank order."""
        return self._rigs

    def samples_for(self, duration_s: float) -> np.ndarray:
        """Samples a window of ``duration_s`` takes in each trace (at least one)."""
        return np.maximum(np.ceil(duration_s / self._dts - 1e-9), 1).astype(np.int64)

    def _plan(self, duration_s: float) -> tuple[np.ndarray, np.ndarray, int]:
        plan = self._plans.get(duration_s)
        if plan is None:
            self.require(duration_s)
            lengths = self.samples_for(duration_s)
            offsets = np.maximum(self._sizes - lengths + 1, 0)
            cum = np.cumsum(offsets)
            plan = (cum, lengths, int(cum[-1]))
            if len(self._plans) >= 64:  # callers use a few durations; keep the cache small
                self._plans.clear()
            self._plans[duration_s] = plan
        return plan

    def on_grid(self, dt_s: float, substep_s: float) -> TraceBank:
        """This bank, replayable on a grid of ``substep_s``: as it is where every trace has
        one Δt that is a whole number of substeps; otherwise with every trace of another Δt
        than ``dt_s`` (the control period) replaced by its exact averages over the whole
        ``dt_s`` intervals it covers (:func:`interval_means`), under its own uid."""
        from disturbances.rows import derived_row

        per = self._dts / substep_s
        whole = np.all(np.abs(per - np.round(per)) <= 1e-9 * per) and np.all(np.round(per) >= 1)
        if whole and np.unique(np.round(per)).size == 1:
            return self
        rows = []
        for row, values, dt in zip(self.traces, self._arrays, self._dts, strict=True):
            if abs(dt - dt_s) <= 1e-9 * dt_s:
                rows.append(row)
                continue
            count = math.floor(values.size * dt / dt_s + 1e-9)
            if count < 2:
                raise ValueError(
                    f"trace {row.uid} ({values.size * dt:g} s) is shorter than two {dt_s:g}-s "
                    "control periods"
                )
            edges = np.arange(count + 1, dtype=np.float64) * dt_s
            u = interval_means(values, float(dt), edges)
            rows.append(derived_row(row, u, dt_s, None, {"averaged_from_dt_s": float(dt)}))
        return TraceBank(rows, f"{self.description}, averaged onto {dt_s:g}-s steps")

    def require(self, duration_s: float) -> None:
        """Raise :class:`BankError` unless some trace is at least ``duration_s`` long."""
        if not (math.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"window duration must be positive, got {duration_s!r}")
        if not np.any(self._sizes >= self.samples_for(duration_s)):
            raise BankError(
                f"an episode is {duration_s:g} s, and the longest trace of {self.description} "
                f"is {self.longest_s:g} s: shorten the episode (--set episode_s={self.longest_s:g} "
                "or less) or add a longer recording"
            )

    def window(self, rng: np.random.Generator, duration_s: float) -> Window:
        """A window of ``duration_s``, uniform over every (trace, offset) that fits.

        Longer traces are drawn more often, in proportion to the windows they
        hold; the offset is on the trace's own Δt grid.
        """
        cum, lengths, total = self._plan(duration_s)
        k = int(rng.integers(total))
        i = int(np.searchsorted(cum, k, side="right"))
        start = k - (int(cum[i - 1]) if i else 0)
        n = int(lengths[i])
        return Window(
            trace=i,
            uid=self._uids[i],
            start=start,
            u_d_deg=self._arrays[i][start : start + n],
            dt_s=float(self._dts[i]),
            params=self._params[i],
        )

    def draw(
        self, rng: np.random.Generator, duration_s: float, size: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """``size`` windows at once, drawn as :meth:`window` does: ``(trace, start)`` arrays.

        One ``rng.integers`` call for all of them, so a batch of environments
        resets without a Python loop.
        """
        cum, _, total = self._plan(duration_s)
        k = rng.integers(total, size=size)
        i = np.searchsorted(cum, k, side="right")
        start = k - np.where(i > 0, cum[np.maximum(i - 1, 0)], 0)
        return i.astype(np.int64), start.astype(np.int64)

    def concatenated(self) -> tuple[FloatArray, np.ndarray]:
        """All traces end to end and the index where each begins (for batched replay)."""
        if self._flat is None:
            flat = np.concatenate(self._arrays) if len(self._arrays) > 1 else self._arrays[0]
            offsets = np.concatenate([[0], np.cumsum(self._sizes)[:-1]]).astype(np.int64)
            flat = np.array(flat, dtype=np.float64)
            flat.flags.writeable = False
            self._flat = (flat, offsets)
        return self._flat

    def at(self, trace: int, start: int, duration_s: float) -> Window:
        """A given window (``trace`` index, ``start`` sample): for replays and evaluation."""
        if not 0 <= trace < len(self):
            raise IndexError(f"trace index {trace} out of range 0..{len(self) - 1}")
        n = int(self.samples_for(duration_s)[trace])
        if not 0 <= start <= self._sizes[trace] - n:
            raise ValueError(
                f"a {duration_s:g} s window at sample {start} does not fit in trace "
                f"{self._uids[trace]} ({self._sizes[trace]} samples)"
            )
        return Window(
            trace=trace,
            uid=self._uids[trace],
            start=start,
            u_d_deg=self._arrays[trace][start : start + n],
            dt_s=float(self._dts[trace]),
            params=self._params[trace],
        )
