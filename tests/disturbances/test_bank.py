"""``TraceBank``: episode windows drawn from traces held in memory.

A window has the length its duration takes on the trace's Δt grid, is a
read-only view equal to the stored trace's slice, carries the trace's
parameters, is reproducible from the generator's seed and uniform over every
(trace, offset) that fits; impossible requests are errors that say why.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats

from disturbances.bank import BankError, TraceBank, Window
from disturbances.db import DisturbanceDB
from disturbances.rows import TraceRow
from identification.model import PAPER_THETA, RollParams

WINDOW_S = 60.0
TRAIN_THETA: dict[str, Any] = {
    "split": "train",
    "method": "paper",
    "model": "theta",
    "kind": "identified",
}


@pytest.fixture(scope="module")
def bank(small_db: Path) -> TraceBank:
    with DisturbanceDB(small_db, create=False) as db:
        return TraceBank.from_db(db, **TRAIN_THETA)


@pytest.fixture(scope="module")
def stored(small_db: Path) -> TraceRow:
    """The one trace of the selection, read again from the database."""
    with DisturbanceDB(small_db, create=False) as db:
        (info,) = db.traces(**TRAIN_THETA)
        return db.trace(info.uid)


def test_from_db_selects_and_describes(bank: TraceBank, stored: TraceRow) -> None:
    assert len(bank) == 1
    (trace,) = bank.traces
    assert trace == stored
    assert np.array_equal(trace.samples(), stored.samples())
    assert (trace.split, trace.method, trace.model, trace.kind) == (
        "train",
        "paper",
        "theta",
        "identified",
    )
    assert bank.total_duration_s == pytest.approx(stored.n_samples * 0.1)
    assert bank.longest_s == pytest.approx(573.0)
    assert bank.params == (stored.params,)
    assert "split='train'" in bank.description and "model='theta'" in bank.description
    assert repr(bank).startswith("TraceBank(1 traces, 573 s, split='train'")


def test_window_is_a_readonly_view_of_the_trace(bank: TraceBank, stored: TraceRow) -> None:
    rng = np.random.default_rng(1)
    n_offsets = stored.n_samples - 600 + 1
    for _ in range(200):
        w = bank.window(rng, WINDOW_S)
        assert isinstance(w, Window)
        assert w.u_d_deg.shape == (600,)  # 60 s at Δt = 0.1 s
        assert w.dt_s == 0.1 and w.trace == 0 and w.uid == stored.uid
        assert 0 <= w.start < n_offsets
        assert w.start_s == pytest.approx(w.start * 0.1)
        assert np.array_equal(w.u_d_deg, stored.samples()[w.start : w.start + 600])
        assert np.shares_memory(w.u_d_deg, bank.traces[0].u_d_deg)  # a view, not a copy
        assert not w.u_d_deg.flags.writeable
        assert w.params == stored.params
    with pytest.raises(ValueError, match="read-only"):
        w.u_d_deg[0] = 0.0
    assert repr(w) == f"Window(uid={w.uid!r}, start={w.start_s:g} s, n=600, dt=0.1 s)"


def test_window_carries_the_identified_parameters(small_db: Path) -> None:
    with DisturbanceDB(small_db, create=False) as db:
        banks = [
            TraceBank.from_db(db, split, model=model)
            for split in ("train", "test")
            for model in ("constant", "theta")
        ]
        idents = {(i.recording, i.model): i.params for i in db.identifications(method="paper")}
    assert [len(b) for b in banks] == [1, 1, 1, 1]  # 2 recordings x 2 models
    rng = np.random.default_rng(3)
    seen = set()
    for bank in banks:
        for _ in range(20):
            w = bank.window(rng, WINDOW_S)
            info = bank.traces[w.trace]
            assert w.uid == info.uid
            assert w.params == idents[(info.recording, info.model)]
            seen.add(info.uid)
    assert len(seen) == 4
    # The two models of one recording have different parameters.
    assert len({b.params[0] for b in banks}) == 4


def test_same_seed_same_windows(bank: TraceBank, small_db: Path) -> None:
    def draws(b: TraceBank, seed: int, duration: float = WINDOW_S) -> list[tuple[str, int]]:
        rng = np.random.default_rng(seed)
        return [(w.uid, w.start) for w in (b.window(rng, duration) for _ in range(500))]

    with DisturbanceDB(small_db, create=False) as db:
        again = TraceBank.from_db(db, **TRAIN_THETA)
    assert draws(bank, 7) == draws(bank, 7) == draws(again, 7)
    assert draws(bank, 7) != draws(bank, 8)

    arrays = TraceBank.from_arrays([np.arange(50.0), np.arange(80.0), np.arange(30.0)], dt_s=1.0)
    assert draws(arrays, 7, 10.0) == draws(arrays, 7, 10.0)
    assert len(set(draws(arrays, 7, 10.0))) > 100


def test_windows_uniform_over_all_valid_offsets() -> None:
    # 10 and 20 samples at Δt = 1 s, 5-s windows: 6 + 16 = 22 (trace, start) pairs.
    bank = TraceBank.from_arrays([np.arange(10.0), 100 + np.arange(20.0)], dt_s=1.0)
    rng = np.random.default_rng(2024)
    n = 22_000
    counts: Counter[tuple[int, int]] = Counter()
    for _ in range(n):
        w = bank.window(rng, 5.0)
        assert w.u_d_deg.size == 5
        # Each sample holds its own index (plus 100 in trace 1): the view is the slice.
        assert w.u_d_deg[0] == w.start + 100 * w.trace
        counts[(w.trace, w.start)] += 1
    cells = [(0, s) for s in range(6)] + [(1, s) for s in range(16)]
    assert set(counts) == set(cells)  # every valid window, and no other
    observed = np.array([counts[c] for c in cells])
    assert stats.chisquare(observed).pvalue > 1e-3
    # Traces are drawn in proportion to the windows they hold (6 : 16).
    share = sum(counts[c] for c in cells[:6]) / n
    assert share == pytest.approx(6 / 22, abs=0.01)


def test_traces_too_short_for_the_window_are_never_drawn() -> None:
    arrays = [np.arange(3.0), np.arange(10.0), np.arange(4.0), np.arange(7.0), np.arange(2.0)]
    bank = TraceBank.from_arrays(arrays, dt_s=1.0)
    rng = np.random.default_rng(5)
    seen = Counter((w.trace, w.start) for w in (bank.window(rng, 5.0) for _ in range(3000)))
    assert set(seen) == {(1, s) for s in range(6)} | {(3, s) for s in range(3)}


def test_window_length_on_each_traces_own_grid() -> None:
    base = TraceBank.from_arrays([np.zeros(100), np.ones(100)], dt_s=0.1)
    coarse = dataclasses.replace(base.traces[1], dt_s=0.2)
    bank = TraceBank([base.traces[0], coarse])
    assert bank.samples_for(1.0).tolist() == [10, 5]
    assert bank.samples_for(0.25).tolist() == [3, 2]  # rounded up to whole samples
    rng = np.random.default_rng(0)
    for _ in range(100):
        w = bank.window(rng, 1.0)
        assert (w.u_d_deg.size, w.dt_s) == ((10, 0.1) if w.trace == 0 else (5, 0.2))
    # k·Δt takes exactly k samples, however k·Δt rounds in floating point.
    ks = np.arange(1, 1001)
    assert [int(base.samples_for(float(k) * 0.1)[0]) for k in ks] == ks.tolist()


def test_from_arrays_params_and_copies() -> None:
    params = RollParams(0.7, 3.0, 1.5, 0.0)
    values = np.arange(20.0)
    bank = TraceBank.from_arrays([values], dt_s=0.5, params=params)
    values[:] = -1.0  # the bank holds its own copy
    w = bank.window(np.random.default_rng(0), 2.0)
    assert w.params == params and w.u_d_deg.size == 4 and w.u_d_deg[0] >= 0
    assert bank.traces[0].model == "constant"
    assert TraceBank.from_arrays([np.arange(5.0)], dt_s=1.0).params == (PAPER_THETA,)


def test_window_longer_than_every_trace(bank: TraceBank) -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match=r"an episode is 600 s, and the longest trace .* 573 s"):
        bank.window(rng, 600.0)
    with pytest.raises(BankError, match=r"is 573 s: shorten the episode \(--set episode_s=573"):
        bank.require(573.1)
    bank.require(573.0)  # the whole trace is one window
    w = bank.window(rng, 573.0)
    assert w.start == 0 and w.u_d_deg.size == bank.traces[0].samples().size
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="must be positive"):
            bank.window(rng, bad)


def test_filters_with_no_match(small_db: Path) -> None:
    with DisturbanceDB(small_db, create=False) as db:
        with pytest.raises(BankError, match=r"no recording named 'no-such-recording' \(split="):
            TraceBank.from_db(db, "train", recording="no-such-recording")
        with pytest.raises(BankError, match=r"no traces match split='train'.*metadata="):
            TraceBank.from_db(db, "train", metadata={"rig": "no-such-rig"})
        with pytest.raises(BankError, match=r"no ar traces of paper's theta model .*kind='ar'"):
            TraceBank.from_db(db, "test", kind="ar")  # no AR surrogates in small_db
        with pytest.raises(ValueError, match="split must be 'train' or 'test'"):
            TraceBank.from_db(db, "validation")
        with pytest.raises(ValueError, match="unknown filter"):
            TraceBank.from_db(db, "train", colour="red")
        # A split is never mixed with the other; surrogates on request.
        both = TraceBank.from_db(db, "train", kind=["identified", "iaaft"])
        assert {t.split for t in both.traces} == {"train"} and len(both) == 2
    with pytest.raises(ValueError, match="no traces match"):
        TraceBank([])


def test_at(bank: TraceBank, stored: TraceRow) -> None:
    n = stored.n_samples
    w = bank.at(0, n - 600, WINDOW_S)
    assert w.start == n - 600 and np.array_equal(w.u_d_deg, stored.samples()[-600:])
    assert bank.at(0, 0, WINDOW_S).u_d_deg[0] == stored.samples()[0]
    with pytest.raises(IndexError, match=r"trace index 1 out of range 0\.\.0"):
        bank.at(1, 0, WINDOW_S)
    with pytest.raises(IndexError, match="out of range"):
        bank.at(-1, 0, WINDOW_S)
    with pytest.raises(ValueError, match=f"at sample {n - 599} does not fit"):
        bank.at(0, n - 599, WINDOW_S)
    with pytest.raises(ValueError, match="does not fit"):
        bank.at(0, -1, WINDOW_S)
    with pytest.raises(ValueError, match="does not fit"):
        bank.at(0, 0, 600.0)
    # A drawn window is replayed exactly.
    drawn = bank.window(np.random.default_rng(9), WINDOW_S)
    again = bank.at(drawn.trace, drawn.start, WINDOW_S)
    assert (again.uid, again.start) == (drawn.uid, drawn.start)
    assert np.array_equal(again.u_d_deg, drawn.u_d_deg)


def test_a_bank_pickles_and_deep_copies_with_surrogates(small_db: Path) -> None:
    """Vector environments in subprocesses and ``deepcopy(env)`` need this."""
    import copy
    import pickle

    with DisturbanceDB(small_db, create=False) as db:
        bank = TraceBank.from_db(db, "train", kind=["identified", "iaaft"])
    assert any(t.validation is not None for t in bank.traces)
    for clone in (pickle.loads(pickle.dumps(bank)), copy.deepcopy(bank)):
        a = clone.window(np.random.default_rng(5), WINDOW_S)
        b = bank.window(np.random.default_rng(5), WINDOW_S)
        assert (a.uid, a.start) == (b.uid, b.start)
        np.testing.assert_array_equal(a.u_d_deg, b.u_d_deg)
