"""The Ray Tune side of ``rocketroll sweep run --ray ADDRESS`` (imported only then: Ray is
the optional extra ``rocketroll[ray]``).

Each trial of the sweep is one Tune trial of one CPU running
:func:`agents.sweep.run_trial` on whichever node Ray places it; the record it
reports comes back to the driver, where :class:`Collect` hands it to the
sweep's store as the trial ends.  Tune pickles its callbacks with the
experiment's state, so the callback carries only a key into :data:`SINKS`
(this module's, in the driver's process), not the store.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import ray
from ray import tune

from rocketroll_common.arrays import nan_to_none

__all__ = ["SINKS", "Collect", "run"]

#: Where the callbacks of running sweeps deliver their records, by key (driver only).
SINKS: dict[int, Callable[[dict[str, Any]], None]] = {}


class Collect(tune.Callback):
    """Hands each trial's record to the sink ``key`` of :data:`SINKS`, in the driver."""

    def __init__(self, key: int) -> None:
        self.key = key

    def on_trial_result(
        self, iteration: int, trials: Any, trial: Any, result: Any, **info: Any
    ) -> None:
        SINKS[self.key](json.loads(result["record"]))


def _trainable(config: dict[str, Any]) -> None:
    """One trial on a Ray worker: its record, reported as JSON text."""
    record = config["run_trial"](config["trial"], config["root"], config["db"])
    tune.report({"record": json.dumps(nan_to_none(record), allow_nan=False)})


def run(
    trials: Sequence[Any],
    run_trial: Callable[[Any, str, str], dict[str, Any]],
    root: Path,
    db: str,
    address: str,
    take: Callable[[dict[str, Any]], None],
) -> dict[str, str]:
    """Run ``run_trial(trial, root, db)`` for each of ``trials`` (:func:`agents.sweep.run_trial`
    and its trials) on the Ray cluster at ``address`` (``"auto"``: this machine's, or a new
    local instance; an initialised Ray as it is); ``take`` gets each record.  Returns the
    errors of the trials that reported none (a worker that died), by trial id."""
    # Quiet: the sweep prints its own progress; no TensorBoard/CSV loggers per trial.
    os.environ.setdefault("TUNE_DISABLE_AUTO_CALLBACK_LOGGERS", "1")
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    logging.getLogger("ray.tune").setLevel(logging.WARNING)
    if not ray.is_initialized():
        ray.init(address=None if address == "auto" else address, log_to_driver=False)
    key = id(take)
    SINKS[key] = take
    tuner = tune.Tuner(
        tune.with_resources(_trainable, {"cpu": 1}),
        param_space={
            "trial": tune.grid_search(list(trials)),
            "run_trial": run_trial,
            "root": str(root),
            "db": db,
        },
        run_config=tune.RunConfig(
            name="tune",
            storage_path=str(root / "ray"),
            callbacks=[Collect(key)],
            verbose=0,
        ),
    )
    try:
        results = tuner.fit()
    finally:
        del SINKS[key]
    errors = {}
    for i in range(len(results)):
        result = results[i]
        if result.error is not None and result.config:
            errors[result.config["trial"].id] = f"{type(result.error).__name__}: {result.error}"
    return errors
