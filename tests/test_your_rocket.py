"""A user's own rocket, end to end: one run of a rocket unlike the bundled ones, split
for an honest evaluation, designs on that rocket and learned policies labelled.

The run is the virtual tunnel's, on ramps (not the paper's long dwells), with a fast,
high-gain rocket (α 2.5 (°/s)/°, a 6 1/s) and θ̄ < 0; nothing here is the paper's rocket.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agents.base import Design
from agents.nominal import NominalModel
from agents.replay import fitted_settings, options_config
from disturbances.db import DisturbanceDB
from identification.instruments.tunnel import run_tunnel, spec_from_command
from identification.recordings.recording import load_recording
from tests.cli import ok, refused

TRUTH = "--model constant --alpha 2.5 --beta -5 --beta-bar 6 --turbulence-sd 3"
RUN = (
    "--seed 3 --log-dt 0.01 --gyro-noise 1 --schedule ramps --steps 8 --dwell-min 2 "
    f"--dwell-max 3 --lead 1 --ramp 1 --name mine {TRUTH}"
)


@pytest.fixture(scope="module")
def mine(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The run as a recording, and a database holding it split 60/40."""
    from disturbances.ingest import add_recording
    from identification.recordings.recording import save_recording

    folder = tmp_path_factory.mktemp("mine")
    rec = run_tunnel(spec_from_command(RUN))
    path = folder / "mine.csv"
    save_recording(rec, path)
    db = folder / "mine.sqlite"
    with DisturbanceDB(db) as store:
        add_recording(store, rec, methods=["ml"], posterior=2, holdout=0.4)
    return path, db


def test_the_holdout_stores_a_design_part_and_the_held_out_end(mine: tuple[Path, Path]) -> None:
    path, db = mine
    rec = load_recording(path)
    with DisturbanceDB(db, create=False) as store:
        parts = {r.split: r for r in store.recordings()}
        assert {r.name for r in parts.values()} == {"mine"}
        design, held = parts["train"], parts["test"]
        cut = float(held.metadata["part.from_s"])
        assert cut == pytest.approx(rec.time_s[0] + 0.6 * rec.duration_s, abs=0.011)
        # the design part ends before the cut: nothing of the held-out end was fitted there
        assert design.metadata["part"] == "design" and design.duration_s < cut
        # the judge is fitted on the whole run; its traces replay only the held-out end
        assert held.n_samples == rec.n_samples
        for trace in store.traces(split="test"):
            assert trace.t0_s >= cut - 1e-9 and trace.t0_s < cut + trace.dt_s
            assert trace.duration_s == pytest.approx(rec.time_s[-1] - trace.t0_s, abs=0.11)
        for trace in store.traces(split="train"):
            assert trace.t0_s + trace.duration_s <= cut + 1e-9
        judged = store.identifications(recording_hash=held.content_hash)
        assert {i.verdict for i in judged} == {"good"}
        fitted = store.identifications(recording_hash=design.content_hash)
        assert all(abs(i.params.alpha / 2.5 - 1) < 0.1 for i in fitted)


def test_designs_read_the_recordings_own_rocket(mine: tuple[Path, Path]) -> None:
    _, db = mine
    config = options_config("RocketRoll-v0", {"recording": "mine"}, "test")
    design = Design(config, "RocketRoll-v0", db=str(db))
    assert design.train_bank.description.endswith("recording='mine'")
    nominal = NominalModel.from_bank(design.train_bank)
    assert nominal.alpha == pytest.approx(2.5, rel=0.1)
    # θ̄ = β/α = -2° (the bundled rockets' is +3.7°); 20 s of turbulence of SD 3° leave
    # it within about a degree
    assert nominal.theta_bar_deg == pytest.approx(-2.0, abs=1.5)


