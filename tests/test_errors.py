"""One error hierarchy: every exception a layer defines is a
:class:`rocketroll_common.errors.RocketrollError` (the command lines turn those into one
line and exit code 2), except :class:`~rocketroll_common.errors.Interrupted` (Ctrl-C) and a
module's private ones (``_Name``: control flow inside the module, never raised to a caller)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

from rocketroll_common.errors import Interrupted, RocketrollError
from tests.import_graph import LAYERS

#: Every library package (the layers but the command line's).
PACKAGES = tuple(package for package in LAYERS if package != "rocketroll")


def _modules() -> list[str]:
    names = []
    for package in PACKAGES:
        found = importlib.import_module(package)
        walked = pkgutil.walk_packages(found.__path__, package + ".")
        names += [m.name for m in walked if not m.name.endswith(".__main__")]  # they run
    return names


@pytest.mark.parametrize("name", _modules())
def test_every_exception_is_in_the_hierarchy(name: str) -> None:
    try:
        module = importlib.import_module(name)
    except ImportError as exc:  # an optional extra's module without the extra
        pytest.skip(f"{name}: {exc}")
    defined = [
        cls
        for _, cls in inspect.getmembers(module, inspect.isclass)
        if cls.__module__ == name
        and issubclass(cls, BaseException)
        and not cls.__name__.startswith("_")
    ]
    for cls in defined:
        assert issubclass(cls, RocketrollError) or cls is Interrupted, cls


def test_errors_with_their_own_arguments_cross_a_process_boundary() -> None:
    """An error raised in a worker process is pickled back to the parent: one whose
    ``__init__`` takes its own arguments must pickle with them (a benchmark's process pool
    once died on a RecordingError it could not unpickle)."""
    import pickle

    from identification.recordings.recording import RecordingError
    from rocketroll_common.errors import SettingError

    for error in (RecordingError("a.csv", 3, "bad"), SettingError("stops", "too small")):
        error.add_note("in the worker")
        back = pickle.loads(pickle.dumps(error))
        assert type(back) is type(error) and str(back) == str(error)
        assert vars(back) == vars(error) and back.__notes__ == ["in the worker"]
