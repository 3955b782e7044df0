"""Evaluation episodes as Minari datasets for offline RL (optional extra ``rocketroll[minari]``).

``rocketroll eval ... --minari PREFIX`` writes one dataset per controller,
``PREFIX-<controller>-v0`` (``rocketroll/angle-test`` → ``rocketroll/angle-test-pid-v0``),
into Minari's local store (``$MINARI_DATASETS_PATH``, else
``~/.minari/datasets``): every protocol episode's observations (what the
controller saw: the flight sensors), actions (its normalised fin command),
rewards, terminations and truncations, with the episode's seed, and the
environment's spec, so ``minari.load_dataset(ID)`` gives them back and
``dataset.recover_environment()`` the environment (``import rollenv`` first:
it registers the ids).  All the datasets of one command or none: one that
cannot be written removes those written before it.
"""

from __future__ import annotations

import contextlib
import re
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rocketroll_common import __version__
from rocketroll_common.errors import UsageError

__all__ = ["check_minari", "dataset_id", "write_minari"]

_ID = re.compile(r"^[A-Za-z0-9_./-]+$")


def dataset_id(prefix: str, controller: str) -> str:
    """``PREFIX-<controller>-v0``: the controller's name lower-cased, runs of anything but
    letters and digits as ``_``."""
    slug = re.sub(r"[^a-z0-9]+", "_", controller.lower()).strip("_") or "controller"
    return f"{prefix}-{slug}-v0"


def check_minari(prefix: str, controllers: Sequence[str]) -> dict[str, str]:
    """The dataset id of each controller; ``UsageError`` (before any work) when Minari is
    not installed, ``prefix`` is not a dataset name, or one of the ids exists already."""
    try:
        import minari
    except ImportError as exc:
        raise UsageError(
            "--minari needs Minari, an optional extra: pip install 'rocketroll[minari]'"
        ) from exc
    from minari.dataset.minari_dataset import parse_dataset_id

    if not _ID.match(prefix):
        raise UsageError(
            f"--minari {prefix!r}: not a dataset name Minari takes ([NAMESPACE/]NAME, as in "
            "rocketroll/angle-test)"
        )
    ids = {name: dataset_id(prefix, name) for name in controllers}
    for made in ids.values():
        try:
            parse_dataset_id(made)
        except ValueError:
            raise UsageError(
                f"--minari {prefix!r}: not a dataset name Minari takes ([NAMESPACE/]NAME, as "
                f"in rocketroll/angle-test; {made} would be malformed)"
            ) from None
    same = sorted({i for i in ids.values() if list(ids.values()).count(i) > 1})
    if same:
        raise UsageError(f"--minari {prefix}: two controllers would both be dataset {same[0]}")
    existing = set(minari.list_local_datasets())
    taken = sorted(i for i in ids.values() if i in existing)
    if taken:
        raise UsageError(
            f"--minari {prefix}: dataset {taken[0]} exists already (minari.delete_dataset, or "
            "another prefix)"
        )
    return ids


def write_minari(
    prefix: str,
    episodes: Mapping[str, Sequence[dict[str, Any]]],
    env_id: str,
    settings: dict[str, Any],
    description: str,
) -> list[str]:
    """Write the ``episodes`` of each controller (name → :func:`agents.evaluate.evaluate`'s
    ``transitions``) as Minari datasets; their ids.

    Raises
    ------
    UsageError
        Minari is not installed, ``prefix`` is not a dataset name, or a
        dataset of that id exists already (nothing is written then).
    """
    import gymnasium as gym

    ids = check_minari(prefix, list(episodes))
    import minari
    from minari.data_collector import EpisodeBuffer

    import rollenv  # noqa: F401 -- registers the env ids the datasets name

    env = gym.make(env_id, **settings)
    written: list[str] = []
    try:
        for name, runs in episodes.items():
            buffers = [
                EpisodeBuffer(
                    id=k,
                    seed=int(run["seed"]),
                    options=run["options"],
                    observations=np.asarray(run["observations"], dtype=np.float32),
                    actions=np.asarray(run["actions"], dtype=np.float32),
                    rewards=list(run["rewards"]),
                    terminations=list(run["terminations"]),
                    truncations=list(run["truncations"]),
                    infos={},
                )
                for k, run in enumerate(runs)
            ]
            with warnings.catch_warnings():  # its advice on author e-mail and permalink
                warnings.filterwarnings("ignore", message=r"`(code_permalink|author_email)`")
                _create(minari, ids[name], buffers, env, name, description)
            written.append(ids[name])
    except BaseException:
        for made in [*written, *(i for i in ids.values() if i not in written)]:
            with contextlib.suppress(Exception):  # all or none: what was begun goes too
                minari.delete_dataset(made)
        raise
    finally:
        env.close()
    return written


def _create(
    minari: Any, dataset: str, buffers: list[Any], env: Any, name: str, description: str
) -> None:
    minari.create_dataset_from_buffers(
        dataset_id=dataset,
        buffer=buffers,
        env=env,
        eval_env=env,
        algorithm_name=name,
        author="rocketroll",
        data_format="arrow",
        description=f"{description}; controller {name}; rocketroll {__version__}",
    )
