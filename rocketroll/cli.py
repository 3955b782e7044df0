"""The ``rocketroll`` command line: one table of commands, each defined by its layer.

``rocketroll --help`` imports nothing but this module and the standard
library, so it answers at once; so does ``rocketroll COMMAND --help``, from
the help kept with the package (:mod:`rocketroll.help`).  ``rocketroll COMMAND ...`` imports the
command's module, builds its parser from the command's settings dataclass
(:mod:`rocketroll_common.settings`) and runs it: errors a user can cause
become one line on stderr and exit code 2, Ctrl-C one line and 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from rocketroll_common import __version__
from rocketroll_common.settings import Command, renamed_note, run_command

__all__ = ["ALIASES", "COMMANDS", "build_parser", "main", "write_help"]

#: Command -> (module defining it in its ``COMMANDS``, one line of help).
COMMANDS: dict[str, tuple[str, str]] = {
    "tunnel": ("identification.cli", "run the virtual wind tunnel and write a synthetic recording"),
    "record-flight": (
        "identification.cli",
        "fly the virtual flight recorder and write a synthetic flight log",
    ),
    "import-csv": ("identification.cli", "convert a foreign CSV/text log into a recording"),
    "info": ("identification.cli", "validate a recording and print its summary"),
    "identify": (
        "disturbances.identify",
        "identify roll parameters and the disturbance u_d(t) from a recording",
    ),
    "db": (
        "disturbances.cli",
        "the disturbance database: build, list, show, add, surrogate, export, import, migrate",
    ),
    "env": ("rollenv.cli", "run RocketRoll episodes (Gymnasium environment)"),
    "train": ("agents.cli", "train a controller (PPO, SAC, TD3; Stable-Baselines3)"),
    "eval": ("agents.cli", "evaluate controllers on held-out episodes (table, JSON, plots)"),
    "seeds": (
        "agents.cli",
        "a learned controller over training seeds: mean, IQM, bootstrap CIs, P(beats PID)",
    ),
    "robustness": (
        "agents.cli",
        "controllers designed once, evaluated on surrogates, randomised rockets, stronger "
        "turbulence and other methods' replays",
    ),
    "sweep": (
        "agents.cli",
        "sweeps over controllers, settings, seeds and tasks, resumable, into a results store",
    ),
    "tune": (
        "agents.cli",
        "re-tune a controller's design on train episodes (the PID's bandwidth)",
    ),
}

#: Former name -> command: renamed commands still run under their old names for a release
#: (not listed; a run says the new name on stderr).
ALIASES: dict[str, str] = {"flight": "record-flight"}


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser: ``--version`` and the list of commands (their options are
    parsed by the command's own parser)."""
    parser = argparse.ArgumentParser(
        prog="rocketroll",
        description="Rocket roll dynamics under turbulence: virtual wind tunnel, recordings, "
        "identification (Minimal modelling approach ..., eq. 36/49), disturbance database, "
        "RocketRoll environments, controllers and their evaluation.  "
        "`rocketroll COMMAND --help` lists a command's options.",
    )
    parser.add_argument("--version", action="version", version=f"rocketroll {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (_, text) in COMMANDS.items():
        sub.add_parser(name, help=text, add_help=False)
    for alias in ALIASES:  # no help=: not in the list of commands
        sub.add_parser(alias, add_help=False)
    return parser


def command(name: str) -> Command:
    """The :class:`Command` called ``name`` (imports its module)."""
    module, _ = COMMANDS[name]
    found: Command = importlib.import_module(module).COMMANDS[name]
    return found


def write_help() -> None:
    """Write ``rocketroll/help.json``: every command's help, for ``rocketroll COMMAND
    --help`` without importing the command (``make help``; imports every command)."""
    from rocketroll.help import CACHE, write

    write({name: command(name).help_tree() for name in COMMANDS})
    print(f"wrote {CACHE}: the help of {len(COMMANDS)} commands")


#: The spec models whose JSON Schemas are kept in ``docs/schemas/`` (``STEM.schema.json``).
SCHEMAS: dict[str, str] = {
    "sweep": "agents.sweep.spec:SweepDocument",
    "hyperparams": "agents.train.hyperparams:HyperparameterFile",
    "ascent": "rocketroll_physics.ascent:AscentDocument",
}


def write_schemas() -> None:
    """Write ``docs/schemas/STEM.schema.json`` for every model of :data:`SCHEMAS` (``make
    schemas``; a test checks that they are current)."""
    from rocketroll_common.specs import SCHEMAS_DIR, schema_text

    SCHEMAS_DIR.mkdir(parents=True, exist_ok=True)
    for stem, target in SCHEMAS.items():
        module, _, name = target.partition(":")
        path = SCHEMAS_DIR / f"{stem}.schema.json"
        path.write_text(schema_text(getattr(importlib.import_module(module), name)), "utf-8")
        print(f"wrote {path}")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    from rocketroll.help import cached_help

    words = list(sys.argv[1:] if argv is None else argv)
    ns, rest = build_parser().parse_known_args(words)
    if ns.command in ALIASES:
        renamed_note(f"rocketroll {ns.command}", f"rocketroll {ALIASES[ns.command]}")
        ns.command = ALIASES[ns.command]
    prog = f"rocketroll {ns.command}"
    text = cached_help(ns.command, rest, prog)  # without importing the command's module
    if text is not None:
        sys.stdout.write(text)
        return 0
    from rocketroll_common.numerics import one_blas_thread

    one_blas_thread()  # before the command's module loads numpy
    return run_command(command(ns.command), rest, prog=prog)


if __name__ == "__main__":
    sys.exit(main())
