"""``rocketroll sweep``: specs, trials, the results store, resume and failing trials."""

from __future__ import annotations

import contextlib
import io
import json
import re
import sqlite3
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from agents.sweep import ResultStore, SweepSpec, expand, load_spec, run_sweep
from rocketroll.cli import command
from rocketroll_common.errors import UsageError
from rocketroll_common.settings import run_command

TINY_PPO = """\
RocketRoll-v0:
  n_envs: 2
  n_timesteps: 64
  policy: MlpPolicy
  normalize: {norm_obs: true, norm_reward: true}
  n_steps: 32
  batch_size: 32
  n_epochs: 1
  policy_kwargs: {net_arch: [8]}
"""


def _spec(tmp_path: Path, text: str) -> Path:
    (tmp_path / "tiny-ppo.yml").write_text(TINY_PPO, encoding="utf-8")
    path = tmp_path / "spec.yml"
    path.write_text(text, encoding="utf-8")
    return path


TWO_TRIALS = """\
name: tiny
env_ids: [RocketRoll-v0]
episodes: 2
seeds: [3]
controllers:
  - {name: pid, policy: pid}
  - name: ppo
    train: ppo
    hyperparams: tiny-ppo.yml
"""


def test_a_spec_expands_to_its_grid_and_a_random_sample_of_it(tmp_path):
    spec = load_spec(
        _spec(
            tmp_path,
            TWO_TRIALS.replace("seeds: [3]", "seeds: [0, 1]")
            + "    grid: {learning_rate: [0.001, 0.0003], n_epochs: [1, 2]}\n"
            + "settings: {method: [ml, paper]}\n",
        )
    )
    trials = expand(spec)
    # per settings point: pid once, ppo 2 x 2 grid x 2 seeds
    assert len(trials) == 2 * (1 + 8)
    assert len({t.id for t in trials}) == len(trials)
    assert {t.seed for t in trials if t.controller.name == "pid"} == {None}
    ppo = [t for t in trials if t.controller.name == "ppo"]
    assert {(t.params["learning_rate"], t.params["n_epochs"], t.seed) for t in ppo} == {
        (lr, e, s) for lr in (0.001, 0.0003) for e in (1, 2) for s in (0, 1)
    }
    assert trials[0].id == expand(spec)[0].id  # the id is the spec's, stable
    assert spec.name == "tiny" and {t.sweep for t in trials} == {"tiny"}
    grid_text = (tmp_path / "spec.yml").read_text(encoding="utf-8")
    random_text = grid_text + "search: {kind: random, trials: 5, seed: 1}\n"
    sample = expand(load_spec(_spec(tmp_path, random_text)))
    assert len(sample) == 5 and {t.id for t in sample} <= {t.id for t in trials}
    assert [t.id for t in sample] == [t.id for t in expand(load_spec(tmp_path / "spec.yml"))]
    other = expand(load_spec(_spec(tmp_path, random_text.replace("seed: 1}", "seed: 2}"))))
    assert {t.id for t in other} != {t.id for t in sample}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "name: x\nenv_ids: [Nope-v0]\ncontrollers: [{name: p, policy: pid}]\n",
            "unknown 'Nope-v0'",
        ),
        (
            "name: x\nenv_ids: [RocketRoll-v0]\ncontrollers: [{name: p, policy: nope}]\n",
            "unknown policy 'nope'",
        ),
        (
            "name: x\nenv_ids: [RocketRoll-v0]\ncontrollers: [{name: p}]\n",
            "give exactly one of policy",
        ),
        (
            "name: x\nenv_ids: [RocketRoll-v0]\ncontrollers: [{name: p, policy: pid}]\nfoo: 1\n",
            "unknown key 'foo'",
        ),
        (
            "name: x\nenv_ids: [RocketRoll-v0]\ncontrollers:\n  - {name: q, train: ppo, "
            "hyperparams: tiny-ppo.yml, grid: {n_epoch: [1]}}\n",
            "unknown key(s) 'n_epoch'",
        ),
        (
            "name: x\nenv_ids: [RocketRoll-v0]\ncontrollers:\n  - {name: q, train: a2c, "
            "hyperparams: tiny-ppo.yml}\n",
            "controllers[0].train: Input should be 'ppo', 'sac' or 'td3', got 'a2c'",
        ),
        (
            "name: x\nenv_ids: [RocketRoll-v0]\ncontrollers: [{name: p, policy: pid}]\n"
            "search: {kind: random}\n",
            "kind random needs trials",
        ),
        (  # it names the sweep's folder, which it must not leave
            "name: ../../etc\nenv_ids: [RocketRoll-v0]\ncontrollers: [{name: p, policy: pid}]\n",
            "name: must be one word of letters, digits",
        ),
        (
            "name: .hidden\nenv_ids: [RocketRoll-v0]\ncontrollers: [{name: p, policy: pid}]\n",
            "got '.hidden'",
        ),
    ],
)
def test_bad_specs_are_named(text, message, tmp_path):
    path = _spec(tmp_path, text)
    with pytest.raises(UsageError, match=re.escape(message)) as info:
        load_spec(path)
    assert str(path) in str(info.value)


