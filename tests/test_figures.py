"""The documentation's figures are what the code computes: the tables of the README and
of the documentation site (``docs/``), reproduced digit for digit.

A change that moves a number they show fails here until the page says so.  The
figures are the same on every x86-64 machine (docs/results/reproducibility.md):
the default database is built under pinned numerics and the evaluation's
arithmetic does not depend on the processor, so the comparison is exact; `make
test` runs these tests a second time under another machine's numerics.  With the
numerics unpinned (``ROCKETROLL_NUMERICS=unpinned``, as where the pin cannot be had) the
tables' figures are exact no more: those tests check the rows' words, then skip, saying
so.  The committed PPO policies are reproduced from their recorded commands by the slow
tests at the end (``pytest -m slow``; minutes each).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from identification.instruments.bundled import load_bundled
from identification.methods.pipeline import identify
from rocketroll.cli import main as rocketroll

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"


def page(name: str) -> str:
    """The text of the site's page ``name`` (``docs/NAME``), or ``README.md``."""
    path = REPO / name if name == "README.md" else DOCS / name
    return path.read_text(encoding="utf-8")


#: Every page of the site, one text (each table starts with a unique row).
SITE = "\n".join(page(p.relative_to(DOCS).as_posix()) for p in sorted(DOCS.rglob("*.md")))
#: The page with the evaluation tables: the angle, rate and flight tasks, in that order.
RESULTS = page("results/evaluation.md")


#: A printed figure: digits, a decimal point and digits, signed (ASCII or typographic minus).
FIGURE = re.compile(r"[-+\u2212]?\d+(?:\.\d+)?")


def assert_same_rows(computed: list[str], shown: list[str], where: str) -> None:
    """The computed table rows are the page's, to the character.  With the numerics unpinned
    (``ROCKETROLL_NUMERICS=unpinned``, as where the pin cannot be had), the page's figures
    are not the machine's (docs/results/reproducibility.md: exact only when pinned): the
    rows and their words are still checked, then the test is skipped, saying so."""
    from rocketroll_common.numerics import is_unpinned

    if computed == shown:
        return
    if is_unpinned():
        words = [FIGURE.sub("#", row) for row in computed]
        assert words == [FIGURE.sub("#", row) for row in shown], where
        pytest.skip(f"{where}: its figures are exact only under the pinned numerics")
    assert len(computed) == len(shown), where
    for ours, theirs in zip(computed, shown, strict=True):
        assert ours == theirs, f"computed:\n{ours}\n{where}:\n{theirs}"


def site_rows(first: str, count: int) -> list[str]:
    """``count`` table rows of the site starting with the row that starts with ``first``."""
    lines = SITE.splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith(first))
    return lines[start : start + count]


#: The flight table's controllers (results/evaluation.md, In flight).
FLIGHT_POLICIES = ("trim", "pid", "pid-tunnel", "observer", "mpc", "oracle", "causal-oracle")


#: How the line under an evaluation table begins that counts the steps that never settled.
UNSETTLED = "Setpoint steps that never settled"


def assert_evaluation_table(printed: list[str], table: int) -> None:
    """``printed`` (an evaluation table's lines: header, rule, rows, and the line under it
    that counts the setpoint steps that never settled) is the results page's table
    ``table`` (0: angle, 1: rate, 2: flight), row for row, with that line as printed."""
    rows = [line for line in printed if line.startswith("| ") and not line.startswith("| contr")]
    lines = RESULTS.splitlines()
    starts = [k for k, line in enumerate(lines) if line.startswith("| trim |")]
    shown = lines[starts[table] : starts[table] + len(rows)]
    after = lines[starts[table] + len(rows) : starts[table] + len(rows) + 2]
    assert_same_rows(rows, shown, "results/evaluation.md")
    notes = [line for line in printed if line.startswith(UNSETTLED)]
    assert notes == [line for line in after if line.startswith(UNSETTLED)], "the unsettled steps"


