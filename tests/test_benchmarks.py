"""The fidelity benchmarks run end to end (tiny settings; the figures are the scripts' job)."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: The scripts these tests run: imported once (as modules, not run) by the script runner.
SCRIPTS = (
    "closed_loop", "code_size", "flight_fidelity", "flight_ground_truth", "ground_truth", "ml_bias",
    "mpc_speed", "real_data", "recurrent_probe", "run_curve", "same_behaviour", "train_curve",
    "train_speed",
)  # fmt: skip

#: The script runner: imports what the scripts import (torch, stable-baselines3, the
#: project: seconds a process) once, then runs each script asked of it on its standard input
#: (a JSON line) as ``python SCRIPT ARGS`` or ``python -m MODULE ARGS`` would, in a forked
#: child of its own: ``__main__`` from the start, its own argv, output to the files named,
#: its exit status answered on a line.
RUNNER = r"""
import json, os, runpy, signal, sys, traceback

sys.path.insert(0, sys.argv[1])
for name in sys.argv[2:]:
    try:
        __import__(name)
    except ImportError:  # the script's own run says what is missing
        pass
for line in sys.stdin:
    job = json.loads(line)
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        signal.alarm(job["timeout"])
        os.dup2(os.open(os.devnull, os.O_RDONLY), 0)
        for fd, path in ((1, job["stdout"]), (2, job["stderr"])):
            os.dup2(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC), fd)
        sys.argv = [job["target"], *job["args"]]
        code = 0
        try:
            if job["module"]:
                runpy.run_module(job["target"], run_name="__main__", alter_sys=True)
            else:
                runpy.run_path(job["target"], run_name="__main__")
        except SystemExit as exc:
            if exc.code is None or isinstance(exc.code, int):
                code = exc.code or 0
            else:
                print(exc.code, file=sys.stderr)
                code = 1
        except BaseException:
            traceback.print_exc()
            code = 1
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    _, status = os.waitpid(pid, 0)
    print(os.waitstatus_to_exitcode(status), flush=True)
"""


class Runner:
    """Runs benchmark scripts (and ``python -m`` modules) in the runner process's forks."""

    def __init__(self, db: Path, folder: Path) -> None:
        self.folder = folder
        self.runs = 0
        self.process = subprocess.Popen(
            [sys.executable, "-c", RUNNER, str(REPO / "benchmarks"), *SCRIPTS],
            cwd=REPO,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env={
                # one OpenBLAS thread, as the rocketroll command runs (unless the environment
                # names a number): a second one spins as long as it waits, and doubled the
                # CPU time of the scripts' fits on a busy 2-core machine
                "OPENBLAS_NUM_THREADS": "1",
                **os.environ,
                "PYTHONPATH": str(REPO),
                "ROCKETROLL_DB": str(db),
            },
        )

    def run(
        self, target: str, *args: str, module: bool = False
    ) -> subprocess.CompletedProcess[str]:
        self.runs += 1
        out, err = self.folder / f"{self.runs}.out", self.folder / f"{self.runs}.err"
        job = {
            "target": target if module else str(REPO / "benchmarks" / target),
            "args": list(args),
            "module": module,
            "stdout": str(out),
            "stderr": str(err),
            "timeout": 600,
        }
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.write(json.dumps(job) + "\n")
        self.process.stdin.flush()
        answer = self.process.stdout.readline()
        assert answer, f"the script runner ended before answering: {self.process.poll()}"
        code = int(answer)
        return subprocess.CompletedProcess([target, *args], code, out.read_text(), err.read_text())

    def close(self) -> None:
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.close()
        self.process.wait(timeout=60)
        self.process.stdout.close()


@pytest.fixture(scope="module")
def runner(default_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Runner]:
    """One runner for the module: each script still runs whole, in a process of its own."""
    scripts = Runner(default_db, tmp_path_factory.mktemp("benchmark-output"))
    yield scripts
    scripts.close()


def run_benchmark(runner: Runner, name: str, *args: str) -> subprocess.CompletedProcess[str]:
    return runner.run(name, *args)


def run_script(runner: Runner, name: str, *args: str) -> str:
    done = run_benchmark(runner, name, *args)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_script_prints_its_help(runner: Runner, name: str) -> None:
    done = run_benchmark(runner, f"{name}.py", "--help")
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.startswith("usage: ") and "--help" in done.stdout