@dataclass(frozen=True)
class _Swept:
    """The two trials of :data:`TWO_TRIALS` run in-process: the spec, its folder, records."""

    spec: SweepSpec
    out: Path
    records: list[dict[str, Any]]


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory: pytest.TempPathFactory, default_db: Path) -> Iterator[_Swept]:
    """One in-process run of the two trials, for the store's test and Ray's to read."""
    folder = tmp_path_factory.mktemp("tiny-sweep")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SB3_LOGDIR", str(folder / "sb3-logs"))
        spec = load_spec(_spec(folder, TWO_TRIALS))
        out = folder / "out"
        yield _Swept(spec, out, run_sweep(spec, out, progress=False))


def test_a_tiny_sweep_stores_every_trial_and_resumes(tiny_sweep: _Swept) -> None:
    """Two trials (PID, a tiny PPO): both stored with spec, version, metrics and artifacts;
    run again, nothing is re-run; the store's numbers are the protocol's."""
    from agents.evaluate import HEADLINE

    spec, out, records = tiny_sweep.spec, tiny_sweep.out, tiny_sweep.records
    assert [r["status"] for r in records] == ["done", "done"], records
    with ResultStore(out / "results.sqlite") as store:
        rows = store.rows("tiny")
    assert len(rows) == 2
    by_name = {r["controller"]: r for r in rows}
    pid, ppo = by_name["pid"], by_name["ppo"]
    assert pid["seed"] is None and ppo["seed"] == 3
    for row in rows:
        assert row["headline"] == HEADLINE and len(row["episode_headline"]) == 2
        assert row["headline_mean"] == pytest.approx(sum(row["episode_headline"]) / 2)
        assert row["metrics"]["rms_error"] > 0 and row["version"]
        assert row["spec"]["episodes"] == 2 and row["wall_s"] > 0
    assert Path(ppo["artifacts"]["model"]).is_file() and ppo["env_steps_per_s"] > 0
    # The PID's row is what `rocketroll eval` measures on the same protocol.
    assert pid["headline_mean"] == pytest.approx(_eval_headline("pid", 2), rel=1e-12)
    again = run_sweep(spec, out, progress=False)
    assert again == []  # resumed: every trial already done


def _eval_headline(policy: str, episodes: int) -> float:
    from agents.evaluate import evaluate, headline_scores, protocol_episodes
    from agents.registry import make_controller
    from rollenv.bank import load_bank, variant_config

    config = variant_config("RocketRoll-v0", {"split": "test"})
    bank = load_bank(config, None)
    specs = protocol_episodes(config, episodes, 0, bank=bank)
    result = evaluate(config, make_controller(policy, config, "RocketRoll-v0"), specs, bank=bank)
    return float(headline_scores(result).mean())


def test_a_failing_trial_is_recorded_and_the_sweep_goes_on(tmp_path, default_db):
    """A trial that raises (here: a learning rate SB3 cannot use) is stored as failed with
    its error; the other trial is done; the command exits 1; a rerun retries only it."""
    text = TWO_TRIALS + "    grid: {learning_rate: [-1.0]}\n"
    spec_path = _spec(tmp_path, text)
    out = tmp_path / "out"
    argv = [str(spec_path), "--out", str(out), "--no-progress"]
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        code = run_command(command("sweep"), ["run", *argv], "rocketroll sweep")
    assert code == 1
    assert "ran 2 trials (1 failed)" in printed.getvalue()
    with ResultStore(out / "results.sqlite") as store:
        rows = {r["controller"]: r for r in store.rows()}
    assert rows["pid"]["status"] == "done"
    failed = rows["ppo learning_rate=-1.0"]
    assert failed["status"] == "failed" and failed["headline_mean"] is None
    assert failed["error"].strip()
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        run_command(command("sweep"), ["run", *argv], "rocketroll sweep")
    assert "ran 1 trials (1 failed), skipped 1 already done" in printed.getvalue()