@pytest.mark.parametrize(
    ("env_id", "table"),
    [("RocketRollRate-v0", 1), ("RocketRollFlight-v0", 2)],
    ids=["rate", "flight"],
)
def test_the_evaluation_tables(
    env_id: str, table: int, default_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`make demo`'s tables, 20 held-out episodes, seed 0, every default controller (in
    flight: trim, the scheduled PID, the tunnel's PID, the scheduled observer and MPC, and
    the two bounds).  The angle task's is the README quickstart's `rocketroll eval`, checked
    by :func:`test_the_front_page_quickstart_runs`."""
    policies = [f"--policy={p}" for p in FLIGHT_POLICIES] if "Flight" in env_id else []
    words = ["eval", "--env-id", env_id, "--episodes", "20", "--seed", "0", *policies]
    assert rocketroll(words) == 0
    assert_evaluation_table(capsys.readouterr().out.splitlines(), table)


# The tests that need no default database come right after the first two that do:
# spread one by one over two workers (`make pytest-varied`), one worker then runs the
# guides while the other builds the database.
def test_the_bring_your_own_rocket_guide_runs_as_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The guide's commands on a user's raw log: a virtual-tunnel run of ramps (not the
    paper's dwells) of a rocket unlike the bundled ones, written as the guide's raw file is
    (headerless, radians, 100 Hz: roll, roll rate, measured fin)."""
    from identification.instruments.tunnel import run_tunnel, spec_from_command

    rec = run_tunnel(
        spec_from_command(
            "--seed 7 --log-dt 0.01 --gyro-noise 1 --measured-fin --schedule ramps --steps 10 "
            "--dwell-min 2 --dwell-max 3 --lead 1 --ramp 1 --alpha 1.8 --beta -4 "
            "--alpha-bar 0.02 --beta-bar 4 --turbulence-sd 4"
        )
    )
    assert rec.roll_deg is not None and rec.roll_rate_dps is not None and rec.fin_deg is not None
    raw = np.radians(np.column_stack([rec.roll_deg, rec.roll_rate_dps, rec.fin_deg]))
    np.savetxt(tmp_path / "raw.csv", raw, delimiter=",", fmt="%.9g")
    monkeypatch.chdir(tmp_path)
    commands = guide_commands()
    assert 1 <= len(commands) <= 4
    printed = []
    for argv in commands:
        assert rocketroll(argv) == 0, argv
        printed.append(capsys.readouterr().out)
    assert "fit adequacy" in printed[1]
    ml_rows = [line.split() for line in printed[1].splitlines() if line.startswith("ml ")]
    assert ml_rows and all(abs(float(row[2]) / 1.8 - 1) < 0.05 for row in ml_rows[:2])
    assert (tmp_path / "mine-report" / "fit-ml.png").is_file()
    assert "held-out part" in printed[2]
    assert "recording mine" in printed[3] and "episode:" in printed[3]
    table = (tmp_path / "mine-eval" / "table.md").read_text()
    assert "| observer |" in table and "(trained on another database's rockets)" in table