def test_ground_truth_reports_every_method_and_the_targets(runner: Runner) -> None:
    out = run_script(runner, "ground_truth.py", "--seeds", "1", "--truth", "negative")
    for method in ("paper:", "output-error:", "ml:"):
        assert method in out
    assert "u_d MAE / true-parameter bound" in out
    assert "Targets, ml:" in out
    assert out.count("PASS") + out.count("FAIL") == 7


def test_flight_ground_truth_reports_each_truth_and_the_targets(runner: Runner) -> None:
    args = ["--seeds", "1", "--truth", "fast-negative", "--truth", "angle-only", "--jobs", "1"]
    out = run_script(runner, "flight_ground_truth.py", *args)
    assert "fast-negative" in out and "angle-only" in out and "paper-theta  " not in out
    assert "re-sim %" in out and "2 fits in" in out
    assert out.count("PASS") + out.count("FAIL") == 2
    joint = ["--seeds", "1", "--truth", "fast-negative", "--joint", "2", "--jobs", "1"]
    out = run_script(runner, "flight_ground_truth.py", *joint)
    assert "1 fits of 2 flights each in" in out


def test_closed_loop_scores_each_replay_against_the_truth(runner: Runner, tmp_path: Path) -> None:
    settings = ["--seeds", "2", "--truth", "rising", "--policies", "trim,pid"]
    settings += ["--tasks", "angle-zero", "--windows", "1", "--draws", "1"]
    serial, parallel = tmp_path / "serial.csv", tmp_path / "parallel.csv"
    out = run_script(runner, "closed_loop.py", *settings, "--csv", str(serial))
    for replay in ("paper", "output-error", "ml", "ml posterior"):
        assert f"  {replay}: " in out
    assert "angle-zero" in out and "settled_rms_error" in out and "regulation_rms_error" in out
    # Recordings scored in worker processes give the same rows, in the same order.
    run_script(runner, "closed_loop.py", *settings, "--jobs", "2", "--csv", str(parallel))
    rows = serial.read_text().splitlines()
    assert len(rows) == 1 + 2 * 4 * 2 * 3  # header; seeds x replays x controllers x metrics
    assert parallel.read_text().splitlines() == rows


