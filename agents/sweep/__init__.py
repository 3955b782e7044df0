"""Experiments as data: ``rocketroll sweep run SPEC.yml`` trains and evaluates a grid or a
random sample of trials and keeps every result in one SQLite file.

A *spec* (YAML) names the tasks, the controllers with the settings to search,
the disturbance sets and the training seeds::

    name: pid-ppo-seeds
    env_ids: [RocketRoll-v0, RocketRollRate-v0]
    episodes: 20              # the evaluation protocol: test split, 20 episodes,
    eval_seed: 0              # episode seed 0 (agents.evaluate.protocol_episodes)
    seeds: [0, 1, 2, 3, 4]    # training seeds (a learned controller's trials)
    settings:                 # environment settings searched over (disturbance sets)
      method: [ml, paper]
    search: {kind: grid}      # or {kind: random, trials: 12, seed: 0}
    controllers:
      - {name: pid, policy: pid}             # any --policy of rocketroll eval
      - name: ppo
        train: ppo                           # ppo, sac or td3: trained per trial
        hyperparams: ../agents/hyperparams/ppo.yml   # relative to the spec (or the cwd)
        timesteps: 100000                    # optional, the entry's n_timesteps otherwise
        grid: {learning_rate: [0.0001, 0.0003]}   # hyperparameters searched over

A *trial* is one point: an env id, a controller with one value of each of its
grid's keys, one value of each ``settings`` key and (learned controllers) one
training seed.  ``kind: grid`` runs every point; ``kind: random`` draws
``trials`` of them without replacement (seeded).  Each trial trains (a
learned controller: ``agents.train.train`` into ``OUT/trials/ID/``, its
hyperparameter entry with the grid's values written to ``hyperparams.yml``
there) and is evaluated on the fixed test protocol
(:func:`agents.evaluate.evaluate`, the same episodes for every trial of an env
id and settings).

The *results store* is ``OUT/results.sqlite`` (:class:`ResultStore`): one row
per trial with its spec, seed, package version, git revision, status, error,
every metric's mean and the per-episode headline, wall time and artifact
paths, written in one transaction when the trial ends.  A trial's id is the
hash of its spec, so a sweep run again with the same ``--out`` skips the
trials already done (resume) and re-runs the ones that failed; a trial that
raises records its error and the sweep goes on.  ``--jobs N`` runs trials in
``N`` worker processes (``concurrent.futures``); the results do not depend on
``N``: every trial is seeded by its spec alone.
"""

from agents.sweep.report import report
from agents.sweep.runner import run_sweep
from agents.sweep.spec import SHIPPED, TRAINABLE, ControllerSpec, SweepSpec, load_spec, points
from agents.sweep.store import ResultStore
from agents.sweep.trials import Trial, expand, failed_record, run_trial

__all__ = [
    "SHIPPED",
    "TRAINABLE",
    "ControllerSpec",
    "ResultStore",
    "SweepSpec",
    "Trial",
    "expand",
    "failed_record",
    "load_spec",
    "points",
    "report",
    "run_sweep",
    "run_trial",
]