def test_the_fly_your_flight_log_guide_runs_as_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The flight guide's commands on a flight computer's log: a virtual flight of a rocket
    whose fin torque grows as ρV^1.5, from a pad at 1500 m, written with time in ms,
    airspeed in km/h and altitude in feet above the pad."""
    import shlex

    from identification.instruments.flightlog import FlightLogSpec, run_flight

    ascent = tmp_path / "high.yml"
    default = (Path(__file__).parent.parent / "identification/data/ascent-default.yml").read_text(
        encoding="utf-8"
    )
    ascent.write_text(default.replace("launch_altitude_m: 0.0", "launch_altitude_m: 1500.0"))
    rec = run_flight(
        FlightLogSpec(
            seed=5, model="constant", torque_exponent=1.5, ascent=str(ascent),
            altitude_above_ground=True,
        )
    )  # fmt: skip
    assert rec.fin_cmd_deg is not None and rec.roll_rate_dps is not None
    assert rec.airspeed_mps is not None and rec.altitude_m is not None
    columns = [
        1000.0 * rec.time_s, rec.fin_cmd_deg, rec.roll_rate_dps, 3.6 * rec.airspeed_mps,
        rec.altitude_m / 0.3048,
    ]  # fmt: skip
    np.savetxt(
        tmp_path / "log.csv", np.column_stack(columns), delimiter=",", fmt="%.9g",
        header="t_ms,fin,gyro,v_kmh,h_ft", comments="",
    )  # fmt: skip
    monkeypatch.chdir(tmp_path)
    section = page("guides/own-flight.md")
    block = section.split("```bash\n", 1)[1].split("```", 1)[0]
    commands = [
        shlex.split(line)[1:] for line in block.splitlines() if line.startswith("rocketroll")
    ]
    assert 1 <= len(commands) <= 4
    printed = []
    for argv in commands:
        assert rocketroll(argv) == 0, argv
        printed.append(capsys.readouterr().out)
    fits = [line for line in printed[1].splitlines() if line.startswith("flight ") and "[" in line]
    assert len(fits) == 2 and all("[good]" in line for line in fits), printed[1]
    assert "scaling measured" in printed[1] and "eq. 4-8 (n 2, m 1) rejected" in printed[1]
    assert (tmp_path / "flight-report" / "flight_identification.png").is_file()
    assert "8 posterior" in printed[2] or "traces" in printed[2]
    assert "recording myflight" in printed[3]
    rows = {
        line.split("|")[1].strip(): float(line.split("|")[2].split("±")[0])
        for line in (tmp_path / "flight-eval" / "table.md").read_text().splitlines()
        if line.startswith("| ") and not line.startswith("| controller")
    }
    assert rows["PID"] < 0.5 * rows["trim"], rows


def test_the_identification_table_of_the_bundled_reconstruction() -> None:
    result = identify(load_bundled("tunnel-paper-seed0"))
    p = result.parameters()
    resim = result.resimulations
    theta = result.statistics.theta
    noise = result.noise
    assert noise is not None
    i10 = list(noise.levels_pct).index(10.0)
    rows = site_rows("| α (°/s)/° |", 7)
    truth = result.truth()
    assert truth is not None
    alpha_error = 100 * (p["alpha"] / truth["alpha"] - 1)
    assert rows[0].startswith(f"| α (°/s)/° | {p['alpha']:.4f} ({alpha_error:+.1f} %) |")
    assert rows[1].startswith(f"| β °/s | {p['beta_dps']:.3f} |")
    assert rows[2].startswith(f"| steady-state R² | {p['steady_state_r2']:.4f} |")
    rate = f"{resim['constant'].rate_mae_dps:.3f} / {resim['theta'].rate_mae_dps:.3f} °/s"
    angle = f"{resim['constant'].angle_mae_deg:.3f} / {resim['theta'].angle_mae_deg:.3f} °"
    assert f"| {rate} |" in rows[3] and f"| {angle} |" in rows[4]
    interval = f"[{theta.q05_deg:.2f}, {theta.q95_deg:.2f}]°".replace("-", "−")
    assert f"| {interval} |" in rows[5]
    assert f"| {noise.mae_deg[i10]:.2f} / {noise.p90_deg[i10]:.2f} ° |" in rows[6]


def test_the_default_database(default_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert rocketroll(["db", "list", "--kind", "identified", "--method", "paper"]) == 0
    out = capsys.readouterr().out
    assert "9 recordings, 54 traces, 36 surrogates, 144 posterior draws; 18 shown" in out
    assert re.search(r"2d68d98ae09b-paper-theta .* 7\.91 \[-12\.48,  13\.58\]", out)
    words = " ".join(SITE.split())
    assert (
        "54 identified traces, 36 surrogates and 144 posterior draws, 6 train and 3 test "
        "recordings" in words
    )


# ------------------------------------------------------------------ slow: the committed policies
def _retrain(env_id: str, out: Path, timesteps: int | None = None) -> dict[str, Any]:
    """The committed policy's recorded training command, run again into ``out`` (with
    ``timesteps``: its first ``timesteps`` env-steps)."""
    from agents.learned import COMMITTED
    from agents.train import HYPERPARAMS_DIR, Args, train

    recorded = json.loads((COMMITTED / env_id / "settings.json").read_text(encoding="utf-8"))
    args = recorded["args"]
    return train(
        Args(
            env_id=env_id,
            timesteps=timesteps,
            seed=args["seed"],
            out=out,
            # The recipe file it names, from this checkout (it recorded the path it was given).
            hyperparams=HYPERPARAMS_DIR / Path(args["hyperparams"]).name,
            eval_freq=args["eval_freq"],
            eval_episodes=args["eval_episodes"],
            eval_seed=args["eval_seed"],
            checkpoint_freq=args["checkpoint_freq"],
            progress_bar=False,
            torch_threads=args["torch_threads"],
        )
    )


@pytest.mark.slow
def test_the_angle_recipe_trains_the_same_bits_twice(default_db: Path, tmp_path: Path) -> None:
    """Train and evaluate (guides), Training PPO: the committed angle policy's command, run twice
    for its first 0.5 M env-steps, trains the same weights and statistics bit for bit (2 x
    about 70 s, one torch thread).  Across machines it does not: torch's kernels differ
    between processors."""
    from stable_baselines3 import PPO

    first = _retrain("RocketRoll-v0", tmp_path / "a", timesteps=500_000)
    second = _retrain("RocketRoll-v0", tmp_path / "b", timesteps=500_000)
    assert first["env_steps"] == second["env_steps"] == 503_808  # whole rollouts of 16 x 256
    weights = [
        PPO.load(tmp_path / run / "model.zip", device="cpu").policy.state_dict()
        for run in ("a", "b")
    ]
    assert weights[0].keys() == weights[1].keys()
    for name, tensor in weights[0].items():
        assert torch.equal(weights[1][name], tensor), name
    norms = [json.loads((tmp_path / run / "normalize.json").read_text()) for run in ("a", "b")]
    np.testing.assert_array_equal(norms[0]["mean"], norms[1]["mean"])
    np.testing.assert_array_equal(norms[0]["var"], norms[1]["var"])


@pytest.mark.slow
def test_the_committed_rate_policy_is_reproduced_by_its_recorded_command(
    default_db: Path, tmp_path: Path
) -> None:
    """Train and evaluate (guides), Training PPO: the rate policy's 10 M steps (5 min) come out
    another draw on another database or processor; its held-out score within 1 % of the committed
    policy's (on this version's database: 0.03 % and 0.2 %)."""
    from agents.learned import COMMITTED

    settings = _retrain("RocketRollRate-v0", tmp_path / "run")
    committed = json.loads((COMMITTED / "RocketRollRate-v0" / "settings.json").read_text())
    assert settings["env_steps"] == committed["env_steps"]
    ours, theirs = settings["final_test_eval"], committed["final_test_eval"]
    assert ours["rms_tracking_error"] == pytest.approx(theirs["rms_tracking_error"], rel=0.01)
    assert ours["mean_reward"] == pytest.approx(theirs["mean_reward"], rel=0.01)


def _table_after(header: str, rows: int) -> list[str]:
    lines = SITE.splitlines()
    start = lines.index(header)
    return lines[start : start + rows]


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ["RocketRoll-v0", "RocketRollRate-v0"])
def test_the_seed_statistics_and_robustness_tables(
    env_id: str, default_db: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`make demo`'s seed statistics (five committed runs each of PPO and of PPO trained at
    a zero setpoint, as a residual on the observer and with memory / SAC) and robustness
    tables, as the results page prints them (about a minute per task)."""
    seeds = f"agents/policies/seeds/{env_id}"
    # Each learner's five runs; the committed policy is its learner's seed 0.
    learners = {"ppo": "ppo:{}/ppo/seed{}", "sac": "sac:{}/sac/seed{}"}
    committed = "ppo"
    if env_id == "RocketRoll-v0":
        learners = {
            "ppo": "ppo:{}/ppo/seed{}",
            "ppo-zero": "ppo-zero=ppo:{}/ppo-zero/seed{}",
            "ppo-residual": "ppo-residual=ppo:{}/ppo-residual/seed{}",
            "ppo-memory": "ppo-memory=ppo:{}/ppo-memory/seed{}",
        }
        committed = "ppo-memory"
    runs = []
    for name, run in learners.items():
        for seed in range(5):
            if name == committed and seed == 0:
                label = "" if name == "ppo" else f"{name}="
                runs += ["--run", f"{label}ppo:agents/policies/{env_id}"]
            else:
                runs += ["--run", run.format(seeds, seed)]
    for argv in (["seeds", "--env-id", env_id, *runs], ["robustness", "--env-id", env_id]):
        assert rocketroll(argv) == 0
        printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("|")]
        assert_same_rows(printed, _table_after(printed[0], len(printed)), f"{argv[0]}'s table")