def test_the_reference_truth_in_closed_loop_scores_what_the_environment_does(
    default_db: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The benchmarks' true rocket outside the model (the reference integrator in closed
    loop, benchmarks/_reference_env.py): with no effects it scores what the environment's
    kernel scores (trim to 1e-6, the observer within 2 %, the PID within 15 % on two
    windows: its loop chatters through the quantised encoder, which magnifies the kernels'
    1e-3 °/s difference; over 16 windows its scores agree to 1 % on average), its
    sensors read the rocket a latency late, and a lag makes the fin trail its command."""
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    monkeypatch.setenv("ROCKETROLL_DB", str(default_db))
    import numpy as np
    from _reference_env import ReferenceRollEnv
    from closed_loop import Rocket, _config, _controller, rockets_of, score, windows

    from identification.instruments.reference import Effects

    true, _ = rockets_of("paper", 0, [], 0)
    for task in ("angle-zero", "rate-steps"):
        config = _config(task)
        specs = windows(config, true, true.u_d_deg.size, 2, 0)
        checked = Rocket(true.params, true.u_d_deg, Effects())
        for policy in ("trim", "pid", "observer"):
            kernel = score(config, _controller(task, policy), true, specs)
            reference = score(config, _controller(task, policy), checked, specs)
            for name, value in kernel.items():
                tolerance = {"trim": 1e-6, "observer": 0.02, "pid": 0.15}[policy]
                assert reference[name] == pytest.approx(value, rel=tolerance), (task, policy)
    from disturbances.bank import TraceBank

    config = _config("rate-steps")
    bank = TraceBank.from_arrays([true.u_d_deg], config.dt_s, true.params)
    late = ReferenceRollEnv(
        dataclasses.replace(config, sensors=False), bank, Effects(latency_s=0.1)
    )
    obs, _ = late.reset(seed=0, options={"trace": bank.traces[0].uid, "start": 0})
    rates = []
    for _ in range(5):
        obs, *_ = late.step(np.array([0.5], dtype=np.float32))
        rates.append((float(obs[1]), float(late.core.state[0, 0])))
    # 0.1 s late is one control step: what the gyro reads is the rate of the step before.
    for (seen, _), (_, before) in zip(rates[1:], rates[:-1], strict=True):
        assert seen == pytest.approx(before, abs=1e-6)
    lagged = ReferenceRollEnv(config, bank, Effects(servo_lag_s=0.2))
    lagged.reset(seed=0, options={"trace": bank.traces[0].uid, "start": 0})
    lagged.step(np.array([0.5], dtype=np.float32))
    assert 0.0 < lagged.core.state[0, 2] < 0.5 * 0.5 * config.fin_range_deg


def test_closed_loop_flies_truths_outside_the_model_and_ranks_the_controllers(
    runner: Runner,
) -> None:
    settings = ["--seeds", "2", "--truth", "latency", "--policies", "trim,pid", "--methods", "ml"]
    settings += ["--tasks", "rate-steps", "--windows", "1", "--draws", "1", "--stated", "1"]
    out = run_script(runner, "closed_loop.py", *settings)
    assert "Ranking agreement on the headline" in out
    assert "  ml posterior: " in out and " pairs against the truth (" in out
    # identified and replayed with the rig the user states: the latency's flattery gone
    assert "  ml posterior, stated x1: 6/6 within the floor" in out


def test_ml_bias_fits_each_seed_three_ways(runner: Runner) -> None:
    # the truth with the shortest record (a 12-step staircase: 493 s, the others 573 s)
    out = run_script(runner, "ml_bias.py", "--seeds", "2", "--truth", "staircase-laplace")
    for line in ("quantised ", "white ", "exact ", "quantised - white", "white - exact"):
        assert f"  {line}" in out
    # The two seeds' offsets are numbers with a spread, not NaN.
    assert "nan" not in out.lower()


def test_mpc_speed_times_both_controllers_on_every_task(runner: Runner) -> None:
    out = run_script(runner, "mpc_speed.py", "--episodes", "1", "--horizon", "5")
    for env_id in ("RocketRoll-v0", "RocketRollRate-v0", "RocketRollFlight-v0"):
        assert f"{env_id:<20} observer" in out and f"{env_id:<20} mpc:5" in out
    assert out.count("vs target 10 ms:") == 3


def test_train_speed_times_two_recipes_side_by_side(runner: Runner, tmp_path: Path) -> None:
    # Two small recipes (one rollout each per block) in alternating blocks: a row each, the
    # second's speed-up over the first, and the threads each trained with.
    small = tmp_path / "small.yml"
    small.write_text(
        "RocketRoll-v0:\n  n_envs: 4\n  n_steps: 64\n  batch_size: 64\n  n_epochs: 1\n"
        "  normalize: true\n"
    )
    out = run_script(
        runner, "train_speed.py",
        "--timesteps", "512", "--blocks", "2", "--ref-steps", "20", "--repeats", "1",
        "--recipe", f"one={small}@1", "--recipe", f"two={small}@2",
    )  # fmt: skip
    rows = [line.split() for line in out.splitlines() if line.startswith(("one ", "two "))]
    assert [r[0] for r in rows] == ["one", "two"]
    assert [r[2] for r in rows] == ["1", "2"]  # torch threads
    assert [r[3] for r in rows] == ["512", "512"]  # env-steps: 2 blocks of one rollout (256)
    assert rows[0][-1] == "1.0x"


def test_train_speed_names_a_bad_recipe(runner: Runner) -> None:
    done = run_benchmark(runner, "train_speed.py", "--recipe", "x=nowhere.yml")
    assert done.returncode != 0
    assert "--recipe x=nowhere.yml: nowhere.yml: no such file" in done.stderr


def test_train_curve_scores_each_seed_and_the_median(runner: Runner, tmp_path: Path) -> None:
    small = tmp_path / "small.yml"  # with a history: the scorer reads the wider observation
    small.write_text(
        "RocketRoll-v0:\n  n_envs: 4\n  n_steps: 64\n  batch_size: 64\n  n_epochs: 1\n"
        "  normalize: true\n  history: 2\n"
    )
    png = tmp_path / "curve.png"
    out = run_script(
        runner, "train_curve.py",
        "--timesteps", "512", "--eval-every", "256", "--episodes", "2", "--seeds", "0", "1",
        "--recipe", f"tiny={small}@1", "--png", str(png),
    )  # fmt: skip
    rows = [line for line in out.splitlines() if line.startswith("| tiny |")]
    assert [r.split("|")[3].strip() for r in rows] == ["0", "1"]  # one row per seed
    median = next(line for line in out.splitlines() if "tiny, median of 2" in line)
    assert median.count("/2)") == 2  # seeds that reached each reference, of 2
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_curve_scores_each_checkpoint_of_finished_runs(runner: Runner, tmp_path: Path) -> None:
    small = tmp_path / "small.yml"
    small.write_text(
        "RocketRoll-v0:\n  n_envs: 4\n  n_steps: 64\n  batch_size: 64\n  n_epochs: 1\n"
        "  normalize: true\n  history: 2\n"
    )
    runs = []
    for seed in (0, 1):
        out = tmp_path / f"seed{seed}"
        done = runner.run(
            "agents.train", "--hyperparams", str(small), "--timesteps", "768",
            "--seed", str(seed), "--out", str(out), "--eval-freq", "0", "--eval-episodes", "1",
            "--checkpoint-freq", "256", "--no-progress-bar", module=True,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr[-3000:]
        runs += ["--run", f"tiny={out}"]
    png = tmp_path / "curve.png"
    out_text = run_script(
        runner, "run_curve.py", *runs, "--episodes", "2", "--split", "train", "--png", str(png),
    )  # fmt: skip
    rows = [line for line in out_text.splitlines() if line.startswith("| tiny (")]
    assert len(rows) == 2
    # checkpoints at 256 and 512 env-steps, then the final model (768; its own checkpoint
    # at 768 is the final model and shown once)
    assert all(r.count(" M: ") == 3 and "0.000768 M" in r for r in rows)
    assert re.search(
        r"tiny: median of 2 run\(s\) .* below the PID \(\d+\.\d+\) in [012]/2", out_text
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = run_benchmark(runner, "run_curve.py", "--run", f"tiny={tmp_path}")
    assert bad.returncode == 2 and "settings.json not found" in bad.stderr


def test_recurrent_probe_scores_an_lstm_policy_as_it_trains(runner: Runner) -> None:
    pytest.importorskip("sb3_contrib", reason="the probe trains sb3-contrib's RecurrentPPO")
    out = run_script(
        runner, "recurrent_probe.py", "--timesteps", "512", "--envs", "4", "--n-steps", "64",
        "--batch", "128", "--every", "256", "--episodes", "2",
    )  # fmt: skip
    assert re.search(r"PID \d+\.\d+ °", out)
    (row,) = [line for line in out.splitlines() if line.startswith("| 0 |")]
    assert row.count(" M: ") == 2 and "0.000512 M" in row
    bad = run_benchmark(runner, "recurrent_probe.py", "--envs", "3", "--n-steps", "5")
    assert bad.returncode == 2 and "is not a multiple of --batch 2048" in bad.stderr
    assert bad.stderr.count("\n") == 1


def test_real_data_fits_the_given_recordings_at_each_rate_and_scores_a_known_truth(
    runner: Runner, tmp_path: Path
) -> None:
    from identification.instruments.tunnel import run_tunnel, spec_from_command
    from identification.recordings.recording import save_recording

    rec = run_tunnel(
        spec_from_command(
            "--seed 2 --log-dt 0.01 --gyro-noise 1 --schedule ramps --steps 6 --dwell-min 2 "
            "--dwell-max 3 --lead 1 --ramp 1 --model constant --alpha 2 --beta -3 --beta-bar 5 "
            "--turbulence-sd 2"
        )
    )
    path = tmp_path / "run.csv"
    save_recording(rec, path)
    out = run_script(
        runner, "real_data.py", str(path), "--every", "1", "--every", "10",
        "--methods", "paper,output-error,ml",
    )  # fmt: skip
    assert out.count("Recording(name=") == 2 and "dt=0.1 s" in out
    assert "truth: alpha = 2, theta_bar = -1.5, a = 5" in out
    assert "paper        cannot fit it:" in out or "paper        constant" in out
    ml = [line.split() for line in out.splitlines() if line.strip().startswith("ml ")]
    assert len(ml) == 4 and all(row[-1] in ("good", "weak", "unreliable") for row in ml)
    lines = out.splitlines()
    ml_errors = [
        lines[k + 1] for k, line in enumerate(lines) if line.strip().startswith("ml ")
    ]  # each ml fit's error line follows its row
    assert all("error: α" in e for e in ml_errors)
    assert all(abs(float(e.split("α")[1].split("%")[0])) < 5 for e in ml_errors)
    bad = run_benchmark(runner, "real_data.py", str(tmp_path / "missing.csv"))
    assert bad.returncode == 2 and "missing.csv" in bad.stderr


def test_real_data_fits_a_flight_with_its_scaling(runner: Runner, tmp_path: Path) -> None:
    """A flight log: the flight method, the measured scaling and eq. 4-8's test, and the
    truth carried to the fit's reference airspeed."""
    from identification.instruments.flightlog import FlightLogSpec, run_flight
    from identification.recordings.recording import save_recording

    path = tmp_path / "flight.csv"
    # logged at 50 Hz (the recorder's default is 100): half the samples to fit, the same checks
    spec = FlightLogSpec(seed=3, model="constant", torque_exponent=1.5, log_dt=0.02)
    save_recording(run_flight(spec), path)
    out = run_script(runner, "real_data.py", str(path))
    rows = [line.split() for line in out.splitlines() if line.strip().startswith("flight ")]
    assert [row[1] for row in rows] == ["constant", "theta"]
    assert out.count("eq. 4-8 (n 2, m 1) rejected") == 2
    scaling = [line for line in out.splitlines() if "at V_ref" in line]
    exponents = [float(line.split("ρV^n, n ")[1].split()[0]) for line in scaling]
    assert len(exponents) == 2 and all(abs(n - 1.5) < 0.1 for n in exponents), scaling
    errors = [line for line in out.splitlines() if "error: α" in line]
    assert len(errors) == 2 and all(abs(float(e.split("α")[1].split("%")[0])) < 5 for e in errors)
    # The fin torque per q against the plain least squares and the truth at the fit's reference.
    torque = [line for line in out.splitlines() if "fin torque per q" in line]
    assert len(torque) == 2 and all("; the truth " in line for line in torque), torque
    assert "the fit's interval holds it" in torque[0], torque[0]