def test_the_store_is_plain_sqlite_and_exports_parquet(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet", reason="Parquet export needs the parquet extra")
    record = {
        "id": "abc",
        "sweep": "s",
        "env_id": "RocketRoll-v0",
        "controller": "pid",
        "seed": None,
        "spec": {"episodes": 2},
        "status": "done",
        "headline": "regulation_rms_error",
        "headline_mean": 0.5,
        "metrics": {"rms_error": float("nan")},
        "episode_headline": [0.4, 0.6],
        "wall_s": 1.0,
        "version": "0",
    }
    with ResultStore(tmp_path / "r.sqlite") as store:
        store.record(record)
        target = store.export_parquet(tmp_path / "r.parquet")
    with sqlite3.connect(tmp_path / "r.sqlite") as db:
        (metrics,) = db.execute("SELECT metrics FROM trials WHERE id = 'abc'").fetchone()
    assert json.loads(metrics) == {"rms_error": None}  # NaN stored as null, valid JSON
    table = pq.read_table(target).to_pylist()
    assert table[0]["id"] == "abc" and table[0]["headline_mean"] == 0.5


def test_the_same_sweep_on_ray_gives_the_same_results(tmp_path, tiny_sweep: _Swept) -> None:
    """The learned trial (trained, then evaluated) as a Ray Tune trial on a local Ray
    instance started here (one CPU): the same trial id and the same numbers, value for
    value, as in-process."""
    ray = pytest.importorskip(
        "ray", reason="Ray is an optional extra (pip install 'rocketroll[ray]'); make test has it"
    )
    pytest.importorskip("ray.tune", reason="Ray Tune is part of the rocketroll[ray] extra")
    spec = load_spec(_spec(tmp_path, TWO_TRIALS.replace("  - {name: pid, policy: pid}\n", "")))
    (learned,) = expand(spec)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        remote = run_sweep(spec, tmp_path / "ray", progress=False, ray="auto")
    finally:
        ray.shutdown()
    assert len(remote) == 1 and all(r["status"] == "done" for r in remote), remote
    with ResultStore(tmp_path / "ray" / "results.sqlite") as store:
        stored = {r["id"]: r for r in store.rows()}
    local_by_id = {r["id"]: r for r in tiny_sweep.records}
    assert stored.keys() == {learned.id} and learned.id in local_by_id
    for trial_id, row in stored.items():
        mine = local_by_id[trial_id]
        assert row["headline_mean"] == mine["headline_mean"]
        assert row["episode_headline"] == mine["episode_headline"]
        assert row["metrics"] == mine["metrics"]


def test_the_report_summarises_seeds_against_the_pid(tmp_path, default_db):
    """Two PPO seeds and the PID: the report's learner is the two runs, its P(beats PID)
    is the share of run x episode scores below the PID's on the same episode, and
    `rocketroll sweep report` writes report.md with the table and a figure."""
    spec = load_spec(_spec(tmp_path, TWO_TRIALS.replace("seeds: [3]", "seeds: [3, 4]")))
    out = tmp_path / "out"
    assert all(r["status"] == "done" for r in run_sweep(spec, out, progress=False))
    from agents.sweep import report

    with ResultStore(out / "results.sqlite") as store:
        rows = store.rows()
    (table,) = report(rows)
    (learner,) = table["learners"]
    assert learner.name == "ppo" and learner.runs == ["seed 3", "seed 4"]
    pid = next(r for r in rows if r["controller"] == "pid")["episode_headline"]
    ppo = [r["episode_headline"] for r in sorted(rows, key=lambda r: str(r["seed"])) if r["seed"]]
    wins = [(a < b) + 0.5 * (a == b) for run in ppo for a, b in zip(run, pid, strict=True)]
    assert learner.p_beats == pytest.approx(sum(wins) / len(wins))
    assert learner.mean == pytest.approx(sum(map(sum, ppo)) / 4)
    assert table["best"] == {"ppo": "ppo"}
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        assert run_command(command("sweep"), ["report", str(out)], "rocketroll sweep") == 0
    assert "| ppo | 2 |" in printed.getvalue() and "| pid | 1 |" in printed.getvalue()
    assert (out / "report.md").is_file() and (out / "report-1.png").stat().st_size > 10_000
    with contextlib.redirect_stderr(io.StringIO()) as errors:
        assert run_command(command("sweep"), ["report", str(tmp_path)], "rocketroll sweep") == 2
    assert "results.sqlite: no results store" in errors.getvalue()


def test_the_shipped_sweep_spec_loads():
    """agents/sweeps/pid-ppo-seeds.yml (the docs' sweep, by name): PID, observer, five PPO
    seeds, both tasks."""
    from agents.sweep import expand

    spec = load_spec("pid-ppo-seeds")
    trials = expand(spec)
    assert len(trials) == 2 * (1 + 1 + 5)
    assert {t.controller.name for t in trials} == {"pid", "observer", "ppo"}
    assert all(
        Path(str(t.controller.hyperparams)).is_file() for t in trials if t.controller.learned
    )


def test_trial_ids_follow_the_recipe_s_content_and_repeats_are_one_trial(tmp_path):
    """An edited recipe makes new trials, the same recipe in another place does not; a
    value listed twice is one trial; a larger random sample holds a smaller one."""
    base = TWO_TRIALS.replace("seeds: [3]", "seeds: [3, 3, 4]")
    first = {t.id for t in expand(load_spec(_spec(tmp_path, base)))}
    assert len(first) == 3  # pid, ppo seeds 3 and 4
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    (moved / "tiny-ppo.yml").write_text(TINY_PPO, encoding="utf-8")
    (moved / "spec.yml").write_text(base, encoding="utf-8")
    assert {t.id for t in expand(load_spec(moved / "spec.yml"))} == first
    (moved / "tiny-ppo.yml").write_text(TINY_PPO.replace("n_epochs: 1", "n_epochs: 2"), "utf-8")
    edited = {t.id for t in expand(load_spec(moved / "spec.yml"))}
    assert len(edited & first) == 1  # only the PID's trial is the same
    grid = base.replace("seeds: [3, 3, 4]", "seeds: [0, 1, 2, 3, 4, 5, 6, 7]")
    small, large = (
        {
            t.id
            for t in expand(
                load_spec(_spec(tmp_path, grid + f"search: {{kind: random, trials: {k}}}\n"))
            )
        }
        for k in (3, 6)
    )
    assert len(small) == 3 and len(large) == 6 and small <= large


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ("settings: {split: [train]}\n", "settings.split: not a setting to search"),
        ("settings: {nope: [1]}\n", "settings {'nope': 1} on RocketRoll-v0"),
    ],
)
def test_bad_settings_are_named_before_any_trial(settings, message, tmp_path):
    with pytest.raises(UsageError, match=re.escape(message)):
        load_spec(_spec(tmp_path, TWO_TRIALS + settings))