def guide_commands() -> list[list[str]]:
    """The "Bring your own rocket" guide's commands, as its page writes them."""
    import shlex

    section = page("guides/own-rocket.md")
    block = section.split("```bash\n", 1)[1].split("```", 1)[0]
    return [shlex.split(line)[1:] for line in block.splitlines() if line.startswith("rocketroll")]


# ------------------------------------------------------------------ the README, a front page
def test_the_front_page_is_short_and_its_headline_table_is_the_results_tables() -> None:
    """The README stays a front page (at most 200 lines), and its headline table is the
    regulation-RMS column of the results page's tables (which the tests above compute)."""
    readme = page("README.md")
    assert len(readme.splitlines()) <= 200
    headline = {
        line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
        for line in readme.splitlines()
        if line.startswith("| angle, ")
        or line.startswith("| rate, ")
        or line.startswith("| flight angle")
    }
    columns = ("trim", "PID", "observer", "MPC", "PPO", "oracle", "causal oracle")
    lines = RESULTS.splitlines()
    starts = [k for k, line in enumerate(lines) if line.startswith("| trim |")]
    for task, start in zip(headline, starts, strict=True):
        shown = {}
        for line in lines[start:]:
            if not line.startswith("| "):
                break
            cells = [c.strip() for c in line.split("|")[1:-1]]
            shown[cells[0]] = cells[1].split(" ± ")[0]
        for name, value in zip(columns, headline[task], strict=True):
            assert value == shown.get(name, "–"), (task, name)