def test_flight_fidelity_scores_a_design_on_the_replay_and_on_the_truth(runner: Runner) -> None:
    args = ["--seeds", "1", "--n", "2.0", "--episodes", "2", "--policies", "trim,pid"]
    out = run_script(runner, "flight_fidelity.py", *args)
    rows = [line.split() for line in out.splitlines() if line.startswith(" 2.0    0  ")]
    assert [row[2] for row in rows] == ["trim", "PID"]
    for row in rows:  # truth, posterior, ratio, smoothed, ratio: numbers, ratios consistent
        truth, posterior, ratio = float(row[3]), float(row[4]), float(row[5])
        assert truth > 0 and abs(posterior / truth - ratio) < 0.006
    assert "within [0.9, 1.1]:" in out


def test_the_readme_names_every_script() -> None:
    readme = (REPO / "benchmarks" / "README.md").read_text(encoding="utf-8")
    scripts = sorted(p.name for p in (REPO / "benchmarks").glob("[a-z]*.py"))
    assert [s for s in scripts if f"| `benchmarks/{s}` |" not in readme] == []


def _suite(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "suite.py"), *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        check=False,
    )


def test_the_benchmark_page_is_what_the_index_and_records_give() -> None:
    done = _suite("tables", "--check")
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_suite_keeps_a_record_per_figure_of_a_run(tmp_path: Path) -> None:
    kept = tmp_path / "records.jsonl"
    done = _suite("run", "--records", str(kept), "code_size.py")
    assert done.returncode == 0, done.stderr[-3000:]
    records = [json.loads(line) for line in kept.read_text(encoding="utf-8").splitlines()]
    by_figure = {r["figure"]: r for r in records}
    modules = by_figure["modules over 800 lines of code"]
    assert modules["target"] == {"low": None, "high": 0.0}
    assert modules["verdict"] == ("PASS" if modules["value"] == 0 else "FAIL")
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
    )
    for record in records:  # every record stamped with how, where and when it was measured
        assert record["script"] == "code_size.py" and record["kind"] == "study"
        assert record["command"] == ".venv/bin/python benchmarks/code_size.py"
        assert record["commit"].startswith(head.stdout.strip())
        assert f"{os.cpu_count()} CPU(s)" in record["machine"] and record["date"]
    lines = by_figure["distribution: lines of code"]["value"]
    assert lines == sum(
        by_figure[f"{p}: lines of code"]["value"]
        for p in ("rocketroll", "rocketroll_common", "rocketroll_physics", "identification",
                  "disturbances", "rollenv", "agents")
    )  # fmt: skip
    # A failed run keeps nothing; a malformed record is named by file and line.
    failed = _suite("run", "--records", str(kept), "code_size.py", "--module-limit", "0")
    assert failed.returncode == 2 and "not kept" in failed.stdout
    assert len(kept.read_text(encoding="utf-8").splitlines()) == len(records)


