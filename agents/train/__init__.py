"""Train Stable-Baselines3 PPO on RocketRoll-v0 / RocketRollRate-v0.

Read top to bottom, as CleanRL's ``ppo_continuous_action.py``: the arguments
(a dataclass, help and bounds on each field), the hyperparameters of the YAML file
keyed by environment id (rl-baselines3-zoo's layout), then the work:

1. seed everything (SB3's ``seed=``, ``torch.manual_seed``, the adapter's
   generator) and set torch's threads;
2. the training envs: ``VecNormalize(VecMonitor(RollVecEnv(split="train")))``
   -- the monitor inside, so it logs the raw returns whatever
   ``VecNormalize`` does to the rewards;
3. the held-out evaluation: the same stack over ``split="test"`` (observation
   statistics synced from training, frozen, raw rewards), the same seeded
   episodes at every evaluation, deterministic actions; it logs the mean
   return and the RMS true tracking error;
4. ``PPO.learn`` with checkpoints and a progress bar;
5. the **final** model is the result (``model.zip``).  It is *not* the best
   model by the test split: the test split is the held-out set, and choosing
   a model on it would leak it into the result.

Output directory::

    model.zip         the final PPO model
    normalize.json    observation normalisation (mean, var, clip, epsilon), portable
    vecnormalize.pkl  the same as SB3's VecNormalize.load(path, venv) reads it
    settings.json     arguments, resolved hyperparameters, command line, versions,
                      wall time, env-steps/s, the final model's test-split evaluation
    checkpoints/      periodic models and VecNormalize pickles (and the one Ctrl-C
                      saves; continue with --resume checkpoints/ppo_N_steps.zip)
    eval/             evaluations.npz (SB3) and tracking_error.csv
    logs/             SB3's progress.csv

Run::

    rocketroll train ppo --env-id RocketRoll-v0 --seed 0 --out runs/ppo-angle
    python -m agents.train --env-id RocketRollRate-v0 --timesteps 2000000   # the same
"""

from agents.train.envs import make_env, normalization_record
from agents.train.hyperparams import (
    ALGORITHMS,
    DEFAULT_HYPERPARAMS,
    HYPERPARAMS_DIR,
    Hyperparameters,
    _LinearSchedule,
    algorithm_arguments,
    algorithm_class,
    algorithm_keywords,
    load_hyperparameters,
    recipe_path,
    shipped_recipes,
    zoo_mapping,
)
from agents.train.run import (
    TRAIN_ARGS,
    VECNORMALIZE_FILE,
    Args,
    SACArgs,
    TD3Args,
    command_of,
    parse_args,
    quiet_logger,
    train,
)

__all__ = [
    "ALGORITHMS",
    "DEFAULT_HYPERPARAMS",
    "HYPERPARAMS_DIR",
    "TRAIN_ARGS",
    "VECNORMALIZE_FILE",
    "Args",
    "Hyperparameters",
    "SACArgs",
    "TD3Args",
    "algorithm_arguments",
    "algorithm_class",
    "algorithm_keywords",
    "command_of",
    "load_hyperparameters",
    "make_env",
    "normalization_record",
    "parse_args",
    "quiet_logger",
    "recipe_path",
    "shipped_recipes",
    "train",
    "zoo_mapping",
]
# Models saved before the package was split pickled their learning-rate schedule as
# agents.train._LinearSchedule: it stays importable from here.
_ = _LinearSchedule