def test_eval_on_the_recording_fits_the_episode_and_labels_a_policy_trained_elsewhere(
    mine: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, db = mine
    out = tmp_path / "eval"
    argv = ["eval", "--db", str(db), "--recording", "mine", "--episodes", "4", "--out", str(out)]
    printed = ok(capsys, [*argv, *(f"--policy={p}" for p in ("trim", "pid", "observer", "ppo"))])
    assert "recording mine" in printed
    line = next(x for x in printed.splitlines() if x.strip().startswith("episode:"))
    episode_s = float(line.split()[1])
    with DisturbanceDB(db, create=False) as store:
        longest = max(t.duration_s for t in store.traces(split="test"))
    assert longest - 0.1 < episode_s <= longest  # the held-out end, in whole 0.1-s steps
    assert "| PPO (trained on another database's rockets) |" in printed
    assert "| observer |" in printed and "| PID |" in printed
    results = json.loads((out / "results.json").read_text())
    assert results["protocol"]["settings"] == {"recording": "mine", "episode_s": episode_s}
    assert "recording='mine'" in results["protocol"]["bank"]
    # the observer, designed on this rocket, holds the angle better than the trim floor
    rows = results["controllers"]
    scores = {name: r["aggregate"]["regulation_rms_error"]["mean"] for name, r in rows.items()}
    assert scores["observer"] < scores["trim"]


def test_tune_and_training_read_the_same_selection(
    mine: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _, db = mine
    printed = ok(
        capsys,
        ["tune", "pid", "--db", str(db), "--recording", "mine", "--episodes", "2",
         "--omegas", "2,4"],
    )  # fmt: skip
    assert "recording='mine'" in printed and "--recording mine" in printed
    hint = printed.splitlines()[-1]  # eval fits its own episode to the held-out trace
    assert hint.startswith("use it with:") and "episode_s" not in hint
    settings, note = fitted_settings("RocketRoll-v0", {}, "mine", str(db))
    assert note is not None and settings["recording"] == "mine"
    with DisturbanceDB(db, create=False) as store:
        shortest = min(
            max(t.duration_s for t in store.traces(split=split)) for split in ("train", "test")
        )
    assert shortest - 0.1 < settings["episode_s"] <= shortest
    assert fitted_settings("RocketRoll-v0", {"episode_s": 3.0}, "mine", str(db))[1] is None
    refused(
        capsys,
        ["eval", "--db", str(db), "--recording", "mine", "--set", "recording=other"],
        "--recording mine",
    )


def test_a_method_is_not_added_to_a_split_run_as_a_whole_one(
    mine: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, db = mine
    import sqlite3

    copy = tmp_path / "copy.sqlite"
    source, target = sqlite3.connect(db), sqlite3.connect(copy)  # with its write-ahead log
    source.backup(target)
    source.close()
    target.close()
    argv = ["db", "add", str(path), "--db", str(copy), "--method", "output-error"]
    refused(capsys, argv, "stored split for a held-out evaluation", "--method output-error")


def test_db_add_holdout_refuses_what_it_cannot_honour(
    mine: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path, _ = mine
    new = tmp_path / "new.sqlite"
    base = ["db", "add", str(path), "--db", str(new), "--method", "ml"]
    refused(capsys, [*base, "--holdout", "0.4", "--split", "test"], "--holdout", "--split")
    refused(capsys, [*base, "--holdout", "0.95"], "--holdout")
    assert not new.exists()
    # a run the database holds already is not split beside its whole traces
    ok(capsys, [*base, "--mc-runs", "0"])
    refused(capsys, [*base, "--holdout", "0.4"], "holds this run's samples (mine) already")
    with DisturbanceDB(new, create=False) as store:
        assert len(store.recordings()) == 1


def test_a_recording_split_by_hand_keeps_its_times() -> None:
    rec = run_tunnel(spec_from_command(RUN))
    part = rec.part(5.0, 10.0, part="x")
    assert part.time_s[0] == pytest.approx(5.0) and part.time_s[-1] < 10.0
    assert part.metadata["part"] == "x" and part.name == rec.name
    assert part.fin_cmd_deg is not None and rec.fin_cmd_deg is not None
    assert np.array_equal(part.fin_cmd_deg, rec.fin_cmd_deg[(rec.time_s >= 5) & (rec.time_s < 10)])
