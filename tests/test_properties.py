"""Generated bad input against every command (hypothesis).

Recordings a user might bring -- the wrong time unit, absurd sampling rates, NaN,
huge values, jittered or shuffled clocks, text where numbers belong, empty or cut
files -- and option values from the edges of their ranges and beyond are thrown at
the commands.  Whatever is drawn, a command must:

* exit 0, or exit 2 with exactly one line on stderr (``rocketroll CMD: error: ...``);
  an exception escaping it (a traceback and exit 1 from the shell) is a bug this test
  reports, never disguised;
* leave every file it was given, and every file it did not make, byte for byte;
* write nothing on exit 2, and only its named outputs on exit 0;
* finish: an example that runs past :data:`HANG_S` fails.

The examples are derandomised (the same every run, on every machine) and the run is
bounded by each test's ``max_examples``.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import os
import signal
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="hypothesis is in the dev extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from rocketroll.cli import main as rocketroll  # noqa: E402

#: Seconds one command may run before the example counts as hung.
HANG_S = 120

PROPERTY = settings(
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


class Hung(BaseException):
    """A command ran past :data:`HANG_S` (a BaseException: no command may catch it)."""


def _alarm(signum: int, frame: FrameType | None) -> None:
    raise Hung(f"still running after {HANG_S} s")


def _snapshot(root: Path) -> dict[Path, str]:
    """Every file's digest and every folder under ``root``."""
    return {
        p: hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "folder"
        for p in sorted(root.rglob("*"))
    }


def _digest(path: Path) -> str:
    """A file's digest, with its SQLite write-ahead log (where a change may sit)."""
    wal = path.with_name(path.name + "-wal")
    data = path.read_bytes() + (wal.read_bytes() if wal.exists() else b"")
    return hashlib.sha256(data).hexdigest()


def run_contract(
    argv: list[str], folder: Path, outputs: tuple[Path, ...] = (), inputs: tuple[Path, ...] = ()
) -> tuple[int, str]:
    """Run ``rocketroll ARGV`` in-process from ``folder`` (so a relative path it makes is
    seen) and check the contract; ``outputs``: the paths the command may create or replace
    (a folder: anything under it); ``inputs``: files outside ``folder`` it must leave as
    they are.  Returns (exit code, stdout)."""
    before = _snapshot(folder)
    held = {p: _digest(p) for p in inputs}
    out, err = io.StringIO(), io.StringIO()
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(HANG_S)
    cwd = Path.cwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = rocketroll(argv)
    except SystemExit as exc:  # argparse's --help or a bare exit: still an exit code
        code = int(exc.code or 0)
    finally:
        os.chdir(cwd)
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    said = err.getvalue()
    hypothesis.event(f"exit {code}")
    lines = [line for line in said.splitlines() if line.strip()]
    assert code in (0, 2), f"rocketroll {' '.join(argv)} -> exit {code}:\n{said[-3000:]}"
    if code == 2:
        assert len(lines) == 1, f"rocketroll {' '.join(argv)}: not one line:\n{said}"
        assert lines[0].startswith(f"rocketroll {argv[0]}: error: "), lines[0]
    after = _snapshot(folder)
    for path, digest in before.items():
        if after.get(path) != digest:
            assert code == 0 and _under(path, outputs), f"{path} changed ({argv})"
    for path in set(after) - set(before):
        assert code == 0, f"exit 2 but {path} was written ({argv})"
        assert _under(path, outputs), f"{path} is not an output of {argv}"
    for path, digest in held.items():
        assert _digest(path) == digest, f"{path} changed"
    return code, out.getvalue()


def _under(path: Path, outputs: tuple[Path, ...]) -> bool:
    """Whether ``path`` is an output, inside one, or a folder made to hold one."""
    return any(path == o or o in path.parents or path in o.parents for o in outputs)


@contextlib.contextmanager
def folder() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="rocketroll-prop-") as name:
        yield Path(name)


def mostly(good: list[str], bad: list[str]) -> st.SearchStrategy[str]:
    """One of ``good`` about three times in four, else one of ``bad``."""
    return st.one_of(st.sampled_from(good), st.sampled_from(good), st.sampled_from(good),
                     st.sampled_from(bad))  # fmt: skip