def test_a_target_gives_the_verdict_and_a_bad_record_is_named(tmp_path: Path) -> None:
    sys.path.insert(0, str(REPO / "benchmarks"))
    try:
        from _records import ENV, Target, emit
    finally:
        sys.path.remove(str(REPO / "benchmarks"))
    assert Target(high=50.0).verdict(50.0) == "PASS"
    assert Target(high=50.0).verdict(50.1) == "FAIL"
    assert Target(low=1.0).verdict(float("nan")) == "FAIL"
    assert [Target(low=0.85, high=0.95).verdict(v) for v in (0.84, 0.9, 0.96)] == [
        "FAIL",
        "PASS",
        "FAIL",
    ]
    assert (str(Target(low=1e7)), str(Target(low=0.85, high=0.95))) == ("≥ 1e+07", "0.85 to 0.95")
    # A NaN is no JSON number: kept as null, said in the note, failing its target.
    kept = tmp_path / "figures.jsonl"
    os.environ[ENV] = str(kept)
    try:
        emit("spread", float("nan"), "", at_most=1.0, note="one seed")
    finally:
        del os.environ[ENV]
    figure = json.loads(kept.read_text(encoding="utf-8"))
    assert (figure["value"], figure["verdict"], figure["note"]) == (None, "FAIL", "nan; one seed")
    records = (REPO / "benchmarks" / "records.jsonl").read_text(encoding="utf-8").splitlines()
    broken = tmp_path / "records.jsonl"
    broken.write_text("\n".join([records[0], records[1].replace('"unit"', '"units"')]) + "\n")
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            "import suite; suite.read_records(suite.Path(__import__('sys').argv[1]))",
            str(broken),
        ],
        cwd=REPO / "benchmarks",
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 1 and f"{broken}:2: " in done.stderr, done.stderr