def test_a_trial_whose_worker_died_is_stored_as_failed(tmp_path, monkeypatch, default_db):
    """No record from a worker (killed, out of memory): the trial is stored as failed, so
    the next run retries it."""
    import agents.sweep.runner as sweep

    spec = load_spec(
        _spec(
            tmp_path,
            TWO_TRIALS.replace(
                "  - name: ppo\n    train: ppo\n    hyperparams: tiny-ppo.yml\n", ""
            ),
        )
    )
    monkeypatch.setattr(sweep, "_execute", lambda *args: iter(()))
    (record,) = run_sweep(spec, tmp_path / "out", progress=False)
    assert record["status"] == "failed" and record["error"] == "no result came back"
    with ResultStore(tmp_path / "out" / "results.sqlite") as store:
        assert store.done() == set() and len(store.rows()) == 1


def test_ray_without_the_extra_is_refused_before_anything_is_made(
    tmp_path, monkeypatch: pytest.MonkeyPatch
):
    """`sweep run ... --ray auto` without Ray started its progress bar and left
    results.sqlite before it refused."""
    import agents.sweep

    monkeypatch.setitem(sys.modules, "agents.sweep.on_ray", None)  # as if Ray were not installed
    monkeypatch.delattr(agents.sweep, "on_ray", raising=False)
    out = tmp_path / "out"
    argv = ["run", str(_spec(tmp_path, TWO_TRIALS)), "--out", str(out), "--ray", "auto"]
    with contextlib.redirect_stderr(io.StringIO()) as errors:
        assert run_command(command("sweep"), argv, "rocketroll sweep") == 2
    assert "--ray needs Ray Tune, an optional extra" in errors.getvalue()
    assert not out.exists()
