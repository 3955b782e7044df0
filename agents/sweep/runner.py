"""Running a sweep: its trials in this process, in worker processes or on a Ray cluster,
skipping those done, each record stored as it comes."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from agents.sweep.spec import SweepSpec
from agents.sweep.store import ResultStore
from agents.sweep.trials import Trial, expand, failed_record, run_trial
from rocketroll_common.errors import UsageError


# ----------------------------------------------------------------------------- running
def run_sweep(
    spec: SweepSpec,
    out: str | os.PathLike[str],
    *,
    jobs: int = 1,
    db: str | None = None,
    progress: bool = True,
    ray: str | None = None,
    trials: Sequence[Trial] | None = None,
) -> list[dict[str, Any]]:
    """Run every trial of ``spec`` (``trials``: its :func:`expand`, if already made) not yet
    done in ``OUT/results.sqlite``; the records of this run (finished and failed), in the
    order they ended.

    ``ray``: run the trials as Ray Tune trials on the cluster at that address
    (``"auto"``: the running cluster this machine belongs to, or a local
    instance; an already initialised Ray is used as it is), one CPU each,
    instead of ``jobs`` local processes.  Each record reaches the store in
    this process as its trial ends, as in-process; ``OUT`` and the database
    must be on a file system every node sees.
    """
    root = Path(out).resolve()
    if db is None:  # name it for the workers, whose environment may differ
        from disturbances.default import default_path

        db = str(default_path())
    db = str(Path(db).resolve())  # Ray runs each trial in a folder of its own
    if ray:
        ray_module(ray)  # refused before anything is made
    if trials is None:
        trials = expand(spec)
    with ResultStore(root / "results.sqlite") as store:
        done = store.done()
        todo = [t for t in trials if t.id not in done]
        records: list[dict[str, Any]] = []
        bar = _bar(len(todo), f"sweep {spec.name}", progress)

        def take(record: dict[str, Any]) -> None:
            store.record(record)
            records.append(record)
            bar.update(1)
            if record["status"] == "failed":
                bar.write(
                    f"trial {record['id']} ({record['controller']}) failed: "
                    f"{record['error'].splitlines()[0]}"
                )

        errors: dict[str, str] = {}
        if ray:
            errors = _on_ray(todo, root, db, ray, take)
        else:
            for record in _execute(todo, root, db, jobs):
                take(record)
        seen = {r["id"] for r in records}
        for trial in todo:  # a worker that died: its trial failed, to be retried
            if trial.id not in seen:
                take(failed_record(trial, errors.get(trial.id, "no result came back")))
        bar.close()
    return records


def _bar(total: int, desc: str, enabled: bool) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="trial", disable=not enabled)


def _execute(
    trials: Sequence[Trial], root: Path, db: str | None, jobs: int
) -> Iterator[dict[str, Any]]:
    if jobs <= 1 or len(trials) <= 1:
        for trial in trials:
            yield run_trial(trial, root, db)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(run_trial, t, root, db): t for t in trials}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:  # the worker died (memory, a signal): the trial failed
                yield failed_record(futures[future], f"{type(exc).__name__}: {exc}")


def _on_ray(
    trials: Sequence[Trial],
    root: Path,
    db: str,
    address: str,
    take: Callable[[dict[str, Any]], None],
) -> dict[str, str]:
    """The trials as Ray Tune trials (one CPU each); ``take`` gets each record as its trial
    ends (:mod:`agents.sweep.on_ray`); the errors of trials that gave none, by trial id."""
    sweep_ray = ray_module(address)
    if not trials:
        return {}
    return sweep_ray.run(trials, run_trial, root, db, address, take)


def ray_module(address: str) -> Any:
    """:mod:`agents.sweep.on_ray`, or a ``UsageError`` when Ray Tune is missing or ``address``
    cannot hold the results store (before anything is made)."""
    try:
        from agents.sweep import on_ray as sweep_ray
    except ImportError as exc:
        raise UsageError(
            "--ray needs Ray Tune, an optional extra: pip install 'rocketroll[ray]'"
        ) from exc
    if address.startswith("ray://"):
        raise UsageError(
            f"--ray {address}: Ray Client runs Tune away from this process, where the results "
            "store is; run the sweep on the cluster's head node (--ray auto) instead"
        )
    return sweep_ray
