"""Stored recordings replayed as stored: a flight shorter than the default ascent evaluates
with its episode fitted to it (as one tunnel recording's trace does), and a recording every
fit of which is judged unreliable is refused by ``db add`` unless accepted, then marked in
``db list`` and under every evaluation table that replays it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from disturbances.db import DisturbanceDB
from identification.instruments.bundled import bundled_path
from identification.instruments.flightlog import FlightLogSpec, run_flight
from identification.recordings.recording import save_recording
from rocketroll.cli import main
from rollenv.config import RollConfig

#: The flight's window: shorter than the default ascent's 21.2 s from 50 km/h to apogee.
WINDOW_S = 6.0
#: A bundled tunnel run the paper's method judges unreliable with both models.
UNRELIABLE = "tunnel-staircase-seed12"


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def one_error_line(err: str, command: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"rocketroll {command}: error: "), lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def short_flight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A database holding a flight's first WINDOW_S s (a cut window, as `import-csv --to`
    makes one), stored with one posterior draw per model."""
    root = tmp_path_factory.mktemp("short-flight")
    whole = run_flight(FlightLogSpec(seed=3, model="constant", split="test", name="short"))
    start = float(whole.time_s[0])
    save_recording(whole.part(start, start + WINDOW_S), root / "short.csv")
    db = root / "mine.sqlite"
    assert main(["db", "add", str(root / "short.csv"), "--db", str(db), "--posterior", "1"]) == 0
    return db


def test_a_short_stored_flight_evaluates_with_its_episode_fitted(
    short_flight: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The default ascent's episode (21.2 s) is longer than the stored flight: without
    --set episode_s the episode is the stored flight's, in eval and in gym.make; a longer
    one given is one line (exit 2) that says what to set, and nothing is written."""
    import gymnasium as gym

    import rollenv  # noqa: F401  (registers the variants)

    capsys.readouterr()
    default = RollConfig(flight="default").episode_length_s
    env = gym.make("RocketRollFlight-v0", db=str(short_flight), recording="short")
    config = env.unwrapped.config  # type: ignore[attr-defined]
    env.close()
    fitted = config.episode_length_s
    assert config.flies_stored_flight and fitted < WINDOW_S < default
    schedule = config.flight_schedule
    assert schedule is not None and fitted == pytest.approx(schedule.duration_s)

    out = tmp_path / "eval"
    argv = ["eval", "--env-id", "RocketRollFlight-v0", "--db", str(short_flight)]
    argv += ["--recording", "short", "--policy", "trim", "--episodes", "1"]
    code, printed, err = run_cli([*argv, "--out", str(out)], capsys)
    assert code == 0, err
    assert f"episode: {fitted:g} s, short's stored flight" in printed
    protocol = json.loads((out / "results.json").read_text())["protocol"]
    assert protocol["config"]["episode_s"] == pytest.approx(fitted)
    assert protocol["settings"]["episode_s"] == pytest.approx(fitted)
    assert "note" not in protocol  # its fits are good: nothing to say under the table

    shorter = tmp_path / "shorter"
    code, printed, err = run_cli([*argv, "--set", "episode_s=3", "--out", str(shorter)], capsys)
    assert code == 0, err
    assert json.loads((shorter / "results.json").read_text())["protocol"]["config"][
        "episode_s"
    ] == pytest.approx(3.0)

    longer = tmp_path / "longer"
    code, printed, err = run_cli([*argv, "--set", "episode_s=10", "--out", str(longer)], capsys)
    assert code == 2
    line = one_error_line(err, "eval")
    assert "episode_s = 10 s is longer than the flight" in line
    assert f"stored flight short ({short_flight}" in line
    assert f"give episode_s={fitted:g} or less, or leave it out" in line
    assert not longer.exists() and "Traceback" not in err


def test_db_add_refuses_a_recording_whose_fits_are_all_unreliable_unless_accepted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Refused in one line naming the verdict's reason and the override, nothing written;
    with --accept-unreliable stored and marked: db list shows the mark, and the evaluation
    that replays it says so under its table (printed, table.md, results.json)."""
    db = tmp_path / "mine.sqlite"
    add = ["db", "add", str(bundled_path(UNRELIABLE)), "--db", str(db), "--method", "paper"]
    add += ["--mc-runs", "0", "--split", "train"]
    code, _, err = run_cli(add, capsys)
    assert code == 2
    line = one_error_line(err, "db")
    assert f"{UNRELIABLE}: every fit of it is judged unreliable" in line
    assert "paper constant, paper theta: 1 of 12 steps give a damping a_i <= 0" in line
    assert "--accept-unreliable" in line
    assert not db.exists()

    code, printed, err = run_cli([*add, "--accept-unreliable"], capsys)
    assert code == 0, err
    assert "stored with --accept-unreliable, marked" in printed
    with DisturbanceDB(db, create=False) as store:
        rows = store.identifications(recording=UNRELIABLE)
    assert len(rows) == 2
    assert all(r.verdict == "unreliable" and r.accepted_unreliable for r in rows)
    good = ["db", "add", str(bundled_path("tunnel-paper-seed0")), "--db", str(db)]
    code, _, err = run_cli([*good, "--method", "paper", "--mc-runs", "0"], capsys)
    assert code == 0, err

    code, listed, _ = run_cli(["db", "list", "--db", str(db)], capsys)
    assert code == 0
    verdicts = {
        line.split()[1]: line.split("  ")[-1].strip()
        for line in listed.splitlines()
        if line.strip()[:1].isdigit()
    }
    marked = {uid for uid, verdict in verdicts.items() if verdict == "unreliable, accepted"}
    assert len(verdicts) == 4 and len(marked) == 2
    assert {verdicts[uid] for uid in verdicts.keys() - marked} == {"good"}
    assert listed.splitlines()[-1].startswith("accepted: stored with db add --accept-unreliable")

    note = (
        f"note: replays {UNRELIABLE}, whose fits were judged unreliable "
        "(stored with --accept-unreliable)"
    )
    out = tmp_path / "eval"
    argv = ["eval", "--db", str(db), "--recording", UNRELIABLE, "--set", "method=paper"]
    argv += ["--split", "train", "--policy", "trim", "--episodes", "1", "--out", str(out)]
    code, printed, err = run_cli(argv, capsys)
    assert code == 0, err
    assert note in printed
    assert (out / "table.md").read_text().rstrip().endswith(note)
    assert json.loads((out / "results.json").read_text())["protocol"]["note"] == note
    # A replay of the good recording alone carries no note.
    other = tmp_path / "other"
    argv = ["eval", "--db", str(db), "--recording", "tunnel-paper-seed0", "--set", "method=paper"]
    argv += ["--split", "train", "--policy", "trim", "--episodes", "1", "--out", str(other)]
    code, printed, err = run_cli(argv, capsys)
    assert code == 0, err
    assert (
        "note:" not in printed
        and "note" not in json.loads((other / "results.json").read_text())["protocol"]
    )
