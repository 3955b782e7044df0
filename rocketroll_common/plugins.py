"""Where rocketroll's plugins come from: the entry points of one group and one environment
variable.  Light to import: the command line asks before it imports anything else (a
plugin's controllers and methods change a command's ``--help``)."""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from functools import partial
from typing import Any

__all__ = ["PLUGIN_GROUP", "PLUGIN_VARIABLE", "plugin_modules"]

#: Entry-point group of rocketroll plugins.
PLUGIN_GROUP = "rocketroll.plugins"
#: Environment variable naming plugin modules (comma-separated).
PLUGIN_VARIABLE = "ROCKETROLL_PLUGINS"


def plugin_modules() -> list[tuple[str, Callable[[], Any]]]:
    """``(what, load)`` of every plugin module, not yet imported: the entry points of
    :data:`PLUGIN_GROUP`, then the modules ``$ROCKETROLL_PLUGINS`` names."""
    from importlib.metadata import entry_points

    modules: list[tuple[str, Callable[[], Any]]] = [
        (f"entry point {p.name!r} ({p.value})", p.load) for p in entry_points(group=PLUGIN_GROUP)
    ]
    for name in os.environ.get(PLUGIN_VARIABLE, "").split(","):
        if name.strip():
            modules.append(
                (
                    f"${PLUGIN_VARIABLE} module {name.strip()!r}",
                    partial(importlib.import_module, name.strip()),
                )
            )
    return modules
