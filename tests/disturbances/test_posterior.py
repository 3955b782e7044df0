"""Posterior u_d draws (``kind="posterior"``): stored with provenance, loaded, replayed."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import rollenv  # noqa: F401  (registers the environments)
from disturbances.bank import TraceBank
from disturbances.db import DisturbanceDB
from disturbances.exchange import import_export, write_export
from disturbances.ingest import add_recording
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods.pipeline import IdentifyOptions
from identification.recordings.recording import Recording
from rocketroll.cli import main as rocketroll

FAST = IdentifyOptions(noise_runs=0)


def short_run(seed: int, split: str) -> Recording:
    """A 2-3 minute staircase of a rocket unlike the paper's (fast to identify)."""
    return run_tunnel(
        TunnelSpec(
            seed=seed,
            schedule="staircase",
            steps=5,
            dwell_min=20.0,
            dwell_max=30.0,
            alpha=0.9,
            beta=-3.0,
            split=split,  # type: ignore[arg-type]
        )
    )


@pytest.fixture(scope="module")
def posterior_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("posterior") / "p.sqlite"
    with DisturbanceDB(path, create=True) as db:
        add_recording(db, short_run(1, "train"), FAST, methods=["ml"], posterior=3)
        add_recording(db, short_run(2, "test"), FAST, methods=["ml", "paper"], posterior=2)
    return path


def test_draws_are_stored_with_their_source_seed_and_parameters(posterior_db: Path) -> None:
    with DisturbanceDB(posterior_db) as db:
        draws = db.traces(kind="posterior", split="train")
        assert [t.seed for t in draws] == [0, 1, 2, 0, 1, 2]  # per model
        assert db.counts()["posterior"] == 3 * 2 + 2 * 2
        assert db.counts()["surrogates"] == 0
        for draw in draws:
            source = db.trace(draw.source_uid or "")
            assert source.kind == "identified" and source.method == "ml"
            assert draw.uid == f"{source.uid}-posterior-{draw.seed}"
            assert draw.params == source.params and draw.model == source.model
            assert draw.n_samples == source.n_samples and draw.dt_s == source.dt_s
            assert "posterior draw" in draw.settings["estimate"]
        # The draws differ from each other and from the posterior mean, and are rougher.
        mean = db.trace(draws[0].source_uid or "").samples()
        samples = [db.trace(d.uid).samples() for d in draws[:3]]
        assert not np.array_equal(samples[0], samples[1])
        assert all(np.std(s) > np.std(mean) for s in samples)


def test_the_same_fit_and_seed_give_the_same_draws(posterior_db: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.sqlite"
    with DisturbanceDB(again, create=True) as db:
        add_recording(db, short_run(1, "train"), FAST, methods=["ml"], posterior=3)
        ours = {t.uid: t.checksum for t in db.traces(kind="posterior")}
    with DisturbanceDB(posterior_db) as db:
        theirs = {t.uid: t.checksum for t in db.traces(kind="posterior", split="train")}
    assert ours == theirs


def test_a_method_without_a_posterior_is_refused(tmp_path: Path) -> None:
    with DisturbanceDB(tmp_path / "x.sqlite", create=True) as db:
        with pytest.raises(ValueError, match="none of paper has one"):
            add_recording(db, short_run(1, "train"), FAST, methods=["paper"], posterior=2)
        assert db.counts()["recordings"] == 0  # nothing half-written
    code = rocketroll(
        ["db", "add", "x.csv", "--db", str(tmp_path / "y.sqlite"), "--posterior", "2"]
    )
    assert code == 2


def test_draws_load_into_a_bank_and_the_environment_replays_them(posterior_db: Path) -> None:
    with DisturbanceDB(posterior_db) as db:
        bank = TraceBank.from_db(db, "train", method="ml", kind="posterior")
        stored = {
            t.uid: db.trace(t.uid).samples() for t in db.traces(kind="posterior", split="train")
        }
    assert len(bank) == 3 and all(t.kind == "posterior" for t in bank.traces)
    env = gym.make(
        "RocketRoll-v0", db=str(posterior_db), method="ml", disturbance="posterior", split="train"
    )
    _, info = env.reset(seed=0)
    uid = info["trace"]
    assert uid in stored
    _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    trace = stored[uid]
    k = round(info["start_s"] / 0.1)
    assert info["u_d_deg"] == pytest.approx(trace[k], abs=1e-9)
    env.close()


def test_draws_survive_export_and_import(posterior_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "export"
    with DisturbanceDB(posterior_db) as db:
        write_export(db, out, "csv", kind="posterior")  # their sources come along
        before = {t.uid: t.checksum for t in db.traces(kind="posterior")}
    with DisturbanceDB(tmp_path / "copy.sqlite", create=True) as db:
        import_export(db, out)
        after = {t.uid: t.checksum for t in db.traces(kind="posterior")}
    assert after == before