def _snapshot(folder: Path, database: str, **results: object) -> Path:
    folder.mkdir()
    manifest = {"commit": "0" * 40, "default_database_content_sha256": database}
    (folder / "snapshot.json").write_text(json.dumps(manifest), encoding="utf-8")
    for name, value in results.items():
        (folder / f"{name}.json").write_text(json.dumps(value), encoding="utf-8")
    return folder


def test_same_behaviour_compares_snapshots_leaf_by_leaf(runner: Runner, tmp_path: Path) -> None:
    def compare(first: Path, second: Path) -> subprocess.CompletedProcess[str]:
        return run_benchmark(runner, "same_behaviour.py", "compare", str(first), str(second))

    fit = {"alpha": 0.659, "n": 3, "method": "ml", "se": [0.01, float("nan")]}
    before = _snapshot(tmp_path / "a", "d1", fit=fit)
    close = _snapshot(tmp_path / "b", "d1", fit={**fit, "alpha": 0.659 * (1 + 1e-12)})
    same = compare(before, close)
    assert same.returncode == 0, same.stdout + same.stderr
    assert "1 JSON files, 3 numbers compared" in same.stdout
    assert "default database content identical: the same" in same.stdout
    moved = {**fit, "alpha": 0.659 * (1 + 1e-6), "n": 4, "extra": 1}
    differ = compare(before, _snapshot(tmp_path / "c", "d2", fit=moved))
    assert differ.returncode == 1
    for said in (
        "fit.json: alpha: 0.659 against",
        "fit.json: n: 3 against 4",
        "fit.json: extra: only in the second",
        "default database: content SHA-256 d1 against d2",
    ):
        assert said in differ.stdout, differ.stdout
    refused = compare(before, tmp_path)
    assert refused.returncode == 2 and "not a snapshot" in refused.stderr