# ----------------------------------------------------------------------------- recordings
#: Sampling intervals from far below to far above what a roll log can have, s.
INTERVALS = st.sampled_from([1e-5, 5e-4, 0.001, 0.01, 0.02, 0.1, 0.5, 1.0, 5.0, 100.0])
#: Cells a corrupt log holds where a number belongs.
ODD_CELLS = st.sampled_from(["nan", "NaN", "inf", "-inf", "1e308", "-1e300", "", "abc", "1,5"])


@st.composite
def logs(draw: Callable[..., Any]) -> dict[str, Any]:
    """A roll log: time, fin command and roll angle, with a user's mistakes drawn in (in
    about half of the logs; the others are clean)."""
    clean = draw(st.booleans())
    n = draw(st.sampled_from([600, 1200, 3000] if clean else [0, 1, 2, 5, 40, 120, 600, 3000]))
    dt = draw(st.sampled_from([0.01, 0.1]) if clean else INTERVALS)
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    jitter = 0.0 if clean else draw(st.sampled_from([0.0, 0.1, 0.6]))  # of one interval
    t = t + rng.uniform(-jitter, jitter, n) * dt
    time_scale = 1.0 if clean else draw(st.sampled_from([1.0, 1000.0, 1e6]))  # ms or µs logged as s
    fin = np.repeat(rng.uniform(-40, 40, max(1, n // 40 + 1)), 40)[:n]
    roll = np.cumsum(rng.normal(0.0, 3.0, n))
    scale = 1.0 if clean else draw(st.sampled_from([1.0, math.pi / 180, 1e6, 1e300]))  # rad, absurd
    rows = np.column_stack([t * time_scale, fin * scale, roll * scale])
    cells = [[repr(float(v)) for v in row] for row in rows]
    for _ in range(0 if clean or not n else draw(st.sampled_from([0, 1, 3]))):  # bad cells
        i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, 2))
        cells[i][j] = draw(ODD_CELLS)
    if not clean and n > 3 and draw(st.booleans()):  # a shuffled stretch of the clock
        k = draw(st.integers(0, n - 3))
        cells[k], cells[k + 2] = cells[k + 2], cells[k]
    cut = not clean and n > 0 and draw(st.integers(0, 4)) == 0  # the last line cut short
    lines = [",".join(row) for row in cells]
    if cut:
        lines[-1] = lines[-1][: len(lines[-1]) // 2]
    return {"lines": lines, "n": n}


def recording_text(log: dict[str, Any]) -> str:
    """The log as a format-v1 recording, as a user might hand-write one."""
    head = "# format: rocketroll-recording/1\n# name: drawn\n# source: wind-tunnel\n"
    return head + "time_s,fin_cmd_deg,roll_deg\n" + "".join(line + "\n" for line in log["lines"])


@settings(PROPERTY, max_examples=60)
@given(
    log=logs(),
    time_unit=mostly(["s"], ["ms", "us"]),
    units=mostly(["deg"], ["rad"]),
    out_name=mostly(["rec.csv", "sub/rec.csv"], ["log.csv", "out.json"]),
)
def test_import_csv(log: dict[str, Any], time_unit: str, units: str, out_name: str) -> None:
    with folder() as root:
        source = root / "log.csv"
        source.write_text("".join(line + "\n" for line in log["lines"]), encoding="utf-8")
        (root / "out.json").write_text('{"mine": true}\n', encoding="utf-8")  # another kind
        out = root / out_name
        argv = ["import-csv", str(source), "--out", str(out), "--columns", "time,fin_cmd,roll"]
        argv += ["--no-header", "--time-unit", time_unit, "--units", units]
        mine = out_name in ("log.csv", "out.json")  # the input, and a file of another kind
        code, _ = run_contract(argv, root, outputs=() if mine else (out,))
        if code == 0:
            from identification.recordings.recording import load_recording

            assert load_recording(out).n_samples > 0


@settings(PROPERTY, max_examples=30)
@given(log=logs(), method=st.sampled_from(["paper", "output-error"]))
def test_info_and_identify(log: dict[str, Any], method: str) -> None:
    with folder() as root:
        rec = root / "rec.csv"
        rec.write_text(recording_text(log), encoding="utf-8")
        run_contract(["info", str(rec)], root)
        report = root / "fit.json"
        argv = ["identify", str(rec), "--method", method, "--mc-runs", "0", "--json", str(report)]
        run_contract(argv, root, outputs=(report,))
        db = root / "my.sqlite"
        argv = ["db", "add", str(rec), "--db", str(db), "--method", method, "--mc-runs", "0"]
        run_contract([*argv, "--surrogates", "0"], root, outputs=(db,))


# ----------------------------------------------------------------------------- options
#: Values an option may be given: edges, beyond them, not numbers at all.
NUMBERS = st.sampled_from(
    ["0", "-1", "1", "2", "3", "1e9", "-1e9", "nan", "inf", "-inf", "1e-12", "abc", "", "0.5"]
)
#: Environment options --set may name, with a known one misspelt among them.
ENV_OPTIONS = st.sampled_from(
    [
        "gyro_noise_pct", "episode_s", "setpoint_period_s", "initial_angle_deg", "dt_s",
        "substep_s", "disturbance_scale", "fin_range_deg", "rate_limit_dps", "encoder_counts",
        "method", "disturbance", "model", "recording", "setpoint", "split", "task", "gyro_nois",
    ]
)  # fmt: skip
SET_VALUES = st.one_of(
    NUMBERS,
    st.sampled_from(["paper", "ml", "replay", "posterior", "none", "zero", "true", "x", "-5"]),
)
#: The registered environments (the tunnel's tasks twice as often as the flight's).
ENV_IDS = ["RocketRoll-v0", "RocketRollRate-v0"] * 2 + ["RocketRollFlight-v0",
                                                        "RocketRollFlightRate-v0"]  # fmt: skip
#: --set pairs that are valid, drawn as often as the rest.
GOOD_OPTIONS = st.sampled_from(
    [
        ("gyro_noise_pct", "0"), ("gyro_noise_pct", "5"), ("episode_s", "20"),
        ("setpoint", "zero"), ("method", "paper"), ("disturbance", "none"),
        ("disturbance", "replay"), ("initial_angle_deg", "10"), ("disturbance_scale", "1.5"),
    ]
)  # fmt: skip
SET_OPTIONS = st.lists(st.one_of(GOOD_OPTIONS, st.tuples(ENV_OPTIONS, SET_VALUES)), max_size=2)


@settings(PROPERTY, max_examples=40)
@given(
    episodes=mostly(["1", "2"], ["0", "-1", "1e9", "nan", "abc", "", "100001"]),
    policy=mostly(["pid", "pid:3", "trim", "observer", "mpc:5"],
                  ["pid:0", "pid:-3", "pid:nan", "mpc:0", "mpc:101", "mpc:100000", "nope",
                   "ppo:/nonexistent"]),
    options=SET_OPTIONS,
    out_kind=st.sampled_from([None, "folder", "folder", "file"]),
    env_id=st.sampled_from(ENV_IDS),
)  # fmt: skip
def test_eval(
    episodes: str, policy: str, options: list[tuple[str, str]], out_kind: str | None,
    env_id: str, default_db: Path,
) -> None:  # fmt: skip
    with folder() as root:
        argv = ["eval", "--env-id", env_id, "--policy", policy, "--episodes", episodes]
        for key, value in options:
            argv += ["--set", f"{key}={value}"]
        outputs: tuple[Path, ...] = ()
        if out_kind == "folder":
            outputs = (root / "eval",)
            argv += ["--out", str(outputs[0])]
        elif out_kind == "file":  # a file where the output folder is wanted
            (root / "eval").write_text("mine\n", encoding="utf-8")
            argv += ["--out", str(root / "eval")]
        run_contract(argv, root, outputs=outputs, inputs=(default_db,))


@settings(PROPERTY, max_examples=25)
@given(
    omegas=mostly(["2", "2,3", "1e-9", "1.5", "8,10"], ["0", "-1", "nan", "1e9", "", "a,b"]),
    episodes=mostly(["1", "2"], ["0", "-2", "x", "1e9"]),
    metric=mostly(["regulation_rms_error", "rms_error", "return"], ["bogus"]),
    options=SET_OPTIONS,
    env_id=st.sampled_from(ENV_IDS),
)
def test_tune(
    omegas: str, episodes: str, metric: str, options: list[tuple[str, str]], env_id: str,
    default_db: Path,
) -> None:  # fmt: skip
    with folder() as root:
        argv = ["tune", "pid", "--env-id", env_id, "--omegas", omegas, "--episodes", episodes]
        argv += ["--metric", metric]
        for key, value in options:
            argv += ["--set", f"{key}={value}"]
        run_contract(argv, root, inputs=(default_db,))


@settings(PROPERTY, max_examples=12)
@given(
    envs=mostly(["1"], ["0", "-1", "5000", "100000", "x"]),
    timesteps=mostly(["256"], ["0", "10", "1e12", "-5", "nan"]),
    eval_episodes=mostly(["1"], ["0", "5000", "-1"]),
    out_kind=mostly(["folder"], ["file"]),
)
def test_train(
    envs: str, timesteps: str, eval_episodes: str, out_kind: str, default_db: Path
) -> None:
    with folder() as root:
        out = root / "run"
        if out_kind == "file":
            out.write_text("mine\n", encoding="utf-8")
        argv = ["train", "ppo", "--envs", envs, "--timesteps", timesteps, "--out", str(out)]
        argv += ["--eval-episodes", eval_episodes, "--eval-freq", "0", "--no-progress-bar"]
        run_contract(
            argv, root, outputs=(out,) if out_kind == "folder" else (), inputs=(default_db,)
        )


@settings(PROPERTY, max_examples=30)
@given(
    args=st.lists(
        st.sampled_from(
            [
                ("--seed", NUMBERS), ("--log-dt", NUMBERS), ("--alpha", NUMBERS),
                ("--beta", NUMBERS), ("--turbulence-sd", NUMBERS), ("--steps", NUMBERS),
                ("--substeps", NUMBERS), ("--dwell-min", NUMBERS), ("--dwell-max", NUMBERS),
                ("--servo-rate", NUMBERS), ("--gyro-noise", NUMBERS),
            ]
        ),
        max_size=3,
        unique_by=lambda pair: pair[0],
    ),
    data=st.data(),
    out_name=st.sampled_from(["rec.csv", "mine.png"]),
)  # fmt: skip
def test_tunnel(args: list[tuple[str, Any]], data: st.DataObject, out_name: str) -> None:
    with folder() as root:
        png = root / "mine.png"
        png.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 16)  # someone's figure
        out = root / out_name
        argv = ["tunnel", "--out", str(out), "--schedule", "staircase", "--steps", "2"]
        for flag, values in args:
            argv += [flag, data.draw(values)]
        run_contract(argv, root, outputs=() if out == png else (out,))


@settings(PROPERTY, max_examples=15)
@given(
    episodes=mostly(["1"], ["0", "-1", "x", "1e9"]),
    frames=st.sampled_from([None, "f.png", "f.png", "f.txt", "rec.csv"]),
    options=SET_OPTIONS,
)
def test_env_rollout(
    episodes: str, frames: str | None, options: list[tuple[str, str]], default_db: Path
) -> None:
    with folder() as root:
        (root / "rec.csv").write_text("# format: rocketroll-recording/1\n", encoding="utf-8")
        argv = ["env", "rollout", "--policy", "random", "--episodes", episodes]
        outputs: tuple[Path, ...] = ()
        if frames is not None:
            outputs = (root / frames,) if frames != "rec.csv" else ()
            argv += ["--frames", str(root / frames)]
        for key, value in options:
            argv += ["--set", f"{key}={value}"]
        run_contract(argv, root, outputs=outputs, inputs=(default_db,))


@settings(PROPERTY, max_examples=20)
@given(
    name=mostly(["ok", "my-sweep.1"], ["../../etc", "a b", "", ".hidden", "x" * 300, "ünï"]),
    episodes=mostly(["2"], ["1", "0", "x", "-3", "1e9"]),
    seeds=mostly(["[0]", "[0, 1]"], ["[]", "[-1]", "x", "[0, 0]"]),
    settings_text=st.sampled_from(["", "", "settings: {method: [paper]}\n",
                                   "settings: {split: [test]}\n", "settings: {nope: [1]}\n",
                                   "settings: {episode_s: [1e9]}\n"]),
    default_out=st.booleans(),
)  # fmt: skip
def test_sweep_run(
    name: str, episodes: str, seeds: str, settings_text: str, default_out: bool, default_db: Path
) -> None:
    with folder() as root:
        spec = root / "spec.yml"
        spec.write_text(
            f"name: {name!r}\nenv_ids: [RocketRoll-v0]\nepisodes: {episodes}\nseeds: {seeds}\n"
            "controllers:\n  - {name: pid, policy: pid}\n" + settings_text,
            encoding="utf-8",
        )
        argv = ["sweep", "run", str(spec), "--no-progress"]
        if default_out:  # runs/sweeps/NAME, below the folder it runs from
            out = root / "runs" / "sweeps"
        else:
            out = root / "sweep"
            argv += ["--out", str(out)]
        run_contract(argv, root, outputs=(out,), inputs=(default_db,))


@settings(PROPERTY, max_examples=12)
@given(
    key=mostly(["1", "2"], ["0", "-1", "999999", "abc", "x" * 200, "1e3"]),
    sub=st.sampled_from(["show", "surrogate"]),
)
def test_db_by_id(key: str, sub: str, default_db: Path) -> None:
    with folder() as root:
        copy = root / "copy.sqlite"
        copy.write_bytes(default_db.read_bytes())
        argv = ["db", sub, key, "--db", str(copy)]
        if sub == "surrogate":
            argv += ["--count", "1"]
        run_contract(argv, root, outputs=(copy,) if sub == "surrogate" else ())


@settings(PROPERTY, max_examples=15)
@given(
    args=st.lists(
        st.sampled_from(
            [
                ("--seed", NUMBERS), ("--alpha", NUMBERS), ("--beta", NUMBERS),
                ("--v-ref", NUMBERS), ("--servo-rate", NUMBERS),
                ("--ascent", st.sampled_from(["default", "nope", "rec.csv"])),
            ]
        ),
        max_size=2,
        unique_by=lambda pair: pair[0],
    ),
    data=st.data(),
)  # fmt: skip
def test_record_flight(args: list[tuple[str, Any]], data: st.DataObject) -> None:
    with folder() as root:
        (root / "rec.csv").write_text("# format: rocketroll-recording/1\n", encoding="utf-8")
        out = root / "flight.csv"
        argv = ["record-flight", "--out", str(out)]
        for flag, values in args:
            value = data.draw(values)
            argv += [flag, str(root / value) if value == "rec.csv" else value]
        run_contract(argv, root, outputs=(out,))


@settings(PROPERTY, max_examples=12)
@given(
    command=st.sampled_from(["seeds", "robustness"]),
    episodes=mostly(["2"], ["0", "1", "-1", "x", "1e9"]),
    options=SET_OPTIONS,
    out_kind=mostly(["folder"], ["file"]),
)
def test_seeds_and_robustness(
    command: str, episodes: str, options: list[tuple[str, str]], out_kind: str, default_db: Path
) -> None:
    seeds = Path(__file__).resolve().parents[1] / "agents/policies/seeds/RocketRoll-v0/ppo"
    with folder() as root:
        out = root / "out"
        if out_kind == "file":
            out.write_text("mine\n", encoding="utf-8")
        if command == "seeds":
            argv = ["seeds", "--run", f"ppo:{seeds / 'seed1'}", "--run", f"ppo:{seeds / 'seed2'}"]
            argv += ["--reference", "pid"]
        else:
            argv = ["robustness", "--policy", "pid", "--condition", "default"]
        argv += ["--episodes", episodes, "--out", str(out)]
        for key, value in options:
            argv += ["--set", f"{key}={value}"]
        outputs = (out,) if out_kind == "folder" else ()
        run_contract(argv, root, outputs=outputs, inputs=(default_db,))


def test_the_property_tests_cover_every_command() -> None:
    from rocketroll.cli import COMMANDS

    tested = {
        name.removeprefix("test_").replace("_", "-")
        for name in globals()
        if name.startswith("test_")
    }
    named = {"info-and-identify": {"info", "identify"}, "seeds-and-robustness":
             {"seeds", "robustness"}, "db-by-id": {"db"}, "env-rollout": {"env"},
             "sweep-run": {"sweep"}}  # fmt: skip
    covered = set().union(*(named.get(t, {t}) for t in tested))
    assert set(COMMANDS) <= covered, set(COMMANDS) - covered
