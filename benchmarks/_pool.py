"""One way the studies spread their independent jobs over processes, with progress."""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from tqdm.auto import tqdm

__all__ = ["run_jobs"]

_Result = TypeVar("_Result")


def run_jobs(
    function: Callable[..., _Result],
    jobs: Sequence[tuple[Any, ...]],
    processes: int,
    desc: str,
    unit: str = "it",
) -> list[_Result]:
    """``function(*job)`` for each of ``jobs``, in order: in this process where
    ``processes`` is 1, else over that many spawned processes; a progress bar either way."""
    if processes == 1:
        return [function(*job) for job in tqdm(jobs, desc=desc, unit=unit)]
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(processes, mp_context=context) as pool:
        mapped = pool.map(function, *zip(*jobs, strict=True))
        return list(tqdm(mapped, total=len(jobs), desc=desc, unit=unit))