def test_the_front_page_quickstart_runs(
    tmp_path: Path, default_db: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The README's quickstart commands and its Gymnasium example, as written."""
    import shlex

    readme = page("README.md")
    quick = readme.split("## Quickstart", 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    commands = [shlex.split(line.split("#", 1)[0]) for line in quick.splitlines() if line]
    assert [c[:2] for c in commands] == [
        ["rocketroll", "tunnel"],
        ["rocketroll", "identify"],
        ["rocketroll", "eval"],
    ]
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        assert rocketroll(argv[1:]) == 0, argv
    # Its evaluation is `make demo`'s angle task (20 held-out episodes, seed 0, the default
    # controllers), whose table the results page shows.
    evaluated = tmp_path / "build" / "eval"
    protocol = json.loads((evaluated / "results.json").read_text(encoding="utf-8"))["protocol"]
    assert protocol["env_id"] == "RocketRoll-v0" and protocol["n_episodes"] == 20
    assert protocol["seed"] == 0 and protocol["split"] == "test" and protocol["settings"] == {}
    example = readme.split("## Gymnasium", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    namespace: dict[str, Any] = {}
    exec(compile(example, "README.md (Gymnasium)", "exec"), namespace)
    assert namespace["envs"].num_envs == 4096
    namespace["envs"].close()
    namespace["env"].close()
    # Last: with the numerics unpinned it skips, saying why.
    assert_evaluation_table((evaluated / "table.md").read_text(encoding="utf-8").splitlines(), 0)
